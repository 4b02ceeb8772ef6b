//! The reaching task's cost per time step, with derivatives, for training the expert
//! (docs/design.md §1.6; GPS `CostFK` + `CostAction` in spirit), and its GPS expansion
//! ([`Cost`]).
//!
//! ℓ_t(s, a) = w_t [ l1 √(d² + α) + ½ l2 d² ] + ½ w_u ‖a − q‖²,
//! with d = ‖s[EE_MINUS_GOAL]‖ (m), q = s[Q] (rad), w_t = t/n for t < n = T−1 and
//! w_n = 1 + final_weight. With α = 0, l1 = 1, l2 = 0, final_weight = 1 and w_u = 0 the sum over
//! an episode is exactly the task cost C(τ) = d_n + Σ_i (i/n) d_i of `ur5_shared::cost`.
//! α > 0 rounds the distance off near the goal the way GPS's l1/l2 penalty does, so the
//! Hessian stays finite; the action term penalises goal angles far from the current angles
//! (units: cost per rad²).

use gps::algorithm::eval_cost::CostDerivs;
use gps::dynamics::Dynamics;
use serde::{Deserialize, Serialize};
use ur5_shared::layout::{DU, DX, EE_MINUS_GOAL, Q};

use super::Cost;
use crate::rollout::Episode;

/// Weights of the task cost.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TaskCostConfig {
    /// Weight of the smoothed distance √(d² + α) (1/m · m = unitless per step). Task cost: 1.
    pub l1: f64,
    /// Weight of ½ d² (1/m). GPS's reacher costs add such a term for a stronger pull far from
    /// the goal; ours: 1.
    pub l2: f64,
    /// Smoothing α (m²): the distance is rounded off below √α. GPS `CostFK` uses 1e-5; ours
    /// 1e-4 (1 cm), well under the 2 cm accuracy asked of the expert.
    pub alpha: f64,
    /// Extra weight on the last step (the task cost's lone d_n): 1.
    pub final_weight: f64,
    /// Weight w_u of ½‖a − q‖² (1/rad²). Ours: 1e-2, small next to the distance terms.
    pub action_weight: f64,
}

impl Default for TaskCostConfig {
    fn default() -> Self {
        Self {
            l1: 1.0,
            l2: 1.0,
            alpha: 1e-4,
            final_weight: 1.0,
            action_weight: 1e-2,
        }
    }
}

/// Cost and derivatives at one (s, a), GPS layout: lx (dX), lu (dU), lxx (dX×dX), luu
/// (dU×dU), lux (dU×dX), all row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct StepDerivs {
    /// ℓ.
    pub l: f64,
    /// ∂ℓ/∂s.
    pub lx: [f64; DX],
    /// ∂ℓ/∂a.
    pub lu: [f64; DU],
    /// ∂²ℓ/∂s².
    pub lxx: [[f64; DX]; DX],
    /// ∂²ℓ/∂a².
    pub luu: [[f64; DU]; DU],
    /// ∂²ℓ/∂a∂s.
    pub lux: [[f64; DX]; DU],
}

impl Default for StepDerivs {
    fn default() -> Self {
        Self {
            l: 0.0,
            lx: [0.0; DX],
            lu: [0.0; DU],
            lxx: [[0.0; DX]; DX],
            luu: [[0.0; DU]; DU],
            lux: [[0.0; DX]; DU],
        }
    }
}

impl TaskCostConfig {
    /// Time weight w_t for step `t` of a horizon-`horizon` episode.
    pub fn weight(&self, t: usize, horizon: usize) -> f64 {
        let n = horizon.saturating_sub(1).max(1);
        if t + 1 >= horizon {
            1.0 + self.final_weight
        } else {
            t as f64 / n as f64
        }
    }

    /// ℓ_t(s, a) and its derivatives, written into `out` (no allocation).
    pub fn eval(
        &self,
        t: usize,
        horizon: usize,
        s: &[f64; DX],
        a: &[f64; DU],
        out: &mut StepDerivs,
    ) {
        *out = StepDerivs::default();
        let w = self.weight(t, horizon);
        let e = [
            s[EE_MINUS_GOAL.start],
            s[EE_MINUS_GOAL.start + 1],
            s[EE_MINUS_GOAL.start + 2],
        ];
        let d2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        let r = (d2 + self.alpha).sqrt();
        out.l = w * (self.l1 * r + 0.5 * self.l2 * d2);
        if r > 0.0 {
            // ∇ = w (l1/r + l2) e;  ∇² = w [ (l1/r + l2) I − l1 e eᵀ / r³ ].
            let g = w * (self.l1 / r + self.l2);
            let h = w * self.l1 / (r * r * r);
            for i in 0..3 {
                out.lx[EE_MINUS_GOAL.start + i] = g * e[i];
                for j in 0..3 {
                    let diag = if i == j { g } else { 0.0 };
                    out.lxx[EE_MINUS_GOAL.start + i][EE_MINUS_GOAL.start + j] =
                        diag - h * e[i] * e[j];
                }
            }
        }
        let wu = self.action_weight;
        for j in 0..DU {
            let qj = Q.start + j;
            let da = a[j] - s[qj];
            out.l += 0.5 * wu * da * da;
            out.lu[j] = wu * da;
            out.lx[qj] -= wu * da;
            out.luu[j][j] = wu;
            out.lxx[qj][qj] += wu;
            out.lux[j][qj] = -wu;
        }
    }
}

