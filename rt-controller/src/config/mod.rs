//! Configuration of the controller (TOML; every option has a key, see `rt-controller
//! print-config`). Unknown keys are rejected so that a typo is an error, not a silently ignored
//! setting.
//!
//! Units: times in seconds (s) unless the key ends in `_ns`; angles in rad; velocities in
//! rad/s; torques in N·m; positions in m (arm base frame).

use serde::{Deserialize, Serialize};
use ur5_shared::config::{ActionMode, ArmLimits, ConfigError, TaskConfig};
use ur5_shared::joints::Joints;
use ur5_shared::{GainBounds, PolicyBounds};

mod ros2;

use ros2::{check_domain, check_topic, is_live_view_default};
pub use ros2::{ur_joint_order, LiveViewConfig, Ros2Config, UR_JOINTS};

/// How the loop is paced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// As fast as the arm answers: after each command the controller waits for the state that
    /// acknowledges it (`ArmState::last_command_seq`). The arm (`hil-sim serve --mode
    /// lockstep`) steps one control period per command. Experiments run like this.
    #[default]
    Lockstep,
    /// Real time at the control rate 1 / `task.dt` (10 Hz–1 kHz), optionally compressed.
    RealTime,
}

/// In real-time mode, what decides when a tick starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Pacing {
    /// The controller sleeps to absolute deadlines (`clock_nanosleep`, `TIMER_ABSTIME`) every
    /// `task.dt / time_compression` s and acts on the newest state.
    #[default]
    Deadline,
    /// Each new state message from the arm starts a tick: the arm's clock paces the loop, as
    /// with a real driver that publishes at the control rate.
    Arm,
}

/// When the controller stops acting on the table and holds the arm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Safety {
    /// The arm's state is stale when no fresh state arrived for this long (wall-clock s):
    /// lockstep, no answer to a command; arm pacing, no new state; deadline pacing, the newest
    /// state is older than this. Ours: 0.5 s, far above a sim step (≈ 1 ms per 0.1 s period)
    /// and above most of the VM stalls we see, yet 5 periods at 10 Hz.
    pub stale_state_timeout_s: f64,
    /// Stop the run when the arm has been stale this long (s); 0 = hold forever.
    pub give_up_after_s: f64,
    /// Stop the run when no valid table has arrived this long after setup (s); 0 = wait forever.
    pub no_table_timeout_s: f64,
    /// Resend the reset when the arm has not acknowledged it after this long (s).
    pub reset_timeout_s: f64,
    /// Torque-mode hold: PD stiffness towards the last safe pose (N·m/rad), one per joint from
    /// the shoulder pan; a wrist joint not given here gets [`WRIST_HOLD_KP`]. Ours: well inside
    /// the effort limits for the errors a hold sees.
    pub hold_kp: Joints,
    /// Torque-mode hold: PD damping (N·m·s/rad), one per joint; a wrist joint not given here
    /// gets [`WRIST_HOLD_KD`].
    pub hold_kd: Joints,
}

impl Default for Safety {
    fn default() -> Self {
        Self {
            stale_state_timeout_s: 0.5,
            give_up_after_s: 0.0,
            no_table_timeout_s: 0.0,
            reset_timeout_s: 1.0,
            hold_kp: Joints::from([200.0, 200.0, 50.0]),
            hold_kd: Joints::from([20.0, 20.0, 5.0]),
        }
    }
}

/// Torque-mode hold stiffness of a wrist joint `safety.hold_kp` leaves out (N·m/rad): a
/// tenth of a UR wrist's 28 N·m at 0.28 rad of error.
pub const WRIST_HOLD_KP: f64 = 10.0;
/// Torque-mode hold damping of a wrist joint `safety.hold_kd` leaves out (N·m·s/rad).
pub const WRIST_HOLD_KD: f64 = 1.0;

impl Safety {
    /// The torque-mode hold's (K_p, K_d) of joint `j`: `hold_kp[j]`, `hold_kd[j]`, or the
    /// wrist's defaults past them.
    pub fn hold_gains(&self, j: usize) -> (f64, f64) {
        (
            self.hold_kp.get(j).copied().unwrap_or(WRIST_HOLD_KP),
            self.hold_kd.get(j).copied().unwrap_or(WRIST_HOLD_KD),
        )
    }
}

