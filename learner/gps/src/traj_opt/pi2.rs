//! PI2 update of a time-varying linear-Gaussian controller's feed-forward terms and
//! covariances (GPS python/gps/algorithm/traj_opt/traj_opt_pi2.py, `TrajOptPI2.update_pi2` and
//! `kl_dual`; Theodorou et al. 2010, Stulp and Sigaud 2012, the temperature as in REPS).
//!
//! Per time step t, each sample i weighs by the soft-min of its cost-to-go
//! `S_i = Σ_{τ ≥ t} c_{i,τ}`: `p_i ∝ exp(−(S_i − min S) / η_t)`. The new mean is `Σ p_i u_i`, the
//! new covariance the weighted maximum-likelihood one, `Σ p_i (u_i − μ)(u_i − μ)ᵀ`, or, with
//! covariance damping d > 0, the old covariance times `(tr(Σ_old⁻¹ Σ_ML) / dU)^{1/d}`. The
//! temperature η_t either is given or minimises the REPS dual
//! `g(η) = η ε + max(−S) + η log(mean exp((−S − max(−S)) / η))` over `η ≥ min_temperature`.
//!
//! Differences from GPS, on purpose:
//! - GPS minimises the dual with scipy's L-BFGS-B from η = 10 (finite-difference gradient,
//!   stopping at a projected gradient of 1e-5). The dual is convex in η, so here it is
//!   minimised to machine precision by bisection on its derivative ([`optimal_temperature`]);
//!   the η found is never worse on the dual than GPS's (tested on the recorded vectors).
//! - When a new covariance is not positive definite, GPS raises η_t by δ (doubling from
//!   `del0`) and retries; with a fitted temperature its retry recomputes the same η and never
//!   ends (up to the 1e16 bound). Here the raised η is kept in both modes.

use faer::Mat;

use crate::error::GpsError;
use crate::linalg::{llt_lower, LuSolver, MatSeq, Scratch};
pub use crate::traj_opt::config::Pi2Config;

/// How each time step's temperature is chosen.
#[derive(Clone, Copy, Debug)]
pub enum Temperature<'a> {
    /// Minimise the dual of the KL bound on this update's own costs.
    Fitted,
    /// Use these temperatures (length T), as PILQR's second PI2 call does.
    Fixed(&'a [f64]),
}

/// GPS `TrajOptPI2.kl_dual`: the REPS dual at temperature `eta` for costs-to-go `costs`.
pub fn kl_dual(eta: f64, kl_threshold: f64, costs: &[f64]) -> f64 {
    let max = costs.iter().map(|c| -c).fold(f64::NEG_INFINITY, f64::max);
    let mean = costs.iter().map(|c| ((-c - max) / eta).exp()).sum::<f64>() / costs.len() as f64;
    eta * kl_threshold + max + eta * mean.ln()
}

/// dg/dη of [`kl_dual`]: `ε + log(mean e^{a/η}) − Σ p a / η`, `a = −S − max(−S) ≤ 0`,
/// `p = softmax(a/η)`. Non-decreasing in η (the dual is convex), tending to ε > 0.
fn kl_dual_slope(eta: f64, kl_threshold: f64, costs: &[f64]) -> f64 {
    let max = costs.iter().map(|c| -c).fold(f64::NEG_INFINITY, f64::max);
    let (mut z, mut za) = (0.0, 0.0);
    for c in costs {
        let a = -c - max;
        let w = (a / eta).exp();
        z += w;
        za += w * a;
    }
    kl_threshold + (z / costs.len() as f64).ln() - za / (z * eta)
}

