//! A time-indexed tracking term from the demonstrations' per-step state distribution, added to
//! another cost (docs/design.md §5 D39):
//!
//!   C'_t(s, a) = C_t(s, a) + ½ w Σ_i P_{t,i} (s_i − μ_{t,i})²,
//!   μ_t = mean over the demonstrations of their state at step t,
//!   P_{t,i} = 1 / (var_{t,i} + (κ σ̄_i)²),
//!
//! var_{t,i} the demonstrations' variance of state input i at step t (over demonstrations,
//! divided by their count), σ̄_i that input's standard deviation over every demonstration and
//! step (the scale the critic's normalisation uses), κ the variance floor's fraction of it (the
//! demonstrations start from one pose, so var_{0,i} = 0) and w the weight. The precision is
//! diagonal: with a handful of demonstrations the per-step covariance of dX inputs has rank
//! below dX. Only the demonstrations' states enter, so it stays imitation from observation;
//! the critic still scores the transitions, the term says where along the motion the arm
//! should be at step t (GPS's trajectory costs are of this kind).
//!
//! Derivatives: ∇_s = w P_t ⊙ (s − μ_t), ∇²_s = w diag(P_t), no action terms. Its values are in
//! the units of the critic's cost (dimensionless): a state one floor-width off in one input
//! adds ½ w / κ² at most.

use super::Cost;
use crate::demos::Demos;
use crate::rollout::Episode;
use crate::ImitationError;
use gps::algorithm::eval_cost::CostDerivs;
use gps::dynamics::Dynamics;

/// The demonstrations' per-step mean state and diagonal precision (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Tracking {
    /// Weight w (dimensionless; > 0).
    pub weight: f64,
    /// μ_t, (T, dX) row-major.
    mean: Vec<f64>,
    /// P_t, (T, dX) row-major, in 1 / (the input's unit)².
    precision: Vec<f64>,
    dx: usize,
}

impl Tracking {
    /// The term of `demos` with weight `weight` and variance floor `floor` (κ, a fraction of
    /// each input's overall standard deviation). Refuses a weight or floor that is not finite
    /// and > 0, naming the setting.
    pub fn from_demos(demos: &Demos, weight: f64, floor: f64) -> Result<Self, ImitationError> {
        crate::error::check_reals(&[
            (
                "path.tracking_weight",
                weight,
                weight.is_finite() && weight > 0.0,
                "finite and > 0 when the term is on",
            ),
            (
                "path.tracking_floor",
                floor,
                floor.is_finite() && floor > 0.0,
                "finite and > 0 (a fraction of each input's spread)",
            ),
        ])
        .map_err(ImitationError::Config)?;
        let (d, t_len, dx) = (demos.count, demos.horizon, demos.layout().dx());
        let mut mean = vec![0.0; t_len * dx];
        let mut var = vec![0.0; t_len * dx];
        for t in 0..t_len {
            for k in 0..d {
                for (m, s) in mean[t * dx..(t + 1) * dx].iter_mut().zip(demos.state(k, t)) {
                    *m += s / d as f64;
                }
            }
            for k in 0..d {
                let s = demos.state(k, t);
                for i in 0..dx {
                    let e = s[i] - mean[t * dx + i];
                    var[t * dx + i] += e * e / d as f64;
                }
            }
        }
        // σ̄_i² over every demonstration and step: the mean of the per-step variances plus the
        // variance of the per-step means.
        let mut floor2 = vec![0.0; dx];
        for (i, f) in floor2.iter_mut().enumerate() {
            let all_mean = (0..t_len).map(|t| mean[t * dx + i]).sum::<f64>() / t_len as f64;
            let total = (0..t_len)
                .map(|t| var[t * dx + i] + (mean[t * dx + i] - all_mean).powi(2))
                .sum::<f64>()
                / t_len as f64;
            // An input that never changes (a locked joint's velocity at rest) gets a floor of
            // 1e-12 of its unit² rather than an infinite precision.
            *f = (floor * floor * total).max(1e-12);
        }
        let precision = var
            .iter()
            .enumerate()
            .map(|(k, v)| 1.0 / (v + floor2[k % dx]))
            .collect();
        Ok(Self {
            weight,
            mean,
            precision,
            dx,
        })
    }

