//! The controller: a fallible [`Controller::setup`] that allocates everything, and
//! [`Controller::run`], the loop phase, which does not allocate, lock or block except in the
//! period wait (docs/design.md §3.4, §3.8; STYLE.md, the iceoryx2 split of setup and tick).
//!
//! # Episodes
//!
//! ```text
//!            ┌──────────── no valid table ────────────┐
//!            ▼                                         │
//! Boundary ──take newest table──▶ Resetting ──ack──▶ Running t = 0 … T−1 ──▶ Boundary
//!    ▲                                                 │ stale / arm fault / non-finite
//!    └────────────── arm fresh again ◀── Holding ◀─────┘
//! ```
//!
//! - **Boundary**: the only place a table is taken, of either kind (copy into the inactive
//!   half, validate, flip; the newest version wins); then a `Reset` command to `task.start_q`.
//! - **Resetting**: waits until the arm acknowledges the reset (`ArmState::last_command_seq`);
//!   the arm is at rest at the start pose and holds it until the first command ("hold, then
//!   start"). The acknowledging state is s_0.
//! - **Running**: per tick s_t → ε_t → a_t = the active table's law
//!   ([`ur5_shared::controller_action`] for a gain table, [`ur5_shared::policy_action`] for a
//!   policy table) → clamp → command → [`ur5_shared::StepSample`]. The state's goal is
//!   `task.goal` (set at run time: `rt-controller run --goal x,y,z`).
//! - **Holding**: a latched fault (stale state, arm fault, non-finite state or action) ends the
//!   episode (it is counted as aborted; its samples stop) and the controller commands a hold
//!   (PD to the last safe pose) every period until the arm is fresh and fault-free again.
//! - **NeedTable**: no valid table yet: hold and poll `controller/gains`.
//!
//! # Pacing
//!
//! Lockstep: after each command, wait for the state that acknowledges it. Real time with
//! deadline pacing: `clock_nanosleep(TIMER_ABSTIME)` to deadlines every `task.dt /
//! time_compression`, act on the newest state; periods that have passed entirely are counted as
//! missed and skipped. Real time with arm pacing: each new state starts a tick.
//!
//! # Files
//!
//! This one: the types, [`Controller::setup`], [`Controller::run`] and the summary; `wait.rs`:
//! the period wait of each pacing mode; `episode.rs`: the state machine above (boundary and
//! table intake, ticks, faults and holds).

use core::sync::atomic::{AtomicBool, Ordering};
use std::io::Write;

use serde::Serialize;
use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ArmLimits;
use ur5_shared::layout::{StateLayout, MAX_JOINTS, MAX_TOOL_POINTS};
use ur5_shared::status::PeerStatus;
use ur5_shared::{ArmState, PolicyScratch};

use crate::arm::{ArmBackend, ArmReport, Iceoryx2Arm, Ros2Arm, UrArm};
use crate::config::{ArmKind, ControllerConfig, Mode};
use crate::live_view::{LiveView, LiveViewReport};
use crate::monitor::{LostPeers, PeerMonitor};
use crate::noise::Noise;
use crate::ports::{ControllerPorts, SetupError};
use crate::rt::{self, RtOutcome};
use crate::safety::Fault;
use crate::stats::{FaultCounts, LoopStats, Percentiles, RejectCounts};
use crate::tables::TableBuffer;

mod episode;
mod wait;

/// Why [`Controller::run`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ExitReason {
    /// The configured number of episodes completed.
    EpisodesDone,
    /// The stop flag was raised (SIGINT/SIGTERM in the binary).
    Stopped,
    /// The arm was stale for `safety.give_up_after_s`, or its backend reports its connection
    /// gone ([`crate::ArmBackend::lost`]).
    ArmLost,
    /// No valid table arrived within `safety.no_table_timeout_s`.
    NoTable,
    /// The arm's driver reported a stop the controller cannot clear (`ArmFaults::DRIVER`: a
    /// protective stop, safety mode not NORMAL, robot not RUNNING, or the robot's program
    /// ended): the arm holds; clear the cause on the robot, then start again.
    ArmStopped,
    /// The controller rejected the learner's table for a task reason (horizon, action mode)
    /// and told the learner so on `controller/status` (docs/design.md §3.12).
    TaskMismatch,
    /// The learner stopped and said why on `learner/status` (e.g. the episodes are not its
    /// task, or the seed differs).
    LearnerStopped,
}

