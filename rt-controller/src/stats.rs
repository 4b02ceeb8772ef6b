//! Loop statistics without allocating, all allocated at setup: [`LoopStats`] (the loop's
//! counters and histograms), [`FaultCounts`], [`RejectCounts`], and the fixed-size log-linear
//! [`Histogram`] of durations (ns) with its [`Percentiles`].
//!
//! A value v < 64 ns has its own bin; above, each power of two is split into 32 bins, so a
//! reported percentile is the upper edge of its bin and at most ≈ 3 % above the true value
//! (like HdrHistogram with 5 significant bits). Percentiles are exact ranks over the bins.

use serde::Serialize;
use ur5_shared::GainTableError;

use crate::safety::Fault;
use crate::tables::Rejection;

const LINEAR: usize = 64;
const SUB_BITS: u32 = 5;
const SUB: usize = 1 << SUB_BITS;
/// Number of bins: 64 linear + 32 per octave for 2^6 … 2^63.
pub const BINS: usize = LINEAR + (64 - 6) * SUB;

/// A histogram of durations in ns.
pub struct Histogram {
    counts: Box<[u64; BINS]>,
    n: u64,
    max: u64,
    sum: u128,
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

#[inline]
fn bin_of(v: u64) -> usize {
    if v < LINEAR as u64 {
        return v as usize;
    }
    let e = 63 - v.leading_zeros(); // ≥ 6
    let m = ((v >> (e - SUB_BITS)) as usize) & (SUB - 1);
    LINEAR + (e as usize - 6) * SUB + m
}

/// Largest value that falls into `bin`.
fn bin_upper(bin: usize) -> u64 {
    if bin < LINEAR {
        return bin as u64;
    }
    let e = ((bin - LINEAR) / SUB + 6) as u32;
    let m = ((bin - LINEAR) % SUB) as u64;
    let lower = (SUB as u64 + m) << (e - SUB_BITS);
    lower.saturating_add((1u64 << (e - SUB_BITS)) - 1)
}

impl Histogram {
    /// An empty histogram (allocates its bins once, ≈ 15 KB).
    pub fn new() -> Self {
        Self {
            counts: Box::new([0; BINS]),
            n: 0,
            max: 0,
            sum: 0,
        }
    }

    /// Adds one value (ns).
    #[inline]
    pub fn record(&mut self, v: u64) {
        self.counts[bin_of(v)] += 1;
        self.n += 1;
        self.sum += v as u128;
        if v > self.max {
            self.max = v;
        }
    }

    /// Forgets everything (no allocation).
    pub fn clear(&mut self) {
        self.counts.fill(0);
        self.n = 0;
        self.max = 0;
        self.sum = 0;
    }

    /// Number of values.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Largest value (ns), 0 when empty.
    pub fn max(&self) -> u64 {
        self.max
    }

    /// Mean (ns), 0 when empty.
    pub fn mean(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.sum as f64 / self.n as f64
        }
    }

    /// The value at quantile `q` ∈ [0, 1] (ns): the upper edge of the bin holding the
    /// ⌈q n⌉-th smallest value, never above the maximum. 0 when empty.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.n == 0 {
            return 0;
        }
        let rank = ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (bin, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return bin_upper(bin).min(self.max);
            }
        }
        self.max
    }

    /// p50, p99, p99.9, max and count.
    pub fn summary(&self) -> Percentiles {
        Percentiles {
            count: self.n,
            p50_ns: self.quantile(0.5),
            p99_ns: self.quantile(0.99),
            p999_ns: self.quantile(0.999),
            max_ns: self.max,
            mean_ns: self.mean(),
        }
    }
}

/// Percentiles of a [`Histogram`] (ns).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Percentiles {
    /// Number of values.
    pub count: u64,
    /// Median.
    pub p50_ns: u64,
    /// 99th percentile.
    pub p99_ns: u64,
    /// 99.9th percentile.
    pub p999_ns: u64,
    /// Maximum.
    pub max_ns: u64,
    /// Mean.
    pub mean_ns: f64,
}

impl core::fmt::Display for Percentiles {
    /// `p50/p99/p99.9/max` in µs; formatting floats does not allocate.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let us = |v: u64| v as f64 / 1e3;
        write!(
            f,
            "p50 {:.2} p99 {:.2} p99.9 {:.2} max {:.2} µs (n={})",
            us(self.p50_ns),
            us(self.p99_ns),
            us(self.p999_ns),
            us(self.max_ns),
            self.count
        )
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

impl Default for LoopStats {
    fn default() -> Self {
        Self::new()
    }
}

impl LoopStats {
    /// Everything zero; allocates the histograms (setup).
    pub fn new() -> Self {
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
    /// [`Fault::WrongJoints`].
    pub wrong_joints: u64,
}

impl FaultCounts {
    /// Counts one fault.
    pub fn add(&mut self, f: Fault) {
        match f {
            Fault::StaleState => self.stale_state += 1,
            Fault::ArmFault => self.arm_fault += 1,
            Fault::NonFiniteState => self.non_finite_state += 1,
            Fault::NonFiniteAction => self.non_finite_action += 1,
            Fault::NoTable => self.no_table += 1,
            Fault::WrongJoints => self.wrong_joints += 1,
        }
    }

