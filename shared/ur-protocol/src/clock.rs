//! The robot's clock (RTDE `timestamp`) checked package by package: a clock that goes
//! backwards or stands still is a fault of the robot's controller (TCP delivers its packages
//! in order), and packages stamped by it cannot be trusted. Allocation-free: the controller's
//! loop and the recorder share it.

/// This many packages in a row with the same `timestamp` are a frozen clock (0.1 s of an
/// e-Series, 0.4 s of a CB3). One repeat is normal (a package sent twice).
pub const FROZEN_CLOCK_PACKAGES: u64 = 50;

/// What is wrong with the robot's clock.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ClockFault {
    /// `timestamp` decreased (or is not a number).
    #[error("the robot's clock went backwards: RTDE timestamp {ts} s after {prev} s; its packages cannot be trusted (restart the robot's controller)")]
    Backwards {
        /// The new timestamp (s).
        ts: f64,
        /// The one before (s).
        prev: f64,
    },
    /// `timestamp` did not advance over [`FROZEN_CLOCK_PACKAGES`] packages.
    #[error("the robot's clock is frozen: RTDE timestamp {ts} s in {packages} packages in a row; its packages cannot be trusted (restart the robot's controller)")]
    Frozen {
        /// The timestamp (s).
        ts: f64,
        /// Packages with it.
        packages: u64,
    },
}

/// Watches the timestamps of consecutive packages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockWatch {
    prev: f64,
    same: u64,
}

impl ClockWatch {
    /// Starts from the timestamp `ts` (s) of a package already read.
    pub fn new(ts: f64) -> Self {
        Self { prev: ts, same: 0 }
    }

    /// The next package's timestamp `ts` (s): a fault if it is earlier than the one before
    /// (or not a number), or the same as the [`FROZEN_CLOCK_PACKAGES`] − 1 before it.
    pub fn check(&mut self, ts: f64) -> Result<(), ClockFault> {
        let prev = self.prev;
        if !(ts >= prev) {
            return Err(ClockFault::Backwards { ts, prev });
        }
        if ts == prev {
            self.same += 1;
            if self.same >= FROZEN_CLOCK_PACKAGES {
                return Err(ClockFault::Frozen {
                    ts,
                    packages: self.same + 1,
                });
            }
        } else {
            self.same = 0;
        }
        self.prev = ts;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clock_that_stands_or_goes_back_is_a_fault() {
        let mut w = ClockWatch::new(1.0);
        w.check(1.002).unwrap();
        w.check(1.002).unwrap(); // a repeat
        w.check(1.004).unwrap();
        for _ in 0..FROZEN_CLOCK_PACKAGES - 1 {
            w.check(1.004).unwrap();
        }
        let e = w.check(1.004).unwrap_err();
        assert_eq!(
            e,
            ClockFault::Frozen {
                ts: 1.004,
                packages: FROZEN_CLOCK_PACKAGES + 1
            }
        );
        assert!(e.to_string().contains("frozen"));
        let mut w = ClockWatch::new(2.0);
        assert!(matches!(w.check(1.9), Err(ClockFault::Backwards { .. })));
        assert!(matches!(
            w.check(f64::NAN),
            Err(ClockFault::Backwards { .. })
        ));
    }
}
