//! The ROS 2 messages of the UR driver's interface, with their DDS type names (rosidl's
//! `pkg::msg::dds_::Name_`) and plain CDR encoding ([`crate::cdr`]). Field order and types are
//! those of the `.msg` files of `builtin_interfaces`, `std_msgs`, `sensor_msgs`,
//! `geometry_msgs` and `ur_dashboard_msgs`, identical in Humble and Jazzy.

use crate::cdr::{CdrError, CdrReader, CdrWriter};

/// A ROS 2 message: its names and its CDR body.
pub trait Message: Sized {
    /// The ROS name, `pkg/msg/Name` (what `ros2 topic echo` takes).
    const ROS_TYPE: &'static str;
    /// The DDS type name on the wire, `pkg::msg::dds_::Name_`.
    const DDS_TYPE: &'static str;
    /// Writes the fields (the writer has already written the encapsulation header).
    fn write(&self, w: &mut CdrWriter<'_>);
    /// Reads the fields.
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;

    /// The whole message, encapsulation header included, appended to `buf`.
    fn encode_into(&self, buf: &mut Vec<u8>) {
        self.write(&mut CdrWriter::new(buf));
    }
    /// The whole message, encapsulation header included.
    fn encode(&self) -> Vec<u8> {
        let mut buf = Vec::new();
        self.encode_into(&mut buf);
        buf
    }
    /// Decodes a whole message (header included; either byte order).
    fn decode(msg: &[u8]) -> Result<Self, CdrError> {
        Self::read(&mut CdrReader::new(msg)?)
    }
}

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds (ROS time; since the Unix epoch, or
/// the simulation's clock).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds (e.g. `CLOCK_REALTIME` or a simulated clock); saturates past 2038.
    pub fn from_ns(ns: u64) -> Self {
        Self {
            sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
    /// In nanoseconds (0 for negative times).
    pub fn to_ns(self) -> u64 {
        if self.sec < 0 {
            0
        } else {
            self.sec as u64 * 1_000_000_000 + self.nanosec as u64
        }
    }
}

impl Message for Time {
    const ROS_TYPE: &'static str = "builtin_interfaces/msg/Time";
    const DDS_TYPE: &'static str = "builtin_interfaces::msg::dds_::Time_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self {
            sec: r.i32()?,
            nanosec: r.u32()?,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Header {
    pub stamp: Time,
    /// The frame the data is expressed in (`base_link`, `world`, …).
    pub frame_id: String,
}

impl Message for Header {
    const ROS_TYPE: &'static str = "std_msgs/msg/Header";
    const DDS_TYPE: &'static str = "std_msgs::msg::dds_::Header_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self {
            stamp: Time::read(r)?,
            frame_id: r.str()?.to_owned(),
        })
    }
}

/// `sensor_msgs/msg/JointState`: per joint, by name, position (rad), velocity (rad/s) and
/// effort (N·m); any of the three may be empty. The UR driver's `joint_state_broadcaster`
/// publishes all six joints, in an order that is not guaranteed: match by name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

impl Message for JointState {
    const ROS_TYPE: &'static str = "sensor_msgs/msg/JointState";
    const DDS_TYPE: &'static str = "sensor_msgs::msg::dds_::JointState_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        self.header.write(w);
        w.string_seq(&self.name);
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self {
            header: Header::read(r)?,
            name: r.string_seq()?,
            position: r.f64_seq()?,
            velocity: r.f64_seq()?,
            effort: r.f64_seq()?,
        })
    }
}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MultiArrayDimension {
    pub label: String,
    pub size: u32,
    pub stride: u32,
}

/// `std_msgs/msg/MultiArrayLayout`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MultiArrayLayout {
    pub dim: Vec<MultiArrayDimension>,
    pub data_offset: u32,
}

/// `std_msgs/msg/Float64MultiArray`: what `forward_command_controller`s take, one value per
/// joint of the controller's `joints` parameter, in that order; the layout is ignored by them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Float64MultiArray {
    pub layout: MultiArrayLayout,
    pub data: Vec<f64>,
}

