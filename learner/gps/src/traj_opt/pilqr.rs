//! PILQR (Chebotar et al. 2017): the KL-bounded LQR step followed by a PI2 update of the
//! feed-forward terms and covariances on the cost the linear model does not explain (GPS
//! python/gps/algorithm/traj_opt/traj_opt_pilqr.py `TrajOptPILQR.update`,
//! traj_opt_utils.py `approximated_cost`, and the `res_percent` step rule of
//! algorithm_traj_opt_pilqr.py `_stepadjust`).
//!
//! After LQR has produced `(K, k, Σ)` from the fitted dynamics and the quadratic cost model:
//! 1. `approximated_cost`: roll the controller executed this iteration through the fitted
//!    linear dynamics from x0's mean with each sample's own noise ε (`u = K x + k + Rᵀ ε`) and
//!    evaluate the quadratic cost model there: what LQR believes each sample cost;
//! 2. residual cost = sampled cost − that prediction (dynamics and cost-model error);
//! 3. PI2 temperature per step from the *sampled* costs-to-go ([`super::pi2`], `Fitted`);
//! 4. PI2 on the residual costs at those temperatures, with the samples
//!    `k_LQR + R_LQRᵀ ε` (GPS `use_lqr_actions`): new `k` and `Σ`; `K` stays LQR's.
//!
//! The step rule `res_percent` sets the next KL step from the residual's share of the sampled
//! cost: `r = mean_i Σ_t |res| / mean_i Σ_t |cs|`; `r > dec` halves the step multiplier,
//! `r < inc` doubles it (GPS `step_rule_res_ratio_dec` 0.2, `_inc` 0.05).
//!
//! The pieces are GPS's (tests/data/gps-vectors, `pilqr_*.json`); the defaults are not
//! ([`PilqrConfig::default`]): with 5 samples per iteration GPS's temperature, fitted on the
//! sampled costs and applied to the residual ones, puts all weight on one sample and
//! collapses the covariance. [`TemperatureFrom::Residual`] fits it on the costs it weighs.

use crate::error::GpsError;
use crate::policy::lin_gauss::LinGaussPolicy;
pub use crate::traj_opt::config::{PilqrConfig, StepRule, TemperatureFrom, TrajOptMethod};
use crate::traj_opt::lqr::TrajInfo;
use crate::traj_opt::pi2::{Temperature, TrajOptPi2};

/// GPS `traj_opt_utils.approximated_cost`: each sample's noise `noise (N, T, dU)` replayed
/// through `pol` on `info`'s linear dynamics from `x0mu`; the trajectories into `mu (N, T,
/// dX+dU)` and the quadratic cost model along them into `cost (N, T)`.
pub fn approximated_cost(
    noise: &[f64],
    n: usize,
    pol: &LinGaussPolicy,
    info: &TrajInfo,
    mu: &mut [f64],
    cost: &mut [f64],
) -> Result<(), GpsError> {
    let (t_len, dx, du) = (pol.t, pol.dx, pol.du);
    let d = dx + du;
    if noise.len() != n * t_len * du || mu.len() != n * t_len * d || cost.len() != n * t_len {
        return Err(GpsError::Shape(format!(
            "approximated_cost for N={n}, T={t_len}, dX={dx}, dU={du}: noise {}, mu {}, cost {}",
            noise.len(),
            mu.len(),
            cost.len()
        )));
    }
    let fm = &info.dynamics.fm;
    let fv = &info.dynamics.fv;
    for i in 0..n {
        let base = i * t_len * d;
        mu[base..base + dx].copy_from_slice(&info.x0mu);
        for t in 0..t_len {
            let row = base + t * d;
            let eps = &noise[(i * t_len + t) * du..(i * t_len + t + 1) * du];
            let (x, u) = mu[row..row + d].split_at_mut(dx);
            pol.act(t, x, eps, u);
            if t + 1 < t_len {
                let f = fm.slice(t);
                let fvt = fv.slice(t);
                for r in 0..dx {
                    let mut v = 0.0;
                    for c in 0..d {
                        v += f[r * d + c] * mu[row + c];
                    }
                    mu[row + d + r] = v + fvt[r];
                }
            }
            let y = &mu[row..row + d];
            let cm = info.cm.slice(t);
            let cv = info.cv.slice(t);
            let mut quad = 0.0;
            for a in 0..d {
                let mut s = 0.0;
                for b in 0..d {
                    s += y[b] * cm[b * d + a];
                }
                quad += s * y[a];
            }
            let lin: f64 = (0..d).map(|a| y[a] * cv[a]).sum();
            cost[i * t_len + t] = info.cc[t] + 0.5 * quad + lin;
        }
    }
    Ok(())
}

