//! The controller: a fallible [`Controller::setup`] that allocates everything, and
//! [`Controller::run`], the loop phase, which does not allocate, lock or block except in the
//! period wait (DESIGN.md §3; STYLE.md, the iceoryx2 split of setup and tick).
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
//! - **Boundary**: the only place a table is taken (copy into the inactive half, validate,
//!   flip); then a `Reset` command to `task.start_q`.
//! - **Resetting**: waits until the arm acknowledges the reset (`ArmState::last_command_seq`);
//!   the arm is at rest at the start pose and holds it until the first command ("hold, then
//!   start"). The acknowledging state is s_0.
//! - **Running**: per tick s_t → ε_t → a_t = controller law ([`ur5_shared::controller_action`])
//!   → clamp → command → [`StepSample`].
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

use core::sync::atomic::{AtomicBool, Ordering};
use std::io::Write;

use serde::Serialize;
use ur5_shared::clock::{monotonic_ns, sleep_until_ns};
use ur5_shared::config::{ActionMode, ArmLimits};
use ur5_shared::layout::N_JOINTS;
use ur5_shared::safety::clamp_action;
use ur5_shared::{controller_action, ArmCommand, ArmState, StepSample, DU, NO_NOISE};

use crate::config::{ControllerConfig, Mode, Pacing};
use crate::monitor::PeerMonitor;
use crate::noise::Noise;
use crate::ports::{ControllerPorts, SetupError};
use crate::rt::{self, RtOutcome};
use crate::safety::hold_command;
use crate::stats::{Histogram, Percentiles};
use crate::tables::{Offer, RejectCounts, TableBuffer};

/// Why [`Controller::run`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ExitReason {
    /// The configured number of episodes completed.
    EpisodesDone,
    /// The stop flag was raised (SIGINT/SIGTERM in the binary).
    Stopped,
    /// The arm was stale for `safety.give_up_after_s`.
    ArmLost,
    /// No valid table arrived within `safety.no_table_timeout_s`.
    NoTable,
}

/// A fault that makes the controller hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// No fresh arm state within `safety.stale_state_timeout_s`.
    StaleState,
    /// The arm reported a fault bit.
    ArmFault,
    /// The arm state is not finite.
    NonFiniteState,
    /// The controller law produced a non-finite action (or failed).
    NonFiniteAction,
    /// No valid table.
    NoTable,
}

impl Fault {
    fn name(self) -> &'static str {
        match self {
            Fault::StaleState => "stale arm state",
            Fault::ArmFault => "arm reports a fault",
            Fault::NonFiniteState => "non-finite arm state",
            Fault::NonFiniteAction => "non-finite action",
            Fault::NoTable => "no valid gain table",
        }
    }
}

/// How often each fault latched.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FaultCounts {
    /// [`Fault::StaleState`].
    pub stale_state: u64,
    /// [`Fault::ArmFault`].
    pub arm_fault: u64,
    /// [`Fault::NonFiniteState`].
    pub non_finite_state: u64,
    /// [`Fault::NonFiniteAction`].
    pub non_finite_action: u64,
    /// [`Fault::NoTable`].
    pub no_table: u64,
}

impl FaultCounts {
    fn add(&mut self, f: Fault) {
        match f {
            Fault::StaleState => self.stale_state += 1,
            Fault::ArmFault => self.arm_fault += 1,
            Fault::NonFiniteState => self.non_finite_state += 1,
            Fault::NonFiniteAction => self.non_finite_action += 1,
            Fault::NoTable => self.no_table += 1,
        }
    }
}

