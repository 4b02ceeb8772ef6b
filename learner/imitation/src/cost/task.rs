//! The reaching task's cost per time step, with derivatives, for training the expert
//! (docs/design.md §1.6; GPS `CostFK` + `CostAction` in spirit), and its GPS expansion
//! ([`Cost`]).
//!
//! ℓ_t(s, a) = w_t [ l1 √(d² + α) + ½ l2 d² ] + ½ w_u ‖a − q‖²,
//! with d = ‖s[points]‖ (m; the tool points' errors together), q = s[q] (rad), w_t = t/n for t < n = T−1 and
//! w_n = 1 + final_weight. With α = 0, l1 = 1, l2 = 0, final_weight = 1 and w_u = 0 the sum over
//! an episode is exactly the task cost C(τ) = d_n + Σ_i (i/n) d_i of `ur5_shared::cost`.
//! α > 0 rounds the distance off near the goal the way GPS's l1/l2 penalty does, so the
//! Hessian stays finite; the action term penalises goal angles far from the current angles
//! (units: cost per rad²).

use gps::algorithm::eval_cost::CostDerivs;
use gps::dynamics::Dynamics;
use serde::{Deserialize, Serialize};
use ur5_shared::layout::StateLayout;

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
    /// ∂ℓ/∂s (dX).
    pub lx: Vec<f64>,
    /// ∂ℓ/∂a (dU).
    pub lu: Vec<f64>,
    /// ∂²ℓ/∂s² (dX × dX).
    pub lxx: Vec<f64>,
    /// ∂²ℓ/∂a² (dU × dU).
    pub luu: Vec<f64>,
    /// ∂²ℓ/∂a∂s (dU × dX).
    pub lux: Vec<f64>,
}

impl StepDerivs {
    /// Zeros for a task of layout `layout`.
    pub fn new(layout: &StateLayout) -> Self {
        let (dx, du) = (layout.dx(), layout.du());
        Self {
            l: 0.0,
            lx: vec![0.0; dx],
            lu: vec![0.0; du],
            lxx: vec![0.0; dx * dx],
            luu: vec![0.0; du * du],
            lux: vec![0.0; du * dx],
        }
    }