/// The residual's share of the sampled cost, `mean_i Σ_t |pred − cs| / mean_i Σ_t |cs|`
/// (GPS `_stepadjust`, `res_percent`), over `n` samples of `t_len` steps.
pub fn residual_share(predicted: &[f64], cs: &[f64], n: usize, t_len: usize) -> f64 {
    tail_share(predicted, cs, n, t_len, 0)
}

/// [`residual_share`] of the steps `from..T` (GPS's per-step rule).
fn tail_share(predicted: &[f64], cs: &[f64], n: usize, t_len: usize, from: usize) -> f64 {
    let (mut res, mut act) = (0.0, 0.0);
    for i in 0..n {
        let r = i * t_len + from..(i + 1) * t_len;
        res += predicted[r.clone()]
            .iter()
            .zip(&cs[r.clone()])
            .map(|(p, c)| (p - c).abs())
            .sum::<f64>();
        act += cs[r].iter().map(|c| c.abs()).sum::<f64>();
    }
    (res / n as f64) / (act / n as f64)
}

/// GPS's `res_percent` factor: 0.5 above `dec`, 2 below `inc`, else 1.
fn res_percent_factor(share: f64, dec: f64, inc: f64) -> f64 {
    if share > dec {
        0.5
    } else if share < inc {
        2.0
    } else {
        1.0
    }
}

/// GPS `_stepadjust` with `step_rule = 'res_percent'` (one KL bound): halve the multiplier
/// when the residual share exceeds `dec`, double it below `inc`, clamp to `[min, max]`.
pub fn res_percent_step_mult(
    share: f64,
    step_mult: f64,
    dec: f64,
    inc: f64,
    min: f64,
    max: f64,
) -> f64 {
    (res_percent_factor(share, dec, inc) * step_mult)
        .min(max)
        .max(min)
}

/// What the PI2 half of a PILQR step did.
#[derive(Clone, Copy, Debug, Default)]
pub struct PilqrReport {
    /// Residual share of the sampled cost (as the step rule computes it).
    pub residual_share: f64,
    /// Mean PI2 temperature over the steps.
    pub mean_eta: f64,
    /// Largest change of the feed-forward term by PI2, action units.
    pub max_dk: f64,
    /// Smallest ratio over the steps of the PI2 covariance's trace to the LQR one's.
    pub min_cov_ratio: f64,
}

/// GPS `TrajOptPILQR`'s PI2 half for one problem size (the LQR half is
/// [`crate::traj_opt::lqr::TrajOptLqr`]): settings and buffers.
pub struct TrajOptPilqr {
    pub cfg: PilqrConfig,
    pi2: TrajOptPi2,
    n: usize,
    mu: Vec<f64>,
    predicted: Vec<f64>,
    residual: Vec<f64>,
    samples: Vec<f64>,
    eta: Vec<f64>,
}

impl TrajOptPilqr {
    /// Settings and buffers for horizon `t`, `dx`, `du` and `n` samples.
    pub fn new(cfg: PilqrConfig, t: usize, dx: usize, du: usize, n: usize) -> Self {
        Self {
            pi2: TrajOptPi2::new(cfg.pi2(), t, du, n),
            cfg,
            n,
            mu: vec![0.0; n * t * (dx + du)],
            predicted: vec![0.0; n * t],
            residual: vec![0.0; n * t],
            samples: vec![0.0; n * t * du],
            eta: vec![0.0; t],
        }
    }

