//! RTDE packages (TCP 30004): the frame, every request a client sends and every answer a
//! controller sends (docs/design.md §3.10).
//!
//! Frame layout: `u16` size (big-endian, counts the 3-byte header), `u8` package type, payload.
//! The same type byte is used for a request and its answer, so a payload's meaning depends on
//! the direction: [`ClientMessage`] (client → controller) and [`RobotMessage`]
//! (controller → client). Two payloads also depend on the negotiated protocol version
//! ([`Protocol`]): SETUP_OUTPUTS carries an `f64` frequency from v2 on, and TEXT_MESSAGE has the
//! v2 layout `u8 len, message, u8 len, source, u8 level` (a v1 text is kept as opaque bytes).
//!
//! Payloads per type (client → controller / controller → client):
//!
//! | type | request | answer |
//! |---|---|---|
//! | `V` 86 REQUEST_PROTOCOL_VERSION | `u16` version | `u8` accepted |
//! | `v` 118 GET_URCONTROL_VERSION | – | 4 × `u32` major, minor, bugfix, build |
//! | `O` 79 SETUP_OUTPUTS | (v2) `f64` Hz, names | `u8` recipe id, types |
//! | `I` 73 SETUP_INPUTS | names | `u8` recipe id, types |
//! | `S` 83 START, `P` 80 PAUSE | – | `u8` accepted |
//! | `U` 85 DATA_PACKAGE | `u8` recipe id, values | `u8` recipe id, values |
//! | `M` 77 TEXT_MESSAGE | text (v2 layout) | text (v2 layout), at any time |
//!
//! Names and types are comma-separated ASCII lists running to the end of the payload.

use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError};

/// Bytes of the frame header (`u16` size, `u8` type).
pub const HEADER_LEN: usize = 3;

/// Largest frame the 16-bit size field allows (bytes, header included).
pub const MAX_FRAME: usize = u16::MAX as usize;

/// RTDE protocol versions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Protocol {
    /// v1: SETUP_OUTPUTS without frequency (packages at the controller's rate).
    V1 = 1,
    /// v2: SETUP_OUTPUTS with an `f64` frequency; structured text messages.
    V2 = 2,
}

impl Protocol {
    /// The version for a requested number, `None` if this project does not speak it.
    pub const fn from_u16(v: u16) -> Option<Self> {
        match v {
            1 => Some(Protocol::V1),
            2 => Some(Protocol::V2),
            _ => None,
        }
    }
}

/// The package type byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PackageType {
    /// `V`: protocol version request / answer.
    RequestProtocolVersion = b'V',
    /// `v`: controller software version.
    GetUrcontrolVersion = b'v',
    /// `M`: text message.
    TextMessage = b'M',
    /// `U`: data package.
    DataPackage = b'U',
    /// `O`: output recipe setup.
    SetupOutputs = b'O',
    /// `I`: input recipe setup.
    SetupInputs = b'I',
    /// `S`: start sending data packages.
    Start = b'S',
    /// `P`: pause.
    Pause = b'P',
}

impl PackageType {
    /// The type for a byte, `None` if unknown.
    pub const fn from_u8(b: u8) -> Option<Self> {
        Some(match b {
            b'V' => Self::RequestProtocolVersion,
            b'v' => Self::GetUrcontrolVersion,
            b'M' => Self::TextMessage,
            b'U' => Self::DataPackage,
            b'O' => Self::SetupOutputs,
            b'I' => Self::SetupInputs,
            b'S' => Self::Start,
            b'P' => Self::Pause,
            _ => return None,
        })
    }
}

/// Why bytes do not start a valid frame. The stream's framing is lost after one of these:
/// close the connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The size field is below the header size.
    #[error("RTDE frame size {size} is below the 3-byte header: not an RTDE stream (wrong port?)")]
    TooShort {
        /// Size field.
        size: u16,
    },
    /// The size field exceeds the receiver's buffer.
    #[error("RTDE frame of {size} bytes exceeds this receiver's {capacity}-byte buffer")]
    TooLarge {
        /// Size field.
        size: u16,
        /// Buffer capacity.
        capacity: usize,
    },
    /// An unknown package type.
    #[error("unknown RTDE package type {0} (0x{0:02x}): not an RTDE stream, or a newer protocol")]
    UnknownType(u8),
}

