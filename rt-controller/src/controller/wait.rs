//! The period wait of every pacing mode (see [`super`], "Pacing"): lockstep waits for the
//! state acknowledging the last command, arm pacing for any new state, deadline pacing sleeps
//! to the next absolute deadline. Each wait drains the arm's queued states and says whether the newest
//! state is fresh.

use ur5_shared::clock::{monotonic_ns, sleep_until_ns};
use ur5_shared::{ArmFaults, ArmState};

use super::Controller;
use crate::arm::ArmBackend;
use crate::config::{Mode, Pacing};

/// Whether the period wait ended with a fresh arm state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum StateFreshness {
    /// The state the wait was for arrived (lockstep: the acknowledgement; arm pacing: a new
    /// state; deadline pacing: the newest state is younger than `safety.stale_state_timeout_s`).
    Fresh,
    /// No such state within `safety.stale_state_timeout_s`.
    Stale,
}

impl<A: ArmBackend> Controller<A> {
    /// Takes every queued state; returns whether a new one arrived.
    #[inline]
    fn drain_states(&mut self) -> bool {
        let mut got = false;
        loop {
            match self.arm.receive() {
                Ok(Some(s)) => {
                    self.latest = s;
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
    fn poll_until(&mut self, ready: impl Fn(&ArmState) -> bool) -> StateFreshness {
        let t0 = monotonic_ns();
        let spin_until = t0 + self.cfg.polling.spin_ns;
        let give_up = t0 + self.stale_ns;
        loop {
            if self.drain_states() && ready(&self.latest) {
                return StateFreshness::Fresh;
            }
            let now = monotonic_ns();
            if now >= give_up {
                return StateFreshness::Stale;
            }
            if now < spin_until {
                core::hint::spin_loop();
            } else {
                sleep_until_ns((now + self.cfg.polling.sleep_ns).min(give_up));
            }
        }
    }

    /// The period wait of every mode; sets `tick_start_ns` and records the wake latency.
    pub(super) fn wait_period(&mut self) -> StateFreshness {
        // Lockstep and arm pacing: latency from the arm's stamp to the controller seeing it.
        let record_arm_latency = match (self.cfg.mode, self.cfg.pacing) {
            (Mode::Lockstep, _) => self.awaiting.is_some(),
            (Mode::RealTime, Pacing::Arm) => true,
            (Mode::RealTime, Pacing::Deadline) => false,
        };
        let freshness = match (self.cfg.mode, self.cfg.pacing) {
            (Mode::Lockstep, _) => match self.awaiting {
                // A robot stop (`DRIVER`) answers every outstanding command: during a reset
                // its acknowledgement would never come.
                Some(seq) => self.poll_until(|s| {
                    s.last_command_seq >= seq || s.faults.contains(ArmFaults::DRIVER)
                }),
                None => {
                    // Nothing outstanding (waiting for a table): idle while the arm holds.
                    self.arm.idle();
                    sleep_until_ns(monotonic_ns() + self.period_ns.clamp(1_000_000, 10_000_000));
                    self.drain_states();
                    StateFreshness::Fresh
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
                    StateFreshness::Fresh
                } else {
                    StateFreshness::Stale
                }
            }
        };
        let now = monotonic_ns();
        self.tick_start_ns = now;
        self.awaiting = None;
        match freshness {
            StateFreshness::Fresh => {
                if record_arm_latency {
                    let lat = now.saturating_sub(self.latest.stamp_ns);
                    self.stats.wake.record(lat);
                    self.stats.wake_episode.record(lat);
                }
                self.stale_since_ns = None;
            }
            StateFreshness::Stale => {
                if self.stale_since_ns.is_none() {
                    self.stale_since_ns = Some(now);
                }
            }
        }
        freshness
    }
}
