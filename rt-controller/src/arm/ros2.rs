//! The `ros2` arm (docs/design.md §3.13): Universal Robots' ROS 2 driver, or `hil-sim
//! ros2-sim`, over DDS. `/joint_states` in (matched to `arm.ros2.joints` by name), six positions
//! on `/forward_position_controller/commands` out, the driver's robot and safety modes watched.
//! The controller's joints are UR's, shoulder pan to wrist 3, found by name in
//! `arm.ros2.joints` (the commands' order) whatever their place there.
//!
//! Trusting no one blindly: joint states from a second writer (two drivers on one domain) are
//! dropped and refuse the setup or end the run; no joint state for `arm.ros2.lost_after_s` ends
//! it as a lost arm (a killed driver closes no connection); a command subscriber whose QoS the
//! commands' cannot serve, or a joint-state publisher whose QoS cannot serve ours, is named.
//!
//! DDS (RustDDS) runs on a thread of its own: it decodes joint states into fixed-size samples in
//! the controller's joint order and hands them to the loop through a preallocated lock-free
//! queue; the loop hands its targets back through another and wakes the thread with an
//! `eventfd` write ([`crate::dds_thread`], shared with the live view). The loop thread neither
//! allocates nor locks.
//!
//! As in the `ur` arm, the joint states clock the loop: one [`ArmState`] per control period of
//! their header stamps; resets are quintic moves published at the joint-state rate; a goal is
//! published once and the forward controller holds it ([`crate::arm::servo`]).

use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use ur5_ros2::{
    Float64MultiArray, JointState, Message, MultiArrayLayout, Node, Reader, RobotMode, SafetyMode,
    Writer,
};
use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ArmLimits;
use ur5_shared::kinematics::Joints6;
use ur5_shared::{ArmCommand, ArmFaults, ArmState, ArmStatus};
use ur_protocol::modes::{robot_mode_name, safety_mode_name};

use crate::arm::servo::{state_due, ArmSensor, Servo};
use crate::arm::ur::check_joints;
use crate::arm::{ArmBackend, ArmIoError, ArmReport};
use crate::config::{Ros2Config, ServoTarget, UrConfig};
use crate::dds_thread::{DdsThread, DdsWork, Handoff, Wake};
use crate::error::{Ros2SetupError, SetupError, StreamFault};
use crate::stats::{Histogram, Percentiles};

/// Joint samples the DDS thread may queue ahead of the loop (0.5 s at 500 Hz); when full, the
/// oldest is dropped (counted).
const STATE_QUEUE: usize = 256;
/// Targets the loop may queue ahead of the DDS thread.
const COMMAND_QUEUE: usize = 64;
/// A mode not received yet.
const UNKNOWN_MODE: i32 = i32::MIN;
/// Why the arm is lost when joint states came from a second writer during the run.
const SECOND_PUBLISHER: &str = "joint states from a second publisher (two drivers on one ROS domain and topic?): the controller would mix their states and drive both arms (arm.foreign counts them)";
/// Why the arm is lost when the driver fell silent.
const SILENT_DRIVER: &str = "no joint state for arm.ros2.lost_after_s: the driver is gone (killed, or its network down); arm.longest_gap_s says how long";

/// One joint state in the controller's joint order.
#[derive(Clone, Copy, Debug, Default)]
struct JointSample {
    /// Header stamp (ns).
    stamp_ns: u64,
    q: Joints6,
    qd: Joints6,
    /// When the DDS thread decoded it (monotonic ns): the handoff latency's start.
    received_ns: u64,
}

/// What the DDS thread and the loop share: the two queues, the wake-up and the modes.
struct Shared {
    states: Handoff<JointSample>,
    commands: Handoff<Joints6>,
    wake: Arc<Wake>,
    robot_mode: AtomicI32,
    safety_mode: AtomicI32,
    // DDS thread counters.
    received: AtomicU64,
    unmatched: AtomicU64,
    /// Joint states from a writer other than the first (a second driver), dropped.
    foreign: AtomicU64,
    published: AtomicU64,
    publish_errors: AtomicU64,
}