/// The task cost as a [`Cost`]: GPS's per-sample expansion of [`TaskCostConfig::eval`].
impl Cost for TaskCostConfig {
    fn expand(&mut self, episodes: &[Episode], _: &Dynamics, out: &mut CostDerivs) {
        let n = episodes.len();
        let t_len = episodes[0].horizon();
        out.resize(n, t_len, DX, DU);
        let mut d = StepDerivs::default();
        for (i, ep) in episodes.iter().enumerate() {
            for t in 0..t_len {
                let s = ep.state(t);
                let a: [f64; DU] = ep.u[t * DU..(t + 1) * DU].try_into().expect("dU");
                self.eval(t, t_len, &s, &a, &mut d);
                let nt = i * t_len + t;
                out.l[nt] = d.l;
                out.lx[nt * DX..(nt + 1) * DX].copy_from_slice(&d.lx);
                out.lu[nt * DU..(nt + 1) * DU].copy_from_slice(&d.lu);
                for r in 0..DX {
                    out.lxx[nt * DX * DX + r * DX..nt * DX * DX + (r + 1) * DX]
                        .copy_from_slice(&d.lxx[r]);
                }
                for r in 0..DU {
                    out.luu[nt * DU * DU + r * DU..nt * DU * DU + (r + 1) * DU]
                        .copy_from_slice(&d.luu[r]);
                    out.lux[nt * DU * DX + r * DX..nt * DU * DX + (r + 1) * DX]
                        .copy_from_slice(&d.lux[r]);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn ell(c: &TaskCostConfig, t: usize, h: usize, y: &[f64]) -> f64 {
        let s: [f64; DX] = y[..DX].try_into().unwrap();
        let a: [f64; DU] = y[DX..].try_into().unwrap();
        let mut d = StepDerivs::default();
        c.eval(t, h, &s, &a, &mut d);
        d.l
    }

    /// Gradient and Hessian against central finite differences at random points, including
    /// points close to the goal where the smoothing matters.
    #[test]
    fn derivatives_match_finite_differences() {
        let c = TaskCostConfig::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let h = 1e-5;
        let mut worst_g = 0.0f64;
        let mut worst_h = 0.0f64;
        for k in 0..40 {
            let scale = if k % 2 == 0 { 0.3 } else { 0.01 };
            let mut y = [0.0; DX + DU];
            for (i, v) in y.iter_mut().enumerate() {
                *v = rng.random_range(-1.0..1.0)
                    * if EE_MINUS_GOAL.contains(&i) {
                        scale
                    } else {
                        1.0
                    };
            }
            let t = rng.random_range(0..100);
            let s: [f64; DX] = y[..DX].try_into().unwrap();
            let a: [f64; DU] = y[DX..].try_into().unwrap();
            let mut d = StepDerivs::default();
            c.eval(t, 100, &s, &a, &mut d);
            let grad: Vec<f64> = d.lx.iter().chain(d.lu.iter()).copied().collect();
            let hess = |i: usize, j: usize| -> f64 {
                match (i < DX, j < DX) {
                    (true, true) => d.lxx[i][j],
                    (false, false) => d.luu[i - DX][j - DX],
                    (false, true) => d.lux[i - DX][j],
                    (true, false) => d.lux[j - DX][i],
                }
            };
            for i in 0..DX + DU {
                let (mut yp, mut ym) = (y, y);
                yp[i] += h;
                ym[i] -= h;
                let fd = (ell(&c, t, 100, &yp) - ell(&c, t, 100, &ym)) / (2.0 * h);
                worst_g = worst_g.max((fd - grad[i]).abs() / (1.0 + grad[i].abs()));
                // Hessian row i from central differences of the analytic gradient.
                let mut dp = StepDerivs::default();
                let mut dm = StepDerivs::default();
                c.eval(
                    t,
                    100,
                    &yp[..DX].try_into().unwrap(),
                    &yp[DX..].try_into().unwrap(),
                    &mut dp,
                );
                c.eval(
                    t,
                    100,
                    &ym[..DX].try_into().unwrap(),
                    &ym[DX..].try_into().unwrap(),
                    &mut dm,
                );
                let gp: Vec<f64> = dp.lx.iter().chain(dp.lu.iter()).copied().collect();
                let gm: Vec<f64> = dm.lx.iter().chain(dm.lu.iter()).copied().collect();
                for j in 0..DX + DU {
                    let fd = (gp[j] - gm[j]) / (2.0 * h);
                    worst_h = worst_h.max((fd - hess(i, j)).abs() / (1.0 + hess(i, j).abs()));
                }
            }
        }
        assert!(worst_g < 1e-7, "gradient rel. error {worst_g:.2e}");
        assert!(worst_h < 1e-5, "Hessian rel. error {worst_h:.2e}");
    }

    /// With the smoothing and extras off, the summed per-step cost is the task cost C(τ).
    #[test]
    fn reduces_to_the_task_cost() {
        let c = TaskCostConfig {
            l1: 1.0,
            l2: 0.0,
            alpha: 0.0,
            final_weight: 1.0,
            action_weight: 0.0,
        };
        let horizon = 7;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut states = Vec::new();
        let mut total = 0.0;
        for t in 0..horizon {
            let mut s = [0.0; DX];
            for v in s.iter_mut() {
                *v = rng.random_range(-0.5..0.5);
            }
            let mut d = StepDerivs::default();
            c.eval(t, horizon, &s, &[0.0; DU], &mut d);
            total += d.l;
            states.push(s);
        }
        let reference = ur5_shared::cost::task_cost_from_states(&states).unwrap();
        assert!((total - reference).abs() < 1e-12, "{total} vs {reference}");
    }
}