impl Message for Float64MultiArray {
    const ROS_TYPE: &'static str = "std_msgs/msg/Float64MultiArray";
    const DDS_TYPE: &'static str = "std_msgs::msg::dds_::Float64MultiArray_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.count(self.layout.dim.len());
        for d in &self.layout.dim {
            w.string(&d.label);
            w.u32(d.size);
            w.u32(d.stride);
        }
        w.u32(self.layout.data_offset);
        w.f64_seq(&self.data);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let n = r.count(13)?;
        let dim = (0..n)
            .map(|_| {
                Ok(MultiArrayDimension {
                    label: r.str()?.to_owned(),
                    size: r.u32()?,
                    stride: r.u32()?,
                })
            })
            .collect::<Result<_, CdrError>>()?;
        Ok(Self {
            layout: MultiArrayLayout {
                dim,
                data_offset: r.u32()?,
            },
            data: r.f64_seq()?,
        })
    }
}

/// `geometry_msgs/msg/Point` (m).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/PointStamped`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointStamped {
    pub header: Header,
    pub point: Point,
}

impl Message for PointStamped {
    const ROS_TYPE: &'static str = "geometry_msgs/msg/PointStamped";
    const DDS_TYPE: &'static str = "geometry_msgs::msg::dds_::PointStamped_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        self.header.write(w);
        w.f64(self.point.x);
        w.f64(self.point.y);
        w.f64(self.point.z);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self {
            header: Header::read(r)?,
            point: Point {
                x: r.f64()?,
                y: r.f64()?,
                z: r.f64()?,
            },
        })
    }
}

/// `ur_dashboard_msgs/msg/RobotMode` (`int8 mode`), as the driver's `io_and_status_controller`
/// publishes it: `RUNNING` = 7 (the constants are those of UR's RTDE `robot_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RobotMode {
    pub mode: i8,
}

impl RobotMode {
    pub const NO_CONTROLLER: i8 = -1;
    pub const DISCONNECTED: i8 = 0;
    pub const POWER_OFF: i8 = 3;
    pub const IDLE: i8 = 5;
    pub const RUNNING: i8 = 7;
}

impl Message for RobotMode {
    const ROS_TYPE: &'static str = "ur_dashboard_msgs/msg/RobotMode";
    const DDS_TYPE: &'static str = "ur_dashboard_msgs::msg::dds_::RobotMode_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.i8(self.mode);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self { mode: r.i8()? })
    }
}

/// `ur_dashboard_msgs/msg/SafetyMode` (`uint8 mode`): `NORMAL` = 1, `PROTECTIVE_STOP` = 3
/// (RTDE's `safety_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SafetyMode {
    pub mode: u8,
}

impl SafetyMode {
    pub const NORMAL: u8 = 1;
    pub const REDUCED: u8 = 2;
    pub const PROTECTIVE_STOP: u8 = 3;
}

impl Message for SafetyMode {
    const ROS_TYPE: &'static str = "ur_dashboard_msgs/msg/SafetyMode";
    const DDS_TYPE: &'static str = "ur_dashboard_msgs::msg::dds_::SafetyMode_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.u8(self.mode);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self { mode: r.u8()? })
    }
}

/// `std_msgs/msg/UInt64` (episode numbers, table versions on the live view).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UInt64 {
    pub data: u64,
}

impl Message for UInt64 {
    const ROS_TYPE: &'static str = "std_msgs/msg/UInt64";
    const DDS_TYPE: &'static str = "std_msgs::msg::dds_::UInt64_";
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.u64(self.data);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self { data: r.u64()? })
    }
}

#[cfg(test)]
mod tests {
    //! Vectors encoded by CycloneDDS's Python binding from the IDL in
    //! `scripts/ros2/ros2_idl.py` (`python scripts/ros2/cdr_vectors.py`): an independent
    //! implementation of the same types.
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    fn round_trip<M: Message + PartialEq + core::fmt::Debug>(msg: &M, bytes: &str) {
        let bytes = hex(bytes);
        assert_eq!(msg.encode(), bytes, "encoding of {}", M::ROS_TYPE);
        assert_eq!(
            &M::decode(&bytes).unwrap(),
            msg,
            "decoding of {}",
            M::ROS_TYPE
        );
    }

    fn joint_state() -> JointState {
        JointState {
            header: Header {
                stamp: Time {
                    sec: 12,
                    nanosec: 345,
                },
                frame_id: "base".into(),
            },
            name: vec!["shoulder_pan_joint".into(), "elbow_joint".into()],
            position: vec![1.0, -2.5],
            velocity: vec![0.5, core::f64::consts::PI],
            effort: vec![],
        }
    }