    /// The predicted costs of the last [`TrajOptPilqr::predict`], `(N, T)`.
    pub fn predicted(&self) -> &[f64] {
        &self.predicted
    }

    /// Residual costs `cs − predicted` of the last [`TrajOptPilqr::update`], `(N, T)`.
    pub fn residual(&self) -> &[f64] {
        &self.residual
    }

    /// The PI2 temperatures of the last [`TrajOptPilqr::update`], `(T)`.
    pub fn eta(&self) -> &[f64] {
        &self.eta
    }

    fn check_n(&self, n: usize) -> Result<(), GpsError> {
        if n != self.n {
            return Err(GpsError::Shape(format!(
                "PILQR built for {} samples, got {n}",
                self.n
            )));
        }
        Ok(())
    }

    /// [`approximated_cost`] of `executed` (the controller the samples were drawn from) with
    /// the samples' noise `noise (N, T, dU)`, kept for the step rule and the update; returns
    /// the residual share of the sampled costs `cs (N, T)`.
    pub fn predict(
        &mut self,
        noise: &[f64],
        cs: &[f64],
        n: usize,
        executed: &LinGaussPolicy,
        info: &TrajInfo,
    ) -> Result<f64, GpsError> {
        self.check_n(n)?;
        approximated_cost(noise, n, executed, info, &mut self.mu, &mut self.predicted)?;
        Ok(residual_share(&self.predicted, cs, n, executed.t))
    }

    /// The PI2 half of GPS `TrajOptPILQR.update`: `pol` holds the LQR step's controller and
    /// receives PILQR's (same `K`, new `k` and covariances). Call [`TrajOptPilqr::predict`]
    /// with the executed controller first. `temperature`: `None` fits PI2's temperatures on
    /// the sampled costs (GPS); `Some` uses the given ones (the conformance test's GPS values).
    pub fn update(
        &mut self,
        noise: &[f64],
        cs: &[f64],
        n: usize,
        pol: &mut LinGaussPolicy,
        temperature: Option<&[f64]>,
    ) -> Result<PilqrReport, GpsError> {
        self.check_n(n)?;
        let (t_len, du) = (pol.t, pol.du);
        if cs.len() != n * t_len || noise.len() != n * t_len * du {
            return Err(GpsError::Shape(format!(
                "PILQR for N={n}, T={t_len}, dU={du}: costs {}, noise {}",
                cs.len(),
                noise.len()
            )));
        }
        let share = residual_share(&self.predicted, cs, n, t_len);
        for (r, (c, p)) in self.residual.iter_mut().zip(cs.iter().zip(&self.predicted)) {
            *r = c - p;
        }
        // Feed-forward samples of the LQR controller with each sample's noise: k + Rᵀ ε.
        for i in 0..n {
            for t in 0..t_len {
                let eps = &noise[(i * t_len + t) * du..(i * t_len + t + 1) * du];
                let k = pol.k.slice(t);
                let r = pol.chol_pol_covar.slice(t);
                let out = &mut self.samples[(i * t_len + t) * du..(i * t_len + t + 1) * du];
                for a in 0..du {
                    out[a] = k[a] + (0..du).map(|b| r[b * du + a] * eps[b]).sum::<f64>();
                }
            }
        }
        match temperature {
            Some(eta) => self.eta.copy_from_slice(eta),
            None => {
                let on = match self.cfg.temperature_from {
                    TemperatureFrom::Sampled => cs,
                    TemperatureFrom::Residual => &self.residual,
                };
                self.pi2
                    .update_pi2(&self.samples, on, n, &pol.pol_covar, Temperature::Fitted)?;
                self.eta.copy_from_slice(&self.pi2.out.eta);
            }
        }
        let out = self.pi2.update_pi2(
            &self.samples,
            &self.residual,
            n,
            &pol.pol_covar,
            Temperature::Fixed(&self.eta),
        )?;
        let mut max_dk: f64 = 0.0;
        let mut min_cov_ratio = f64::INFINITY;
        let trace = |m: &[f64]| (0..du).map(|a| m[a * du + a]).sum::<f64>();
        for t in 0..t_len {
            for (a, b) in pol.k.slice(t).iter().zip(out.mean.slice(t)) {
                max_dk = max_dk.max((a - b).abs());
            }
            min_cov_ratio =
                min_cov_ratio.min(trace(out.cov.slice(t)) / trace(pol.pol_covar.slice(t)));
        }
        pol.k.copy_from(&out.mean);
        pol.pol_covar.copy_from(&out.cov);
        pol.inv_pol_covar.copy_from(&out.inv_cov);
        pol.chol_pol_covar.copy_from(&out.chol_cov);
        Ok(PilqrReport {
            residual_share: share,
            mean_eta: self.eta.iter().sum::<f64>() / t_len as f64,
            max_dk,
            min_cov_ratio,
        })
    }
}

