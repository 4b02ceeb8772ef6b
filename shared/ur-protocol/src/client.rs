//! A blocking RTDE client over a [`TcpStream`] (std): the one the project's setup and
//! recording code share (`rt-controller`'s `ur` arm setup, `learner record`, the `hil-sim`
//! tests of `ur-sim`). It allocates and blocks: setup and observers only, never a real-time
//! loop (that one reads through [`crate::stream::FrameDecoder`] itself).
//!
//! Every read of a step is bounded by one deadline ([`Client::restart_deadline`]), not per
//! read: a robot that keeps sending text messages and never the answer does not hold the
//! caller for ever. Text messages are counted and the newest [`KEPT_TEXTS`] kept.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use crate::modes::{robot_mode_name, safety_mode_name};
use crate::recipe::{OutputRecipe, RecipeError};
use crate::rtde::{ControllerVersion, Frame, FrameError, PackageType, Protocol, MAX_FRAME};
use crate::{
    ClientMessage, DecodeError, EncodeError, FrameDecoder, RobotMessage, RobotMode, RobotState,
    SafetyMode, TextMessage,
};

/// Text messages a client keeps (the newest; all are counted): a robot that only talks
/// cannot grow them without bound.
pub const KEPT_TEXTS: usize = 16;

/// What can go wrong talking RTDE to a controller; `during` names the step.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// No TCP connection.
    #[error("cannot connect to the RTDE interface at {addr}: {why}")]
    Connect {
        /// Where.
        addr: SocketAddr,
        /// The OS error.
        why: std::io::Error,
    },
    /// A read or write failed.
    #[error("RTDE {during}: {why}")]
    Io {
        /// The step.
        during: &'static str,
        /// The OS error.
        why: std::io::Error,
    },
    /// The robot closed the connection.
    #[error("the robot closed the RTDE connection during {0}")]
    Closed(&'static str),
    /// Framing lost.
    #[error("RTDE {during}: {why}")]
    Frame {
        /// The step.
        during: &'static str,
        /// The decoder's error.
        why: FrameError,
    },
    /// A package that does not decode.
    #[error("RTDE {during}: {why}")]
    Decode {
        /// The step.
        during: &'static str,
        /// The decoder's error.
        why: DecodeError,
    },
    /// A request that does not encode.
    #[error("RTDE {during}: {why}")]
    Encode {
        /// The step.
        during: &'static str,
        /// The encoder's error.
        why: EncodeError,
    },
    /// An answer of the wrong type.
    #[error("RTDE {during}: expected its answer, got a {got:?} package")]
    Unexpected {
        /// The step.
        during: &'static str,
        /// What came.
        got: PackageType,
    },
    /// The step's deadline passed.
    #[error("RTDE {during}: no answer within {timeout_s} s; the robot sent {texts_total} text messages meanwhile{}{texts:?}", if *texts_total > 0 { ", the newest: " } else { "" })]
    Deadline {
        /// The step.
        during: &'static str,
        /// The timeout (s).
        timeout_s: f64,
        /// Text messages received, all of them counted.
        texts_total: u64,
        /// The newest of them (at most [`KEPT_TEXTS`]).
        texts: Vec<String>,
    },
    /// Neither protocol version accepted.
    #[error("the controller refused RTDE protocol versions 2 and 1; is this a UR controller (CB3 ≥ 3.4 or e-Series)?")]
    NoProtocol,
    /// The output recipe is unusable.
    #[error("RTDE output recipe: {0}")]
    Recipe(#[from] RecipeError),
    /// START refused.
    #[error("the controller refused RTDE START; another client may hold the interface, or the controller is busy: try again")]
    StartRefused,
    /// robot_mode is not RUNNING.
    #[error("robot mode is {name} ({code}), not RUNNING: power the arm on and release the brakes (teach pendant or dashboard server), then start again")]
    NotRunning {
        /// The mode's name.
        name: &'static str,
        /// Its code.
        code: i32,
    },
    /// safety_mode is not NORMAL.
    #[error("safety mode is {name} ({code}), not NORMAL: clear the stop on the teach pendant (and its cause), then start again")]
    NotNormal {
        /// The mode's name.
        name: &'static str,
        /// Its code.
        code: i32,
    },
}

/// A frame copied out of the decoder.
#[derive(Debug, Clone)]
pub struct OwnedFrame {
    /// Its package type.
    pub kind: PackageType,
    /// Its payload (the header stripped).
    pub payload: Vec<u8>,
}

impl OwnedFrame {
    /// The frame decoded under `protocol`.
    pub fn decode(
        &self,
        protocol: Protocol,
        during: &'static str,
    ) -> Result<RobotMessage<'_>, ClientError> {
        let f = Frame {
            kind: self.kind,
            payload: &self.payload,
        };
        RobotMessage::decode(&f, protocol).map_err(|why| ClientError::Decode { during, why })
    }
}