/// Optional real-time privileges, each with a logged fallback when not permitted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct RtSetup {
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`: no page faults in the loop.
    pub mlockall: bool,
    /// `SCHED_FIFO` priority 1–99; 0 = keep the normal scheduler.
    pub fifo_priority: i32,
    /// Pin the loop thread to this CPU; none = no pinning.
    pub cpu: Option<usize>,
}

/// Waiting for a message (lockstep, arm pacing, setup).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Polling {
    /// Busy-poll this long before sleeping between polls (ns). Spinning trades CPU for wake-up
    /// latency; on shared 2-core machines keep it short.
    pub spin_ns: u64,
    /// Sleep between polls after the spin (ns).
    pub sleep_ns: u64,
}

impl Default for Polling {
    fn default() -> Self {
        Self {
            spin_ns: 20_000,
            sleep_ns: 20_000,
        }
    }
}

/// Which arm the loop drives ([`crate::arm`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ArmKind {
    /// `arm/state` and `arm/command` over iceoryx2 on `prefix` (`hil-sim serve`).
    #[default]
    Iceoryx2,
    /// A Universal Robots controller (or `hil-sim ur-sim`): RTDE for the state, the project's
    /// URScript program and its reverse socket for the commands (docs/design.md §3.10).
    Ur,
    /// Universal Robots' ROS 2 driver (`ur_robot_driver`, or `hil-sim ros2-sim`) over DDS:
    /// `/joint_states` in, `/forward_position_controller/commands` out (docs/design.md §3.13).
    Ros2,
}

/// Which UR controller generation, hence the arm cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum UrSeries {
    /// From the controller version RTDE reports: major ≥ 5 is an e-Series (500 Hz), below a
    /// CB3 (125 Hz).
    #[default]
    Auto,
    /// e-Series: 500 Hz (2 ms cycle); setup fails if the controller reports a CB3.
    E,
    /// CB3: 125 Hz (8 ms cycle); setup fails if the controller reports an e-Series.
    Cb3,
}

/// The `ur` arm: where the robot is and how the program watches the PC (`[arm.ur]`). Ports are
/// Universal Robots' (and URCL's) defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UrConfig {
    /// The robot's model (`"ur5"`, `"ur5e"`, …; docs/ur.md, "Arm models"): the forward
    /// kinematics that turn its joint angles into the end-effector point. Must be the model
    /// the demonstrations and the learner's `sim.model` were made with. Not serialised when it
    /// is the UR5 (the default), so UR5 configurations print and hash as before.
    #[serde(skip_serializing_if = "ur5_shared::UrModel::is_ur5")]
    pub model: ur5_shared::UrModel,
    /// The robot controller's IPv4 address.
    pub host: String,
    /// RTDE port on the robot.
    pub rtde_port: u16,
    /// Secondary-interface port on the robot (the program is sent there, headless).
    pub secondary_port: u16,
    /// Port this PC listens on for the program's reverse connection (0: any free port; the
    /// program sent to the robot names the one bound).
    pub reverse_port: u16,
    /// Controller generation; `auto` reads it from the controller version.
    pub series: UrSeries,
    /// The program's receive timeout on the reverse socket (ms): with no command for this long
    /// it runs `stopj` and exits, the arm's own watchdog for a dead controller. URCL's default
    /// is 20 ms; it must exceed an arm cycle (8 ms on a CB3).
    pub receive_timeout_ms: u32,
    /// What the program servos to between the controller's goals, every arm cycle
    /// (docs/design.md §3.10): `hold` (the goal as sent, the zero-order hold the learner's
    /// model and hil-sim serve assume) or `ramp` (a straight line from the previous target to
    /// the goal over one control period).
    pub servo_target: ServoTarget,
    /// The wrist angles (rad, wrist 1–3) the arm keeps: the resets move the wrists there, every
    /// servo target carries them. Must equal the sim's `sim.wrist_q` the demonstrations were
    /// made with.
    pub wrist_q: [f64; 3],
    /// The end-effector point in the `wrist_3_link` (flange) frame (m): the sim's
    /// `sim.ee_offset`.
    pub ee_offset: [f64; 3],
    /// Peak joint speed of the reset motion to `task.start_q` (rad/s): a smooth (quintic)
    /// joint-space move; keep it low on a real arm.
    pub reset_speed_rad_s: f64,
    /// The robot's dashboard-server port (Universal Robots': 29999): the model check, the
    /// bring-up and the protective-stop recovery speak to it.
    #[serde(skip_serializing_if = "is_dashboard_default")]
    pub dashboard_port: u16,
    /// Ask the robot its model over the dashboard (`get robot model`, `PolyscopeVersion`) at
    /// setup and refuse to drive another model than `model` (docs/ur.md, "The dashboard").
    /// `false` skips the check (and the dashboard, unless `bring_up` or
    /// `recover_protective_stop` need it).
    #[serde(skip_serializing_if = "is_true")]
    pub check_model: bool,
    /// At setup, power the arm on and release its brakes over the dashboard if it is not
    /// RUNNING, then wait for RUNNING (at most `setup_timeout_s` per step).
    #[serde(skip_serializing_if = "is_false")]
    pub bring_up: bool,
    /// After a protective stop: wait until 5 s of arm time have passed since it, `unlock
    /// protective stop` over the dashboard, send the program again and go on with the next
    /// episode (the stopped one counts as aborted). Otherwise the run ends (exit code 5). Clear
    /// the cause first: a protective stop means the arm hit something or was driven past a
    /// limit.
    #[serde(skip_serializing_if = "is_false")]
    pub recover_protective_stop: bool,
    /// servoj's `lookahead_time` (s, 0.03–0.2): the robot smooths the target trajectory over
    /// this horizon; longer is smoother and lags more.
    #[serde(skip_serializing_if = "is_lookahead_default")]
    pub servoj_lookahead_time_s: f64,
    /// servoj's `gain` (100–2000): the proportional gain on the position error; higher
    /// tracks tighter and may overshoot or vibrate.
    #[serde(skip_serializing_if = "is_gain_default")]
    pub servoj_gain: f64,
}