/// The end-of-run summary (`--json`).
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Always "run".
    pub command: &'static str,
    /// Why the loop ended.
    pub exit_reason: ExitReason,
    /// Lockstep or real time.
    pub mode: Mode,
    /// Episodes that ran all T ticks.
    pub episodes_completed: u64,
    /// Episodes ended by a fault.
    pub episodes_aborted: u64,
    /// Running ticks.
    pub ticks: u64,
    /// Version of the active table at exit.
    pub table_version: Option<u64>,
    /// Tables taken.
    pub swaps: u64,
    /// Rejections by reason.
    pub rejected: RejectCounts,
    /// Total rejections.
    pub rejected_total: u64,
    /// Faults by kind.
    pub faults: FaultCounts,
    /// The fault still latched at exit, if any.
    pub fault_at_exit: Option<Fault>,
    /// Deadline pacing: missed periods.
    pub missed_periods: u64,
    /// Ticks whose action was clamped.
    pub saturated_ticks: u64,
    /// Resets resent.
    pub reset_retries: u64,
    /// IPC send/receive failures.
    pub ipc_errors: u64,
    /// Samples no learner received.
    pub samples_unheard: u64,
    /// Compute per tick (law + clamp + publish), ns.
    pub compute: Percentiles,
    /// Wake-up lateness, ns.
    pub wake: Percentiles,
    /// Table swap (copy + flip), ns.
    pub swap: Percentiles,
    /// Table validation, ns.
    pub validate: Percentiles,
    /// Boundary intake (receive + copy + validate + flip), ns.
    pub intake: Percentiles,
    /// Peer processes that died or left during the run ([`crate::monitor`]), if it ran.
    pub lost_peers: Option<LostPeers>,
    /// Why the arm is gone, if the backend knows (e.g. the robot closed RTDE).
    pub arm_lost: Option<&'static str>,
    /// Why the controller or the learner stopped the run (`task_mismatch`, `learner_stopped`):
    /// the same message on both sides.
    pub stop_message: Option<String>,
    /// The arm backend's own counters (the `ur` arm: packages, commands, keepalives, robot
    /// stop).
    pub arm: Option<ArmReport>,
    /// The live view's counters (`[live_view]`), if it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub live_view: Option<LiveViewReport>,
    /// Real-time privileges obtained.
    pub rt: RtOutcome,
    /// Wall time of the loop phase (s).
    pub wall_s: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Boundary,
    Resetting { seq: u64, sent_ns: u64 },
    Running { t: usize },
    Holding,
    NeedTable,
}

/// The controller: configuration, arm, learner ports, tables, noise, statistics and loop state.
/// Generic over the arm ([`crate::arm`]; static dispatch). `arm` is declared before `ports` so
/// that it drops first: the iceoryx2 arm's ports live on the node `ports` owns.
pub struct Controller<A: ArmBackend = Iceoryx2Arm> {
    cfg: ControllerConfig,
    arm: A,
    ports: ControllerPorts,
    tables: TableBuffer,
    /// Layer buffers of [`ur5_shared::policy_action`] (allocated at setup).
    scratch: Box<PolicyScratch>,
    limits: ArmLimits,
    noise: Noise,
    stats: LoopStats,
    rt: RtOutcome,
    period_ns: u64,
    stale_ns: u64,
    // Loop state.
    phase: Phase,
    cmd_seq: u64,
    /// Lockstep: the command whose acknowledgement the next wait expects.
    awaiting: Option<u64>,
    episode: u64,
    episodes_started: u64,
    episodes_with_version: u64,
    /// Episodes of the active version aborted (in reset or running): its cycle runs again
    /// (`cycles_per_table`).
    aborted_with_version: u64,
    /// Holding at a boundary for a table newer than the active one (`cycles_per_table`).
    waiting_newer: bool,
    noisy: bool,
    /// The task's layout (`task.joints`, point or pose goal): the dimensions of every table,
    /// state and action.
    layout: StateLayout,
    /// The task's targets of its tool points (m, base frame; `TaskConfig::targets`).
    task_targets: [[f64; 3]; MAX_TOOL_POINTS],
    /// The targets of the running episode in `targets[..tool points]`: the active table's goal
    /// for a point task ([`ur5_shared::EpisodePlan`]), or the task's.
    targets: [[f64; 3]; MAX_TOOL_POINTS],
    latest: ArmState,
    have_state: bool,
    used_state_seq: u64,
    /// The last safe pose of the active joints in `last_safe_q[..joints]` (rad).
    last_safe_q: [f64; MAX_JOINTS],
    stale_since_ns: Option<u64>,
    next_deadline_ns: u64,
    tick_start_ns: u64,
    fault: Option<Fault>,
    /// Why the run stops (a task mismatch found here, or the learner's fatal status).
    stop_status: Option<PeerStatus>,
    /// The exit the loop takes at its next check ([`ExitReason::TaskMismatch`]).
    pending_exit: Option<ExitReason>,
    no_table_since_ns: u64,
    wall_s: f64,
    monitor: Option<PeerMonitor>,
    /// `[live_view]`, when enabled ([`crate::live_view`]).
    live: Option<LiveView>,
}

