//! `hil-sim serve`: the simulated arm behind `arm/state` and `arm/command` (docs/design.md §3.1, §3.5), as a
//! real arm driver would be.
//!
//! - **Zero-order hold**: the last goal (or torque) command stays in force until the next one.
//! - **Lockstep** (`mode = "lockstep"`): every command advances the arm by one control period
//!   `task.dt` (a reset by none) and is answered by exactly one state, whose
//!   `last_command_seq` is the command's `seq`. Experiments run like this.
//! - **Real time** (`mode = "real_time"`): the arm runs on its own clock. Every
//!   `state_period_s / time_compression` wall seconds (absolute deadlines) it applies the
//!   commands that arrived, advances `state_period_s` of physics under the held command and
//!   publishes a state. Without a command for `command_timeout_s` it holds its pose and reports
//!   [`ArmFaults::STALE_COMMAND`] until commands come again.
//! - **Reset** commands teleport the arm to `reset_pose` at rest (goal: `task.goal`); the arm
//!   then holds that pose until the next command.
//! - **Hold** commands: goal-angle mode holds the angles measured when the hold began; torque
//!   mode applies the nominal gravity torque minus damping (`hold_damping`).
//! - A command of the wrong kind for the arm's `sim.mode`, an unknown kind or non-finite values
//!   is ignored, the arm holds and reports it in `faults` (for that state).
//!
//! Stamps are `CLOCK_MONOTONIC` ns at publication ([`ur5_shared::clock`]), in both modes.

use core::sync::atomic::{AtomicBool, Ordering};
use core::time::Duration;

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use ur5_shared::clock::{monotonic_ns, sleep_until_ns};
use ur5_shared::config::{ActionMode, ConfigError, SimConfig, TaskConfig};
use ur5_shared::kinematics::Joints6;
use ur5_shared::layout::{MAX_JOINTS, MAX_TOOL_POINTS, N_JOINTS};
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{ArmCommand, ArmFaults, ArmState, ArmStatus, CommandKind};

use crate::{SimError, Ur5Sim};

/// How the arm is clocked.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ServeMode {
    /// One control period per command, one state per command.
    #[default]
    Lockstep,
    /// The arm's own physics clock, states every `state_period_s`.
    RealTime,
}

/// Options of `hil-sim serve` (the `[serve]` table of the config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServeConfig {
    /// iceoryx2 service prefix; the controller must use the same.
    pub prefix: String,
    /// Lockstep or real time.
    pub mode: ServeMode,
    /// Real time: the arm runs this many times faster than wall time (≥ 1); use the
    /// controller's factor.
    pub time_compression: f64,
    /// Real time: arm time between two published states (s); a whole multiple of
    /// `sim.physics_dt`. Ours: 0.01 s (100 Hz); a real UR5 publishes at 125–500 Hz.
    pub state_period_s: f64,
    /// Real time: hold and report a stale command after this long without one (wall s).
    pub command_timeout_s: f64,
    /// Torque-mode hold: joint damping added to the gravity torque (N·m·s/rad).
    pub hold_damping: [f64; N_JOINTS],
    /// Stop after this many commands (0 = until SIGINT/SIGTERM); for scripted runs.
    pub max_commands: u64,
    /// Active joints of the served arm: 3 (the wrist locked at `sim.wrist_q`) or 6; states carry
    /// that many joints and commands for another number are refused (`WRONG_JOINTS`). At six,
    /// reset poses and goals have six values; the torque-mode hold damps the wrist with its
    /// servo's velocity gains (`hil_sim::servo::wrist_velocity_gain`). A task of six joints
    /// (`task.joints = 6`) serves six whatever this says. Left out when serialised at 3.
    #[serde(skip_serializing_if = "is_three")]
    pub joints: usize,
}

fn is_three(n: &usize) -> bool {
    *n == 3
}

impl Default for ServeConfig {
    fn default() -> Self {
        Self {
            prefix: String::new(),
            mode: ServeMode::Lockstep,
            time_compression: 1.0,
            state_period_s: 0.01,
            command_timeout_s: 1.0,
            hold_damping: [20.0, 20.0, 5.0],
            max_commands: 0,
            joints: 3,
        }
    }
}