/// Universal Robots' dashboard-server port.
pub const UR_DASHBOARD_PORT: u16 = 29999;
/// servoj's `lookahead_time` range (s), as URScript accepts it.
pub const UR_LOOKAHEAD_RANGE_S: (f64, f64) = (0.03, 0.2);
/// servoj's `gain` range, as URScript accepts it.
pub const UR_GAIN_RANGE: (f64, f64) = (100.0, 2000.0);
/// The driver's servoj `lookahead_time` (s) unless configured (URCL's default).
pub const UR_DEFAULT_LOOKAHEAD_S: f64 = 0.1;
/// The driver's servoj `gain` unless configured (URCL's default).
pub const UR_DEFAULT_GAIN: f64 = 300.0;

// Defaults are not serialised, so that configurations without the newer keys print and hash
// as before.
fn is_dashboard_default(p: &u16) -> bool {
    *p == UR_DASHBOARD_PORT
}
fn is_true(b: &bool) -> bool {
    *b
}
fn is_false(b: &bool) -> bool {
    !*b
}
fn is_lookahead_default(v: &f64) -> bool {
    *v == UR_DEFAULT_LOOKAHEAD_S
}
fn is_gain_default(v: &f64) -> bool {
    *v == UR_DEFAULT_GAIN
}

/// What the `ur` arm's program servos to between two controller goals.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ServoTarget {
    /// The newest goal, held for the control period (zero-order hold).
    #[default]
    Hold,
    /// A straight line from the previous target to the new goal, reached after one control
    /// period.
    Ramp,
}

impl Default for UrConfig {
    fn default() -> Self {
        Self {
            model: ur5_shared::UrModel::Ur5,
            host: "127.0.0.1".into(),
            rtde_port: 30004,
            secondary_port: 30002,
            reverse_port: 50001,
            series: UrSeries::Auto,
            receive_timeout_ms: 20,
            servo_target: ServoTarget::Hold,
            wrist_q: ur5_shared::config::SimConfig::default().wrist_q,
            ee_offset: [0.0; 3],
            reset_speed_rad_s: 0.5,
            dashboard_port: UR_DASHBOARD_PORT,
            check_model: true,
            bring_up: false,
            recover_protective_stop: false,
            servoj_lookahead_time_s: UR_DEFAULT_LOOKAHEAD_S,
            servoj_gain: UR_DEFAULT_GAIN,
        }
    }
}

/// The arm backend (`[arm]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct ArmConfig {
    /// `iceoryx2` (default), `ur` or `ros2`.
    pub backend: ArmKind,
    /// Used when `backend = "ur"`; for `ros2`, the arm's model, wrist angles, end-effector
    /// offset, reset speed and servo target.
    pub ur: UrConfig,
    /// Used when `backend = "ros2"`. Not serialised when it is the default, so configurations
    /// of the other backends print and hash as before.
    #[serde(skip_serializing_if = "is_ros2_default")]
    pub ros2: Ros2Config,
}

fn is_ros2_default(c: &Ros2Config) -> bool {
    *c == Ros2Config::default()
}

/// Accepted `arm.ur.receive_timeout_ms` (ms): above a CB3 cycle, at most a second.
pub const UR_RECEIVE_TIMEOUT_RANGE_MS: (u32, u32) = (10, 1000);

