//! The controller's setup errors, every backend's in one place below the modules that raise
//! them (`ports`, `arm`, `controller`), so that none of those imports another for its errors.

use std::net::{IpAddr, SocketAddr};

use ur_protocol::client::ClientError;
use ur_protocol::clock::ClockFault;
use ur_protocol::rtde::ControllerVersion;

use crate::config::UrSeries;

/// Setup failures; each message says what to check.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// Invalid configuration.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    /// The configured arm backend is not the one this setup builds.
    #[error("this setup builds the {0} arm but the configuration's arm.backend differs; call the setup of the configured backend (Controller::setup for iceoryx2, Controller::setup_ur for ur, Controller::setup_ros2 for ros2)")]
    BackendMismatch(&'static str),
    /// The `ur` arm's setup failed.
    #[error(transparent)]
    Ur(#[from] UrSetupError),
    /// The `ros2` arm's setup failed.
    #[error(transparent)]
    Ros2(#[from] Ros2SetupError),
    /// The live view (`[live_view]`) could not start.
    #[error(transparent)]
    LiveView(#[from] LiveViewError),
    /// Another controller runs on the prefix.
    #[error(transparent)]
    Role(#[from] ur5_shared::services::RoleLockError),
    /// A service name iceoryx2 refused.
    #[error(transparent)]
    Name(#[from] ur5_shared::services::InvalidServiceName),
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node: {0}; is /dev/shm writable?")]
    Node(String),
    /// A service could not be opened or created.
    #[error(transparent)]
    Service(#[from] ur5_shared::services::OpenServiceError),
    /// A port could not be created.
    #[error("cannot create a {kind} on `{name}`: {why}; too many processes may be connected (stale ports of killed processes count until cleaned up)")]
    Port {
        /// publisher / subscriber.
        kind: &'static str,
        /// Full service name.
        name: String,
        /// iceoryx2's error.
        why: String,
    },
    /// A peer did not show up in time.
    #[error("no {what} within {timeout_s} s on prefix `{prefix}`: start it with the same --prefix (`{start} --prefix {prefix}`), or raise setup_timeout_s")]
    PeerTimeout {
        /// What was waited for.
        what: &'static str,
        /// The command that provides it (`hil-sim serve`, `learner serve`).
        start: &'static str,
        /// Timeout (s).
        timeout_s: f64,
        /// The service prefix.
        prefix: String,
    },
}

/// `SetupError::Port` for a port iceoryx2 refused.
pub(crate) fn port_err(kind: &'static str, name: &str, e: &dyn core::fmt::Debug) -> SetupError {
    SetupError::Port {
        kind,
        name: name.to_owned(),
        why: format!("{e:?}"),
    }
}

/// Why the robot's RTDE stream cannot be trusted: a measured state or the arm's clock that no
/// network fault produces (TCP delivers the robot's bytes as sent), a fault of the robot or of
/// its controller. In setup it is a [`UrSetupError::Stream`]; in the loop the arm is no longer
/// driven (the program's receive timeout stops it), the run ends as arm lost (exit 3) with
/// [`StreamFault::reason`], and the summary's `arm.stream_fault` gives this message.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum StreamFault {
    /// `actual_q` or `actual_qd` not finite.
    #[error("the robot measured a non-finite joint state: joint {joint} actual_q = {q} rad, actual_qd = {qd} rad/s; a fault of the robot or its controller (not of the network): see the robot's log")]
    NonFinite {
        /// Joint index 0..6.
        joint: usize,
        /// Its angle (rad).
        q: f64,
        /// Its speed (rad/s).
        qd: f64,
    },
    /// An active joint's `actual_q` outside `[limits]` by more than the margin.
    #[error("the robot measured joint {joint} at {q} rad, outside [limits] {lower} ..= {upper} rad (by more than {margin} rad); the arm is not driven there: move it inside the limits (freedrive or the teach pendant) or check [limits] against the robot, then start again")]
    OutsideLimits {
        /// Joint index 0..3.
        joint: usize,
        /// Its angle (rad).
        q: f64,
        /// Lower limit (rad).
        lower: f64,
        /// Upper limit (rad).
        upper: f64,
        /// Tolerance (rad).
        margin: f64,
    },
    /// The robot's clock (`timestamp`) went backwards or stands still.
    #[error(transparent)]
    Clock(#[from] ur_protocol::clock::ClockFault),
}

impl StreamFault {
    /// The reason without numbers (the summary's `arm_lost`; no allocation in the loop).
    pub const fn reason(&self) -> &'static str {
        match self {
            StreamFault::NonFinite { .. } => "the robot measured a non-finite joint angle or speed (a fault of the robot, not of the network; see arm.stream_fault)",
            StreamFault::OutsideLimits { .. } => "the robot measured a joint angle outside [limits] (see arm.stream_fault)",
            StreamFault::Clock(ClockFault::Backwards { .. }) => "the robot's clock (RTDE timestamp) went backwards (see arm.stream_fault)",
            StreamFault::Clock(ClockFault::Frozen { .. }) => "the robot's clock (RTDE timestamp) is frozen (see arm.stream_fault)",
        }
    }
}

/// A live view (`[live_view]`, [`crate::live_view`]) that cannot start: DDS (the participant,
/// a topic, a writer) or its thread.
#[derive(Debug, thiserror::Error)]
pub enum LiveViewError {
    #[error("cannot start the live view ([live_view]) on ROS domain {domain}: {source}")]
    Dds {
        domain: u16,
        #[source]
        source: ur5_ros2::DdsError,
    },
    #[error("cannot start the live view's DDS thread or its wake-up: {0}")]
    Thread(#[source] std::io::Error),
}

/// Why the `ros2` arm could not be set up; each message names the topic and what to start.
#[derive(Debug, thiserror::Error)]
pub enum Ros2SetupError {
    /// DDS refused a participant, topic, reader or writer.
    #[error(transparent)]
    Dds(#[from] ur5_ros2::DdsError),
    /// The loop's wake-up descriptor.
    #[error("cannot create the eventfd that wakes the DDS thread: {0}")]
    Eventfd(String),
    /// The DDS thread.
    #[error("cannot start the DDS thread: {0}")]
    Thread(String),
    /// Nobody publishes the joint states.
    #[error("no publisher on {topic} (sensor_msgs/msg/JointState) on ROS domain {domain} within {timeout_s} s: start UR's driver (`ros2 launch ur_robot_driver ur_control.launch.py ...`) or `hil-sim ros2-sim`, on the same ROS_DOMAIN_ID (arm.ros2.domain_id) and network (arm.ros2.network), or fix arm.ros2.joint_states_topic")]
    NoPublisher {
        topic: String,
        domain: u16,
        timeout_s: f64,
    },
    /// The topic carries another type.
    #[error("{topic} is published with DDS type {found}, not {expected}: fix arm.ros2.joint_states_topic")]
    WrongType {
        topic: String,
        found: String,
        expected: &'static str,
    },
    /// The joint states do not name the controller's joints.
    #[error("the joint states on {topic} name {names:?}, not all of arm.ros2.joints {joints:?}: set arm.ros2.joints to the driver's names (a tf_prefix?)")]
    JointsMissing {
        topic: String,
        joints: [String; 6],
        names: Vec<String>,
    },
    /// A publisher is there but nothing arrived.
    #[error("{publishers} publisher(s) on {topic} but no joint state arrived within {timeout_s} s: the QoS may not match (arm.ros2.joint_states_qos: a reliable reader does not match a best-effort writer)")]
    NothingReceived {
        topic: String,
        publishers: usize,
        timeout_s: f64,
    },
    /// Nobody takes the commands.
    #[error("no subscriber on {topic} within {timeout_s} s: activate the driver's forward_position_controller (`ros2 control switch_controllers --activate forward_position_controller --deactivate scaled_joint_trajectory_controller`), or fix arm.ros2.command_topic")]
    NoSubscriber { topic: String, timeout_s: f64 },
    /// The first joint state cannot be acted on.
    #[error("the first joint state: {0}")]
    Stream(StreamFault),
    /// More than one writer of the joint states.
    #[error("{publishers} publishers of {topic} on ROS domain {domain}: two drivers (or a driver and hil-sim ros2-sim) on one domain; the controller would mix their joint states and drive both arms: stop one, or give each its own ROS_DOMAIN_ID (arm.ros2.domain_id)")]
    SecondPublisher {
        topic: String,
        domain: u16,
        publishers: usize,
    },
    /// A reliability DDS cannot match between the controller and the driver.
    #[error("{key} {ours} but on {topic} {theirs}: DDS never matches them, so nothing would pass; set {key}.reliability = \"{fix}\" (or change the driver's QoS)")]
    Qos {
        topic: String,
        key: &'static str,
        ours: String,
        theirs: String,
        fix: &'static str,
    },
    /// `arm.ros2.joints` does not name UR's joints.
    #[error("{0}")]
    Joints(String),
}

/// Why the `ur` arm could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum UrSetupError {
    /// No TCP connection.
    #[error("cannot connect to the robot's {what} at {addr}: {why}; is the robot (or `hil-sim ur-sim`) running, and are arm.ur.host and the port right?")]
    Connect {
        /// RTDE or secondary interface.
        what: &'static str,
        /// Where.
        addr: SocketAddr,
        /// The OS error.
        why: std::io::Error,
    },
    /// A read or write failed (a read timeout included).
    #[error("RTDE {during}: {why}; the robot stopped answering (check the network, or raise setup_timeout_s)")]
    Io {
        /// The step.
        during: &'static str,
        /// The OS error.
        why: std::io::Error,
    },
    /// The robot closed the RTDE connection.
    #[error("the robot closed the RTDE connection during {0}; see its log (another client, or a controller restart)")]
    Closed(&'static str),
    /// The RTDE client's failure whose message needs nothing of the configuration: framing
    /// lost, a package that does not decode, an unexpected answer, both protocol versions or
    /// START refused, an unusable recipe, the arm not RUNNING or not NORMAL.
    #[error(transparent)]
    Rtde(ClientError),
    /// `arm.ur.series` disagrees with the controller.
    #[error("arm.ur.series = {configured:?} but the controller reports version {reported} ({}); set arm.ur.series = \"auto\" or the right one", if reported.is_e_series() { "e-Series" } else { "CB3" })]
    SeriesMismatch {
        /// Configured.
        configured: UrSeries,
        /// Reported.
        reported: ControllerVersion,
    },
    /// The RTDE socket's local address is not IPv4 (the program connects back to it).
    #[error("this PC's address toward the robot is {0}, not IPv4; the program needs an IPv4 address to connect back to")]
    NotIpv4(IpAddr),
    /// The reverse port could not be opened.
    #[error("cannot listen on {addr} for the program's reverse connection: {why}; is another driver running, or arm.ur.reverse_port taken?")]
    Listen {
        /// Where.
        addr: SocketAddr,
        /// The OS error.
        why: std::io::Error,
    },
    /// Sending the program failed.
    #[error("cannot send the program to the secondary interface: {0}")]
    SendProgram(std::io::Error),
    /// The dashboard server cannot be reached.
    #[error("cannot reach the robot's dashboard server at {addr}: {why}; is arm.ur.dashboard_port right (29999 on a UR)? The model check needs it: set arm.ur.check_model = false to skip the check")]
    Dashboard {
        /// Where.
        addr: SocketAddr,
        /// The OS error (a read timeout included).
        why: std::io::Error,
    },
    /// A dashboard reply that is not the expected one.
    #[error("the dashboard server answered `{command}` with \"{reply}\", expected {expected}")]
    DashboardReply {
        /// The command sent.
        command: &'static str,
        /// What came back.
        reply: String,
        /// What was expected.
        expected: &'static str,
    },
    /// The robot is another model than `arm.ur.model`.
    #[error("arm.ur.model = \"{configured}\" but the robot says it is a {robot} on {polyscope}, that is {}; set arm.ur.model (and the learner's sim.model) to the robot's model, or arm.ur.check_model = false to drive it anyway", robot_model.map_or("a model this project does not know".to_string(), |m| format!("a {m}")))]
    ModelMismatch {
        /// The configured model.
        configured: ur5_shared::UrModel,
        /// `get robot model`'s reply.
        robot: String,
        /// `PolyscopeVersion`'s reply.
        polyscope: String,
        /// The model both replies name, if this project knows it.
        robot_model: Option<ur5_shared::UrModel>,
    },
    /// The bring-up did not reach RUNNING.
    #[error("bring-up: after `{step}` the robot mode was still {mode} after {timeout_s} s (expected {expected}); check the teach pendant (e-Series: remote control, no popup), or raise setup_timeout_s")]
    BringUp {
        /// The dashboard command sent.
        step: &'static str,
        /// The last robot mode seen.
        mode: String,
        /// What was awaited.
        expected: &'static str,
        /// Waited (s).
        timeout_s: f64,
    },
    /// The protective stop could not be cleared.
    #[error("protective-stop recovery: {0}")]
    Recovery(String),
    /// The robot's stream cannot be trusted (see [`StreamFault`]).
    #[error("RTDE {during}: {fault}")]
    Stream {
        /// The step.
        during: &'static str,
        /// What is wrong.
        fault: StreamFault,
    },
    /// The setup's deadline (`setup_timeout_s`, over the whole RTDE setup, not per read)
    /// passed.
    #[error("RTDE {during}: no answer within setup_timeout_s = {timeout_s} s (a deadline over the whole setup); the robot sent {texts_total} text messages meanwhile{}{texts:?}; check the robot, or raise setup_timeout_s", if *texts_total > 0 { ", the newest: " } else { "" })]
    Deadline {
        /// The step.
        during: &'static str,
        /// The timeout (s).
        timeout_s: f64,
        /// Text messages received, all of them counted.
        texts_total: u64,
        /// The newest of them (at most [`ur_protocol::client::KEPT_TEXTS`]).
        texts: Vec<String>,
    },
    /// The RTDE port does not answer RTDE, the secondary port does: swapped.
    #[error("arm.ur.rtde_port = {rtde_port} does not answer RTDE within {timeout_s} s, but arm.ur.secondary_port = {secondary_port} does: the two ports are swapped; set rtde_port = {secondary_port} and secondary_port = {rtde_port} (on a UR, RTDE is 30004, the secondary interface 30002)")]
    PortsSwapped {
        /// Configured RTDE port.
        rtde_port: u16,
        /// Configured secondary port.
        secondary_port: u16,
        /// Waited (s).
        timeout_s: f64,
    },
    /// Something answers on the RTDE port, but not RTDE (or nothing answers).
    #[error("{addr} (arm.ur.rtde_port) is not an RTDE interface: {what}; on a UR, RTDE is port 30004 and the secondary interface (arm.ur.secondary_port = {secondary_port}) 30002: check both ports and arm.ur.host")]
    NotRtde {
        /// Where.
        addr: SocketAddr,
        /// The configured secondary port.
        secondary_port: u16,
        /// What came instead.
        what: String,
    },
    /// The program did not connect back.
    #[error("the program did not connect back to {addr} within {timeout_s} s: can the robot reach this PC on that port (firewall, route)? Is the robot in remote control (e-Series)? The robot's text messages so far: {texts:?}")]
    NoCallback {
        /// Our reverse address.
        addr: SocketAddr,
        /// Waited (s).
        timeout_s: f64,
        /// Text messages the robot sent on RTDE.
        texts: Vec<String>,
    },
}

impl From<ClientError> for UrSetupError {
    /// The shared RTDE client's failures as the setup's: those whose advice names the setup's
    /// configuration (`setup_timeout_s`, the `arm.ur` address) get their own variants.
    fn from(e: ClientError) -> Self {
        match e {
            ClientError::Connect { addr, why } => Self::Connect {
                what: "RTDE interface",
                addr,
                why,
            },
            ClientError::Io { during, why } => Self::Io { during, why },
            ClientError::Closed(during) => Self::Closed(during),
            ClientError::Deadline {
                during,
                timeout_s,
                texts_total,
                texts,
            } => Self::Deadline {
                during,
                timeout_s,
                texts_total,
                texts,
            },
            e => Self::Rtde(e),
        }
    }
}