impl ServeConfig {
    /// Checks ranges; the message names the key and the allowed range.
    pub fn validate(&self, sim: &SimConfig) -> Result<(), ConfigError> {
        let bad = |key, why: String| Err(ConfigError::Invalid { key, why });
        if let Err(why) = ur5_shared::config::check_time_compression(self.time_compression) {
            return bad("serve.time_compression", why);
        }
        let ratio = self.state_period_s / sim.physics_dt;
        if !(self.state_period_s > 0.0
            && ratio.round() >= 1.0
            && (ratio - ratio.round()).abs() < 1e-9)
        {
            return bad(
                "serve.state_period_s",
                format!(
                    "{} s must be a whole multiple of sim.physics_dt = {} s",
                    self.state_period_s, sim.physics_dt
                ),
            );
        }
        if !(self.command_timeout_s.is_finite() && self.command_timeout_s > 0.0) {
            return bad(
                "serve.command_timeout_s",
                format!("{} must be > 0", self.command_timeout_s),
            );
        }
        if !self.hold_damping.iter().all(|d| d.is_finite() && *d >= 0.0) {
            return bad("serve.hold_damping", "must be finite and >= 0".into());
        }
        services::ServiceNames::new(&self.prefix)
            .arm_state()
            .map_err(|e| ConfigError::Invalid {
                key: "serve.prefix",
                why: e.to_string(),
            })?;
        Ok(())
    }
}

/// The config file of `hil-sim serve`: `[task]`, `[sim]` and `[serve]`, all optional.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServeFile {
    /// Task (control period, start pose, goal).
    pub task: TaskConfig,
    /// Simulated arm.
    pub sim: SimConfig,
    /// Serving options.
    pub serve: ServeConfig,
}

/// What a serve run did (`--json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ServeSummary {
    /// Always "serve".
    pub command: &'static str,
    /// Commands received.
    pub commands: u64,
    /// Reset commands.
    pub resets: u64,
    /// Hold commands.
    pub holds: u64,
    /// Commands ignored (wrong kind for the mode, unknown kind, non-finite values, bad reset).
    pub rejected_commands: u64,
    /// States published.
    pub states: u64,
    /// Real time: periods that passed entirely while the arm was late.
    pub missed_periods: u64,
    /// Real time: times the arm began holding for lack of commands.
    pub stale_command_events: u64,
    /// Simulated time stepped, over all episodes (s).
    pub sim_time_s: f64,
}

/// Errors of `serve`.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// Invalid configuration or simulator error.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Invalid configuration.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Another arm serves the prefix.
    #[error(transparent)]
    Role(#[from] ur5_shared::services::RoleLockError),
    /// iceoryx2 setup failed.
    #[error("iceoryx2 setup failed for `{what}`: {why}; use a fresh --prefix if a stale run left services of other types")]
    Ipc {
        /// What was being set up.
        what: String,
        /// iceoryx2's error.
        why: String,
    },
}

fn ipc_err(what: &str) -> impl Fn(&dyn core::fmt::Debug) -> ServeError + '_ {
    move |e| ServeError::Ipc {
        what: what.to_owned(),
        why: format!("{e:?}"),
    }
}

/// Helpers on the simulated arm that serving needs; kept here, apart from the simulator.
impl Ur5Sim {
    /// Torque that holds the arm still where it is: the nominal gravity torque minus
    /// `damping` × q̇ (N·m).
    pub fn hold_torque(&self, damping: &[f64; N_JOINTS]) -> [f64; N_JOINTS] {
        let g = self.gravity_torque();
        let (_, qd) = self.joint_state();
        core::array::from_fn(|j| g[j] - damping[j] * qd[j])
    }

    /// [`Ur5Sim::hold_torque`] of every active joint (first [`Ur5Sim::joints`] entries): the
    /// wrist joints damped with their servo's velocity gains.
    pub fn hold_torque_all(&self, damping: &[f64; N_JOINTS]) -> Joints6 {
        let g = self.gravity_torque_all();
        let (_, qd) = self.joint_state_all();
        let w = crate::servo::wrist_velocity_gain(self.config().model);
        let d = [damping[0], damping[1], damping[2], w[0], w[1], w[2]];
        core::array::from_fn(|j| g[j] - d[j] * qd[j])
    }
}

/// The command in force (zero-order hold).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Held {
    /// Goal angles (rad) or torques (N·m), per the sim's mode (first `joints()` entries).
    Action(Joints6),
    /// Holding: goal-angle mode at these angles; torque mode by gravity torque.
    Hold(Joints6),
}

struct Arm {
    sim: Ur5Sim,
    task: TaskConfig,
    /// The task's tool points (`TaskConfig::tool_offsets`), reported in every state.
    offsets: [[f64; 3]; MAX_TOOL_POINTS],
    points: usize,
    cfg: ServeConfig,
    held: Held,
    state: ArmState,
    summary: ServeSummary,
    /// Arm time per step (s).
    period_s: f64,
    /// Faults of the command just applied (reported once, in the next state).
    command_faults: ArmFaults,
}

impl Arm {
    fn hold_here(&self) -> Held {
        Held::Hold(self.sim.joint_state_all().0)
    }