impl ArmConfig {
    /// Checks the `ur` settings when that backend is chosen.
    fn validate(&self, action_mode: ActionMode) -> Result<(), ConfigError> {
        let bad = |key, why: String| Err(ConfigError::Invalid { key, why });
        match self.backend {
            ArmKind::Iceoryx2 => return Ok(()),
            ArmKind::Ur => {}
            ArmKind::Ros2 => {
                let r = &self.ros2;
                check_domain("arm.ros2.domain_id", r.domain_id)?;
                for (key, topic) in [
                    ("arm.ros2.joint_states_topic", &r.joint_states_topic),
                    ("arm.ros2.command_topic", &r.command_topic),
                    ("arm.ros2.robot_mode_topic", &r.robot_mode_topic),
                    ("arm.ros2.safety_mode_topic", &r.safety_mode_topic),
                ] {
                    check_topic(key, topic)?;
                }
                for (key, q) in [
                    ("arm.ros2.joint_states_qos.depth", r.joint_states_qos),
                    ("arm.ros2.command_qos.depth", r.command_qos),
                    ("arm.ros2.status_qos.depth", r.status_qos),
                ] {
                    if q.depth == 0 {
                        return bad(key, "must be >= 1".into());
                    }
                }
                r.check_joints_and_silence()?;
                if !(r.joint_state_rate_hz >= 10.0 && r.joint_state_rate_hz <= 10_000.0) {
                    return bad(
                        "arm.ros2.joint_state_rate_hz",
                        format!(
                            "{} must be in [10, 10000] Hz (500 for an e-Series, 125 for a CB3)",
                            r.joint_state_rate_hz
                        ),
                    );
                }
                if action_mode != ActionMode::GoalAngles {
                    return bad(
                        "action_mode",
                        format!("{action_mode:?} is not possible with arm.backend = \"ros2\": the forward position controller takes joint positions; use action_mode = \"goal_angles\""),
                    );
                }
            }
        }
        let u = &self.ur;
        if u.host.parse::<std::net::Ipv4Addr>().is_err() {
            return bad(
                "arm.ur.host",
                format!("`{}` is not an IPv4 address; give the robot's address (e.g. \"192.168.1.10\", or \"127.0.0.1\" for hil-sim ur-sim)", u.host),
            );
        }
        for (key, port) in [
            ("arm.ur.rtde_port", u.rtde_port),
            ("arm.ur.secondary_port", u.secondary_port),
        ] {
            if port == 0 {
                return bad(key, "0 is not a port on the robot; the defaults are 30004 (RTDE) and 30002 (secondary)".into());
            }
        }
        if u.dashboard_port == 0 {
            return bad(
                "arm.ur.dashboard_port",
                "0 is not a port on the robot; the dashboard server listens on 29999".into(),
            );
        }
        if u.rtde_port == u.secondary_port {
            return bad(
                "arm.ur.secondary_port",
                format!("{} is also arm.ur.rtde_port; the robot serves them on different ports (30002, 30004)", u.secondary_port),
            );
        }
        let (lo, hi) = UR_RECEIVE_TIMEOUT_RANGE_MS;
        if !(lo..=hi).contains(&u.receive_timeout_ms) {
            return bad(
                "arm.ur.receive_timeout_ms",
                format!(
                    "{} must be in {lo}..={hi} (above a CB3 cycle of 8 ms)",
                    u.receive_timeout_ms
                ),
            );
        }
        if !u
            .wrist_q
            .iter()
            .chain(&u.ee_offset)
            .all(|v| v.is_finite() && v.abs() <= 7.0)
        {
            return bad(
                "arm.ur.wrist_q/ee_offset",
                format!(
                    "{:?} / {:?} must be finite, within ±7 (rad, m)",
                    u.wrist_q, u.ee_offset
                ),
            );
        }
        let (lo, hi) = UR_LOOKAHEAD_RANGE_S;
        if !(u.servoj_lookahead_time_s >= lo && u.servoj_lookahead_time_s <= hi) {
            return bad(
                "arm.ur.servoj_lookahead_time_s",
                format!(
                    "{} must be in [{lo}, {hi}] s, the range servoj accepts (default {UR_DEFAULT_LOOKAHEAD_S})",
                    u.servoj_lookahead_time_s
                ),
            );
        }
        let (lo, hi) = UR_GAIN_RANGE;
        if !(u.servoj_gain >= lo && u.servoj_gain <= hi) {
            return bad(
                "arm.ur.servoj_gain",
                format!(
                    "{} must be in [{lo}, {hi}], the range servoj accepts (default {UR_DEFAULT_GAIN})",
                    u.servoj_gain
                ),
            );
        }
        if !(u.reset_speed_rad_s > 0.0 && u.reset_speed_rad_s <= 3.0) {
            return bad(
                "arm.ur.reset_speed_rad_s",
                format!(
                    "{} must be in (0, 3] rad/s (UR joints: π rad/s at most)",
                    u.reset_speed_rad_s
                ),
            );
        }
        if action_mode != ActionMode::GoalAngles {
            return bad(
                "action_mode",
                format!("{action_mode:?} is not possible with arm.backend = \"ur\": the reverse interface carries joint position targets (servoj); use action_mode = \"goal_angles\""),
            );
        }
        Ok(())
    }
}