impl Shared {
    fn new() -> std::io::Result<Self> {
        Ok(Self {
            states: Handoff::new(STATE_QUEUE),
            commands: Handoff::new(COMMAND_QUEUE),
            wake: Arc::new(Wake::new()?),
            robot_mode: AtomicI32::new(UNKNOWN_MODE),
            safety_mode: AtomicI32::new(UNKNOWN_MODE),
            received: AtomicU64::new(0),
            unmatched: AtomicU64::new(0),
            foreign: AtomicU64::new(0),
            published: AtomicU64::new(0),
            publish_errors: AtomicU64::new(0),
        })
    }

    /// Queues a target and wakes the DDS thread (one `write` on the eventfd; no allocation).
    fn command(&self, q: Joints6) {
        self.commands.push(q);
        self.wake.notify();
    }
}

/// Maps a joint state's names onto the controller's joints, UR's order (cached while the
/// names repeat).
struct JointMap {
    /// The names of the controller's joints: `arm.ros2.joints` in UR's order.
    joints: [String; 6],
    names: Vec<String>,
    index: Option<[usize; 6]>,
}

impl JointMap {
    /// `order[k]`: where UR's joint `k` is in `joints`.
    fn new(joints: &[String; 6], order: &[usize; 6]) -> Self {
        Self {
            joints: order.map(|i| joints[i].clone()),
            names: Vec::new(),
            index: None,
        }
    }

    /// The sample in the controller's order; `Err(joint)`: a joint missing from the message
    /// (or its position or velocity).
    fn sample(&mut self, m: &JointState) -> Result<JointSample, usize> {
        if m.name != self.names {
            self.names.clone_from(&m.name);
            let mut index = [0usize; 6];
            let mut missing = None;
            for (j, want) in self.joints.iter().enumerate() {
                match m.name.iter().position(|n| n == want) {
                    Some(i) => index[j] = i,
                    None => {
                        missing.get_or_insert(j);
                    }
                }
            }
            self.index = if missing.is_none() { Some(index) } else { None };
            if let Some(j) = missing {
                return Err(j);
            }
        }
        let index = self.index.ok_or(0usize)?;
        let mut s = JointSample {
            stamp_ns: m.header.stamp.to_ns(),
            received_ns: monotonic_ns(),
            ..JointSample::default()
        };
        for (j, &i) in index.iter().enumerate() {
            s.q[j] = *m.position.get(i).ok_or(j)?;
            s.qd[j] = *m.velocity.get(i).ok_or(j)?;
        }
        Ok(s)
    }
}

/// The DDS endpoints, created in setup and moved to the DDS thread at [`ArmBackend::connect`].
struct Endpoints {
    node: Node,
    joint_states: Reader<JointState>,
    robot_mode: Option<Reader<RobotMode>>,
    safety_mode: Option<Reader<SafetyMode>>,
    commands: Writer<Float64MultiArray>,
    map: JointMap,
    /// Where UR's joint `k` goes in a command (`arm.ros2.joints`' order).
    order: [usize; 6],
    /// The writer of the first joint state taken; another's are dropped and counted.
    writer: Option<[u8; 16]>,
}

impl Endpoints {
    fn create(cfg: &Ros2Config) -> Result<Self, Ros2SetupError> {
        // Checked with the configuration.
        let order = crate::config::ur_joint_order("arm.ros2.joints", &cfg.joints)
            .map_err(|e| Ros2SetupError::Joints(e.to_string()))?;
        let node = Node::new(cfg.domain_id, cfg.network)?;
        let joint_states = node.reader(&cfg.joint_states_topic, cfg.joint_states_qos)?;
        let commands = node.writer(&cfg.command_topic, cfg.command_qos)?;
        let (robot_mode, safety_mode) = if cfg.watch_status {
            (
                Some(node.reader(&cfg.robot_mode_topic, cfg.status_qos)?),
                Some(node.reader(&cfg.safety_mode_topic, cfg.status_qos)?),
            )
        } else {
            (None, None)
        };
        Ok(Self {
            node,
            joint_states,
            robot_mode,
            safety_mode,
            commands,
            map: JointMap::new(&cfg.joints, &order),
            order,
            writer: None,
        })
    }