impl Controller<Iceoryx2Arm> {
    /// Setup phase with the iceoryx2 arm (`arm/state`, `arm/command` on `cfg.prefix`): see
    /// [`Controller::setup_with`].
    pub fn setup(cfg: ControllerConfig) -> Result<Self, SetupError> {
        cfg.validate()?;
        if cfg.arm.backend != ArmKind::Iceoryx2 {
            return Err(SetupError::BackendMismatch("iceoryx2"));
        }
        Self::setup_with(cfg, |_, ports| {
            Iceoryx2Arm::create(ports.node(), &ports.names)
        })
    }
}

impl Controller<UrArm> {
    /// Setup phase with the `ur` arm (`cfg.arm.ur`; docs/design.md §3.10): see
    /// [`Controller::setup_with`].
    pub fn setup_ur(cfg: ControllerConfig) -> Result<Self, SetupError> {
        cfg.validate()?;
        if cfg.arm.backend != ArmKind::Ur {
            return Err(SetupError::BackendMismatch("ur"));
        }
        Self::setup_with(cfg, |cfg, _| Ok(UrArm::new(cfg)))
    }
}

impl Controller<Ros2Arm> {
    /// Setup phase with the `ros2` arm (`cfg.arm.ros2`; docs/design.md §3.13): see
    /// [`Controller::setup_with`].
    pub fn setup_ros2(cfg: ControllerConfig) -> Result<Self, SetupError> {
        cfg.validate()?;
        if cfg.arm.backend != ArmKind::Ros2 {
            return Err(SetupError::BackendMismatch("ros2"));
        }
        Self::setup_with(cfg, |cfg, _| Ros2Arm::new(cfg))
    }
}

