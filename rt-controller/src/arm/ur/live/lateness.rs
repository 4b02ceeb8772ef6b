//! The `ur` loop's lateness measurement ([`super::UrReport::lateness`]): when a package was
//! handled against the arm's clock.

use crate::stats::Histogram;

use super::LATENESS_BASELINE;

/// The lateness measurement of [`UrReport::lateness`].
pub(super) struct Lateness {
    pub(super) compression: f64,
    pub(super) first: Option<(u64, f64)>,
    pub(super) baseline_ns: i64,
    pub(super) hist: Histogram,
}

impl Lateness {
    pub(super) fn record(&mut self, package: u64, wall_ns: u64, ts: f64) {
        let (w0, t0) = *self.first.get_or_insert((wall_ns, ts));
        let offset = (wall_ns - w0) as i64 - ((ts - t0) * 1e9 / self.compression) as i64;
        if package <= LATENESS_BASELINE {
            self.baseline_ns = if package == 1 {
                offset
            } else {
                self.baseline_ns.min(offset)
            };
        } else {
            self.hist.record((offset - self.baseline_ns).max(0) as u64);
        }
    }
}