    /// Reads every queued message: joint states into `shared.states`, modes into the atomics.
    fn pump(&mut self, shared: &Shared) {
        while let Some((m, writer)) = self.joint_states.take_with_writer() {
            shared.received.fetch_add(1, Ordering::Relaxed);
            if *self.writer.get_or_insert(writer) != writer {
                shared.foreign.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            match self.map.sample(&m) {
                Ok(s) => shared.states.push(s),
                Err(_) => {
                    shared.unmatched.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if let Some(r) = self.robot_mode.as_mut() {
            while let Some(m) = r.take() {
                shared
                    .robot_mode
                    .store(i32::from(m.mode), Ordering::Relaxed);
            }
        }
        if let Some(r) = self.safety_mode.as_mut() {
            while let Some(m) = r.take() {
                shared
                    .safety_mode
                    .store(i32::from(m.mode), Ordering::Relaxed);
            }
        }
    }

    /// Publishes every queued target.
    fn publish(&mut self, shared: &Shared, msg: &mut Float64MultiArray) {
        while let Some(q) = shared.commands.pop() {
            msg.data.clear();
            msg.data.resize(6, 0.0);
            for (k, &i) in self.order.iter().enumerate() {
                msg.data[i] = q[k];
            }
            let ok = self.commands.write(msg.clone()).is_ok();
            let c = if ok {
                &shared.published
            } else {
                &shared.publish_errors
            };
            c.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The DDS thread's work: moves messages both ways after every wake-up (a reader's data or
/// the loop's target), every 20 ms regardless ([`DdsThread`]).
struct ArmDds {
    ep: Endpoints,
    shared: Arc<Shared>,
    msg: Float64MultiArray,
}

impl DdsWork for ArmDds {
    fn register(&mut self, r: &rustdds::mio1::Registry) {
        use rustdds::mio1::{Interest, Token};
        let ep = &mut self.ep;
        let _ = r.register(ep.joint_states.source(), Token(0), Interest::READABLE);
        if let Some(rd) = ep.robot_mode.as_mut() {
            let _ = r.register(rd.source(), Token(1), Interest::READABLE);
        }
        if let Some(rd) = ep.safety_mode.as_mut() {
            let _ = r.register(rd.source(), Token(2), Interest::READABLE);
        }
    }

    fn step(&mut self) {
        self.ep.publish(&self.shared, &mut self.msg);
        self.ep.pump(&self.shared);
    }
}

/// What the `ros2` arm did (the summary's `arm` field).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Ros2Report {
    /// Joint states received, of them not matching `arm.ros2.joints` (a joint missing), and
    /// dropped because the loop fell 256 behind.
    pub joint_states: u64,
    pub unmatched: u64,
    /// Joint states from a second publisher (another driver on the domain), dropped.
    pub foreign: u64,
    pub dropped: u64,
    /// Joint states the loop used, and states handed to the controller.
    pub samples: u64,
    pub states: u64,
    /// Stamps that did not advance (skipped).
    pub out_of_order: u64,
    /// Commands published, and publications that failed.
    pub commands: u64,
    pub publish_errors: u64,
    /// Commands the controller sent that could not go to the arm (non-finite, outside the
    /// limits, torques): replaced by a hold.
    pub commands_refused: u64,
    pub resets: u64,
    pub resets_unsettled: u64,
    /// Gaps between joint states longer than `safety.stale_state_timeout_s` (a stale stream: the
    /// controller held), and the longest gap (s of wall time).
    pub stale_gaps: u64,
    pub longest_gap_s: f64,
    /// Why the robot stopped the run, if it did.
    pub robot_stop: Option<String>,
    /// Why the arm is gone, if it is.
    pub lost: Option<&'static str>,
    pub stream_fault: Option<String>,
    /// Joint state decoded on the DDS thread → taken by the loop (ns).
    pub handoff: Percentiles,
}

/// The loop side.
struct Live {
    sensor: ArmSensor,
    servo: Servo,
    servo_target: ServoTarget,
    q: Joints6,
    qd: Joints6,
    first_stamp_ns: u64,
    last_stamp_ns: u64,
    /// Arm time (s since the first joint state's stamp).
    ts: f64,
    next_emit_ts: f64,
    state_seq: u64,
    robot_stop: Option<(i32, i32)>,
    lost: Option<&'static str>,
    stream_fault: Option<StreamFault>,
    last_sample_ns: u64,
    in_gap: bool,
    samples: u64,
    states: u64,
    out_of_order: u64,
    stale_gaps: u64,
    longest_gap_ns: u64,
    handoff: Histogram,
}

/// The `ros2` arm backend.
pub struct Ros2Arm {
    cfg: Ros2Config,
    ur: UrConfig,
    limits: ArmLimits,
    period_s: f64,
    cycle_s: f64,
    /// A gap between joint states longer than this (ns of wall time) is a stale stream
    /// (`safety.stale_state_timeout_s`: the controller holds), counted.
    stale_gap_ns: u64,
    /// No joint state for this long (ns of wall time): the driver is gone
    /// (`arm.ros2.lost_after_s`).
    lost_gap_ns: u64,
    shared: Arc<Shared>,
    endpoints: Option<Endpoints>,
    first: Option<JointSample>,
    /// Stopped and joined when the arm drops.
    thread: Option<DdsThread>,
    live: Option<Live>,
    /// The task's active joints and tool points as the arm reports them.
    sensor: ArmSensor,
    joints: usize,
}

impl Ros2Arm {
    /// The arm of `cfg.arm.ros2` (and `cfg.arm.ur`'s arm description), not connected yet.
    pub fn new(cfg: &crate::config::ControllerConfig) -> Result<Self, SetupError> {
        let shared = Shared::new().map_err(|e| Ros2SetupError::Eventfd(e.to_string()))?;
        Ok(Self {
            cfg: cfg.arm.ros2.clone(),
            ur: cfg.arm.ur.clone(),
            limits: cfg.limits(),
            period_s: cfg.task.dt,
            cycle_s: 1.0 / cfg.arm.ros2.joint_state_rate_hz,
            stale_gap_ns: (cfg.safety.stale_state_timeout_s * 1e9) as u64,
            lost_gap_ns: (cfg.arm.ros2.lost_after_s * 1e9) as u64,
            shared: Arc::new(shared),
            endpoints: None,
            first: None,
            thread: None,
            live: None,
            sensor: ArmSensor::new(cfg.arm.ur.model, cfg.arm.ur.ee_offset, &cfg.task),
            joints: cfg.task.joints,
        })
    }

    /// What the loop saw (allocates; after the loop).
    pub fn report(&self) -> Ros2Report {
        let sh = &self.shared;
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        let mut r = Ros2Report {
            joint_states: g(&sh.received),
            unmatched: g(&sh.unmatched),
            foreign: g(&sh.foreign),
            dropped: sh.states.dropped(),
            commands: g(&sh.published),
            publish_errors: g(&sh.publish_errors),
            ..Ros2Report::default()
        };
        if let Some(l) = &self.live {
            r.samples = l.samples;
            r.states = l.states;
            r.out_of_order = l.out_of_order;
            r.commands_refused = l.servo.refused;
            r.resets = l.servo.resets;
            r.resets_unsettled = l.servo.unsettled;
            r.stale_gaps = l.stale_gaps;
            r.longest_gap_s = l.longest_gap_ns as f64 * 1e-9;
            r.robot_stop = l.robot_stop.map(|(rm, sm)| {
                format!(
                    "robot mode {} ({rm}), safety mode {} ({sm})",
                    if rm == UNKNOWN_MODE {
                        "not received"
                    } else {
                        robot_mode_name(rm)
                    },
                    if sm == UNKNOWN_MODE {
                        "not received"
                    } else {
                        safety_mode_name(sm)
                    },
                )
            });
            r.lost = l.lost;
            r.stream_fault = l.stream_fault.map(|f| f.to_string());
            r.handoff = l.handoff.summary();
        }
        r
    }

    /// Why setup found no usable joint state in time: the topic has no publisher, one of
    /// another type, or the joints do not match.
    fn diagnose(&self, ep: &Endpoints, timeout_s: f64) -> Ros2SetupError {
        let c = &self.cfg;
        let writers = ep.node.writers_on(&c.joint_states_topic);
        let publishers: Vec<String> = writers.iter().map(|w| w.type_name.clone()).collect();
        if publishers.is_empty() {
            return Ros2SetupError::NoPublisher {
                topic: c.joint_states_topic.clone(),
                domain: c.domain_id,
                timeout_s,
            };
        }
        if let Some(other) = publishers.iter().find(|t| *t != JointState::DDS_TYPE) {
            return Ros2SetupError::WrongType {
                topic: c.joint_states_topic.clone(),
                found: other.clone(),
                expected: JointState::DDS_TYPE,
            };
        }
        let requested = c.joint_states_qos.reliability;
        if let Some(w) = writers.iter().find(|w| !w.reliability.serves(requested)) {
            return Ros2SetupError::Qos {
                topic: c.joint_states_topic.clone(),
                key: "arm.ros2.joint_states_qos",
                ours: format!("requests {}", requested.name()),
                theirs: format!("its publisher offers {}", w.reliability.name()),
                fix: w.reliability.name(),
            };
        }
        if self.shared.unmatched.load(Ordering::Relaxed) > 0 {
            return Ros2SetupError::JointsMissing {
                topic: c.joint_states_topic.clone(),
                joints: c.joints.clone(),
                names: ep.map.names.clone(),
            };
        }
        Ros2SetupError::NothingReceived {
            topic: c.joint_states_topic.clone(),
            publishers: publishers.len(),
            timeout_s,
        }
    }

    /// Whether the commands have a subscriber; `Err` when every one discovered requests a
    /// reliability `arm.ros2.command_qos` does not offer (DDS would never match them: the
    /// commands would go nowhere).
    fn check_subscribers(&self, ep: &Endpoints) -> Result<bool, Ros2SetupError> {
        let c = &self.cfg;
        let readers = ep.node.readers_on(&c.command_topic);
        let offered = c.command_qos.reliability;
        match readers.iter().find(|r| offered.serves(r.reliability)) {
            Some(_) => Ok(true),
            None if readers.is_empty() => Ok(false),
            None => Err(Ros2SetupError::Qos {
                topic: c.command_topic.clone(),
                key: "arm.ros2.command_qos",
                ours: format!("offers {}", offered.name()),
                theirs: format!(
                    "its subscriber (the forward position controller) requests {}",
                    readers[0].reliability.name()
                ),
                fix: readers[0].reliability.name(),
            }),
        }
    }

    /// Two writers of the joint states: two drivers (or a driver and a simulator) on one
    /// domain, whose states the controller would mix and whose arms it would both drive.
    fn second_publisher(&self, ep: &Endpoints) -> Ros2SetupError {
        Ros2SetupError::SecondPublisher {
            topic: self.cfg.joint_states_topic.clone(),
            domain: self.cfg.domain_id,
            publishers: ep
                .node
                .writers_on(&self.cfg.joint_states_topic)
                .len()
                .max(2),
        }
    }
}

impl ArmBackend for Ros2Arm {
    fn wait_ready(&mut self, timeout_s: f64) -> Result<ArmState, SetupError> {
        let mut ep = Endpoints::create(&self.cfg)?;
        let t0 = monotonic_ns();
        let timeout_ns = (timeout_s * 1e9) as u64;
        let mut first = None;
        let mut subscribed = false;
        while first.is_none() || !subscribed {
            ep.pump(&self.shared);
            while let Some(s) = self.shared.states.pop() {
                first = Some(s);
            }
            if !subscribed {
                subscribed = self.check_subscribers(&ep)?;
            }
            if self.shared.foreign.load(Ordering::Relaxed) > 0 {
                return Err(self.second_publisher(&ep).into());
            }
            if monotonic_ns() - t0 > timeout_ns {
                return Err(if first.is_none() {
                    self.diagnose(&ep, timeout_s)
                } else {
                    Ros2SetupError::NoSubscriber {
                        topic: self.cfg.command_topic.clone(),
                        timeout_s,
                    }
                }
                .into());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let s = first.expect("loop ends with a sample");
        if ep.node.writers_on(&self.cfg.joint_states_topic).len() > 1 {
            // Discovered, no sample of it yet: still a second driver.
            return Err(self.second_publisher(&ep).into());
        }
        check_joints(&s.q, &s.qd, &self.limits).map_err(Ros2SetupError::Stream)?;
        self.first = Some(s);
        self.endpoints = Some(ep);
        Ok(self.sensor.state(&s.q, &s.qd, 0, 0, 0, ArmStatus::READY))
    }

    fn connect(&mut self) -> Result<(), SetupError> {
        let ep = self
            .endpoints
            .take()
            .expect("wait_ready succeeded before connect");
        let mut s = self.first.take().expect("wait_ready kept its sample");
        // The newest sample queued meanwhile (the thread is not running yet).
        let mut ep = ep;
        ep.pump(&self.shared);
        while let Some(n) = self.shared.states.pop() {
            s = n;
        }
        let work = ArmDds {
            ep,
            shared: Arc::clone(&self.shared),
            msg: Float64MultiArray {
                layout: MultiArrayLayout::default(),
                data: Vec::with_capacity(6),
            },
        };
        self.thread = Some(
            DdsThread::spawn(
                "ros2-dds",
                Arc::clone(&self.shared.wake),
                Duration::from_millis(20),
                work,
            )
            .map_err(|e| Ros2SetupError::Thread(e.to_string()))?,
        );
        let mut servo = Servo::new(
            s.q,
            0.0,
            self.cycle_s,
            self.period_s,
            self.joints,
            self.ur.wrist_q,
        );
        servo.hold_here(&s.q, 0.0);
        let live = Live {
            sensor: self.sensor,
            servo,
            servo_target: self.ur.servo_target,
            q: s.q,
            qd: s.qd,
            first_stamp_ns: s.stamp_ns,
            last_stamp_ns: s.stamp_ns,
            ts: 0.0,
            next_emit_ts: self.period_s,
            state_seq: 0,
            robot_stop: None,
            lost: None,
            stream_fault: None,
            last_sample_ns: monotonic_ns(),
            in_gap: false,
            samples: 0,
            states: 0,
            out_of_order: 0,
            stale_gaps: 0,
            longest_gap_ns: 0,
            handoff: Histogram::new(),
        };
        // Hold where the arm is until the controller's first command.
        self.shared.command(live.servo.goal);
        self.live = Some(live);
        Ok(())
    }

    fn receive(&mut self) -> Result<Option<ArmState>, ArmIoError> {
        let Some(l) = self.live.as_mut() else {
            return Err(ArmIoError::Receive);
        };
        if l.lost.is_some() {
            return Ok(None);
        }
        let now = monotonic_ns();
        let gap = now.saturating_sub(l.last_sample_ns);
        if !l.in_gap && gap > self.stale_gap_ns {
            l.in_gap = true;
            l.stale_gaps += 1;
        }
        if self.shared.foreign.load(Ordering::Relaxed) > 0 {
            l.lost = Some(SECOND_PUBLISHER);
            return Err(ArmIoError::Receive);
        }
        if gap > self.lost_gap_ns && self.shared.states.is_empty() {
            l.longest_gap_ns = l.longest_gap_ns.max(gap);
            l.lost = Some(SILENT_DRIVER);
            return Err(ArmIoError::Receive);
        }
        if self.thread.as_ref().is_some_and(|t| t.is_finished()) {
            l.lost = Some("the DDS thread ended");
            return Err(ArmIoError::Receive);
        }
        while let Some(s) = self.shared.states.pop() {
            if s.stamp_ns <= l.last_stamp_ns {
                l.out_of_order += 1;
                continue;
            }
            l.longest_gap_ns = l.longest_gap_ns.max(now.saturating_sub(l.last_sample_ns));
            l.in_gap = false;
            l.last_sample_ns = now;
            l.handoff.record(now.saturating_sub(s.received_ns));
            l.samples += 1;
            if let Err(f) = check_joints(&s.q, &s.qd, &self.limits) {
                l.stream_fault = Some(f);
                l.lost = Some(f.reason());
                return Err(ArmIoError::Receive);
            }
            l.q = s.q;
            l.qd = s.qd;
            l.last_stamp_ns = s.stamp_ns;
            l.ts = (s.stamp_ns - l.first_stamp_ns) as f64 * 1e-9;
            if let Some(state) = l.on_sample(&self.cfg, &self.shared, self.period_s, self.cycle_s) {
                l.states += 1;
                return Ok(Some(state));
            }
        }
        Ok(None)
    }

    fn send(&mut self, cmd: &ArmCommand) -> Result<(), ArmIoError> {
        let Some(l) = self.live.as_mut() else {
            return Err(ArmIoError::Send);
        };
        let ok = l.servo.take_command(
            cmd,
            &self.limits,
            self.ur.reset_speed_rad_s,
            self.ur.servo_target,
            l.q,
            l.ts,
        );
        if l.robot_stop.is_none() {
            self.shared
                .command(l.servo.target(self.ur.servo_target, l.ts));
        }
        if ok {
            Ok(())
        } else {
            Err(ArmIoError::Send)
        }
    }

    fn lost(&self) -> Option<&'static str> {
        self.live.as_ref().and_then(|l| l.lost)
    }

    fn report(&self) -> Option<ArmReport> {
        Some(ArmReport::Ros2(Ros2Arm::report(self)))
    }
}

impl Live {
    /// One joint state: the modes, the reset's progress, the target stream of a reset or a
    /// ramp, and the control-period state if one is due.
    fn on_sample(
        &mut self,
        cfg: &Ros2Config,
        shared: &Shared,
        period_s: f64,
        cycle_s: f64,
    ) -> Option<ArmState> {
        let ts = self.ts;
        if cfg.watch_status && self.robot_stop.is_none() {
            let rm = shared.robot_mode.load(Ordering::Relaxed);
            let sm = shared.safety_mode.load(Ordering::Relaxed);
            let robot_bad = rm != UNKNOWN_MODE && rm != i32::from(RobotMode::RUNNING);
            let safety_bad = sm != UNKNOWN_MODE
                && sm != i32::from(SafetyMode::NORMAL)
                && sm != i32::from(SafetyMode::REDUCED);
            if robot_bad || safety_bad {
                self.robot_stop = Some((rm, sm));
                // The controller hears of it at once, not at the next control period.
                return Some(self.emit(ArmStatus::READY));
            }
        }
        let mut status = ArmStatus::READY;
        if self.servo.resetting() {
            if self.servo.reset_done(&self.q, &self.qd, ts).is_some() {
                self.next_emit_ts = ts + period_s;
                shared.command(self.servo.goal);
                return Some(self.emit(ArmStatus::READY));
            }
            status = ArmStatus::RESETTING;
        }
        if (self.servo.resetting() || self.servo_target == ServoTarget::Ramp)
            && self.robot_stop.is_none()
        {
            shared.command(self.servo.target(self.servo_target, ts));
        }
        if state_due(&mut self.next_emit_ts, ts, cycle_s, period_s) {
            return Some(self.emit(status));
        }
        None
    }

    fn emit(&mut self, status: ArmStatus) -> ArmState {
        self.state_seq += 1;
        let mut s = self.sensor.state(
            &self.q,
            &self.qd,
            self.state_seq,
            self.servo.last_command_seq,
            self.servo.episode,
            status,
        );
        if self.robot_stop.is_some() {
            s.faults.insert(ArmFaults::DRIVER);
        }
        s
    }
}
