//! `hil-sim ros2-sim`: the simulated arm as Universal Robots' ROS 2 driver presents it
//! (docs/design.md §3.13), over DDS without ROS:
//!
//! - `/joint_states` (`sensor_msgs/msg/JointState`) every arm cycle (500 Hz), all six joints
//!   in the order the driver's `joint_state_broadcaster` is commonly seen to use
//!   ([`DRIVER_ORDER`]; clients must match by name), stamped with the wall clock at start plus
//!   arm time;
//! - `/forward_position_controller/commands` (`std_msgs/msg/Float64MultiArray`): six positions
//!   in the order of the controller's `joints` parameter ([`Ros2SimConfig::joints`]); the newest is the position servo's goal from the next
//!   cycle on, held until the next (the wrist joints stay locked: their values are ignored);
//! - `/io_and_status_controller/robot_mode` and `/safety_mode` (`ur_dashboard_msgs`) every
//!   0.1 s of arm time and on change: RUNNING; NORMAL until a target outside the joint limits
//!   (or an injected fault) raises a protective stop, after which commands are ignored.
//!
//! Real time only: each cycle of `1 / rate / time_compression` of wall time applies the newest
//! command, steps the physics (the same [`crate::ur_sim::plant::Arm`] as `ur-sim`) and publishes.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::Serialize;
use ur5_ros2::{
    Float64MultiArray, Header, JointState, Network, Node, RobotMode, SafetyMode, Time, TopicQos,
};
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};

use crate::ur_sim::plant::{Arm, Phase};
use crate::{SimError, Ur5Sim};

/// The order of `/joint_states` from UR's driver as commonly observed (alphabetical by
/// interface registration it is not: shoulder_pan comes last).
pub const DRIVER_ORDER: [&str; 6] = [
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
    "shoulder_pan_joint",
];

/// The forward position controller's joints (its `joints` parameter in the driver's
/// `ur_controllers.yaml`), the order of the commands.
pub use ur5_ros2::UR_JOINTS as CONTROLLER_ORDER;

/// Options of `hil-sim ros2-sim`; the topic names and QoS are the driver's.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Ros2SimConfig {
    /// ROS_DOMAIN_ID.
    pub domain_id: u16,
    pub network: Network,
    pub joint_states_topic: String,
    pub command_topic: String,
    pub robot_mode_topic: String,
    pub safety_mode_topic: String,
    pub qos: TopicQos,
    /// The forward position controller's `joints` parameter: the order of the commands' six
    /// values (UR's driver: shoulder pan to wrist 3; any order of UR's six names).
    pub joints: [String; 6],
    /// Joint states per second of arm time (500: an e-Series driver).
    pub rate_hz: f64,
    /// Real time runs this many times faster than wall time (≥ 1).
    pub time_compression: f64,
    /// A protective stop this many arm cycles after the first command (0: none), as on a
    /// detected collision. Faults count from the first command so that they fall at the same
    /// point of a controller's run however long its setup took.
    pub fault_protective_stop_after: u64,
    /// No joint states from this many arm cycles after the first command on (0: none) …
    pub fault_silence_after: u64,
    /// … for this many cycles (the arm holds meanwhile).
    pub fault_silence_cycles: u64,
}

impl Default for Ros2SimConfig {
    fn default() -> Self {
        Self {
            domain_id: 0,
            network: Network::Loopback,
            joint_states_topic: "/joint_states".into(),
            command_topic: "/forward_position_controller/commands".into(),
            robot_mode_topic: "/io_and_status_controller/robot_mode".into(),
            safety_mode_topic: "/io_and_status_controller/safety_mode".into(),
            qos: TopicQos::reliable(10),
            joints: CONTROLLER_ORDER.map(String::from),
            rate_hz: 500.0,
            time_compression: 1.0,
            fault_protective_stop_after: 0,
            fault_silence_after: 0,
            fault_silence_cycles: 0,
        }
    }
}