    /// Horizon T the term was built for.
    pub fn horizon(&self) -> usize {
        self.mean.len() / self.dx
    }

    /// ½ w Σ_i P_{t,i} (s_i − μ_{t,i})² at step `t`, and its gradient added into `lx` (dX) and
    /// its (diagonal) Hessian added into `lxx` (dX × dX, row-major) when given.
    pub fn add(&self, t: usize, s: &[f64], lx: Option<&mut [f64]>, lxx: Option<&mut [f64]>) -> f64 {
        let dx = self.dx;
        let (mu, p) = (
            &self.mean[t * dx..(t + 1) * dx],
            &self.precision[t * dx..(t + 1) * dx],
        );
        let mut value = 0.0;
        for i in 0..dx {
            let e = s[i] - mu[i];
            value += 0.5 * self.weight * p[i] * e * e;
        }
        if let Some(lx) = lx {
            for i in 0..dx {
                lx[i] += self.weight * p[i] * (s[i] - mu[i]);
            }
        }
        if let Some(lxx) = lxx {
            for i in 0..dx {
                lxx[i * dx + i] += self.weight * p[i];
            }
        }
        value
    }
}

/// A cost `inner` scaled by `inner_weight`, plus the [`Tracking`] term `tracking`, when
/// there is one.
pub struct WithTracking<'a, C: Cost> {
    /// The cost the term is added to (LQR+GAIfO's composite cost).
    pub inner: C,
    /// Factor on `inner` (its value and every derivative); 1 leaves it untouched, bit for
    /// bit, and 0 leaves the tracking term alone (an ablation).
    pub inner_weight: f64,
    /// The term; `None` (with `inner_weight` 1) leaves `inner` untouched, bit for bit.
    pub tracking: Option<&'a Tracking>,
}