    fn clear(&mut self) {
        self.l = 0.0;
        for v in [
            &mut self.lx,
            &mut self.lu,
            &mut self.lxx,
            &mut self.luu,
            &mut self.lux,
        ] {
            v.fill(0.0);
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

    /// ℓ_t(s, a) and its derivatives for a task of layout `layout` (`s` dX, `a` dU), written
    /// into `out` (made by [`StepDerivs::new`] for the same layout; no allocation). The
    /// distance d is that of every tool point to its target together (e = s[points], 3p
    /// entries): for a pose goal ‖(e_1, e_2, e_3)‖.
    pub fn eval(
        &self,
        layout: &StateLayout,
        t: usize,
        horizon: usize,
        s: &[f64],
        a: &[f64],
        out: &mut StepDerivs,
    ) {
        let (dx, du) = (layout.dx(), layout.du());
        out.clear();
        let w = self.weight(t, horizon);
        let pts = layout.points();
        let e = &s[pts.clone()];
        let mut d2 = 0.0;
        for v in e {
            d2 += v * v;
        }
        let r = (d2 + self.alpha).sqrt();
        out.l = w * (self.l1 * r + 0.5 * self.l2 * d2);
        if r > 0.0 {
            // ∇ = w (l1/r + l2) e;  ∇² = w [ (l1/r + l2) I − l1 e eᵀ / r³ ].
            let g = w * (self.l1 / r + self.l2);
            let h = w * self.l1 / (r * r * r);
            for i in 0..e.len() {
                out.lx[pts.start + i] = g * e[i];
                for j in 0..e.len() {
                    let diag = if i == j { g } else { 0.0 };
                    out.lxx[(pts.start + i) * dx + pts.start + j] = diag - h * e[i] * e[j];
                }
            }
        }
        let wu = self.action_weight;
        let q0 = layout.q().start;
        for j in 0..du {
            let qj = q0 + j;
            let da = a[j] - s[qj];
            out.l += 0.5 * wu * da * da;
            out.lu[j] = wu * da;
            out.lx[qj] -= wu * da;
            out.luu[j * du + j] = wu;
            out.lxx[qj * dx + qj] += wu;
            out.lux[j * dx + qj] = -wu;
        }
    }
}

/// The task cost as a [`Cost`]: GPS's per-sample expansion of [`TaskCostConfig::eval`].
impl Cost for TaskCostConfig {
    fn expand(&mut self, episodes: &[Episode], _: &Dynamics, out: &mut CostDerivs) {
        let n = episodes.len();
        let t_len = episodes[0].horizon();
        let layout = episodes[0].layout;
        let (dx, du) = (layout.dx(), layout.du());
        out.resize(n, t_len, dx, du);
        let mut d = StepDerivs::new(&layout);
        for (i, ep) in episodes.iter().enumerate() {
            for t in 0..t_len {
                self.eval(&layout, t, t_len, ep.state(t), ep.action(t), &mut d);
                let nt = i * t_len + t;
                out.l[nt] = d.l;
                out.lx[nt * dx..(nt + 1) * dx].copy_from_slice(&d.lx);
                out.lu[nt * du..(nt + 1) * du].copy_from_slice(&d.lu);
                out.lxx[nt * dx * dx..(nt + 1) * dx * dx].copy_from_slice(&d.lxx);
                out.luu[nt * du * du..(nt + 1) * du * du].copy_from_slice(&d.luu);
                out.lux[nt * du * dx..(nt + 1) * du * dx].copy_from_slice(&d.lux);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn ell(c: &TaskCostConfig, layout: &StateLayout, t: usize, h: usize, y: &[f64]) -> f64 {
        let dx = layout.dx();
        let mut d = StepDerivs::new(layout);
        c.eval(layout, t, h, &y[..dx], &y[dx..], &mut d);
        d.l
    }

    /// Gradient and Hessian against central finite differences at random points, including
    /// points close to the goal where the smoothing matters, for a point goal (three joints)
    /// and a pose goal (six joints, three tool points).
    #[test]
    fn derivatives_match_finite_differences() {
        for layout in [StateLayout::REACH3, StateLayout::POSE6] {
            let (dx, du) = (layout.dx(), layout.du());
            let c = TaskCostConfig::default();
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            let h = 1e-5;
            let mut worst_g = 0.0f64;
            let mut worst_h = 0.0f64;
            for k in 0..40 {
                let scale = if k % 2 == 0 { 0.3 } else { 0.01 };
                let mut y = vec![0.0; dx + du];
                for (i, v) in y.iter_mut().enumerate() {
                    *v = rng.random_range(-1.0..1.0)
                        * if layout.points().contains(&i) {
                            scale
                        } else {
                            1.0
                        };
                }
                let t = rng.random_range(0..100);
                let mut d = StepDerivs::new(&layout);
                c.eval(&layout, t, 100, &y[..dx], &y[dx..], &mut d);
                let grad: Vec<f64> = d.lx.iter().chain(d.lu.iter()).copied().collect();
                let hess = |i: usize, j: usize| -> f64 {
                    match (i < dx, j < dx) {
                        (true, true) => d.lxx[i * dx + j],
                        (false, false) => d.luu[(i - dx) * du + j - dx],
                        (false, true) => d.lux[(i - dx) * dx + j],
                        (true, false) => d.lux[(j - dx) * dx + i],
                    }
                };
                for i in 0..dx + du {
                    let (mut yp, mut ym) = (y.clone(), y.clone());
                    yp[i] += h;
                    ym[i] -= h;
                    let fd =
                        (ell(&c, &layout, t, 100, &yp) - ell(&c, &layout, t, 100, &ym)) / (2.0 * h);
                    worst_g = worst_g.max((fd - grad[i]).abs() / (1.0 + grad[i].abs()));
                    // Hessian row i from central differences of the analytic gradient.
                    let mut dp = StepDerivs::new(&layout);
                    let mut dm = StepDerivs::new(&layout);
                    c.eval(&layout, t, 100, &yp[..dx], &yp[dx..], &mut dp);
                    c.eval(&layout, t, 100, &ym[..dx], &ym[dx..], &mut dm);
                    let gp: Vec<f64> = dp.lx.iter().chain(dp.lu.iter()).copied().collect();
                    let gm: Vec<f64> = dm.lx.iter().chain(dm.lu.iter()).copied().collect();
                    for j in 0..dx + du {
                        let fd = (gp[j] - gm[j]) / (2.0 * h);
                        worst_h = worst_h.max((fd - hess(i, j)).abs() / (1.0 + hess(i, j).abs()));
                    }
                }
            }
            assert!(
                worst_g < 1e-7,
                "{layout}: gradient rel. error {worst_g:.2e}"
            );
            assert!(worst_h < 1e-5, "{layout}: Hessian rel. error {worst_h:.2e}");
        }
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
        for layout in [StateLayout::REACH3, StateLayout::POSE6] {
            let horizon = 7;
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            let mut x = Vec::new();
            let mut total = 0.0;
            for t in 0..horizon {
                let s: Vec<f64> = (0..layout.dx())
                    .map(|_| rng.random_range(-0.5..0.5))
                    .collect();
                let mut d = StepDerivs::new(&layout);
                c.eval(&layout, t, horizon, &s, &vec![0.0; layout.du()], &mut d);
                total += d.l;
                x.extend_from_slice(&s);
            }
            let reference = ur5_shared::cost::task_cost_of_states(&layout, &x).unwrap();
            assert!((total - reference).abs() < 1e-12, "{total} vs {reference}");
        }
    }
}
