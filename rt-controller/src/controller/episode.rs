//! The episode state machine of [`super`]: Boundary (table intake, reset), Resetting, Running
//! (one tick: law, clamp, command, sample), Holding and NeedTable, with the faults that end an
//! episode and the commands it sends. Nothing here allocates.

use std::io::Write;

use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ActionMode;
use ur5_shared::layout::{MAX_DU, MAX_DX};
use ur5_shared::safety::clamp_action;
use ur5_shared::{controller_action, policy_action, ArmCommand, ArmFaults, StepSample};

use super::wait::StateFreshness;
use super::{Controller, ExitReason, Phase};
use crate::arm::ArmBackend;
use crate::config::Mode;
use crate::monitor::LostPeers;
use crate::safety::{hold_command, Fault};
use crate::tables::{Active, Offer, Rejection};
use ur5_shared::status::PeerStatus;

impl<A: ArmBackend> Controller<A> {
    // ---------------------------------------------------------------- sending

    fn send(&mut self, cmd: ArmCommand) {
        match self.arm.send(&cmd) {
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

    pub(super) fn send_hold(&mut self) {
        let seq = self.next_seq();
        let fresh = self.stale_since_ns.is_none() && self.have_state;
        let n = self.layout.joints();
        let (q, qd) = (&self.latest.q[..n], &self.latest.qd[..n]);
        let cmd = hold_command(
            self.cfg.action_mode,
            &self.limits,
            &self.cfg.safety,
            &self.last_safe_q[..n],
            if fresh { Some((q, qd)) } else { None },
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
        if matches!(self.phase, Phase::Running { .. } | Phase::Resetting { .. }) {
            self.aborted_with_version += 1;
        }
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
        if s.check_layout(&self.layout).is_err() {
            return Some(Fault::WrongJoints);
        }
        if !s.is_finite() {
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

    /// After a stop the arm reported: the backend's recovery, then the next episode from the
    /// boundary (`None`), or [`ExitReason::ArmStopped`]. Blocks and may allocate (a failure's
    /// message), as setup does; the period clock restarts afterwards.
    #[cold]
    fn recover_arm(&mut self) -> Option<ExitReason> {
        match self.arm.recover() {
            Ok(true) => {
                self.fault = None;
                self.latest.faults = ArmFaults::default();
                self.phase = Phase::Boundary;
                self.awaiting = None;
                self.stale_since_ns = None;
                self.next_deadline_ns = monotonic_ns() + self.period_ns;
                None
            }
            Ok(false) => Some(ExitReason::ArmStopped),
            Err(e) => {
                let _ = writeln!(
                    std::io::stderr(),
                    "rt-controller: error: the arm stopped and could not be recovered: {e}"
                );
                Some(ExitReason::ArmStopped)
            }
        }
    }

    /// One loop iteration after the period wait.
    pub(super) fn step(&mut self, freshness: StateFreshness) -> Option<ExitReason> {
        let lost = self.arm.lost().is_some();
        if freshness == StateFreshness::Stale && (self.give_up() || lost) {
            if self.fault != Some(Fault::StaleState) {
                self.latch(Fault::StaleState);
            }
            return Some(ExitReason::ArmLost);
        }
        if freshness == StateFreshness::Fresh && self.latest.faults.contains(ArmFaults::DRIVER) {
            // The robot stopped (protective stop, safety mode, program ended): end the
            // episode and hold; then the backend may clear the stop (a setup-like step outside
            // the tick, `ArmBackend::recover`) and the next episode starts with a reset, or
            // only a person at the robot can clear it and the run ends.
            self.abort_episode(Fault::ArmFault);
            return self.recover_arm();
        }
        if lost {
            // The connection is gone for good, and a wait need not have been stale to see it:
            // in lockstep a command that could not be sent leaves nothing to wait for, and
            // the wait counts as fresh (tests/tests/suite/lost_arm.rs).
            return Some(ExitReason::ArmLost);
        }
        if !matches!(self.phase, Phase::Running { .. }) {
            if let Some(st) = self.ports.learner_status() {
                // The learner stopped and said why: stop with the same message.
                self.stop_status = Some(st);
                return Some(ExitReason::LearnerStopped);
            }
        }
        // Between episodes the live view shows the arm too; a tick (and the acknowledged
        // reset that starts one) offers its own state.
        let ticks = match self.phase {
            Phase::Running { .. } => true,
            Phase::Resetting { seq, .. } => self.latest.last_command_seq >= seq,
            _ => false,
        };
        if freshness == StateFreshness::Fresh && !ticks {
            self.show(false, self.tables.active_version().unwrap_or(0));
        }
        match self.phase {
            Phase::Boundary => self.boundary(),
            Phase::NeedTable => {
                self.intake_tables();
                if let Some(reason) = self.pending_exit {
                    return Some(reason);
                }
                if self.tables.active().is_some() {
                    self.fault = None;
                    self.phase = Phase::Boundary;
                    return self.boundary();
                }
                self.wait_for_table()
            }
            Phase::Resetting { seq, sent_ns } => {
                if freshness == StateFreshness::Fresh && self.latest.last_command_seq >= seq {
                    if let Some(f) = self.check_state() {
                        self.abort_episode(f);
                        return None;
                    }
                    self.last_safe_q = self.latest.q;
                    self.phase = Phase::Running { t: 0 };
                    self.tick(0);
                } else if freshness == StateFreshness::Stale && self.cfg.mode == Mode::Lockstep {
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
                if freshness == StateFreshness::Stale {
                    self.abort_episode(Fault::StaleState);
                } else {
                    self.tick(t);
                }
                None
            }
            Phase::Holding => {
                if freshness == StateFreshness::Fresh && self.check_state().is_none() {
                    self.fault = None;
                    self.phase = Phase::Boundary;
                    return self.boundary();
                }
                self.send_hold();
                None
            }
        }
    }

    fn boundary(&mut self) -> Option<ExitReason> {
        if self.cfg.episodes > 0
            && self.stats.episodes_completed + self.stats.episodes_aborted >= self.cfg.episodes
        {
            return Some(ExitReason::EpisodesDone);
        }
        self.intake_tables();
        if let Some(reason) = self.pending_exit {
            return Some(reason);
        }
        let Some((version, plan)) = self.tables.active().map(|t| (t.version(), *t.plan())) else {
            if self.phase != Phase::NeedTable {
                self.latch(Fault::NoTable);
                self.phase = Phase::NeedTable;
                // Lockstep: nothing moves without a command, and the run must not depend on
                // whether the first table came before the first boundary (docs/ur.md,
                // "Lockstep over RTDE").
                if self.cfg.mode == Mode::RealTime {
                    self.send_hold();
                }
            }
            return None;
        };
        let cycle = self.cfg.noisy_episodes + self.cfg.eval_episodes;
        let k = self.episodes_with_version;
        if self.cfg.cycles_per_table > 0
            && self.aborted_with_version == 0
            && k >= cycle * self.cfg.cycles_per_table
        {
            return self.hold_for_newer_table();
        }
        // The table's episode plan (docs/design.md §3.3): its goal, noise stream and whether
        // every episode runs noise-free; the default plan is the controller's own.
        self.noisy = !plan.is_noise_free() && k % cycle < self.cfg.noisy_episodes;
        // A goal point applies to a point task only (the table buffer refuses it for a pose).
        self.targets = self.task_targets;
        if let Some(goal) = plan.goal() {
            self.targets[0] = *goal;
        }
        self.noise
            .reseed(plan.noise_seed(self.cfg.seed), version, k);
        self.episodes_with_version += 1;
        self.episodes_started += 1;
        let seq = self.send_reset();
        self.phase = Phase::Resetting {
            seq,
            sent_ns: monotonic_ns(),
        };
        None
    }

    /// The version's cycles are done (`cycles_per_table`): hold until the learner's next
    /// table; in lockstep nothing is commanded (the arm does not move), in real time a hold
    /// every period. `safety.no_table_timeout_s` bounds the wait as it bounds NeedTable.
    fn hold_for_newer_table(&mut self) -> Option<ExitReason> {
        if !self.waiting_newer {
            self.waiting_newer = true;
            self.no_table_since_ns = monotonic_ns();
        }
        self.wait_for_table()
    }

    /// One period of waiting for a table (NeedTable, or a newer one): `NoTable` once
    /// `safety.no_table_timeout_s` passed since `no_table_since_ns`; else a hold in real time,
    /// nothing in lockstep.
    fn wait_for_table(&mut self) -> Option<ExitReason> {
        let t = self.cfg.safety.no_table_timeout_s;
        if t > 0.0 && (monotonic_ns() - self.no_table_since_ns) as f64 * 1e-9 >= t {
            return Some(ExitReason::NoTable);
        }
        if self.cfg.mode == Mode::RealTime {
            self.send_hold();
        }
        None
    }

    /// Takes the newest tables from `controller/gains` and `controller/policy`, if any: the
    /// only place tables change. Gains are read first, then policies; since versions form one
    /// sequence, the newest of either kind ends up active.
    fn intake_tables(&mut self) {
        loop {
            let t0 = monotonic_ns();
            let sample = match self.ports.gains_sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => break,
                Err(_) => {
                    self.stats.ipc_errors += 1;
                    break;
                }
            };
            let result = self.tables.offer(&sample, monotonic_ns);
            let version = sample.version;
            drop(sample);
            self.record_offer(t0, version, "gain", result);
        }
        loop {
            let t0 = monotonic_ns();
            let sample = match self.ports.policy_sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return,
                Err(_) => {
                    self.stats.ipc_errors += 1;
                    return;
                }
            };
            let result = self.tables.offer_policy(&sample, monotonic_ns);
            let version = sample.version;
            drop(sample);
            self.record_offer(t0, version, "policy", result);
        }
    }

    /// Statistics and the report line of one offered table.
    fn record_offer(
        &mut self,
        t0: u64,
        version: u64,
        kind: &str,
        result: Result<Offer, Rejection>,
    ) {
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
                self.aborted_with_version = 0;
                self.waiting_newer = false;
                if self.cfg.episode_report {
                    let _ = writeln!(
                        std::io::stderr(),
                        "rt-controller: {kind} table version {version} taken at the boundary before episode {} (copy {:.1} µs, validate {:.1} µs)",
                        self.episode,
                        copy_ns as f64 / 1e3,
                        validate_ns as f64 / 1e3
                    );
                }
            }
            Ok(Offer::Unchanged) => {}
            Err(r) => {
                self.stats.rejected.add(&r);
                if r.is_task_mismatch() {
                    // Learner and controller cannot work together: say why to the learner and
                    // stop, rather than hold and wait (docs/design.md §3.12).
                    let st = PeerStatus::fatal(
                        monotonic_ns(),
                        format_args!("rt-controller rejected the learner's {kind} table: {r}"),
                    );
                    self.ports.send_status(&st);
                    self.stop_status = Some(st);
                    self.pending_exit = Some(ExitReason::TaskMismatch);
                    return;
                }
                let _ = writeln!(
                    std::io::stderr(),
                    "rt-controller: rejected {kind} table: {r}; keeping version {:?}",
                    self.tables.active_version()
                );
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
        let state = self.latest;
        let (dx, du, p) = (
            self.layout.dx(),
            self.layout.du(),
            self.layout.tool_points(),
        );
        let mut s_buf = [0.0; MAX_DX];
        let s = &mut s_buf[..dx];
        state.fill_state(&self.layout, &self.targets[..p], s);
        let mut eps_buf = [0.0; MAX_DU];
        let eps = &mut eps_buf[..du];
        if self.noisy {
            self.noise.next_into(eps);
        }
        let mut a_buf = [0.0; MAX_DU];
        let a = &mut a_buf[..du];
        let (ok, version, epoch) = match self.tables.active() {
            Some(Active::Gains(table)) => (
                controller_action(table, t, s, eps, a).is_ok(),
                table.version,
                table.epoch,
            ),
            Some(Active::Policy(table)) => (
                policy_action(table, s, eps, &mut self.scratch, a).is_ok(),
                table.version,
                table.epoch,
            ),
            None => {
                self.abort_episode(Fault::NoTable);
                return;
            }
        };
        if !ok || !a.iter().all(|v| v.is_finite()) {
            self.abort_episode(Fault::NonFiniteAction);
            return;
        }
        let mut sent_buf = a_buf;
        let sent = &mut sent_buf[..du];
        let saturated = clamp_action(
            self.cfg.action_mode,
            &self.limits,
            self.cfg.task.dt,
            &state.q[..du],
            sent,
        );
        let seq = self.next_seq();
        let stamp = monotonic_ns();
        let cmd = match self.cfg.action_mode {
            ActionMode::GoalAngles => ArmCommand::goal_angles(seq, stamp, self.episode, &*sent),
            ActionMode::Torque => ArmCommand::torques(seq, stamp, self.episode, &*sent),
        };
        self.send(cmd);
        let mut sample = StepSample {
            table_version: version,
            episode: self.episode,
            t: t as u32,
            noise: self.noisy as u32,
            table_epoch: epoch,
            state_seq: state.seq,
            state_stamp_ns: state.stamp_ns,
            command_stamp_ns: stamp,
            ..StepSample::default()
        };
        sample.set_state(&s_buf[..dx]);
        sample.set_actions(&a_buf[..du], &sent_buf[..du]);
        match self.ports.sample_pub.loan_uninit() {
            Ok(slot) => match slot.write_payload(sample).send() {
                Ok(0) => self.stats.samples_unheard += 1,
                Ok(_) => {}
                Err(_) => self.stats.ipc_errors += 1,
            },
            Err(_) => self.stats.ipc_errors += 1,
        }
        self.show(true, version);
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

    /// Offers the latest state to the live view, if there is one (no allocation, no system
    /// call; [`crate::live_view::LiveView::offer`]). `tick`: the controller acted on it.
    #[inline]
    fn show(&mut self, tick: bool, table_version: u64) {
        if let Some(live) = self.live.as_mut() {
            live.offer(
                monotonic_ns(),
                &self.latest,
                tick,
                self.episode,
                table_version,
            );
        }
    }

    /// One line per episode on stderr (no allocation), then clears the episode histograms.
    fn report_episode(&mut self, ticks: usize, aborted: bool) {
        if self.cfg.episode_report {
            let lost = self
                .monitor
                .as_ref()
                .map_or(LostPeers { arm: 0, learner: 0 }, |m| m.health.lost());
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
                self.stats.faults.total(),
                lost.arm,
                lost.learner,
            );
        }
        self.stats.compute_episode.clear();
        self.stats.wake_episode.clear();
    }
}