/// One complete RTDE frame, borrowed from the receive buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame<'a> {
    /// Package type.
    pub kind: PackageType,
    /// Payload (after the header).
    pub payload: &'a [u8],
}

impl<'a> Frame<'a> {
    /// Parses the frame at the start of `bytes`: `Ok(None)` if more bytes are needed, else the
    /// frame and its length. `capacity` bounds the accepted size (the receiver's buffer).
    pub fn parse(bytes: &'a [u8], capacity: usize) -> Result<Option<(Self, usize)>, FrameError> {
        let [s0, s1, kind, ..] = *bytes else {
            return Ok(None);
        };
        let size = u16::from_be_bytes([s0, s1]);
        if usize::from(size) < HEADER_LEN {
            return Err(FrameError::TooShort { size });
        }
        if usize::from(size) > capacity {
            return Err(FrameError::TooLarge { size, capacity });
        }
        let kind = PackageType::from_u8(kind).ok_or(FrameError::UnknownType(kind))?;
        let size = usize::from(size);
        if bytes.len() < size {
            return Ok(None);
        }
        Ok(Some((
            Frame {
                kind,
                payload: &bytes[HEADER_LEN..size],
            },
            size,
        )))
    }
}

/// The controller's software version (GET_URCONTROL_VERSION answer).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct ControllerVersion {
    /// Major: 3 = CB3, ≥ 5 = e-Series.
    pub major: u32,
    /// Minor.
    pub minor: u32,
    /// Bugfix.
    pub bugfix: u32,
    /// Build.
    pub build: u32,
}

impl ControllerVersion {
    /// True for an e-Series (or later) controller: major ≥ 5.
    pub const fn is_e_series(&self) -> bool {
        self.major >= 5
    }

    /// The controller's control and RTDE rate (Hz): 500 for e-Series, 125 for CB3.
    pub const fn max_frequency_hz(&self) -> f64 {
        if self.is_e_series() {
            500.0
        } else {
            125.0
        }
    }
}

impl core::fmt::Display for ControllerVersion {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{}.{}.{}.{}",
            self.major, self.minor, self.bugfix, self.build
        )
    }
}

/// Warning level of a text message.
pub mod level {
    /// Exception.
    pub const EXCEPTION: u8 = 0;
    /// Error.
    pub const ERROR: u8 = 1;
    /// Warning.
    pub const WARNING: u8 = 2;
    /// Information.
    pub const INFO: u8 = 3;
}

/// A text message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextMessage<'a> {
    /// v2 layout: `u8` length + message, `u8` length + source, `u8` level ([`level`]).
    V2 {
        /// Message text (≤ 255 bytes).
        message: &'a str,
        /// Who sent it (≤ 255 bytes).
        source: &'a str,
        /// Warning level.
        level: u8,
    },
    /// v1: the payload as sent (this project does not interpret v1 text).
    V1(&'a [u8]),
}

impl<'a> TextMessage<'a> {
    fn decode(r: &mut Reader<'a>, protocol: Protocol) -> Result<Self, DecodeError> {
        Ok(match protocol {
            Protocol::V1 => TextMessage::V1(r.rest()),
            Protocol::V2 => TextMessage::V2 {
                message: r.short_str()?,
                source: r.short_str()?,
                level: r.u8()?,
            },
        })
    }

    fn encode(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        match *self {
            TextMessage::V2 {
                message,
                source,
                level,
            } => {
                w.short_str("text message", message)?;
                w.short_str("text message source", source)?;
                w.u8(level)
            }
            TextMessage::V1(raw) => w.put(raw),
        }
    }
}

/// A package from the client to the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ClientMessage<'a> {
    /// Asks for a protocol version.
    RequestProtocolVersion(u16),
    /// Asks the controller's software version.
    GetUrcontrolVersion,
    /// Output recipe: frequency (Hz, v2 only) and comma-separated names.
    SetupOutputs {
        /// Requested package rate (Hz); `None` in v1.
        frequency: Option<f64>,
        /// Comma-separated names.
        names: &'a str,
    },
    /// Input recipe: comma-separated names.
    SetupInputs {
        /// Comma-separated names.
        names: &'a str,
    },
    /// Start the data stream.
    Start,
    /// Pause the data stream.
    Pause,
    /// Input values for a recipe.
    DataPackage {
        /// Input recipe id.
        recipe_id: u8,
        /// Values in recipe order.
        values: &'a [u8],
    },
    /// A text message for the controller's log.
    TextMessage(TextMessage<'a>),
}