    /// All faults.
    pub fn total(&self) -> u64 {
        self.stale_state
            + self.arm_fault
            + self.non_finite_state
            + self.non_finite_action
            + self.no_table
            + self.wrong_joints
    }
}

/// Rejection reasons as counters (for the statistics and the JSON summary).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RejectCounts {
    /// `dx`/`du` of no task (a damaged header).
    pub dimensions: u64,
    /// A valid table of another task's dimensions than the controller's layout, or with a
    /// goal point for a pose task.
    pub layout_mismatch: u64,
    /// Horizon 0 or > MAX_HORIZON.
    pub horizon: u64,
    /// Checksum mismatch.
    pub checksum: u64,
    /// NaN or infinity.
    pub non_finite: u64,
    /// L not lower triangular, or its diagonal not positive.
    pub cholesky: u64,
    /// A value outside [`ur5_shared::GainBounds`].
    pub out_of_bounds: u64,
    /// Horizon differs from `task.horizon`.
    pub horizon_mismatch: u64,
    /// Version not newer than the active one.
    pub stale_version: u64,
    /// A gain table's episode plan is not valid ([`ur5_shared::EpisodePlan::validate`]).
    pub plan: u64,
    /// A policy table failed [`ur5_shared::PolicyTable::validate`].
    pub invalid_policy: u64,
    /// A policy table acts in another action mode than the controller's.
    pub mode_mismatch: u64,
    /// A policy table trained on another arm model than the controller's.
    pub model_mismatch: u64,
}

impl RejectCounts {
    /// Counts one rejection.
    pub fn add(&mut self, r: &Rejection) {
        let c = match r {
            Rejection::Invalid(GainTableError::WrongDimensions { .. }) => &mut self.dimensions,
            Rejection::Invalid(GainTableError::BadHorizon { .. }) => &mut self.horizon,
            Rejection::Invalid(GainTableError::ChecksumMismatch { .. }) => &mut self.checksum,
            Rejection::Invalid(GainTableError::NonFinite { .. }) => &mut self.non_finite,
            Rejection::Invalid(GainTableError::NotLowerTriangular { .. })
            | Rejection::Invalid(GainTableError::NonPositiveDiagonal { .. }) => &mut self.cholesky,
            Rejection::Invalid(GainTableError::OutOfBounds { .. }) => &mut self.out_of_bounds,
            Rejection::Invalid(GainTableError::Plan { .. }) => &mut self.plan,
            Rejection::HorizonMismatch { .. } => &mut self.horizon_mismatch,
            Rejection::StaleVersion { .. } => &mut self.stale_version,
            Rejection::InvalidPolicy(_) => &mut self.invalid_policy,
            Rejection::ModeMismatch { .. } => &mut self.mode_mismatch,
            Rejection::ModelMismatch { .. } => &mut self.model_mismatch,
            Rejection::LayoutMismatch(_) | Rejection::GoalPointForPose { .. } => {
                &mut self.layout_mismatch
            }
        };
        *c += 1;
    }

    /// All rejections.
    pub fn total(&self) -> u64 {
        self.dimensions
            + self.horizon
            + self.checksum
            + self.non_finite
            + self.cholesky
            + self.out_of_bounds
            + self.horizon_mismatch
            + self.stale_version
            + self.plan
            + self.invalid_policy
            + self.mode_mismatch
            + self.model_mismatch
            + self.layout_mismatch
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_cover_and_order_all_values() {
        let mut prev = 0;
        for v in (0..5000u64).chain([1 << 20, (1 << 20) + 1, u64::MAX / 3, u64::MAX]) {
            let b = bin_of(v);
            assert!(b < BINS);
            assert!(b >= prev || v < 5000, "bins must not decrease");
            assert!(bin_upper(b) >= v, "v={v} b={b} upper={}", bin_upper(b));
            if v >= 64 {
                // Relative width of a bin ≤ 1/32.
                assert!((bin_upper(b) - v) as f64 <= v as f64 / 32.0 + 1.0);
            }
            prev = b;
        }
        assert_eq!(bin_of(u64::MAX), BINS - 1);
    }

    #[test]
    fn quantiles_are_within_a_bin_of_the_exact_ones() {
        let mut h = Histogram::new();
        assert_eq!(h.summary().p50_ns, 0);
        for v in 1..=10_000u64 {
            h.record(v * 10);
        }
        for (q, exact) in [(0.5, 50_000.0), (0.99, 99_000.0), (0.999, 99_900.0)] {
            let got = h.quantile(q) as f64;
            assert!(
                got >= exact && got <= exact * (1.0 + 1.0 / 32.0),
                "q={q}: {got} vs {exact}"
            );
        }
        assert_eq!(h.max(), 100_000);
        assert_eq!(h.quantile(1.0), 100_000);
        assert!((h.mean() - 50_005.0).abs() < 1e-9);
        h.clear();
        assert_eq!(h.count(), 0);
        h.record(7);
        assert_eq!(h.summary().p999_ns, 7);
    }
}
