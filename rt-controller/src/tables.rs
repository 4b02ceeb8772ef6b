//! The double-buffered gain table (docs/design.md §3.4, §5 D19): the loop reads the active half; a new table
//! is copied into the inactive half, validated there and made active by flipping an index, at an
//! episode boundary only. Both halves are allocated at setup; nothing here allocates.
//!
//! The copy comes before the validation, unlike the order "validate, copy, flip" one might
//! expect: the private copy cannot change while it is checked, whereas the shared-memory sample
//! is written by another process. A rejected table only ever overwrites the inactive half.

use ur5_shared::{GainBounds, GainTable, GainTableError};

/// Why a received table was not taken.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum Rejection {
    /// [`GainTable::validate`] failed.
    #[error(transparent)]
    Invalid(#[from] GainTableError),
    /// The table's horizon differs from the controller's episode length.
    #[error("gain table version {version} has horizon T = {horizon}, the controller runs episodes of T = {expected} (task.horizon): learner and controller disagree about the task")]
    HorizonMismatch {
        /// Table version.
        version: u64,
        /// Its horizon.
        horizon: u64,
        /// `task.horizon`.
        expected: u64,
    },
    /// The version is not newer than the active table's (versions increase, docs/design.md §3.3).
    #[error("gain table version {version} is not newer than the active version {active}; ignored")]
    StaleVersion {
        /// Received version.
        version: u64,
        /// Active version.
        active: u64,
    },
}

/// What [`TableBuffer::offer`] did with a table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Offer {
    /// The table is now active.
    Swapped {
        /// Time to copy it into the inactive half (ns).
        copy_ns: u64,
        /// Time to validate the copy (ns).
        validate_ns: u64,
    },
    /// Same version as the active table (e.g. redelivered history): nothing to do.
    Unchanged,
}

/// Two preallocated tables and which one is active.
pub struct TableBuffer {
    halves: [Box<GainTable>; 2],
    active: Option<usize>,
    bounds: GainBounds,
    horizon: usize,
}

impl TableBuffer {
    /// Allocates both halves (setup). `horizon` is the episode length tables must have.
    pub fn new(bounds: GainBounds, horizon: usize) -> Self {
        Self {
            halves: [GainTable::new_boxed(), GainTable::new_boxed()],
            active: None,
            bounds,
            horizon,
        }
    }

    /// The active table, if any was ever accepted.
    #[inline]
    pub fn active(&self) -> Option<&GainTable> {
        self.active.map(|i| &*self.halves[i])
    }

    /// Version of the active table.
    pub fn active_version(&self) -> Option<u64> {
        self.active().map(|t| t.version)
    }

    /// Takes `incoming` if it is valid and newer: copy into the inactive half, validate the
    /// copy, flip. Call only at an episode boundary. `now` is a clock for the timings (ns).
    pub fn offer(
        &mut self,
        incoming: &GainTable,
        now: impl Fn() -> u64,
    ) -> Result<Offer, Rejection> {
        if let Some(active) = self.active() {
            if incoming.version == active.version {
                return Ok(Offer::Unchanged);
            }
            if incoming.version < active.version {
                return Err(Rejection::StaleVersion {
                    version: incoming.version,
                    active: active.version,
                });
            }
        }
        let inactive = match self.active {
            Some(i) => 1 - i,
            None => 0,
        };
        let t0 = now();
        self.halves[inactive].copy_from(incoming);
        let t1 = now();
        let table = &self.halves[inactive];
        let checked = table.validate(&self.bounds);
        let t2 = now();
        checked?;
        if table.horizon() != self.horizon {
            return Err(Rejection::HorizonMismatch {
                version: table.version,
                horizon: table.horizon() as u64,
                expected: self.horizon as u64,
            });
        }
        self.active = Some(inactive);
        Ok(Offer::Swapped {
            copy_ns: t1 - t0,
            validate_ns: t2 - t1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::RejectCounts;
    use ur5_shared::MAX_HORIZON;

    fn table(version: u64, horizon: usize, a_hat: f64) -> Box<GainTable> {
        let mut t = GainTable::new_boxed();
        t.set_version(version);
        t.set_horizon(horizon).unwrap();
        for s in 0..horizon {
            let st = t.step_mut(s);
            st.a_hat = [a_hat; 3];
            st.chol = [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]];
        }
        t.seal();
        t
    }

    #[test]
    fn swaps_valid_tables_and_keeps_the_old_one_on_rejection() {
        let clock = || 0;
        let mut b = TableBuffer::new(GainBounds::default(), 100);
        assert!(b.active().is_none());
        assert!(matches!(
            b.offer(&table(1, 100, 0.5), clock),
            Ok(Offer::Swapped { .. })
        ));
        assert_eq!(b.active_version(), Some(1));
        assert_eq!(b.offer(&table(1, 100, 0.5), clock), Ok(Offer::Unchanged));

        let mut counts = RejectCounts::default();
        let mut nan = table(2, 100, 0.5);
        nan.steps[3].k_vec[1] = f64::NAN;
        nan.seal();
        let mut dims = table(3, 100, 0.5);
        dims.dx = 13;
        dims.seal();
        let mut sum = table(4, 100, 0.5);
        sum.steps[0].a_hat[0] = 0.25;
        for (bad, field) in [
            (nan, "non_finite"),
            (dims, "dimensions"),
            (sum, "checksum"),
            (table(5, 50, 0.5), "horizon_mismatch"),
        ] {
            let r = b.offer(&bad, clock).unwrap_err();
            counts.add(&r);
            assert_eq!(b.active_version(), Some(1), "{field}");
            assert_eq!(b.active().unwrap().steps[0].a_hat, [0.5; 3]);
        }
        assert_eq!(
            (
                counts.non_finite,
                counts.dimensions,
                counts.checksum,
                counts.horizon_mismatch
            ),
            (1, 1, 1, 1)
        );

        assert!(matches!(
            b.offer(&table(7, 100, 0.75), clock),
            Ok(Offer::Swapped { .. })
        ));
        assert_eq!(b.active().unwrap().steps[99].a_hat, [0.75; 3]);
        let r = b.offer(&table(6, 100, 0.5), clock).unwrap_err();
        assert!(matches!(
            r,
            Rejection::StaleVersion {
                version: 6,
                active: 7
            }
        ));
        assert_eq!(b.active_version(), Some(7));
        // A full-horizon table passes when the task runs that long.
        let mut long = TableBuffer::new(GainBounds::default(), MAX_HORIZON);
        long.offer(&table(1, MAX_HORIZON, 0.0), clock).unwrap();
    }
}