/// The temperature minimising [`kl_dual`] over `η ≥ min_temperature`: `min_temperature` when
/// the dual rises from there (ε ≥ log(N / #minima) or equal costs), otherwise the root of its
/// slope, bracketed by doubling and bisected to the last bit.
pub fn optimal_temperature(kl_threshold: f64, min_temperature: f64, costs: &[f64]) -> f64 {
    let slope = |eta: f64| kl_dual_slope(eta, kl_threshold, costs);
    if !(slope(min_temperature) < 0.0) {
        return min_temperature;
    }
    let mut lo = min_temperature;
    let mut hi = min_temperature.max(1.0);
    while slope(hi) < 0.0 {
        lo = hi;
        hi *= 2.0;
        if !hi.is_finite() {
            return lo;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if slope(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // Of the two ends, the one with the lower dual (equal to the last bits in practice).
    if kl_dual(lo, kl_threshold, costs) <= kl_dual(hi, kl_threshold, costs) {
        lo
    } else {
        hi
    }
}

/// The result of [`TrajOptPi2::update_pi2`] (GPS's five return values), sized for one
/// problem and rewritten by every call.
#[derive(Clone, Debug)]
pub struct Pi2Result {
    /// New mean, `(T, dU, 1)`.
    pub mean: MatSeq,
    /// New covariance, `(T, dU, dU)`.
    pub cov: MatSeq,
    /// Its inverse (LU, as scipy `inv`), `(T, dU, dU)`.
    pub inv_cov: MatSeq,
    /// Its upper Cholesky factor `R`, `cov = Rᵀ R`, `(T, dU, dU)`.
    pub chol_cov: MatSeq,
    /// Temperature used at each step (GPS returns zeros for fixed temperatures; here the
    /// temperature used, raised where a covariance needed it), `(T)`.
    pub eta: Vec<f64>,
}

/// GPS `TrajOptPI2` for one problem size: settings and scratch memory.
pub struct TrajOptPi2 {
    pub cfg: Pi2Config,
    t: usize,
    du: usize,
    ctg: Vec<f64>,
    prob: Vec<f64>,
    cov: Mat<f64>,
    l: Mat<f64>,
    inv: Mat<f64>,
    lu: LuSolver,
    scratch: Scratch,
    pub out: Pi2Result,
}

impl TrajOptPi2 {
    /// Settings plus buffers for horizon `t`, `du` actions and up to `n` samples.
    pub fn new(cfg: Pi2Config, t: usize, du: usize, n: usize) -> Self {
        Self {
            cfg,
            t,
            du,
            ctg: Vec::with_capacity(n),
            prob: Vec::with_capacity(n),
            cov: Mat::zeros(du, du),
            l: Mat::zeros(du, du),
            inv: Mat::zeros(du, du),
            lu: LuSolver::new(du, du),
            scratch: Scratch::for_llt(du.max(1)),
            out: Pi2Result {
                mean: MatSeq::zeros(t, du, 1),
                cov: MatSeq::zeros(t, du, du),
                inv_cov: MatSeq::zeros(t, du, du),
                chol_cov: MatSeq::zeros(t, du, du),
                eta: vec![0.0; t],
            },
        }
    }

    /// GPS `TrajOptPI2.update_pi2`: new means and covariances from `n` policy samples
    /// `samples (n, T, dU)` with per-step costs `costs (n, T)`, the old covariances
    /// `cov_old (T, dU, dU)` (for the damping) and the temperature rule; into [`Self::out`].
    pub fn update_pi2(
        &mut self,
        samples: &[f64],
        costs: &[f64],
        n: usize,
        cov_old: &MatSeq,
        temperature: Temperature<'_>,
    ) -> Result<&Pi2Result, GpsError> {
        let (t_len, du) = (self.t, self.du);
        if samples.len() != n * t_len * du || costs.len() != n * t_len || n == 0 {
            return Err(GpsError::Shape(format!(
                "PI2 for T={t_len}, dU={du}: samples {} and costs {} do not fit n = {n}",
                samples.len(),
                costs.len()
            )));
        }
        if let Temperature::Fixed(eta) = temperature {
            if eta.len() != t_len {
                return Err(GpsError::Shape(format!(
                    "PI2 fixed temperatures: {} for T = {t_len}",
                    eta.len()
                )));
            }
        }
        for t in 0..t_len {
            self.ctg.clear();
            self.ctg
                .extend((0..n).map(|i| costs[i * t_len + t..(i + 1) * t_len].iter().sum::<f64>()));
            let mut eta = match temperature {
                Temperature::Fixed(e) => e[t],
                Temperature::Fitted => {
                    optimal_temperature(self.cfg.kl_threshold, self.cfg.min_temperature, &self.ctg)
                }
            };
            let mut del = self.cfg.del0;
            loop {
                if self.step(samples, n, t, eta, cov_old) {
                    break;
                }
                eta += del;
                del *= 2.0;
                if eta >= crate::traj_opt::lqr::ETA_ERROR_THRESHOLD {
                    return Err(GpsError::NotPositiveDefinite {
                        what: "PI2 covariance",
                        t,
                    });
                }
            }
            self.out.eta[t] = eta;
        }
        Ok(&self.out)
    }

    /// One time step at temperature `eta`; false when the new covariance is not positive
    /// definite (GPS's `LinAlgError`).
    fn step(&mut self, samples: &[f64], n: usize, t: usize, eta: f64, cov_old: &MatSeq) -> bool {
        let (t_len, du) = (self.t, self.du);
        let max = self
            .ctg
            .iter()
            .map(|c| -c)
            .fold(f64::NEG_INFINITY, f64::max);
        self.prob.clear();
        self.prob
            .extend(self.ctg.iter().map(|c| ((-c - max) / eta).exp()));
        let z: f64 = self.prob.iter().sum();
        self.prob.iter_mut().for_each(|p| *p /= z);
        let sample = |i: usize| &samples[(i * t_len + t) * du..(i * t_len + t + 1) * du];
        let mean = self.out.mean.slice_mut(t);
        mean.fill(0.0);
        for i in 0..n {
            for (m, s) in mean.iter_mut().zip(sample(i)) {
                *m += self.prob[i] * s;
            }
        }
        let mean = self.out.mean.slice(t);
        self.cov.fill(0.0);
        for i in 0..n {
            let s = sample(i);
            for a in 0..du {
                for b in 0..du {
                    self.cov[(a, b)] += self.prob[i] * ((s[a] - mean[a]) * (s[b] - mean[b]));
                }
            }
        }
        let old = cov_old.mat(t);
        if self.cfg.covariance_damping > 0.0 {
            // mult = tr(Σ_old⁻¹ Σ_ML) / dU, to the power 1/d, times Σ_old.
            self.inv.copy_from(&self.cov);
            if !self.lu.solve(old, self.inv.as_mut()) {
                return false;
            }
            let tr: f64 = (0..du).map(|i| self.inv[(i, i)]).sum();
            let mult = (tr / du as f64).powf(1.0 / self.cfg.covariance_damping);
            for a in 0..du {
                for b in 0..du {
                    self.cov[(a, b)] = mult * old[(a, b)];
                }
            }
        }
        // Inverse (LU) and upper Cholesky factor; either failing is GPS's LinAlgError.
        self.l.copy_from(&self.cov);
        if !llt_lower(self.l.as_mut(), &mut self.scratch) {
            return false;
        }
        self.inv.fill(0.0);
        for i in 0..du {
            self.inv[(i, i)] = 1.0;
        }
        if !self.lu.solve(self.cov.as_ref(), self.inv.as_mut()) {
            return false;
        }
        let (cov, inv, chol) = (self.out.cov.slice_mut(t), &self.inv, &self.l);
        for a in 0..du {
            for b in 0..du {
                cov[a * du + b] = self.cov[(a, b)];
            }
        }
        let inv_out = self.out.inv_cov.slice_mut(t);
        for a in 0..du {
            for b in 0..du {
                inv_out[a * du + b] = inv[(a, b)];
            }
        }
        let chol_out = self.out.chol_cov.slice_mut(t);
        for a in 0..du {
            for b in 0..du {
                // R = Lᵀ (upper).
                chol_out[a * du + b] = chol[(b, a)];
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperature_minimises_the_dual() {
        let costs = [3.0, 1.5, 2.2, 7.0, 1.6, 4.4, 2.9];
        for eps in [0.1, 0.5, 1.0, 1.5] {
            let eta = optimal_temperature(eps, 1e-3, &costs);
            let g = kl_dual(eta, eps, &costs);
            for f in [0.999, 0.99, 0.9, 1.001, 1.01, 1.1] {
                assert!(
                    kl_dual(eta * f, eps, &costs) >= g - 1e-14 * g.abs(),
                    "eps {eps} f {f}"
                );
            }
            // The slope against a central difference of the dual.
            let h = 1e-6 * eta;
            let fd = (kl_dual(eta + h, eps, &costs) - kl_dual(eta - h, eps, &costs)) / (2.0 * h);
            assert!(fd.abs() < 1e-6, "eps {eps}: slope {fd}");
        }
        // ε ≥ log N: the bound cannot bind, the lowest temperature.
        assert_eq!(optimal_temperature(3.0, 1e-3, &costs), 1e-3);
        // Equal costs: every temperature is as good; the lowest.
        assert_eq!(optimal_temperature(0.5, 1e-3, &[2.0; 4]), 1e-3);
    }

    #[test]
    fn slope_matches_finite_differences() {
        let costs = [0.3, 1.1, 0.2, 2.5, 0.9];
        for eta in [0.05, 0.3, 1.0, 4.0] {
            let h = 1e-5 * eta;
            let fd = (kl_dual(eta + h, 0.7, &costs) - kl_dual(eta - h, 0.7, &costs)) / (2.0 * h);
            let s = kl_dual_slope(eta, 0.7, &costs);
            assert!(
                (fd - s).abs() < 1e-7 * (1.0 + s.abs()),
                "eta {eta}: {fd} vs {s}"
            );
        }
    }

    #[test]
    fn large_temperature_gives_the_sample_moments() {
        // η → ∞: equal weights, the sample mean and the (biased) sample covariance.
        let (t, du, n) = (1, 2, 4);
        let samples = [1.0, 0.0, -1.0, 2.0, 0.5, 0.5, 2.5, -0.5];
        let costs = [1.0, 2.0, 3.0, 4.0];
        let mut pi2 = TrajOptPi2::new(
            Pi2Config {
                covariance_damping: 0.0,
                ..Pi2Config::default()
            },
            t,
            du,
            n,
        );
        let old = MatSeq::from_vec(1, 2, 2, vec![1.0, 0.0, 0.0, 1.0]);
        let r = pi2
            .update_pi2(&samples, &costs, n, &old, Temperature::Fixed(&[1e12]))
            .unwrap();
        let m = [0.75, 0.5];
        assert!(
            (r.mean.slice(0)[0] - m[0]).abs() < 1e-9 && (r.mean.slice(0)[1] - m[1]).abs() < 1e-9
        );
        let mut c = [0.0; 4];
        for i in 0..n {
            let d = [samples[2 * i] - m[0], samples[2 * i + 1] - m[1]];
            for a in 0..2 {
                for b in 0..2 {
                    c[a * 2 + b] += d[a] * d[b] / n as f64;
                }
            }
        }
        for k in 0..4 {
            assert!((r.cov.slice(0)[k] - c[k]).abs() < 1e-9);
        }
    }
}