/// Counters and histograms of the loop, allocated at setup.
pub struct LoopStats {
    /// Compute time of each Running tick (state read → command and sample published), this
    /// episode (ns).
    pub compute_episode: Histogram,
    /// The same over the run.
    pub compute: Histogram,
    /// Wake-up lateness per tick (ns): deadline pacing, wake time − deadline; lockstep and arm
    /// pacing, time the state was seen − its stamp (arm → controller latency incl. polling).
    pub wake_episode: Histogram,
    /// The same over the run.
    pub wake: Histogram,
    /// Swap time per accepted table: copy into the inactive half + flip (ns).
    pub swap: Histogram,
    /// Validation time per received table (ns).
    pub validate: Histogram,
    /// Whole boundary intake per received table: receive + copy + validate + flip (ns).
    pub intake: Histogram,
    /// Loop iterations (all phases).
    pub iterations: u64,
    /// Running ticks (samples published or attempted).
    pub ticks: u64,
    /// Episodes that ran all T ticks.
    pub episodes_completed: u64,
    /// Episodes ended by a fault.
    pub episodes_aborted: u64,
    /// Deadline pacing: whole periods that passed while the loop was late.
    pub missed_periods: u64,
    /// Tables taken.
    pub swaps: u64,
    /// Tables rejected, by reason.
    pub rejected: RejectCounts,
    /// Faults latched, by kind.
    pub faults: FaultCounts,
    /// Ticks whose action the clamp changed.
    pub saturated_ticks: u64,
    /// Resets sent again after `safety.reset_timeout_s`.
    pub reset_retries: u64,
    /// Failed sends of commands / samples; failed receives.
    pub ipc_errors: u64,
    /// Samples delivered to no subscriber (no learner connected).
    pub samples_unheard: u64,
}

impl LoopStats {
    fn new() -> Self {
        Self {
            compute_episode: Histogram::new(),
            compute: Histogram::new(),
            wake_episode: Histogram::new(),
            wake: Histogram::new(),
            swap: Histogram::new(),
            validate: Histogram::new(),
            intake: Histogram::new(),
            iterations: 0,
            ticks: 0,
            episodes_completed: 0,
            episodes_aborted: 0,
            missed_periods: 0,
            swaps: 0,
            rejected: RejectCounts::default(),
            faults: FaultCounts::default(),
            saturated_ticks: 0,
            reset_retries: 0,
            ipc_errors: 0,
            samples_unheard: 0,
        }
    }
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
    /// Real-time privileges obtained.
    pub rt: RtOutcome,
    /// Wall time of the loop phase (s).
    pub wall_s: f64,
}

/// Peer processes that died or left ([`crate::monitor`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct LostPeers {
    /// Arm processes.
    pub arm: u64,
    /// Learner processes.
    pub learner: u64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Boundary,
    Resetting { seq: u64, sent_ns: u64 },
    Running { t: usize },
    Holding,
    NeedTable,
}

/// The controller: configuration, ports, tables, noise, statistics and loop state.
pub struct Controller {
    cfg: ControllerConfig,
    ports: ControllerPorts,
    tables: TableBuffer,
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
    noisy: bool,
    latest: ArmState,
    have_state: bool,
    used_state_seq: u64,
    last_safe_q: [f64; N_JOINTS],
    stale_since_ns: Option<u64>,
    next_deadline_ns: u64,
    tick_start_ns: u64,
    fault: Option<Fault>,
    no_table_since_ns: u64,
    wall_s: f64,
    monitor: Option<PeerMonitor>,
}

/// Wait outcome of one period.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Arm {
    Fresh,
    Stale,
}