    /// Applies one command to what is held; resets happen at once.
    fn apply(&mut self, cmd: &ArmCommand) {
        self.summary.commands += 1;
        self.state.episode = cmd.episode;
        self.state.last_command_seq = cmd.seq;
        let mode = self.sim.config().mode;
        let finite = cmd
            .values
            .iter()
            .chain(&cmd.reset_pose)
            .all(|v| v.is_finite());
        // The active joints' values; a command for another number of joints is refused.
        let n = self.sim.joints();
        let joints = |v: &[f64]| {
            (v.len() == n).then(|| {
                let mut a = [0.0; 6];
                a[..n].copy_from_slice(v);
                a
            })
        };
        let (values, reset_pose) = (joints(cmd.values()), joints(cmd.reset_pose()));
        match cmd.kind() {
            _ if !finite => self.reject(ArmFaults::NON_FINITE_COMMAND),
            Ok(CommandKind::Hold) => {
                self.summary.holds += 1;
                if !matches!(self.held, Held::Hold(_)) {
                    self.held = self.hold_here();
                }
            }
            Ok(_) if cmd.joints as usize != n => self.reject(ArmFaults::WRONG_JOINTS),
            Ok(CommandKind::Reset) => {
                let reset_pose = reset_pose.expect("n values");
                self.summary.resets += 1;
                match self.sim.restart(&reset_pose[..n], self.task.goal) {
                    Ok(_) => self.held = Held::Hold(reset_pose),
                    Err(e) => {
                        eprintln!("hil-sim serve: reset refused: {e}");
                        self.reject(ArmFaults::UNKNOWN_COMMAND);
                    }
                }
            }
            Ok(CommandKind::GoalAngles) if mode == ActionMode::GoalAngles => {
                self.held = Held::Action(values.expect("n values"))
            }
            Ok(CommandKind::Torques) if mode == ActionMode::Torque => {
                self.held = Held::Action(values.expect("n values"))
            }
            Ok(_) | Err(_) => self.reject(ArmFaults::UNKNOWN_COMMAND),
        }
    }

    fn reject(&mut self, fault: ArmFaults) {
        self.summary.rejected_commands += 1;
        self.command_faults.insert(fault);
        if !matches!(self.held, Held::Hold(_)) {
            self.held = self.hold_here();
        }
    }

    /// Advances one period of the sim under what is held.
    fn step(&mut self) {
        let action = match (self.held, self.sim.config().mode) {
            (Held::Action(a), _) => a,
            (Held::Hold(q), ActionMode::GoalAngles) => q,
            (Held::Hold(_), ActionMode::Torque) => self.sim.hold_torque_all(&self.cfg.hold_damping),
        };
        self.summary.sim_time_s += self.period_s;
        self.sim.advance(&action[..self.sim.joints()]);
    }

    /// Measures the arm (sensor noise included, as `Ur5Sim::observe_points` draws it: for three
    /// joints and one point the draws of `Ur5Sim::observe`) and publishes the state.
    fn publish(
        &mut self,
        publisher: &iceoryx2::port::publisher::Publisher<ipc::Service, ArmState, ()>,
        extra: ArmFaults,
    ) {
        let (n, p) = (self.sim.joints(), self.points);
        let (mut q, mut qd) = ([0.0; MAX_JOINTS], [0.0; MAX_JOINTS]);
        let (mut points, mut vels) = ([[0.0; 3]; MAX_TOOL_POINTS], [[0.0; 3]; MAX_TOOL_POINTS]);
        self.sim.observe_points(
            &self.offsets[..p],
            &mut q[..n],
            &mut qd[..n],
            &mut points[..p],
            &mut vels[..p],
        );
        let s = &mut self.state;
        s.seq += 1;
        s.set_joints(&q[..n], &qd[..n]);
        s.set_points(&points[..p], &vels[..p]);
        let mut status = ArmStatus::READY;
        if matches!(self.held, Held::Hold(_)) {
            status.insert(ArmStatus::HOLDING);
        }
        s.status = status;
        let mut faults = self.command_faults;
        faults.insert(extra);
        if !s.is_finite() {
            faults.insert(ArmFaults::PHYSICS);
        }
        s.faults = faults;
        self.command_faults = ArmFaults::default();
        s.stamp_ns = monotonic_ns();
        if publisher.send_copy(*s).is_ok() {
            self.summary.states += 1;
        }
    }
}