/// Everything `rt-controller run` reads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// iceoryx2 service prefix (`{prefix}/arm/state`, …); "" for the plain names.
    pub prefix: String,
    /// Lockstep or real time.
    pub mode: Mode,
    /// Real-time pacing.
    pub pacing: Pacing,
    /// Real time runs this many times faster than the arm's clock (≥ 1): the wall period is
    /// `task.dt / time_compression`. The arm must be started with the same factor.
    pub time_compression: f64,
    /// Episodes to run; 0 = until stopped (SIGINT/SIGTERM).
    pub episodes: u64,
    /// Seed of the exploration noise ([`crate::noise::episode_seed`]).
    pub seed: u64,
    /// Per table version: this many episodes with noise, then `eval_episodes` without, then
    /// again (the paper's Algorithm 1, step 1: N = 5 noisy plus one noise-free).
    pub noisy_episodes: u64,
    /// Noise-free (evaluation) episodes per cycle.
    pub eval_episodes: u64,
    /// Cycles (`noisy_episodes + eval_episodes` episodes) to run with one table version, after
    /// which the controller holds until a newer table (or a new publication of it) arrives;
    /// 0 = keep running the version until then. With an arm whose reset is a motion (the `ur`
    /// backend), 1 makes a lockstep run independent of how long the learner takes: no episode
    /// of an old version moves the arm between the versions (docs/ur.md, "Lockstep"). The
    /// learner must then need one cycle per version (`samples` ≤ `noisy_episodes`); a cycle
    /// with an aborted episode is run again.
    pub cycles_per_table: u64,
    /// Meaning of actions (must match the arm's).
    pub action_mode: ActionMode,
    /// The arm backend and, for `ur`, the robot's address and ports.
    pub arm: ArmConfig,
    /// Control period (s), horizon T, start pose and goal. Tables whose horizon differs from
    /// `task.horizon` are rejected.
    pub task: TaskConfig,
    /// Joint limits for the clamp ([`ur5_shared::safety::clamp_action`]); not given: the arm
    /// model's own (`arm.ur.model`, [`ArmLimits::for_model`]); read them with
    /// [`ControllerConfig::limits`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limits: Option<ArmLimits>,
    /// Hold conditions.
    pub safety: Safety,
    /// Bounds a gain table must satisfy ([`GainBounds`]).
    pub bounds: GainBounds,
    /// Bounds a policy table must satisfy ([`PolicyBounds`]).
    pub policy_bounds: PolicyBounds,
    /// Real-time privileges.
    pub rt: RtSetup,
    /// Message polling.
    pub polling: Polling,
    /// Setup waits this long for the arm (and the learner, if `wait_for_learner`) (s).
    pub setup_timeout_s: f64,
    /// Setup waits for the learner's ports too (docs/design.md §5 D20: every peer connected before the
    /// first episode, because iceoryx2 allocates inside send/receive when connections change).
    /// Off, the loop starts without a learner and holds until a table arrives; a learner that
    /// connects later then costs one allocation burst in the loop (at its first sample send).
    pub wait_for_learner: bool,
    /// Print a line per episode on stderr.
    pub episode_report: bool,
    /// How often a background thread looks for dead peer processes (s); 0 = never.
    pub monitor_period_s: f64,
    /// The live view on ROS 2 topics (off by default). Not serialised when it is the default,
    /// so configurations without it print and hash as before.
    #[serde(skip_serializing_if = "is_live_view_default")]
    pub live_view: LiveViewConfig,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            prefix: String::new(),
            mode: Mode::Lockstep,
            pacing: Pacing::Deadline,
            time_compression: 1.0,
            episodes: 0,
            seed: 0,
            noisy_episodes: 5,
            eval_episodes: 1,
            cycles_per_table: 0,
            action_mode: ActionMode::GoalAngles,
            arm: ArmConfig::default(),
            task: TaskConfig::default(),
            limits: None,
            safety: Safety::default(),
            bounds: GainBounds::default(),
            policy_bounds: PolicyBounds::default(),
            rt: RtSetup::default(),
            polling: Polling::default(),
            setup_timeout_s: 10.0,
            wait_for_learner: true,
            episode_report: true,
            monitor_period_s: 0.2,
            live_view: LiveViewConfig::default(),
        }
    }
}

/// Control rates the loop supports (Hz): the project's ([`ur5_shared::config::RATE_RANGE_HZ`]).
pub use ur5_shared::config::RATE_RANGE_HZ;