impl Controller {
    /// Setup phase: validates `cfg`, applies the real-time privileges, creates the node and
    /// ports, waits for the arm (a state and a command subscriber) and, if configured, the
    /// learner, then preallocates tables, histograms and noise. Allocates; may fail.
    pub fn setup(cfg: ControllerConfig) -> Result<Self, SetupError> {
        cfg.validate()?;
        let rt = rt::apply(&cfg.rt);
        let ports = ControllerPorts::create(&cfg.prefix)?;
        let t0 = monotonic_ns();
        let timeout_ns = (cfg.setup_timeout_s * 1e9) as u64;
        let mut latest = None;
        loop {
            if let Ok(Some(s)) = ports.state_sub.receive() {
                latest = Some(*s);
            }
            let (_, cmd_subs) = ports.arm_peers();
            if latest.is_some() && cmd_subs > 0 {
                break;
            }
            if monotonic_ns() - t0 > timeout_ns {
                return Err(SetupError::PeerTimeout {
                    what: if latest.is_none() {
                        "arm state on arm/state"
                    } else {
                        "arm subscriber on arm/command"
                    },
                    timeout_s: cfg.setup_timeout_s,
                    prefix: cfg.prefix.clone(),
                });
            }
            std::thread::sleep(core::time::Duration::from_millis(1));
        }
        if cfg.wait_for_learner {
            loop {
                let (subs, pubs) = ports.learner_peers();
                if subs > 0 && pubs > 0 {
                    break;
                }
                if monotonic_ns() - t0 > timeout_ns {
                    return Err(SetupError::PeerTimeout {
                        what: "learner (subscriber on learner/samples and publisher on controller/gains)",
                        timeout_s: cfg.setup_timeout_s,
                        prefix: cfg.prefix.clone(),
                    });
                }
                std::thread::sleep(core::time::Duration::from_millis(1));
            }
        }
        ports.connect();
        let latest = latest.expect("loop exits with a state");
        // Warm up stderr (its lock and handle) so the first episode report does not.
        let _ = writeln!(
            std::io::stderr(),
            "rt-controller: arm connected on prefix `{}`; mode {:?}",
            cfg.prefix,
            cfg.mode
        );
        let period_ns = cfg.wall_period_ns();
        let stale_ns = (cfg.safety.stale_state_timeout_s * 1e9) as u64;
        Ok(Self {
            tables: TableBuffer::new(cfg.bounds.clone(), cfg.task.horizon),
            limits: cfg.limits.clone(),
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
            noisy: false,
            last_safe_q: latest.q,
            have_state: true,
            used_state_seq: 0,
            latest,
            stale_since_ns: None,
            next_deadline_ns: 0,
            tick_start_ns: 0,
            fault: None,
            no_table_since_ns: 0,
            wall_s: 0.0,
            monitor: (cfg.monitor_period_s > 0.0).then(|| {
                PeerMonitor::spawn(
                    &cfg.prefix,
                    core::time::Duration::from_secs_f64(cfg.monitor_period_s),
                )
            }),
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

    /// The ports (e.g. to count connected peers).
    pub fn ports(&self) -> &ControllerPorts {
        &self.ports
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
            let arm = self.wait_period();
            if let Some(reason) = self.step(arm) {
                break reason;
            }
        };
        self.send_hold();
        self.wall_s = (monotonic_ns() - start) as f64 * 1e-9;
        if self.cfg.episode_report {
            let _ = writeln!(
                std::io::stderr(),
                "rt-controller: exit ({reason:?}) after {} episodes ({} aborted), {} ticks; compute {}; wake {}; swaps {}, rejected {}, missed periods {}",
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
            lost_peers: self.monitor.as_ref().map(|m| LostPeers {
                arm: m.health.lost_arm.load(Ordering::Relaxed),
                learner: m.health.lost_learner.load(Ordering::Relaxed),
            }),
            rt: self.rt.clone(),
            wall_s: self.wall_s,
        }
    }

    // ---------------------------------------------------------------- waiting

    /// Takes every queued state; returns whether a new one arrived.
    #[inline]
    fn drain_states(&mut self) -> bool {
        let mut got = false;
        loop {
            match self.ports.state_sub.receive() {
                Ok(Some(s)) => {
                    self.latest = *s;
                    got = true;
                }
                Ok(None) => break,
                Err(_) => {
                    self.stats.ipc_errors += 1;
                    break;
                }
            }
        }
        if got {
            self.have_state = true;
        }
        got
    }

    /// Polls until `ready(latest)` or the stale timeout: spin first, then sleep between polls.
    fn poll_until(&mut self, ready: impl Fn(&ArmState) -> bool) -> Arm {
        let t0 = monotonic_ns();
        let spin_until = t0 + self.cfg.polling.spin_ns;
        let give_up = t0 + self.stale_ns;
        loop {
            if self.drain_states() && ready(&self.latest) {
                return Arm::Fresh;
            }
            let now = monotonic_ns();
            if now >= give_up {
                return Arm::Stale;
            }
            if now < spin_until {
                core::hint::spin_loop();
            } else {
                sleep_until_ns((now + self.cfg.polling.sleep_ns).min(give_up));
            }
        }
    }

    /// The period wait of every mode; sets `tick_start_ns` and records the wake latency.
    fn wait_period(&mut self) -> Arm {
        // Lockstep and arm pacing: latency from the arm's stamp to the controller seeing it.
        let record_arm_latency = match (self.cfg.mode, self.cfg.pacing) {
            (Mode::Lockstep, _) => self.awaiting.is_some(),
            (Mode::RealTime, Pacing::Arm) => true,
            (Mode::RealTime, Pacing::Deadline) => false,
        };
        let arm = match (self.cfg.mode, self.cfg.pacing) {
            (Mode::Lockstep, _) => match self.awaiting {
                Some(seq) => self.poll_until(|s| s.last_command_seq >= seq),
                None => {
                    // Nothing outstanding (waiting for a table): idle while the arm holds.
                    sleep_until_ns(monotonic_ns() + self.period_ns.clamp(1_000_000, 10_000_000));
                    self.drain_states();
                    Arm::Fresh
                }
            },
            (Mode::RealTime, Pacing::Arm) => {
                let used = self.used_state_seq;
                self.poll_until(|s| s.seq > used)
            }
            (Mode::RealTime, Pacing::Deadline) => {
                let deadline = self.next_deadline_ns;
                sleep_until_ns(deadline);
                let now = monotonic_ns();
                let late = now.saturating_sub(deadline);
                self.stats.wake.record(late);
                self.stats.wake_episode.record(late);
                let missed = late / self.period_ns;
                self.stats.missed_periods += missed;
                self.next_deadline_ns = deadline + (missed + 1) * self.period_ns;
                self.drain_states();
                if self.have_state && now.saturating_sub(self.latest.stamp_ns) <= self.stale_ns {
                    Arm::Fresh
                } else {
                    Arm::Stale
                }
            }
        };
        let now = monotonic_ns();
        self.tick_start_ns = now;
        self.awaiting = None;
        match arm {
            Arm::Fresh => {
                if record_arm_latency {
                    let lat = now.saturating_sub(self.latest.stamp_ns);
                    self.stats.wake.record(lat);
                    self.stats.wake_episode.record(lat);
                }
                self.stale_since_ns = None;
            }
            Arm::Stale => {
                if self.stale_since_ns.is_none() {
                    self.stale_since_ns = Some(now);
                }
            }
        }
        arm
    }

    // ---------------------------------------------------------------- sending

    fn send(&mut self, cmd: ArmCommand) {
        match self.ports.cmd_pub.send_copy(cmd) {
            Ok(_) => {
                if self.cfg.mode == Mode::Lockstep {
                    self.awaiting = Some(cmd.seq);
                }
            }
            Err(_) => self.stats.ipc_errors += 1,
        }
    }

    fn next_seq(&mut self) -> u64 {
        self.cmd_seq += 1;
        self.cmd_seq
    }

    fn send_hold(&mut self) {
        let seq = self.next_seq();
        let fresh = self.stale_since_ns.is_none() && self.have_state;
        let (q, qd) = (self.latest.q, self.latest.qd);
        let cmd = hold_command(
            self.cfg.action_mode,
            &self.limits,
            &self.cfg.safety,
            &self.last_safe_q,
            if fresh { Some((&q, &qd)) } else { None },
            seq,
            monotonic_ns(),
            self.episode,
        );
        self.send(cmd);
    }

    fn send_reset(&mut self) -> u64 {
        let seq = self.next_seq();
        let cmd = ArmCommand::reset(seq, monotonic_ns(), self.episode, self.cfg.task.start_q);
        self.send(cmd);
        seq
    }

    // ---------------------------------------------------------------- faults

    fn latch(&mut self, fault: Fault) {
        self.stats.faults.add(fault);
        if self.cfg.episode_report {
            let _ = writeln!(
                std::io::stderr(),
                "rt-controller: fault latched: {} (episode {}, phase {:?}); holding at q = {:?} rad",
                fault.name(),
                self.episode,
                self.phase,
                self.last_safe_q
            );
        }
        self.fault = Some(fault);
    }

    fn abort_episode(&mut self, fault: Fault) {
        self.latch(fault);
        if let Phase::Running { t } = self.phase {
            self.stats.episodes_aborted += 1;
            self.report_episode(t, true);
            self.episode += 1;
        }
        self.phase = Phase::Holding;
        self.send_hold();
    }

    /// Checks the state for arm faults and finiteness.
    fn check_state(&self) -> Option<Fault> {
        let s = &self.latest;
        if s.faults.any() {
            return Some(Fault::ArmFault);
        }
        let finite =
            s.q.iter()
                .chain(&s.qd)
                .chain(&s.ee_pos)
                .chain(&s.ee_vel)
                .all(|v| v.is_finite());
        if !finite {
            return Some(Fault::NonFiniteState);
        }
        None
    }

    // ---------------------------------------------------------------- the state machine

    fn give_up(&self) -> bool {
        let g = self.cfg.safety.give_up_after_s;
        match self.stale_since_ns {
            Some(since) if g > 0.0 => (monotonic_ns() - since) as f64 * 1e-9 >= g,
            _ => false,
        }
    }

    /// One loop iteration after the period wait.
    fn step(&mut self, arm: Arm) -> Option<ExitReason> {
        if arm == Arm::Stale && self.give_up() {
            if self.fault != Some(Fault::StaleState) {
                self.latch(Fault::StaleState);
            }
            return Some(ExitReason::ArmLost);
        }
        match self.phase {
            Phase::Boundary => self.boundary(arm),
            Phase::NeedTable => {
                self.intake_tables();
                if self.tables.active().is_some() {
                    self.fault = None;
                    self.phase = Phase::Boundary;
                    return self.boundary(arm);
                }
                let t = self.cfg.safety.no_table_timeout_s;
                if t > 0.0 && (monotonic_ns() - self.no_table_since_ns) as f64 * 1e-9 >= t {
                    return Some(ExitReason::NoTable);
                }
                if self.cfg.mode == Mode::RealTime {
                    self.send_hold();
                }
                None
            }
            Phase::Resetting { seq, sent_ns } => {
                if arm == Arm::Fresh && self.latest.last_command_seq >= seq {
                    if let Some(f) = self.check_state() {
                        self.abort_episode(f);
                        return None;
                    }
                    self.last_safe_q = self.latest.q;
                    self.phase = Phase::Running { t: 0 };
                    self.tick(0);
                } else if arm == Arm::Stale && self.cfg.mode == Mode::Lockstep {
                    self.abort_episode(Fault::StaleState);
                } else if monotonic_ns() - sent_ns > (self.cfg.safety.reset_timeout_s * 1e9) as u64
                {
                    self.stats.reset_retries += 1;
                    let seq = self.send_reset();
                    self.phase = Phase::Resetting {
                        seq,
                        sent_ns: monotonic_ns(),
                    };
                }
                None
            }
            Phase::Running { t } => {
                // Deadline pacing may find no new state since the last tick (the arm's clock
                // and ours drift): it acts on the newest one, whose age the stale check bounds.
                if arm == Arm::Stale {
                    self.abort_episode(Fault::StaleState);
                } else {
                    self.tick(t);
                }
                None
            }
            Phase::Holding => {
                if arm == Arm::Fresh && self.check_state().is_none() {
                    self.fault = None;
                    self.phase = Phase::Boundary;
                    return self.boundary(arm);
                }
                self.send_hold();
                None
            }
        }
    }

    fn boundary(&mut self, _arm: Arm) -> Option<ExitReason> {
        if self.cfg.episodes > 0
            && self.stats.episodes_completed + self.stats.episodes_aborted >= self.cfg.episodes
        {
            return Some(ExitReason::EpisodesDone);
        }
        self.intake_tables();
        let Some(version) = self.tables.active_version() else {
            if self.phase != Phase::NeedTable {
                self.latch(Fault::NoTable);
                self.phase = Phase::NeedTable;
                self.send_hold();
            }
            return None;
        };
        let cycle = self.cfg.noisy_episodes + self.cfg.eval_episodes;
        let k = self.episodes_with_version;
        self.noisy = k % cycle < self.cfg.noisy_episodes;
        self.noise.reseed(self.cfg.seed, version, k);
        self.episodes_with_version += 1;
        self.episodes_started += 1;
        let seq = self.send_reset();
        self.phase = Phase::Resetting {
            seq,
            sent_ns: monotonic_ns(),
        };
        None
    }

    /// Takes the newest table from `controller/gains`, if any: the only place tables change.
    fn intake_tables(&mut self) {
        loop {
            let t0 = monotonic_ns();
            let sample = match self.ports.gains_sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return,
                Err(_) => {
                    self.stats.ipc_errors += 1;
                    return;
                }
            };
            let result = self.tables.offer(&sample, monotonic_ns);
            let version = sample.version;
            drop(sample);
            match result {
                Ok(Offer::Swapped {
                    copy_ns,
                    validate_ns,
                }) => {
                    // The flip itself is an index store: the swap is the copy.
                    self.stats.swap.record(copy_ns);
                    self.stats.validate.record(validate_ns);
                    self.stats.intake.record(monotonic_ns() - t0);
                    self.stats.swaps += 1;
                    self.episodes_with_version = 0;
                    if self.cfg.episode_report {
                        let _ = writeln!(
                            std::io::stderr(),
                            "rt-controller: gain table version {version} taken at the boundary before episode {} (copy {:.1} µs, validate {:.1} µs)",
                            self.episode,
                            copy_ns as f64 / 1e3,
                            validate_ns as f64 / 1e3
                        );
                    }
                }
                Ok(Offer::Unchanged) => {}
                Err(r) => {
                    self.stats.rejected.add(&r);
                    let _ = writeln!(
                        std::io::stderr(),
                        "rt-controller: rejected gain table: {r}; keeping version {:?}",
                        self.tables.active_version()
                    );
                }
            }
        }
    }

    /// One Running tick at time step `t` on the latest state.
    #[inline]
    fn tick(&mut self, t: usize) {
        if let Some(f) = self.check_state() {
            self.abort_episode(f);
            return;
        }
        let table = match self.tables.active() {
            Some(table) => table,
            None => {
                self.abort_episode(Fault::NoTable);
                return;
            }
        };
        let state = self.latest;
        let s = state.state_vector(&self.cfg.task.goal);
        let eps = if self.noisy {
            self.noise.next()
        } else {
            NO_NOISE
        };
        let mut a = [0.0; DU];
        let ok = controller_action(table, t, &s, &eps, &mut a).is_ok();
        let version = table.version;
        if !ok || !a.iter().all(|v| v.is_finite()) {
            self.abort_episode(Fault::NonFiniteAction);
            return;
        }
        let mut sent = a;
        let saturated = clamp_action(
            self.cfg.action_mode,
            &self.limits,
            self.cfg.task.dt,
            &state.q,
            &mut sent,
        );
        let seq = self.next_seq();
        let stamp = monotonic_ns();
        let cmd = match self.cfg.action_mode {
            ActionMode::GoalAngles => ArmCommand::goal_angles(seq, stamp, self.episode, sent),
            ActionMode::Torque => ArmCommand::torques(seq, stamp, self.episode, sent),
        };
        self.send(cmd);
        let sample = StepSample {
            table_version: version,
            episode: self.episode,
            t: t as u32,
            noise: self.noisy as u32,
            s,
            a,
            a_sent: sent,
            state_seq: state.seq,
            state_stamp_ns: state.stamp_ns,
            command_stamp_ns: stamp,
        };
        match self.ports.sample_pub.loan_uninit() {
            Ok(slot) => match slot.write_payload(sample).send() {
                Ok(0) => self.stats.samples_unheard += 1,
                Ok(_) => {}
                Err(_) => self.stats.ipc_errors += 1,
            },
            Err(_) => self.stats.ipc_errors += 1,
        }
        let dt = monotonic_ns() - self.tick_start_ns;
        self.stats.compute.record(dt);
        self.stats.compute_episode.record(dt);
        self.stats.ticks += 1;
        self.stats.saturated_ticks += saturated as u64;
        self.used_state_seq = state.seq;
        self.last_safe_q = state.q;
        let next = t + 1;
        if next >= self.cfg.task.horizon {
            self.stats.episodes_completed += 1;
            self.report_episode(next, false);
            self.episode += 1;
            self.phase = Phase::Boundary;
        } else {
            self.phase = Phase::Running { t: next };
        }
    }

    /// One line per episode on stderr (no allocation), then clears the episode histograms.
    fn report_episode(&mut self, ticks: usize, aborted: bool) {
        if self.cfg.episode_report {
            let _ = writeln!(
                std::io::stderr(),
                "rt-controller: episode {} {} (table v{}, {}, {} ticks): compute {}; wake {}; missed periods {}, swaps {}, rejected {}, faults {}, lost peers: arm {} learner {}",
                self.episode,
                if aborted { "ABORTED" } else { "done" },
                self.tables.active_version().unwrap_or(0),
                if self.noisy { "noisy" } else { "noise-free" },
                ticks,
                self.stats.compute_episode.summary(),
                self.stats.wake_episode.summary(),
                self.stats.missed_periods,
                self.stats.swaps,
                self.stats.rejected.total(),
                self.stats.faults.stale_state
                    + self.stats.faults.arm_fault
                    + self.stats.faults.non_finite_state
                    + self.stats.faults.non_finite_action
                    + self.stats.faults.no_table,
                self.monitor.as_ref().map_or(0, |m| m.health.lost_arm.load(Ordering::Relaxed)),
                self.monitor.as_ref().map_or(0, |m| m.health.lost_learner.load(Ordering::Relaxed)),
            );
        }
        self.stats.compute_episode.clear();
        self.stats.wake_episode.clear();
    }
}