/// Builds the arm from `sim_cfg` and serves it until `stop` is raised, SIGINT/SIGTERM arrives,
/// or `cfg.max_commands` commands were applied. Starts at rest at `task.start_q` and publishes
/// that state at once.
pub fn serve(
    task: &TaskConfig,
    sim_cfg: &SimConfig,
    cfg: &ServeConfig,
    stop: &AtomicBool,
) -> Result<ServeSummary, ServeError> {
    task.validate()?;
    cfg.validate(sim_cfg)?;
    let period_s = match cfg.mode {
        ServeMode::Lockstep => task.dt,
        ServeMode::RealTime => cfg.state_period_s,
    };
    let joints = cfg.joints.max(task.joints);
    let sim = Ur5Sim::with_joints(sim_cfg.clone(), period_s, joints)?;
    let _role = services::RoleLock::acquire(&cfg.prefix, "arm")?;
    let names = ServiceNames::new(&cfg.prefix);
    let node = NodeBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| ipc_err("node")(&e))?;
    let state_svc = services::ARM_STATE_QOS
        .open_or_create_retrying::<ArmState>(&node, &names.arm_state)
        .map_err(|e| ipc_err(&names.arm_state)(&e))?;
    let cmd_svc = services::ARM_COMMAND_QOS
        .open_or_create_retrying::<ArmCommand>(&node, &names.arm_command)
        .map_err(|e| ipc_err(&names.arm_command)(&e))?;
    let publisher = state_svc
        .publisher_builder()
        .create()
        .map_err(|e| ipc_err(&names.arm_state)(&e))?;
    let subscriber = cmd_svc
        .subscriber_builder()
        .create()
        .map_err(|e| ipc_err(&names.arm_command)(&e))?;

    let tool = task.tool_offsets();
    let mut offsets = [[0.0; 3]; MAX_TOOL_POINTS];
    offsets[..tool.len()].copy_from_slice(tool);
    let mut arm = Arm {
        sim,
        task: task.clone(),
        offsets,
        points: tool.len(),
        cfg: cfg.clone(),
        held: Held::Hold([0.0; 6]), // set below, after the reset
        state: ArmState::default(),
        summary: ServeSummary {
            command: "serve",
            ..Default::default()
        },
        command_faults: ArmFaults::default(),
        period_s,
    };
    // The task's start pose; a wrist the task does not move at its rest. Held as given (not
    // as the f32 physics rounds it).
    let start = task.start_six(&arm.sim.model().wrist_q);
    arm.sim.restart(&start[..joints], task.goal)?;
    arm.held = Held::Hold(start);
    arm.publish(&publisher, ArmFaults::default());
    let done = |arm: &Arm| {
        stop.load(Ordering::Relaxed)
            || (cfg.max_commands > 0 && arm.summary.commands >= cfg.max_commands)
    };
    eprintln!(
        "hil-sim serve: {:?} on prefix `{}`, control period {} s, mode {:?}",
        cfg.mode,
        cfg.prefix,
        task.dt,
        arm.sim.config().mode
    );

    match cfg.mode {
        ServeMode::Lockstep => {
            let mut idle: u32 = 0;
            while !done(&arm) {
                match subscriber.receive() {
                    Ok(Some(cmd)) => {
                        idle = 0;
                        let cmd = *cmd;
                        arm.apply(&cmd);
                        if cmd.kind() != Ok(CommandKind::Reset) {
                            arm.step();
                        }
                        arm.publish(&publisher, ArmFaults::default());
                    }
                    Ok(None) | Err(_) => {
                        idle = idle.saturating_add(1);
                        if idle < 200 {
                            core::hint::spin_loop();
                            continue;
                        }
                        // Delivers the last state (history) to a controller that joins late.
                        let _ = publisher.update_connections();
                        // Sleeps and notices SIGINT/SIGTERM.
                        if node
                            .wait(Duration::from_micros(if idle < 20_000 { 20 } else { 500 }))
                            .is_err()
                        {
                            break;
                        }
                    }
                }
            }
        }
        ServeMode::RealTime => {
            let period_ns = (cfg.state_period_s / cfg.time_compression * 1e9).round() as u64;
            let timeout_ns = (cfg.command_timeout_s * 1e9) as u64;
            let mut next = monotonic_ns() + period_ns;
            let mut last_cmd_ns: Option<u64> = None;
            let mut stale = false;
            while !done(&arm) {
                sleep_until_ns(next);
                let now = monotonic_ns();
                let missed = now.saturating_sub(next) / period_ns;
                arm.summary.missed_periods += missed;
                next += (missed + 1) * period_ns;
                if node.wait(Duration::ZERO).is_err() {
                    break;
                }
                let _ = publisher.update_connections();
                while let Ok(Some(cmd)) = subscriber.receive() {
                    let cmd = *cmd;
                    arm.apply(&cmd);
                    last_cmd_ns = Some(now);
                    stale = false;
                }
                let mut extra = ArmFaults::default();
                if let Some(t) = last_cmd_ns {
                    if now - t > timeout_ns {
                        if !stale {
                            stale = true;
                            arm.summary.stale_command_events += 1;
                            arm.held = arm.hold_here();
                            eprintln!(
                                "hil-sim serve: no command for {} s: holding",
                                cfg.command_timeout_s
                            );
                        }
                        extra.insert(ArmFaults::STALE_COMMAND);
                    }
                }
                arm.step();
                arm.publish(&publisher, extra);
            }
        }
    }
    Ok(arm.summary)
}