/// GPS `_stepadjust` with `res_percent` and one KL bound per step (`cons_per_step`): the rule
/// applied to each tail `t..T` of the costs; multipliers and bounds per step, into `step_mult`.
#[allow(clippy::too_many_arguments)]
pub fn res_percent_step_mult_per_step(
    predicted: &[f64],
    cs: &[f64],
    n: usize,
    t_len: usize,
    dec: f64,
    inc: f64,
    min: &[f64],
    max: &[f64],
    step_mult: &mut [f64],
) {
    for t in 0..t_len {
        let share = tail_share(predicted, cs, n, t_len, t);
        step_mult[t] = (res_percent_factor(share, dec, inc) * step_mult[t])
            .min(max[t])
            .max(min[t]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traj_opt::lqr::TrajOptConfig;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[cfg(feature = "conformance")]
    #[test]
    fn default_settings_serialise_as_before_pilqr() {
        let v = serde_json::to_value(TrajOptConfig::default()).unwrap();
        assert!(v.get("method").is_none() && v.get("pilqr").is_none(), "{v}");
        let c: TrajOptConfig =
            serde_json::from_str(r#"{"method":"pilqr","pilqr":{"kl_threshold":0.5}}"#).unwrap();
        assert_eq!(c.method, TrajOptMethod::Pilqr);
        assert_eq!(c.pilqr.kl_threshold, 0.5);
        assert!(serde_json::to_value(&c).unwrap().get("method").is_some());
        assert!(serde_json::from_str::<TrajOptConfig>(r#"{"method":"pi2"}"#).is_err());
    }

    /// A residual that is the same for every sample carries no information: PI2 weighs the
    /// samples equally, so `k` becomes the samples' mean `k + Rᵀ mean(ε)` and (damping 0)
    /// the covariance their biased sample covariance; `K` is untouched.
    #[test]
    fn uninformative_residual_gives_the_sample_moments() {
        let (t, dx, du, n) = (4, 3, 2, 6);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut pol = LinGaussPolicy::zeros(t, dx, du);
        for v in pol.gain.data.iter_mut().chain(pol.k.data.iter_mut()) {
            *v = rng.random_range(-1.0..1.0);
        }
        for s in 0..t {
            let r = [0.5, 0.1, 0.0, 0.3]; // upper
            pol.chol_pol_covar.slice_mut(s).copy_from_slice(&r);
            let c = [0.25, 0.05, 0.05, 0.1]; // RᵀR
            pol.pol_covar.slice_mut(s).copy_from_slice(&c);
        }
        let info = TrajInfo::zeros(t, dx, du);
        let noise: Vec<f64> = (0..n * t * du)
            .map(|_| rng.random_range(-2.0..2.0))
            .collect();
        // Predicted cost 0 (zero cost model), so the residual is cs: equal across samples.
        let cs: Vec<f64> = (0..n * t).map(|i| (i % t) as f64).collect();
        let cfg = PilqrConfig {
            covariance_damping: 0.0,
            ..PilqrConfig::default()
        };
        let mut p = TrajOptPilqr::new(cfg, t, dx, du, n);
        let share = p.predict(&noise, &cs, n, &pol, &info).unwrap();
        assert_eq!(share, 1.0);
        let mut new = pol.clone();
        p.update(&noise, &cs, n, &mut new, Some(&[1.0; 4])).unwrap();
        assert_eq!(new.gain, pol.gain);
        for s in 0..t {
            let r = pol.chol_pol_covar.slice(s);
            let samples: Vec<[f64; 2]> = (0..n)
                .map(|i| {
                    let e = &noise[(i * t + s) * du..(i * t + s + 1) * du];
                    let k = pol.k.slice(s);
                    [k[0] + r[0] * e[0], k[1] + r[1] * e[0] + r[3] * e[1]]
                })
                .collect();
            let m = [0, 1].map(|a| samples.iter().map(|x| x[a]).sum::<f64>() / n as f64);
            for a in 0..2 {
                assert!((new.k.slice(s)[a] - m[a]).abs() < 1e-12);
                for b in 0..2 {
                    let c = samples
                        .iter()
                        .map(|x| (x[a] - m[a]) * (x[b] - m[b]))
                        .sum::<f64>()
                        / n as f64;
                    assert!((new.pol_covar.slice(s)[a * 2 + b] - c).abs() < 1e-12);
                }
            }
        }
    }

    /// approximated_cost against a direct roll-out of u = K x + k + Rᵀ ε through the model.
    #[test]
    fn approximated_cost_rolls_the_model() {
        let (t, dx, du, n) = (3, 2, 1, 2);
        let mut pol = LinGaussPolicy::zeros(t, dx, du);
        pol.gain
            .data
            .copy_from_slice(&[0.5, -0.2, 0.1, 0.3, -0.4, 0.2]);
        pol.k.data.copy_from_slice(&[0.1, 0.2, 0.3]);
        pol.chol_pol_covar.data.copy_from_slice(&[0.5, 0.5, 0.5]);
        let mut info = TrajInfo::zeros(t, dx, du);
        info.x0mu.copy_from_slice(&[1.0, -1.0]);
        for s in 0..t - 1 {
            info.dynamics
                .fm
                .slice_mut(s)
                .copy_from_slice(&[1.0, 0.1, 0.0, 0.0, 1.0, 0.1]);
            info.dynamics
                .fv
                .slice_mut(s)
                .copy_from_slice(&[0.01, -0.02]);
        }
        for s in 0..t {
            info.cc[s] = 0.5;
            info.cv.slice_mut(s).copy_from_slice(&[1.0, 0.0, 2.0]);
            info.cm
                .slice_mut(s)
                .copy_from_slice(&[2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 4.0]);
        }
        let noise = [1.0, -1.0, 0.5, 0.0, 2.0, -0.5];
        let mut mu = vec![0.0; n * t * 3];
        let mut cost = vec![0.0; n * t];
        approximated_cost(&noise, n, &pol, &info, &mut mu, &mut cost).unwrap();
        for i in 0..n {
            let mut x = [1.0, -1.0];
            for s in 0..t {
                let g = pol.gain.slice(s);
                let u = g[0] * x[0] + g[1] * x[1] + pol.k.slice(s)[0] + 0.5 * noise[i * t + s];
                let c =
                    0.5 + x[0] + 2.0 * u + 0.5 * (2.0 * x[0] * x[0] + x[1] * x[1] + 4.0 * u * u);
                assert!((cost[i * t + s] - c).abs() < 1e-12);
                x = [x[0] + 0.1 * x[1] + 0.01, x[1] + 0.1 * u - 0.02];
            }
        }
    }
}