/// Errors starting `ros2-sim`.
#[derive(Debug, thiserror::Error)]
pub enum Ros2SimError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    #[error(transparent)]
    Dds(#[from] ur5_ros2::DdsError),
    #[error("ros2-sim needs sim.mode = \"goal_angles\" (the forward position controller sets the position servo's goal)")]
    TorqueMode,
    #[error("time_compression {0}")]
    TimeCompression(String),
    #[error("rate_hz {0} must be in [10, 2000]")]
    Rate(f64),
    #[error("joints {0:?}: the forward position controller's joints must be UR's six joint names, each once")]
    Joints([String; 6]),
    #[error("cannot start the ros2-sim thread: {0}")]
    Thread(String),
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Ros2SimSummary {
    /// Always "ros2-sim".
    pub command: &'static str,
    pub cycles: u64,
    pub joint_states: u64,
    pub commands: u64,
    /// Commands with fewer than six values, or after a protective stop (ignored).
    pub commands_ignored: u64,
    pub protective_stops: u64,
}

#[derive(Default)]
struct Counters {
    cycles: AtomicU64,
    joint_states: AtomicU64,
    commands: AtomicU64,
    ignored: AtomicU64,
    stops: AtomicU64,
}

/// A running `ros2-sim`; [`Ros2SimHandle::stop`] ends it.
pub struct Ros2SimHandle {
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    thread: Option<JoinHandle<()>>,
}

impl Ros2SimHandle {
    /// What the run did so far.
    pub fn summary(&self) -> Ros2SimSummary {
        let c = &self.counters;
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Ros2SimSummary {
            command: "ros2-sim",
            cycles: g(&c.cycles),
            joint_states: g(&c.joint_states),
            commands: g(&c.commands),
            commands_ignored: g(&c.ignored),
            protective_stops: g(&c.stops),
        }
    }

    /// Stops the clock thread and returns what the run did.
    pub fn stop(mut self) -> Ros2SimSummary {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.summary()
    }

    /// Blocks until the clock thread ends (the binary's foreground mode: until killed).
    pub fn wait(mut self) -> Ros2SimSummary {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.summary()
    }
}

impl Drop for Ros2SimHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Builds the arm at rest at `task.start_q`, joins the DDS domain and starts the clock.
pub fn spawn(
    task: &TaskConfig,
    sim_cfg: &SimConfig,
    cfg: &Ros2SimConfig,
) -> Result<Ros2SimHandle, Ros2SimError> {
    task.validate()?;
    sim_cfg.validate()?;
    if sim_cfg.mode != ActionMode::GoalAngles {
        return Err(Ros2SimError::TorqueMode);
    }
    ur5_shared::config::check_time_compression(cfg.time_compression)
        .map_err(Ros2SimError::TimeCompression)?;
    if !(10.0..=2000.0).contains(&cfg.rate_hz) {
        return Err(Ros2SimError::Rate(cfg.rate_hz));
    }
    command_order(&cfg.joints).ok_or_else(|| Ros2SimError::Joints(cfg.joints.clone()))?;
    let dt = 1.0 / cfg.rate_hz;
    let mut arm = Arm::new(
        Ur5Sim::with_joints(sim_cfg.clone(), dt, task.joints)?,
        task.start_six(&sim_cfg.wrist_q),
        task.goal,
        dt,
    )?;
    // The forward position controller is active: the arm follows its commands.
    arm.phase = Phase::Running;
    let node = Node::new(cfg.domain_id, cfg.network)?;
    let io = Io {
        joint_states: node.writer(&cfg.joint_states_topic, cfg.qos)?,
        robot_mode: node.writer(&cfg.robot_mode_topic, cfg.qos)?,
        safety_mode: node.writer(&cfg.safety_mode_topic, cfg.qos)?,
        commands: node.reader(&cfg.command_topic, cfg.qos)?,
        _node: node,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let counters = Arc::new(Counters::default());
    let (s, c, cfg) = (Arc::clone(&stop), Arc::clone(&counters), cfg.clone());
    let thread = std::thread::Builder::new()
        .name("ros2-sim".into())
        .spawn(move || run(arm, io, &cfg, &s, &c))
        .map_err(|e| Ros2SimError::Thread(e.to_string()))?;
    Ok(Ros2SimHandle {
        stop,
        counters,
        thread: Some(thread),
    })
}

struct Io {
    joint_states: ur5_ros2::Writer<JointState>,
    robot_mode: ur5_ros2::Writer<RobotMode>,
    safety_mode: ur5_ros2::Writer<SafetyMode>,
    commands: ur5_ros2::Reader<Float64MultiArray>,
    _node: Node,
}

/// `order[k]`: the place of UR's joint `k` (shoulder pan … wrist 3) in a command of the
/// controller whose `joints` parameter is `joints`; `None` unless those are UR's six names.
fn command_order(joints: &[String; 6]) -> Option<[usize; 6]> {
    let mut order = [0usize; 6];
    for (k, name) in CONTROLLER_ORDER.iter().enumerate() {
        order[k] = joints.iter().position(|j| j == name)?;
    }
    Some(order)
}

/// Nanoseconds since the Unix epoch (the stamps' origin).
fn realtime_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// The clock: absolute deadlines one cycle apart (after a long stall it restarts instead of
/// catching up in a burst).
fn run(mut arm: Arm, mut io: Io, cfg: &Ros2SimConfig, stop: &AtomicBool, c: &Counters) {
    let period = Duration::from_secs_f64(1.0 / cfg.rate_hz / cfg.time_compression);
    let cycle_ns = (1e9 / cfg.rate_hz) as u64;
    let stamp0 = realtime_ns();
    // Where each controller joint goes: the URDF's active joints are the first three.
    let mut js = JointState {
        header: Header::default(),
        name: DRIVER_ORDER.iter().map(|s| s.to_string()).collect(),
        position: vec![0.0; 6],
        velocity: vec![0.0; 6],
        effort: vec![0.0; 6],
    };
    let from_controller: [usize; 6] = DRIVER_ORDER.map(|n| {
        CONTROLLER_ORDER
            .iter()
            .position(|m| *m == n)
            .expect("a UR joint")
    });
    let order = command_order(&cfg.joints).expect("checked by spawn");
    let mut last_modes = (i8::MIN, 0u8);
    // The arm cycle of the first command (the faults' origin).
    let mut first_command: Option<u64> = None;
    let mut next = Instant::now() + period;
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > 10 * period {
            next = now;
        }
        next += period;
        // The newest command.
        let mut goal = None;
        while let Some(m) = io.commands.take() {
            c.commands.fetch_add(1, Ordering::Relaxed);
            first_command.get_or_insert(arm.cycle);
            if m.data.len() < 6 || arm.safety != ur_protocol::SafetyMode::Normal {
                c.ignored.fetch_add(1, Ordering::Relaxed);
            } else {
                // All six: an arm with a locked wrist ignores the wrist's (`Arm::set_goal`).
                goal = Some(order.map(|i| m.data[i]));
            }
        }
        let mut violation = goal.and_then(|q: [f64; 6]| {
            let v = arm.check_target(&q).err();
            if v.is_none() {
                arm.set_goal(q);
            }
            v
        });
        violation = violation.or(arm.step());
        let since_command = first_command.map_or(0, |c0| arm.cycle - c0);
        let after = cfg.fault_protective_stop_after;
        if after > 0 && since_command == after {
            violation = violation.or(Some(crate::ur_sim::plant::Violation(
                "a collision was detected (injected fault)".into(),
            )));
        }
        if let Some(v) = violation {
            if arm.safety == ur_protocol::SafetyMode::Normal {
                eprintln!("hil-sim ros2-sim: protective stop: {}", v.0);
                arm.protective_stop();
                c.stops.fetch_add(1, Ordering::Relaxed);
            }
        }
        c.cycles.fetch_add(1, Ordering::Relaxed);
        let s = &arm.snapshot;
        let silent = cfg.fault_silence_after > 0
            && since_command >= cfg.fault_silence_after
            && since_command < cfg.fault_silence_after + cfg.fault_silence_cycles;
        if !silent {
            js.header.stamp = Time::from_ns(stamp0 + arm.cycle * cycle_ns);
            for (i, &j) in from_controller.iter().enumerate() {
                js.position[i] = s.actual_q[j];
                js.velocity[i] = s.actual_qd[j];
                js.effort[i] = s.actual_current[j];
            }
            if io.joint_states.write(js.clone()).is_ok() {
                c.joint_states.fetch_add(1, Ordering::Relaxed);
            }
        }
        let modes = (RobotMode::RUNNING, arm.safety.code() as u8);
        if modes != last_modes || arm.cycle % (cfg.rate_hz as u64 / 10).max(1) == 0 {
            last_modes = modes;
            let _ = io.robot_mode.write(RobotMode { mode: modes.0 });
            let _ = io.safety_mode.write(SafetyMode { mode: modes.1 });
        }
    }
}
