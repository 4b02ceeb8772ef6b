//! ROS 2 without ROS: the messages of Universal Robots' ROS 2 driver (`ur_robot_driver`) and of
//! the live view, their CDR encoding, and the DDS node that carries them (RustDDS, pure Rust:
//! nothing of ROS is needed to build or run). Wire-compatible with ROS 2 Humble and Jazzy
//! (docs/design.md §3.13).
//!
//! - [`cdr`]: plain CDR (XCDR1) reader and writer.
//! - [`msg`]: `sensor_msgs/JointState`, `std_msgs/Float64MultiArray`, `geometry_msgs/PointStamped`,
//!   `ur_dashboard_msgs/RobotMode` and `SafetyMode`, `std_msgs/UInt64`.
//! - [`dds`]: ROS topic names and QoS on DDS, the participant and typed readers and writers.

pub mod cdr;
pub mod dds;
pub mod msg;

/// The six joints of a UR arm in the order of UR's ROS 2 driver's controllers (the
/// `joints` parameter of `forward_position_controller` in its `ur_controllers.yaml`): the
/// order of the commands it takes.
pub const UR_JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

pub use dds::{
    dds_topic, DdsError, Endpoint, Network, Node, Reader, ReliabilityKind, TopicQos, Writer,
};
pub use msg::{
    Float64MultiArray, Header, JointState, Message, MultiArrayDimension, MultiArrayLayout, Point,
    PointStamped, RobotMode, SafetyMode, Time, UInt64,
};