/// A blocking RTDE client (see the module documentation).
pub struct Client {
    s: TcpStream,
    dec: Box<FrameDecoder<8192>>,
    /// Protocol v1 until [`Client::negotiate`] (or the caller) sets it.
    pub protocol: Protocol,
    texts: Vec<String>,
    texts_total: u64,
    deadline: Instant,
    timeout: Duration,
}

impl Client {
    /// A client on the connected socket `s`, protocol v1, its deadline `timeout` from now.
    pub fn new(s: TcpStream, timeout: Duration) -> Self {
        Self {
            s,
            dec: Box::default(),
            protocol: Protocol::V1,
            texts: Vec::new(),
            texts_total: 0,
            deadline: Instant::now() + timeout,
            timeout,
        }
    }

    /// Connects to `addr` within `timeout` (no delay on the socket).
    pub fn connect(addr: SocketAddr, timeout: Duration) -> Result<Self, ClientError> {
        let s = TcpStream::connect_timeout(&addr, timeout)
            .map_err(|why| ClientError::Connect { addr, why })?;
        s.set_nodelay(true).map_err(io("setup"))?;
        Ok(Self::new(s, timeout))
    }

    /// The next steps end by `timeout` from now.
    pub fn restart_deadline(&mut self, timeout: Duration) {
        self.timeout = timeout;
        self.deadline = Instant::now() + timeout;
    }

    /// The socket (its local address, raw writes).
    pub fn socket(&mut self) -> &mut TcpStream {
        &mut self.s
    }

    /// The newest [`KEPT_TEXTS`] text messages, oldest first.
    pub fn texts(&self) -> &[String] {
        &self.texts
    }

    /// The kept text messages, taken (the count goes on).
    pub fn take_texts(&mut self) -> Vec<String> {
        std::mem::take(&mut self.texts)
    }

    /// Socket, decoder (frames not read yet included), protocol and kept texts.
    pub fn into_parts(self) -> (TcpStream, Box<FrameDecoder<8192>>, Protocol, Vec<String>) {
        (self.s, self.dec, self.protocol, self.texts)
    }

    /// Sends one request (any size up to the RTDE maximum).
    pub fn send(&mut self, m: ClientMessage<'_>, during: &'static str) -> Result<(), ClientError> {
        let mut buf = vec![0u8; MAX_FRAME];
        let n = m
            .encode(&mut buf)
            .map_err(|why| ClientError::Encode { during, why })?;
        self.s.write_all(&buf[..n]).map_err(io(during))
    }