/// A package from the controller to the client.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RobotMessage<'a> {
    /// Whether the requested protocol version is accepted.
    ProtocolVersion {
        /// Accepted.
        accepted: bool,
    },
    /// Controller software version.
    UrcontrolVersion(ControllerVersion),
    /// Output recipe answer.
    SetupOutputs {
        /// Recipe id.
        recipe_id: u8,
        /// Comma-separated types (or NOT_FOUND / IN_USE).
        types: &'a str,
    },
    /// Input recipe answer.
    SetupInputs {
        /// Recipe id.
        recipe_id: u8,
        /// Comma-separated types (or NOT_FOUND / IN_USE).
        types: &'a str,
    },
    /// Whether START was accepted.
    Start {
        /// Accepted.
        accepted: bool,
    },
    /// Whether PAUSE was accepted.
    Pause {
        /// Accepted.
        accepted: bool,
    },
    /// Output values for a recipe.
    DataPackage {
        /// Output recipe id.
        recipe_id: u8,
        /// Values in recipe order.
        values: &'a [u8],
    },
    /// A text message (may come at any time, also before an answer).
    TextMessage(TextMessage<'a>),
}

fn accepted(r: &mut Reader<'_>) -> Result<bool, DecodeError> {
    Ok(r.u8()? != 0)
}

impl<'a> ClientMessage<'a> {
    /// Decodes a frame the controller received.
    pub fn decode(frame: &Frame<'a>, protocol: Protocol) -> Result<Self, DecodeError> {
        use PackageType as T;
        let what = match frame.kind {
            T::RequestProtocolVersion => "REQUEST_PROTOCOL_VERSION",
            T::GetUrcontrolVersion => "GET_URCONTROL_VERSION",
            T::SetupOutputs => "SETUP_OUTPUTS",
            T::SetupInputs => "SETUP_INPUTS",
            T::Start => "START",
            T::Pause => "PAUSE",
            T::DataPackage => "DATA_PACKAGE",
            T::TextMessage => "TEXT_MESSAGE",
        };
        let mut r = Reader::new(frame.payload, what);
        let m = match frame.kind {
            T::RequestProtocolVersion => ClientMessage::RequestProtocolVersion(r.u16()?),
            T::GetUrcontrolVersion => ClientMessage::GetUrcontrolVersion,
            T::SetupOutputs => ClientMessage::SetupOutputs {
                frequency: match protocol {
                    Protocol::V1 => None,
                    Protocol::V2 => Some(r.f64()?),
                },
                names: r.rest_str()?,
            },
            T::SetupInputs => ClientMessage::SetupInputs {
                names: r.rest_str()?,
            },
            T::Start => ClientMessage::Start,
            T::Pause => ClientMessage::Pause,
            T::DataPackage => ClientMessage::DataPackage {
                recipe_id: r.u8()?,
                values: r.rest(),
            },
            T::TextMessage => ClientMessage::TextMessage(TextMessage::decode(&mut r, protocol)?),
        };
        r.end()?;
        Ok(m)
    }

    /// Encodes this package into `buf`; returns its length.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::after_header(buf, HEADER_LEN)?;
        let kind = match *self {
            ClientMessage::RequestProtocolVersion(v) => {
                w.u16(v)?;
                PackageType::RequestProtocolVersion
            }
            ClientMessage::GetUrcontrolVersion => PackageType::GetUrcontrolVersion,
            ClientMessage::SetupOutputs { frequency, names } => {
                if let Some(f) = frequency {
                    w.f64(f)?;
                }
                w.put(names.as_bytes())?;
                PackageType::SetupOutputs
            }
            ClientMessage::SetupInputs { names } => {
                w.put(names.as_bytes())?;
                PackageType::SetupInputs
            }
            ClientMessage::Start => PackageType::Start,
            ClientMessage::Pause => PackageType::Pause,
            ClientMessage::DataPackage { recipe_id, values } => {
                w.u8(recipe_id)?;
                w.put(values)?;
                PackageType::DataPackage
            }
            ClientMessage::TextMessage(t) => {
                t.encode(&mut w)?;
                PackageType::TextMessage
            }
        };
        w.finish_package(kind as u8)
    }
}