impl<C: Cost> Cost for WithTracking<'_, C> {
    fn expand(&mut self, episodes: &[Episode], dynamics: &Dynamics, out: &mut CostDerivs) {
        self.inner.expand(episodes, dynamics, out);
        if self.inner_weight != 1.0 {
            let w = self.inner_weight;
            for v in [
                &mut out.l,
                &mut out.lx,
                &mut out.lu,
                &mut out.lxx,
                &mut out.luu,
                &mut out.lux,
            ] {
                v.iter_mut().for_each(|x| *x *= w);
            }
        }
        let Some(tr) = self.tracking else { return };
        let t_len = episodes[0].horizon();
        let dx = tr.dx;
        for (k, ep) in episodes.iter().enumerate() {
            for t in 0..t_len {
                let nt = k * t_len + t;
                out.l[nt] += tr.add(
                    t,
                    ep.state(t),
                    Some(&mut out.lx[nt * dx..(nt + 1) * dx]),
                    Some(&mut out.lxx[nt * dx * dx..(nt + 1) * dx * dx]),
                );
            }
        }
    }

    fn sampled(&mut self, episodes: &[Episode], derivs: &CostDerivs, out: &mut Vec<f64>) {
        self.inner.sampled(episodes, derivs, out);
        if self.inner_weight != 1.0 {
            out.iter_mut().for_each(|x| *x *= self.inner_weight);
        }
        let Some(tr) = self.tracking else { return };
        let t_len = episodes[0].horizon();
        for (k, ep) in episodes.iter().enumerate() {
            for t in 0..t_len {
                out[k * t_len + t] += tr.add(t, ep.state(t), None, None);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::joints::Joints;
    use ur5_shared::layout::StateLayout;
    use ur5_shared::UrModel;

    fn demos(count: usize, horizon: usize) -> Demos {
        let dx = StateLayout::REACH3.dx();
        let states = (0..count * horizon * dx)
            .map(|k| {
                let (d, t, i) = (k / (horizon * dx), (k / dx) % horizon, k % dx);
                (t as f64 * 0.1 + i as f64).sin() + 0.05 * (d as f64) * (i as f64 + 1.0).cos()
            })
            .collect();
        Demos {
            states,
            actions: vec![0.0; count * horizon * 3],
            model: UrModel::Ur5,
            count,
            horizon,
            goal: [-0.45, -0.25, 0.25],
            goal_pose: None,
            tool_points: [[0.0; 3]; 3],
            start_q: Joints::from_slice(&[0.0, -1.5, 1.8]),
            dt: 0.1,
            seed: 0,
            cost_random: 10.0,
            cost_expert: 1.0,
        }
    }

    /// By hand: two demonstrations of one step that differ by 2 in input i have variance 1
    /// there; with a floor κ σ̄ the precision is 1 / (1 + κ² σ̄²).
    #[test]
    fn mean_and_precision_are_the_demonstrations_per_step_statistics() {
        let mut d = demos(2, 1);
        let dx = 12;
        d.states = (0..2 * dx)
            .map(|k| if k < dx { 1.0 } else { 3.0 })
            .collect();
        let tr = Tracking::from_demos(&d, 2.0, 0.5).unwrap();
        // σ̄² = 1 (one step): floor² = 0.25.
        let s = vec![2.0; dx];
        assert_eq!(tr.add(0, &s, None, None), 0.0, "at the mean");
        let mut s1 = s.clone();
        s1[4] = 4.0;
        let v = tr.add(0, &s1, None, None);
        assert!((v - 0.5 * 2.0 * 4.0 / 1.25).abs() < 1e-12, "{v}");
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences() {
        let d = demos(5, 7);
        let tr = Tracking::from_demos(&d, 0.3, 0.1).unwrap();
        let dx = 12;
        for t in [0, 3, 6] {
            let s: Vec<f64> = (0..dx).map(|i| 0.3 * (i as f64 - 5.0).sin()).collect();
            let (mut g, mut h) = (vec![0.0; dx], vec![0.0; dx * dx]);
            tr.add(t, &s, Some(&mut g), Some(&mut h));
            let f = |z: &[f64]| tr.add(t, z, None, None);
            let e = 1e-5;
            let scale = g.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let hscale = h.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for i in 0..dx {
                let (mut p, mut m) = (s.clone(), s.clone());
                p[i] += e;
                m[i] -= e;
                let fd = (f(&p) - f(&m)) / (2.0 * e);
                assert!(
                    (fd - g[i]).abs() < 1e-6 * scale,
                    "t {t} i {i}: {fd} vs {}",
                    g[i]
                );
                for j in 0..dx {
                    let q = |di: f64, dj: f64| {
                        let mut z = s.clone();
                        z[i] += di;
                        z[j] += dj;
                        f(&z)
                    };
                    let hh = 1e-3;
                    let fd2 = (q(hh, hh) - q(hh, -hh) - q(-hh, hh) + q(-hh, -hh)) / (4.0 * hh * hh);
                    assert!(
                        (fd2 - h[i * dx + j]).abs() < 1e-6 * hscale,
                        "t {t} ({i},{j}): {fd2} vs {}",
                        h[i * dx + j]
                    );
                }
            }
        }
    }

    #[test]
    fn settings_that_cannot_work_are_refused_by_name() {
        let d = demos(3, 4);
        let e = Tracking::from_demos(&d, 0.0, 0.1).unwrap_err().to_string();
        assert!(e.contains("path.tracking_weight"), "{e}");
        let e = Tracking::from_demos(&d, 1.0, f64::NAN)
            .unwrap_err()
            .to_string();
        assert!(e.contains("path.tracking_floor"), "{e}");
    }
}