    /// The next frame of any type, text messages included (and counted, kept).
    pub fn next_frame(&mut self, during: &'static str) -> Result<OwnedFrame, ClientError> {
        loop {
            let frame = self
                .dec
                .next_frame()
                .map_err(|why| ClientError::Frame { during, why })?
                .map(|f| OwnedFrame {
                    kind: f.kind,
                    payload: f.payload.to_vec(),
                });
            if let Some(f) = frame {
                if f.kind == PackageType::TextMessage {
                    self.keep_text(&f);
                }
                return Ok(f);
            }
            let left = self.deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(self.deadline_passed(during));
            }
            self.s.set_read_timeout(Some(left)).map_err(io(during))?;
            match self.s.read(self.dec.spare()) {
                Ok(0) => return Err(ClientError::Closed(during)),
                Ok(n) => self.dec.commit(n),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if crate::stream::timed_out(&e) => return Err(self.deadline_passed(during)),
                Err(why) => return Err(ClientError::Io { during, why }),
            }
        }
    }

    /// The next frame that is not a text message (texts are kept).
    pub fn next(&mut self, during: &'static str) -> Result<OwnedFrame, ClientError> {
        loop {
            let f = self.next_frame(during)?;
            if f.kind != PackageType::TextMessage {
                return Ok(f);
            }
        }
    }

    fn keep_text(&mut self, f: &OwnedFrame) {
        let text = match f.decode(self.protocol, "text message") {
            Ok(RobotMessage::TextMessage(TextMessage::V1(b))) => {
                // v1 (before negotiation): a level byte, then the text.
                String::from_utf8_lossy(b)
                    .trim_start_matches(|c: char| c.is_control())
                    .to_owned()
            }
            Ok(RobotMessage::TextMessage(t)) => format!("{t:?}"),
            _ => "(undecodable text message)".into(),
        };
        if self.texts.len() >= KEPT_TEXTS {
            self.texts.remove(0);
        }
        self.texts.push(text);
        self.texts_total += 1;
    }

    fn deadline_passed(&self, during: &'static str) -> ClientError {
        ClientError::Deadline {
            during,
            timeout_s: self.timeout.as_secs_f64(),
            texts_total: self.texts_total,
            texts: self.texts.clone(),
        }
    }

    /// Sends `m` and picks its answer from the next frame that is not a text message.
    pub fn ask<T>(
        &mut self,
        m: ClientMessage<'_>,
        during: &'static str,
        pick: impl Fn(RobotMessage<'_>) -> Option<T>,
    ) -> Result<T, ClientError> {
        self.send(m, during)?;
        let frame = self.next(during)?;
        pick(frame.decode(self.protocol, during)?).ok_or(ClientError::Unexpected {
            during,
            got: frame.kind,
        })
    }

    /// Asks for protocol `version`; on yes the client speaks it.
    pub fn request_protocol(&mut self, version: u16) -> Result<bool, ClientError> {
        let accepted = self.ask(
            ClientMessage::RequestProtocolVersion(version),
            "protocol negotiation",
            |m| match m {
                RobotMessage::ProtocolVersion { accepted } => Some(accepted),
                _ => None,
            },
        )?;
        if let (true, Some(p)) = (accepted, Protocol::from_u16(version)) {
            self.protocol = p;
        }
        Ok(accepted)
    }

    /// Protocol v2, else v1.
    pub fn negotiate(&mut self) -> Result<Protocol, ClientError> {
        for v in [2u16, 1] {
            if self.request_protocol(v)? {
                return Ok(self.protocol);
            }
        }
        Err(ClientError::NoProtocol)
    }

    /// The controller's version.
    pub fn controller_version(&mut self) -> Result<ControllerVersion, ClientError> {
        self.ask(
            ClientMessage::GetUrcontrolVersion,
            "controller version",
            |m| match m {
                RobotMessage::UrcontrolVersion(v) => Some(v),
                _ => None,
            },
        )
    }

    /// The output recipe `names` at `rate_hz` (sent under v2 only).
    pub fn setup_outputs(
        &mut self,
        names: &str,
        rate_hz: f64,
    ) -> Result<OutputRecipe, ClientError> {
        let (recipe_id, types) = self.ask(
            ClientMessage::SetupOutputs {
                frequency: (self.protocol == Protocol::V2).then_some(rate_hz),
                names,
            },
            "output recipe",
            |m| match m {
                RobotMessage::SetupOutputs { recipe_id, types } => {
                    Some((recipe_id, types.to_owned()))
                }
                _ => None,
            },
        )?;
        Ok(OutputRecipe::from_answer(names, recipe_id, &types)?)
    }

    /// START; refused is an error.
    pub fn start(&mut self) -> Result<(), ClientError> {
        let started = self.ask(ClientMessage::Start, "START", |m| match m {
            RobotMessage::Start { accepted } => Some(accepted),
            _ => None,
        })?;
        started.then_some(()).ok_or(ClientError::StartRefused)
    }

    /// An observer's handshake: the protocol, the controller's version, `names` at the
    /// controller's rate, START.
    pub fn handshake(
        &mut self,
        names: &str,
    ) -> Result<(ControllerVersion, OutputRecipe), ClientError> {
        self.negotiate()?;
        let version = self.controller_version()?;
        let recipe = self.setup_outputs(names, version.max_frequency_hz())?;
        self.start()?;
        Ok((version, recipe))
    }

    /// The next data package decoded into a state.
    pub fn state(&mut self, recipe: &OutputRecipe) -> Result<RobotState, ClientError> {
        let during = "first data package";
        loop {
            let frame = self.next(during)?;
            let m = frame.decode(self.protocol, during)?;
            let mut s = RobotState::default();
            if s.update(recipe, &m)
                .map_err(|why| ClientError::Decode { during, why })?
            {
                return Ok(s);
            }
        }
    }

    /// Reads every package queued since the last read (non-blocking) into `state`.
    pub fn catch_up(
        &mut self,
        recipe: &OutputRecipe,
        state: &mut RobotState,
    ) -> Result<(), ClientError> {
        let during = "reading the queued packages";
        self.s.set_nonblocking(true).map_err(io(during))?;
        let result = loop {
            match self.s.read(self.dec.spare()) {
                Ok(0) => break Err(ClientError::Closed(during)),
                Ok(n) => {
                    self.dec.commit(n);
                    while let Some(f) = self
                        .dec
                        .next_frame()
                        .map_err(|why| ClientError::Frame { during, why })?
                    {
                        let m = RobotMessage::decode(&f, self.protocol)
                            .map_err(|why| ClientError::Decode { during, why })?;
                        state
                            .update(recipe, &m)
                            .map_err(|why| ClientError::Decode { during, why })?;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break Ok(()),
                Err(why) => break Err(ClientError::Io { during, why }),
            }
        };
        self.s.set_nonblocking(false).map_err(io(during))?;
        result
    }
}

/// Refuses an arm that is not RUNNING with safety NORMAL.
pub fn check_modes(s: &RobotState) -> Result<(), ClientError> {
    let (robot, safety) = (s.robot_mode, s.safety_mode);
    if robot != RobotMode::Running.code() {
        return Err(ClientError::NotRunning {
            name: robot_mode_name(robot),
            code: robot,
        });
    }
    if safety != SafetyMode::Normal.code() {
        return Err(ClientError::NotNormal {
            name: safety_mode_name(safety),
            code: safety,
        });
    }
    Ok(())
}

fn io(during: &'static str) -> impl Fn(std::io::Error) -> ClientError {
    move |why| ClientError::Io { during, why }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mode_check_names_the_mode() {
        let mut s = RobotState {
            robot_mode: RobotMode::Running.code(),
            safety_mode: SafetyMode::Normal.code(),
            ..RobotState::default()
        };
        check_modes(&s).unwrap();
        s.safety_mode = SafetyMode::ProtectiveStop.code();
        let e = check_modes(&s).unwrap_err().to_string();
        assert!(
            e.contains("PROTECTIVE_STOP") && e.contains("not NORMAL"),
            "{e}"
        );
        s.robot_mode = 3;
        let e = check_modes(&s).unwrap_err().to_string();
        assert!(e.contains("POWER_OFF") && e.contains("not RUNNING"), "{e}");
    }
}