impl<'a> RobotMessage<'a> {
    /// Decodes a frame the client received.
    pub fn decode(frame: &Frame<'a>, protocol: Protocol) -> Result<Self, DecodeError> {
        use PackageType as T;
        let what = match frame.kind {
            T::RequestProtocolVersion => "protocol version answer",
            T::GetUrcontrolVersion => "controller version answer",
            T::SetupOutputs => "SETUP_OUTPUTS answer",
            T::SetupInputs => "SETUP_INPUTS answer",
            T::Start => "START answer",
            T::Pause => "PAUSE answer",
            T::DataPackage => "DATA_PACKAGE",
            T::TextMessage => "TEXT_MESSAGE",
        };
        let mut r = Reader::new(frame.payload, what);
        let m = match frame.kind {
            T::RequestProtocolVersion => RobotMessage::ProtocolVersion {
                accepted: accepted(&mut r)?,
            },
            T::GetUrcontrolVersion => RobotMessage::UrcontrolVersion(ControllerVersion {
                major: r.u32()?,
                minor: r.u32()?,
                bugfix: r.u32()?,
                build: r.u32()?,
            }),
            T::SetupOutputs => RobotMessage::SetupOutputs {
                recipe_id: r.u8()?,
                types: r.rest_str()?,
            },
            T::SetupInputs => RobotMessage::SetupInputs {
                recipe_id: r.u8()?,
                types: r.rest_str()?,
            },
            T::Start => RobotMessage::Start {
                accepted: accepted(&mut r)?,
            },
            T::Pause => RobotMessage::Pause {
                accepted: accepted(&mut r)?,
            },
            T::DataPackage => RobotMessage::DataPackage {
                recipe_id: r.u8()?,
                values: r.rest(),
            },
            T::TextMessage => RobotMessage::TextMessage(TextMessage::decode(&mut r, protocol)?),
        };
        r.end()?;
        Ok(m)
    }

    /// Encodes this package into `buf`; returns its length.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::after_header(buf, HEADER_LEN)?;
        let kind = match *self {
            RobotMessage::ProtocolVersion { accepted } => {
                w.u8(accepted.into())?;
                PackageType::RequestProtocolVersion
            }
            RobotMessage::UrcontrolVersion(v) => {
                for x in [v.major, v.minor, v.bugfix, v.build] {
                    w.u32(x)?;
                }
                PackageType::GetUrcontrolVersion
            }
            RobotMessage::SetupOutputs { recipe_id, types } => {
                w.u8(recipe_id)?;
                w.put(types.as_bytes())?;
                PackageType::SetupOutputs
            }
            RobotMessage::SetupInputs { recipe_id, types } => {
                w.u8(recipe_id)?;
                w.put(types.as_bytes())?;
                PackageType::SetupInputs
            }
            RobotMessage::Start { accepted } => {
                w.u8(accepted.into())?;
                PackageType::Start
            }
            RobotMessage::Pause { accepted } => {
                w.u8(accepted.into())?;
                PackageType::Pause
            }
            RobotMessage::DataPackage { recipe_id, values } => {
                w.u8(recipe_id)?;
                w.put(values)?;
                PackageType::DataPackage
            }
            RobotMessage::TextMessage(t) => {
                t.encode(&mut w)?;
                PackageType::TextMessage
            }
        };
        w.finish_package(kind as u8)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_client(m: ClientMessage<'_>, p: Protocol) {
        let mut buf = [0u8; 512];
        let n = m.encode(&mut buf).unwrap();
        let (f, len) = Frame::parse(&buf[..n], 4096).unwrap().unwrap();
        assert_eq!(len, n);
        assert_eq!(ClientMessage::decode(&f, p).unwrap(), m);
    }

    fn round_robot(m: RobotMessage<'_>, p: Protocol) {
        let mut buf = [0u8; 512];
        let n = m.encode(&mut buf).unwrap();
        let (f, len) = Frame::parse(&buf[..n], 4096).unwrap().unwrap();
        assert_eq!(len, n);
        assert_eq!(RobotMessage::decode(&f, p).unwrap(), m);
    }