impl<A: ArmBackend> Controller<A> {
    /// Setup phase: validates `cfg`, applies the real-time privileges, creates the node and
    /// learner ports, creates the arm with `make_arm` and waits for it (a state, and commands
    /// accepted) and, if configured, for the learner, then preallocates tables, histograms and
    /// noise. Allocates; may fail.
    pub fn setup_with(
        cfg: ControllerConfig,
        make_arm: impl FnOnce(&ControllerConfig, &ControllerPorts) -> Result<A, SetupError>,
    ) -> Result<Self, SetupError> {
        cfg.validate()?;
        let rt = rt::apply(&cfg.rt);
        let ports = ControllerPorts::create(&cfg.prefix)?;
        // Before the arm: a live view that cannot start fails the setup at once.
        let live = if cfg.live_view.enabled {
            Some(LiveView::start(
                &cfg.live_view,
                cfg.task.goal,
                cfg.arm.ur.wrist_q,
            )?)
        } else {
            None
        };
        let mut arm = make_arm(&cfg, &ports)?;
        let t0 = monotonic_ns();
        let timeout_ns = (cfg.setup_timeout_s * 1e9) as u64;
        let latest = arm.wait_ready(cfg.setup_timeout_s)?;
        if cfg.wait_for_learner {
            loop {
                let (subs, pubs) = ports.learner_peers();
                if subs > 0 && pubs > 0 {
                    break;
                }
                if monotonic_ns() - t0 > timeout_ns {
                    return Err(SetupError::PeerTimeout {
                        what: "learner (subscriber on learner/samples and publisher on controller/gains)",
                        start: "learner serve",
                        timeout_s: cfg.setup_timeout_s,
                        prefix: cfg.prefix.clone(),
                    });
                }
                std::thread::sleep(core::time::Duration::from_millis(1));
            }
        }
        arm.connect()?;
        ports.connect();
        // Warm up stderr (its lock and handle) so the first episode report does not.
        let _ = writeln!(
            std::io::stderr(),
            "rt-controller: arm connected on prefix `{}`; mode {:?}",
            cfg.prefix,
            cfg.mode
        );
        let period_ns = cfg.wall_period_ns();
        let stale_ns = (cfg.safety.stale_state_timeout_s * 1e9) as u64;
        let layout = cfg.task.layout();
        let mut task_targets = [[0.0; 3]; MAX_TOOL_POINTS];
        let t = cfg.task.targets();
        task_targets[..t.len()].copy_from_slice(&t);
        let mut last_safe_q = [0.0; MAX_JOINTS];
        last_safe_q.copy_from_slice(&latest.q);
        let monitor = (cfg.monitor_period_s > 0.0).then(|| {
            let m = PeerMonitor::spawn(
                &cfg.prefix,
                core::time::Duration::from_secs_f64(cfg.monitor_period_s),
            );
            // The peers connected above are known before the first episode.
            if !m.wait_first_scan(core::time::Duration::from_secs_f64(cfg.setup_timeout_s)) {
                let _ = writeln!(
                    std::io::stderr(),
                    "rt-controller: the peer monitor did not finish a scan within {} s; a peer \
                     lost early may not be reported",
                    cfg.setup_timeout_s
                );
            }
            m
        });
        Ok(Self {
            tables: TableBuffer::new(
                cfg.bounds,
                cfg.policy_bounds,
                cfg.task.horizon,
                cfg.action_mode,
                layout,
            )
            .for_arm_model(cfg.arm.ur.model),
            scratch: Box::default(),
            limits: cfg.limits(),
            noise: Noise::new(cfg.seed, 0, 0),
            stats: LoopStats::new(),
            rt,
            period_ns,
            stale_ns,
            phase: Phase::Boundary,
            cmd_seq: 0,
            awaiting: None,
            episode: 0,
            episodes_started: 0,
            episodes_with_version: 0,
            aborted_with_version: 0,
            waiting_newer: false,
            noisy: false,
            layout,
            task_targets,
            targets: task_targets,
            last_safe_q,
            have_state: true,
            used_state_seq: 0,
            latest,
            stale_since_ns: None,
            next_deadline_ns: 0,
            tick_start_ns: 0,
            fault: None,
            stop_status: None,
            pending_exit: None,
            no_table_since_ns: 0,
            wall_s: 0.0,
            monitor,
            live,
            arm,
            ports,
            cfg,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }

    /// Statistics so far.
    pub fn stats(&self) -> &LoopStats {
        &self.stats
    }

    /// The learner ports (e.g. to count connected peers).
    pub fn ports(&self) -> &ControllerPorts {
        &self.ports
    }

    /// The arm backend.
    pub fn arm(&self) -> &A {
        &self.arm
    }

    /// Loop phase: runs episodes until `cfg.episodes` complete, `stop` is raised, the arm is
    /// lost for `safety.give_up_after_s`, or no table arrives within
    /// `safety.no_table_timeout_s`. Does not allocate (tested with a counting allocator in
    /// tests/tests/no_alloc_loop.rs). Sends a hold before returning.
    pub fn run(&mut self, stop: &AtomicBool) -> ExitReason {
        let start = monotonic_ns();
        self.next_deadline_ns = start + self.period_ns;
        self.no_table_since_ns = start;
        let reason = loop {
            if stop.load(Ordering::Relaxed) {
                break ExitReason::Stopped;
            }
            self.stats.iterations += 1;
            let freshness = self.wait_period();
            if let Some(reason) = self.step(freshness) {
                break reason;
            }
        };
        self.send_hold();
        self.wall_s = (monotonic_ns() - start) as f64 * 1e-9;
        if let Some(st) = &self.stop_status {
            let _ = writeln!(
                std::io::stderr(),
                "rt-controller: stopping ({reason:?}): {}",
                st.text()
            );
        }
        if self.cfg.episode_report {
            let _ = writeln!(
                std::io::stderr(),
                "rt-controller: exit ({reason:?}{}{}) after {} episodes ({} aborted), {} ticks; compute {}; wake {}; swaps {}, rejected {}, missed periods {}",
                if self.arm.lost().is_some() { ": " } else { "" },
                self.arm.lost().unwrap_or(""),
                self.stats.episodes_completed,
                self.stats.episodes_aborted,
                self.stats.ticks,
                self.stats.compute.summary(),
                self.stats.wake.summary(),
                self.stats.swaps,
                self.stats.rejected.total(),
                self.stats.missed_periods
            );
        }
        reason
    }

    /// The end-of-run summary (allocates; call after [`Self::run`]).
    pub fn summary(&self, exit_reason: ExitReason) -> Summary {
        let s = &self.stats;
        Summary {
            command: "run",
            exit_reason,
            mode: self.cfg.mode,
            episodes_completed: s.episodes_completed,
            episodes_aborted: s.episodes_aborted,
            ticks: s.ticks,
            table_version: self.tables.active_version(),
            swaps: s.swaps,
            rejected: s.rejected,
            rejected_total: s.rejected.total(),
            faults: s.faults,
            fault_at_exit: self.fault,
            missed_periods: s.missed_periods,
            saturated_ticks: s.saturated_ticks,
            reset_retries: s.reset_retries,
            ipc_errors: s.ipc_errors,
            samples_unheard: s.samples_unheard,
            compute: s.compute.summary(),
            wake: s.wake.summary(),
            swap: s.swap.summary(),
            validate: s.validate.summary(),
            intake: s.intake.summary(),
            lost_peers: self.monitor.as_ref().map(|m| m.health.lost()),
            arm_lost: self.arm.lost(),
            stop_message: self.stop_status.as_ref().map(|s| s.text().to_owned()),
            arm: self.arm.report(),
            live_view: self.live.as_ref().map(LiveView::report),
            rt: self.rt.clone(),
            wall_s: self.wall_s,
        }
    }
}
