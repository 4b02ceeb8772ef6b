//! Loop statistics without allocating: fixed-size log-linear histograms of durations (ns) and
//! counters, all allocated at setup.
//!
//! A value v < 64 ns has its own bin; above, each power of two is split into 32 bins, so a
//! reported percentile is the upper edge of its bin and at most ≈ 3 % above the true value
//! (like HdrHistogram with 5 significant bits). Percentiles are exact ranks over the bins.

use serde::Serialize;

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