    #[test]
    fn every_package_round_trips() {
        use Protocol::*;
        round_client(ClientMessage::RequestProtocolVersion(2), V2);
        round_client(ClientMessage::GetUrcontrolVersion, V2);
        round_client(
            ClientMessage::SetupOutputs {
                frequency: Some(500.0),
                names: "timestamp,actual_q,",
            },
            V2,
        );
        round_client(
            ClientMessage::SetupOutputs {
                frequency: None,
                names: "timestamp",
            },
            V1,
        );
        round_client(
            ClientMessage::SetupInputs {
                names: "input_int_register_24",
            },
            V2,
        );
        round_client(ClientMessage::Start, V2);
        round_client(ClientMessage::Pause, V1);
        round_client(
            ClientMessage::DataPackage {
                recipe_id: 2,
                values: &[0, 0, 0, 7],
            },
            V2,
        );
        round_client(
            ClientMessage::TextMessage(TextMessage::V2 {
                message: "hi",
                source: "test",
                level: level::INFO,
            }),
            V2,
        );
        round_robot(RobotMessage::ProtocolVersion { accepted: true }, V2);
        round_robot(
            RobotMessage::UrcontrolVersion(ControllerVersion {
                major: 5,
                minor: 9,
                bugfix: 4,
                build: 1031232,
            }),
            V2,
        );
        round_robot(
            RobotMessage::SetupOutputs {
                recipe_id: 1,
                types: "DOUBLE,NOT_FOUND",
            },
            V2,
        );
        round_robot(
            RobotMessage::SetupInputs {
                recipe_id: 2,
                types: "IN_USE",
            },
            V2,
        );
        round_robot(RobotMessage::Start { accepted: false }, V2);
        round_robot(RobotMessage::Pause { accepted: true }, V2);
        round_robot(
            RobotMessage::TextMessage(TextMessage::V2 {
                message: "SafetySetup has not been confirmed yet",
                source: "hil-sim",
                level: level::WARNING,
            }),
            V2,
        );
        round_robot(RobotMessage::TextMessage(TextMessage::V1(b"\x03hello")), V1);
    }

    #[test]
    fn urcl_data_package_vector() {
        // docs/design.md §3.10: URCL's allocation-test package: 20 bytes, DATA_PACKAGE,
        // recipe 1, timestamp 16412.206…, then 1.0.
        let bytes = [
            0x00, 0x14, 0x55, 0x01, 0x40, 0xd0, 0x07, 0x0d, 0x2f, 0x1a, 0x9f, 0xbe, 0x3f, 0xf0, 0,
            0, 0, 0, 0, 0,
        ];
        let (f, n) = Frame::parse(&bytes, 64).unwrap().unwrap();
        assert_eq!((f.kind, n), (PackageType::DataPackage, 20));
        let RobotMessage::DataPackage { recipe_id, values } =
            RobotMessage::decode(&f, Protocol::V2).unwrap()
        else {
            panic!("not a data package")
        };
        assert_eq!(recipe_id, 1);
        let t = f64::from_be_bytes(values[0..8].try_into().unwrap());
        assert!((t - 16412.206).abs() < 1e-3, "{t}");
        assert_eq!(f64::from_be_bytes(values[8..16].try_into().unwrap()), 1.0);
    }

    #[test]
    fn bad_frames_are_typed_errors() {
        assert_eq!(
            Frame::parse(&[0, 2, b'U'], 64),
            Err(FrameError::TooShort { size: 2 })
        );
        assert_eq!(
            Frame::parse(&[1, 0, b'U'], 64),
            Err(FrameError::TooLarge {
                size: 256,
                capacity: 64
            })
        );
        assert_eq!(
            Frame::parse(&[0, 3, b'x'], 64),
            Err(FrameError::UnknownType(b'x'))
        );
        assert_eq!(Frame::parse(&[0, 4, b'U'], 64), Ok(None));
        // A START answer with two bytes is refused, not silently accepted.
        let f = Frame::parse(&[0, 5, b'S', 1, 1], 64).unwrap().unwrap().0;
        assert!(matches!(
            RobotMessage::decode(&f, Protocol::V2),
            Err(DecodeError::TrailingBytes { .. })
        ));
        let mut tiny = [0u8; 2];
        assert!(ClientMessage::Start.encode(&mut tiny).is_err());
    }
}