impl ControllerConfig {
    /// Checks ranges; the message names the key and the allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |key, why: String| Err(ConfigError::Invalid { key, why });
        // The rate bound (task.dt) is the task's own check.
        self.task.validate()?;
        if let Err(why) = ur5_shared::config::check_time_compression(self.time_compression) {
            return bad("time_compression", why);
        }
        if self.noisy_episodes + self.eval_episodes == 0 {
            return bad(
                "noisy_episodes",
                "noisy_episodes + eval_episodes must be >= 1".into(),
            );
        }
        let l = &self.limits();
        // The clamp may be tighter than the robot's own limits, never looser (docs/ur.md, "Arm
        // models"): e.g. the UR5's exceed a UR10e's joint speeds.
        let model = self.arm.ur.model;
        let own = ArmLimits::for_model_joints(model, 6);
        let n = self.task.joints;
        if [&l.lower, &l.upper, &l.velocity, &l.effort]
            .iter()
            .any(|v| v.len() < n)
        {
            return bad(
                "limits",
                format!("[limits] must give every one of the task's {n} joints (task.joints)"),
            );
        }
        for j in 0..n {
            if l.lower[j] < own.lower[j]
                || l.upper[j] > own.upper[j]
                || l.velocity[j] > own.velocity[j]
                || l.effort[j] > own.effort[j]
            {
                return bad(
                    "limits",
                    format!(
                        "joint {j}: [limits] allow more than the {model}'s own limits \
                         (lower {:?}, upper {:?}, velocity {:?} rad/s, effort {:?} N·m): \
                         write these (or tighter) in [limits]",
                        own.lower, own.upper, own.velocity, own.effort
                    ),
                );
            }
        }
        for j in 0..n {
            let ok = l.lower[j].is_finite()
                && l.upper[j].is_finite()
                && l.lower[j] < l.upper[j]
                && l.velocity[j] > 0.0
                && l.effort[j] > 0.0
                && l.velocity[j].is_finite()
                && l.effort[j].is_finite();
            if !ok {
                return bad(
                    "limits",
                    format!("joint {j}: need finite lower < upper, velocity > 0, effort > 0"),
                );
            }
            if !(l.lower[j] <= self.task.start_q[j] && self.task.start_q[j] <= l.upper[j]) {
                return bad(
                    "task.start_q",
                    format!(
                        "joint {j}: {} rad is outside the limits",
                        self.task.start_q[j]
                    ),
                );
            }
        }
        let s = &self.safety;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if !pos(s.stale_state_timeout_s) || !pos(s.reset_timeout_s) {
            return bad(
                "safety",
                "stale_state_timeout_s and reset_timeout_s must be > 0".into(),
            );
        }
        if !nonneg(s.give_up_after_s) || !nonneg(s.no_table_timeout_s) {
            return bad(
                "safety",
                "give_up_after_s and no_table_timeout_s must be >= 0 (0 = never)".into(),
            );
        }
        if s.hold_kp.len() < 3 || s.hold_kd.len() < 3 {
            return bad(
                "safety.hold_kp/hold_kd",
                "need a gain for each of the three arm joints at least".into(),
            );
        }
        if !s.hold_kp.iter().chain(s.hold_kd.iter()).all(|v| nonneg(*v)) {
            return bad("safety.hold_kp/hold_kd", "must be finite and >= 0".into());
        }
        if !nonneg(self.monitor_period_s) {
            return bad(
                "monitor_period_s",
                format!("{} must be >= 0 (0 = off)", self.monitor_period_s),
            );
        }
        self.arm.validate(self.action_mode)?;
        self.live_view.validate(&self.arm)?;
        if self.arm.backend == ArmKind::Ros2 && self.mode == Mode::Lockstep {
            return bad(
                "mode",
                "arm.backend = \"ros2\" runs in real time, clocked by the driver's joint states: set mode = \"real_time\" and pacing = \"arm\"".into(),
            );
        }
        if matches!(self.arm.backend, ArmKind::Ur | ArmKind::Ros2)
            && self.mode == Mode::RealTime
            && self.pacing != Pacing::Arm
        {
            return bad(
                "pacing",
                format!("arm.backend = \"{}\" is clocked by the robot's {}: set pacing = \"arm\" (or --pacing arm)", if self.arm.backend == ArmKind::Ur { "ur" } else { "ros2" }, if self.arm.backend == ArmKind::Ur { "RTDE packages" } else { "joint states" }),
            );
        }
        if let Err((key, v)) = self.bounds.validate() {
            return bad("bounds", format!("{key} = {v}: must be finite and > 0"));
        }
        if let Err((key, v)) = self.policy_bounds.validate() {
            return bad(
                "policy_bounds",
                format!(
                    "{key} = {v}: must be finite and > 0 (and min_input_scale < max_input_scale)"
                ),
            );
        }
        if !pos(self.setup_timeout_s) {
            return bad(
                "setup_timeout_s",
                format!("{} must be > 0", self.setup_timeout_s),
            );
        }
        if !(0..=99).contains(&self.rt.fifo_priority) {
            return bad(
                "rt.fifo_priority",
                format!("{} must be 0 (off) or 1..=99", self.rt.fifo_priority),
            );
        }
        if self.polling.sleep_ns == 0 || self.polling.sleep_ns > 100_000_000 {
            return bad(
                "polling.sleep_ns",
                format!("{} must be in 1..=100000000", self.polling.sleep_ns),
            );
        }
        ur5_shared::services::ServiceNames::new(&self.prefix)
            .arm_state()
            .map_err(|e| ConfigError::Invalid {
                key: "prefix",
                why: e.to_string(),
            })?;
        Ok(())
    }

    /// The clamp's joint limits: `[limits]`, else those of `arm.ur.model`, for the task's
    /// active joints.
    pub fn limits(&self) -> ArmLimits {
        self.limits
            .clone()
            .unwrap_or_else(|| ArmLimits::for_model_joints(self.arm.ur.model, self.task.joints))
    }

    /// Wall-clock period of one tick (ns): `task.dt / time_compression`.
    pub fn wall_period_ns(&self) -> u64 {
        (self.task.dt / self.time_compression * 1e9).round() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_round_trip() {
        let c = ControllerConfig::default();
        c.validate().unwrap();
        let text = toml::to_string(&c).unwrap();
        let back: ControllerConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, c);
        assert_eq!(c.wall_period_ns(), 100_000_000);
    }

    #[test]
    fn limits_looser_than_the_models_own_are_refused() {
        let mut c: ControllerConfig = toml::from_str("[arm.ur]\nmodel = \"ur10e\"").unwrap();
        c.limits = Some(ArmLimits::default());
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("limits") && e.contains("ur10e"), "{e}");
        let mut own = ArmLimits::for_model(ur5_shared::UrModel::Ur10e);
        c.limits = Some(own.clone());
        c.validate().unwrap();
        own.velocity[0] *= 0.5;
        c.limits = Some(own.clone());
        c.validate().unwrap();
        own.velocity[0] = 10.0;
        c.limits = Some(own);
        assert!(c.validate().is_err());
    }

    #[test]
    fn the_limits_default_to_the_models_own() {
        let bits = |l: &ArmLimits| {
            [l.lower, l.upper, l.velocity, l.effort]
                .map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        };
        // A UR10e without [limits]: the UR10e's, valid.
        let c: ControllerConfig = toml::from_str("[arm.ur]\nmodel = \"ur10e\"").unwrap();
        let ur10e = ArmLimits::for_model(ur5_shared::UrModel::Ur10e);
        assert_eq!(bits(&c.limits()), bits(&ur10e));
        assert_ne!(
            bits(&ur10e),
            bits(&ArmLimits::default()),
            "the test tells them apart"
        );
        c.validate().unwrap();
        // A UR5 config: the UR5's limits as before, bit for bit, with or without [limits].
        let ur5 = ArmLimits::default();
        let c: ControllerConfig = toml::from_str("").unwrap();
        assert_eq!(bits(&c.limits()), bits(&ur5));
        let text = toml::to_string(&ControllerConfig {
            limits: Some(ur5.clone()),
            ..ControllerConfig::default()
        })
        .unwrap();
        assert!(text.contains("[limits]"), "{text}");
        let c: ControllerConfig = toml::from_str(&text).unwrap();
        assert_eq!(bits(&c.limits()), bits(&ur5));
        // Given limits win over the model's.
        let c: ControllerConfig =
            toml::from_str("[arm.ur]\nmodel = \"ur10e\"\n[limits]\nvelocity = [1.0, 1.0, 1.0]")
                .unwrap();
        assert_eq!(c.limits().velocity, [1.0; 3]);
        assert_eq!(c.limits().lower, ur5.lower, "the rest: ArmLimits' defaults");
    }

    #[test]
    fn rejects_typos_and_out_of_range_values() {
        assert!(toml::from_str::<ControllerConfig>("mode = \"lock_step\"").is_err());
        assert!(toml::from_str::<ControllerConfig>("episodez = 3").is_err());
        let mut c: ControllerConfig = toml::from_str("[task]\ndt = 0.0005").unwrap();
        assert!(c.validate().unwrap_err().to_string().contains("task.dt"));
        c.task.dt = 0.001;
        c.validate().unwrap();
        c.time_compression = 0.5;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("time_compression"));
        let c: ControllerConfig = toml::from_str("[safety]\nstale_state_timeout_s = 0").unwrap();
        assert!(c.validate().is_err());
        let c: ControllerConfig = toml::from_str("[task]\nstart_q = [0.0, 0.0, 4.0]").unwrap();
        assert!(c.validate().unwrap_err().to_string().contains("start_q"));
    }

    /// A six-joint task without `start_q` starts with the wrist at the controller's
    /// `arm.ur.wrist_q`, as the learner's does at its `sim.wrist_q`.
    #[test]
    fn a_six_joint_start_takes_the_wrist_of_the_arm() {
        let c: ControllerConfig = ur5_shared::config::from_toml_str(
            "[arm.ur]\nwrist_q = [-1.5, 1.4, 0.2]\n[task]\njoints = 6\ngoal_pose = [-0.44, -0.3, 0.37, 0.47, -0.11, -0.81]",
        )
        .unwrap();
        c.validate().unwrap();
        assert_eq!(&c.task.start_q[3..], &[-1.5, 1.4, 0.2]);
        assert_eq!(c.task.start_q[..3], TaskConfig::default().start_q[..3]);
    }

    #[test]
    fn the_dashboard_and_servoj_keys_print_only_when_set() {
        // Unset, they are not serialised: older configurations print and hash as before.
        let text = toml::to_string(&ControllerConfig::default()).unwrap();
        for key in [
            "dashboard_port",
            "check_model",
            "bring_up",
            "recover_protective_stop",
            "servoj_",
        ] {
            assert!(!text.contains(key), "{key} in\n{text}");
        }
        let c: ControllerConfig = toml::from_str(
            "[arm.ur]\ncheck_model = false\nbring_up = true\nservoj_gain = 1000.0\nservoj_lookahead_time_s = 0.05",
        )
        .unwrap();
        let text = toml::to_string(&c).unwrap();
        for key in [
            "check_model = false",
            "bring_up = true",
            "servoj_gain = 1000.0",
            "servoj_lookahead_time_s = 0.05",
        ] {
            assert!(text.contains(key), "{key} in\n{text}");
        }
        assert_eq!(toml::from_str::<ControllerConfig>(&text).unwrap(), c);
    }

    #[test]
    fn the_live_view_is_off_by_default_and_checked_when_on() {
        let c = ControllerConfig::default();
        assert!(!c.live_view.enabled);
        // Off: not printed, so configurations print and hash as before.
        assert!(!toml::to_string(&c).unwrap().contains("live_view"));
        let on: ControllerConfig = toml::from_str(
            "[live_view]
enabled = true
domain_id = 3",
        )
        .unwrap();
        on.validate().unwrap();
        assert_eq!(on.live_view.namespace, "/rt_controller");
        assert_eq!(on.live_view.frame_id, "base");
        // Off, its values are not checked.
        let off: ControllerConfig = toml::from_str(
            "[live_view]
domain_id = 300",
        )
        .unwrap();
        off.validate().unwrap();
        let ros2 = "mode = \"real_time\"\npacing = \"arm\"\n[arm]\nbackend = \"ros2\"\n";
        for (text, key) in [
            ("[live_view]\nenabled = true\ndomain_id = 233".to_owned(), "live_view.domain_id"),
            ("[live_view]\nenabled = true\nrate_hz = 0.0".to_owned(), "live_view.rate_hz"),
            ("[live_view]\nenabled = true\nnamespace = \"a b\"".to_owned(), "live_view.namespace"),
            ("[live_view]\nenabled = true\nframe_id = \"\"".to_owned(), "live_view.frame_id"),
            ("[live_view]\nenabled = true\n[live_view.qos]\nreliability = \"reliable\"\ndepth = 0".to_owned(), "live_view.qos.depth"),
            // The ros2 arm's driver publishes /joint_states on the same domain.
            (format!("{ros2}[live_view]\nenabled = true\njoint_states = true"), "live_view.joint_states"),
        ] {
            let c: ControllerConfig = toml::from_str(&text).unwrap();
            match c.validate() {
                Err(ConfigError::Invalid { key: k, .. }) => assert_eq!(k, key, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
        // On another topic or domain it may.
        let c: ControllerConfig = toml::from_str(&format!(
            "{ros2}[live_view]\nenabled = true\njoint_states = true\ndomain_id = 1"
        ))
        .unwrap();
        c.validate().unwrap();
    }

    #[test]
    fn arm_backend_defaults_to_iceoryx2_and_ur_settings_are_checked() {
        assert_eq!(ControllerConfig::default().arm.backend, ArmKind::Iceoryx2);
        let c: ControllerConfig =
            toml::from_str("[arm]\nbackend = \"ur\"\n[arm.ur]\nhost = \"127.0.0.1\"").unwrap();
        c.validate().unwrap();
        assert_eq!(c.arm.ur.rtde_port, 30004);
        assert_eq!(c.arm.ur.reverse_port, 50001);
        assert_eq!(c.arm.ur.secondary_port, 30002);
        assert_eq!(c.arm.ur.series, UrSeries::Auto);
        assert!(toml::from_str::<ControllerConfig>("[arm]\nbackend = \"ros\"").is_err());
        let ros2: ControllerConfig = toml::from_str(
            "mode = \"real_time\"\npacing = \"arm\"\n[arm]\nbackend = \"ros2\"\n[arm.ros2]\ndomain_id = 7\n[arm.ros2.command_qos]\nreliability = \"best_effort\"\ndepth = 1",
        )
        .unwrap();
        assert_eq!(ros2.arm.ros2.domain_id, 7);
        assert_eq!(ros2.arm.ros2.joint_states_topic, "/joint_states");
        assert_eq!(
            ros2.arm.ros2.command_qos.reliability,
            ur5_ros2::ReliabilityKind::BestEffort
        );
        ros2.validate().unwrap();
        for (extra, key) in [
            ("", "mode"),
            ("mode = \"real_time\"\n", "pacing"),
            ("mode = \"real_time\"\npacing = \"arm\"\n[arm.ros2]\ndomain_id = 233", "arm.ros2.domain_id"),
            ("mode = \"real_time\"\npacing = \"arm\"\n[arm.ros2]\njoints = [\"a\", \"b\", \"c\", \"d\", \"e\", \"a\"]", "arm.ros2.joints"),
            ("mode = \"real_time\"\npacing = \"arm\"\n[arm.ros2]\ncommand_topic = \"/\"", "arm.ros2.command_topic"),
        ] {
            let (head, tail) = extra.split_once("[arm.ros2]").unwrap_or((extra, ""));
            let text = format!("{head}[arm]\nbackend = \"ros2\"\n{}", if tail.is_empty() { String::new() } else { format!("[arm.ros2]{tail}") });
            let c: ControllerConfig = toml::from_str(&text).unwrap();
            match c.validate() {
                Err(ConfigError::Invalid { key: k, .. }) => assert_eq!(k, key, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
        assert!(toml::from_str::<ControllerConfig>("[arm.ur]\nhots = \"x\"").is_err());
        for (text, key) in [
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nhost = \"robot.local\"",
                "arm.ur.host",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nrtde_port = 0",
                "arm.ur.rtde_port",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nsecondary_port = 30004",
                "arm.ur.secondary_port",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nreceive_timeout_ms = 5",
                "arm.ur.receive_timeout_ms",
            ),
            (
                "action_mode = \"torque\"\n[arm]\nbackend = \"ur\"",
                "action_mode",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nservoj_lookahead_time_s = 0.01",
                "arm.ur.servoj_lookahead_time_s",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nservoj_lookahead_time_s = 0.25",
                "arm.ur.servoj_lookahead_time_s",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nservoj_gain = 50.0",
                "arm.ur.servoj_gain",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\nservoj_gain = 2500.0",
                "arm.ur.servoj_gain",
            ),
            (
                "[arm]\nbackend = \"ur\"\n[arm.ur]\ndashboard_port = 0",
                "arm.ur.dashboard_port",
            ),
        ] {
            let c: ControllerConfig = toml::from_str(text).unwrap();
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        // The iceoryx2 backend ignores the ur settings.
        let c: ControllerConfig = toml::from_str("[arm.ur]\nhost = \"robot.local\"").unwrap();
        c.validate().unwrap();
    }
}
