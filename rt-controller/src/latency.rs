//! Wake-up lateness of the loop's period wait, measured alone (`rt-controller bench
//! --real-time`): a thread sleeps to absolute deadlines one period apart
//! ([`ur5_shared::clock::sleep_until_ns`], `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`, the
//! wait of deadline pacing, docs/design.md §3.5) and records how late it woke, the same quantity
//! cyclictest measures in its default (absolute) mode.

use ur5_shared::clock::{monotonic_ns, sleep_until_ns};

use crate::config::RtSetup;
use crate::rt::{self, RtOutcome};
use crate::stats::{Histogram, Percentiles};

/// Settings that cannot give a measurement.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum LatencyError {
    /// The rate is not finite, not positive, or gives a period under 1 µs.
    #[error(
        "rate {rate_hz} Hz: give a finite rate with a period of at least 1 µs (0 < rate ≤ 1e6 Hz)"
    )]
    BadRate {
        /// The rate given (Hz).
        rate_hz: f64,
    },
    /// The duration is not finite or gives no wake-up at this rate.
    #[error("{seconds} s at {rate_hz} Hz gives no wake-up: give a finite duration of at least one period")]
    BadDuration {
        /// The duration given (s).
        seconds: f64,
        /// The rate given (Hz).
        rate_hz: f64,
    },
}

/// What one measurement did and found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LatencyReport {
    /// Period between deadlines (ns), 1e9 / rate rounded to the ns.
    pub period_ns: u64,
    /// Wake-up lateness (ns): wake time − deadline, one value per wake-up.
    pub lateness: Percentiles,
    /// The real-time privileges asked for and obtained.
    pub rt: RtOutcome,
}

/// The period (ns) and number of wake-ups for `rate_hz` over `seconds`.
pub fn schedule(rate_hz: f64, seconds: f64) -> Result<(u64, u64), LatencyError> {
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 1e6) {
        return Err(LatencyError::BadRate { rate_hz });
    }
    let wakeups = (rate_hz * seconds).round();
    if !(seconds.is_finite() && wakeups >= 1.0) {
        return Err(LatencyError::BadDuration { seconds, rate_hz });
    }
    Ok(((1e9 / rate_hz).round() as u64, wakeups as u64))
}

/// Applies `setup` to the calling thread (see [`rt::apply`]), then sleeps to `rate_hz ·
/// seconds` absolute deadlines one period apart, the first one period from now, and records
/// each wake-up's lateness. A deadline that has already passed when the loop reaches it (after
/// a long stall) is slept to at once and counts its full lateness; the deadlines do not shift.
/// Blocks for about `seconds`.
pub fn measure_wakeups(
    rate_hz: f64,
    seconds: f64,
    setup: &RtSetup,
) -> Result<LatencyReport, LatencyError> {
    let (period_ns, wakeups) = schedule(rate_hz, seconds)?;
    let outcome = rt::apply(setup);
    let mut hist = Histogram::new();
    let mut deadline = monotonic_ns() + period_ns;
    for _ in 0..wakeups {
        sleep_until_ns(deadline);
        hist.record(monotonic_ns().saturating_sub(deadline));
        deadline += period_ns;
    }
    Ok(LatencyReport {
        period_ns,
        lateness: hist.summary(),
        rt: outcome,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_checks_rate_and_duration() {
        assert_eq!(schedule(1000.0, 20.0), Ok((1_000_000, 20_000)));
        assert_eq!(schedule(3.0, 1.0), Ok((333_333_333, 3)));
        for rate_hz in [0.0, -1.0, f64::NAN, f64::INFINITY, 2e6] {
            assert!(matches!(
                schedule(rate_hz, 1.0),
                Err(LatencyError::BadRate { .. })
            ));
        }
        for seconds in [0.0, 0.0004, -1.0, f64::NAN, f64::INFINITY] {
            let e = schedule(1000.0, seconds).unwrap_err();
            assert!(
                matches!(e, LatencyError::BadDuration { .. }),
                "{seconds}: {e}"
            );
            assert!(e.to_string().contains("at 1000 Hz"));
        }
    }

    #[test]
    fn measures_one_value_per_wakeup() {
        // 20 wake-ups at 1 kHz without privileges; no assertion on the values (shared machines).
        let r = measure_wakeups(1000.0, 0.02, &RtSetup::default()).unwrap();
        assert_eq!(r.period_ns, 1_000_000);
        assert_eq!(r.lateness.count, 20);
        assert!(r.lateness.p50_ns <= r.lateness.max_ns);
        assert_eq!(r.rt, RtOutcome::default());
    }
}