    #[test]
    fn joint_state_matches_cyclonedds() {
        round_trip(
            &joint_state(),
            "000100000c00000059010000050000006261736500000000020000001300000073686f756c6465725f\
             70616e5f6a6f696e7400000c000000656c626f775f6a6f696e740002000000000000000000000000\
             00f03f00000000000004c00200000000000000000000000000e03f182d4454fb2109400000000\
             0",
        );
    }

    #[test]
    fn big_endian_joint_state_decodes() {
        let be = hex(
            "000000000000000c00000159000000056261736500000000000000020000001373686f756c646572\
             5f70616e5f6a6f696e7400000000000c656c626f775f6a6f696e74000000000200000000\
             3ff0000000000000c00400000000000000000002000000003fe0000000000000400921fb54442d18\
             00000000",
        );
        assert_eq!(JointState::decode(&be).unwrap(), joint_state());
    }

    #[test]
    fn float64_multi_array_matches_cyclonedds() {
        round_trip(
            &Float64MultiArray {
                layout: MultiArrayLayout {
                    dim: vec![MultiArrayDimension {
                        label: "joints".into(),
                        size: 6,
                        stride: 6,
                    }],
                    data_offset: 0,
                },
                data: vec![
                    0.0,
                    -2.0,
                    2.4,
                    -core::f64::consts::FRAC_PI_2,
                    core::f64::consts::FRAC_PI_2,
                    0.25,
                ],
            },
            "0001000001000000070000006a6f696e7473000006000000060000000000000006000000000000000\
             000000000000000000000c03333333333330340182d4454fb21f9bf182d4454fb21f93f00000000\
             0000d03f",
        );
        round_trip(
            &Float64MultiArray {
                layout: MultiArrayLayout::default(),
                data: vec![1.5],
            },
            "0001000000000000000000000100000000000000000000000000f83f",
        );
    }

    #[test]
    fn point_stamped_matches_cyclonedds() {
        round_trip(
            &PointStamped {
                header: Header {
                    stamp: Time {
                        sec: -1,
                        nanosec: 999_999_999,
                    },
                    frame_id: "world".into(),
                },
                point: Point {
                    x: 0.1,
                    y: -0.2,
                    z: 0.3,
                },
            },
            "00010000ffffffffffc99a3b06000000776f726c64000000000000009a9999999999b93f9a99999999\
             99c9bf333333333333d33f",
        );
    }

    #[test]
    fn status_messages_match_cyclonedds() {
        round_trip(&RobotMode { mode: 7 }, "0001000007");
        round_trip(&RobotMode { mode: -1 }, "00010000ff");
        round_trip(&SafetyMode { mode: 3 }, "0001000003");
        round_trip(
            &UInt64 {
                data: (1 << 40) + 3,
            },
            "000100000300000000010000",
        );
    }

    #[test]
    fn trailing_padding_is_ignored() {
        // ROS 2 writers built on Fast DDS pad the payload to a multiple of 4.
        assert_eq!(
            RobotMode::decode(&hex("0001000307000000")).unwrap(),
            RobotMode { mode: 7 }
        );
    }

    #[test]
    fn malformed_messages_are_refused_not_panicked_on() {
        let good = joint_state().encode();
        for n in 0..good.len() {
            assert!(
                JointState::decode(&good[..n]).is_err(),
                "prefix of {n} bytes"
            );
        }
        assert_eq!(
            JointState::decode(&hex("00030000")).unwrap_err(),
            CdrError::Encapsulation([0, 3])
        );
        // A count of 2^31 names in a 40-byte message.
        let mut huge = good.clone();
        huge[24..28].copy_from_slice(&0x8000_0000u32.to_le_bytes());
        assert!(matches!(
            JointState::decode(&huge).unwrap_err(),
            CdrError::SequenceTooLong { .. }
        ));
        // A string without its NUL.
        let mut no_nul = good;
        no_nul[16 + 4] = b'x';
        assert!(matches!(
            JointState::decode(&no_nul).unwrap_err(),
            CdrError::BadString { .. }
        ));
    }

    #[test]
    fn time_from_ns_round_trips() {
        let t = Time::from_ns(1_700_000_000_123_456_789);
        assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_789));
        assert_eq!(t.to_ns(), 1_700_000_000_123_456_789);
    }
}
