//! Seeded synthetic problems for tests and the benchmark: a random stable linear plant, a
//! quadratic cost, and noisy rollouts of a linear-Gaussian controller. Not part of GPS.

use faer::Mat;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::dynamics::Dynamics;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::lqr::TrajInfo;

/// `x' = A x + B u + c + w`, `w ~ N(0, proc_std² I)`, `x_0 ~ N(x0, x0_std² I)`.
#[derive(Clone, Debug)]
pub struct LinearSystem {
    pub dx: usize,
    pub du: usize,
    pub a: Mat<f64>,
    pub b: Mat<f64>,
    pub c: Vec<f64>,
    pub x0: Vec<f64>,
    pub x0_std: f64,
    pub proc_std: f64,
}

fn randn(rng: &mut impl Rng) -> f64 {
    StandardNormal.sample(rng)
}

impl LinearSystem {
    /// Random plant with `‖A‖₂ ≤ 0.98` (so stable): `A = 0.98 (0.7 I + 0.3 R / ‖R‖_F)`.
    pub fn random_stable(rng: &mut impl Rng, dx: usize, du: usize) -> Self {
        let r = Mat::<f64>::from_fn(dx, dx, |_, _| randn(rng));
        let rn = r.norm_l2();
        let a = Mat::<f64>::from_fn(dx, dx, |i, j| {
            0.98 * (if i == j { 0.7 } else { 0.0 } + 0.3 * r[(i, j)] / rn)
        });
        let b = Mat::<f64>::from_fn(dx, du, |_, _| 0.3 * randn(rng));
        let c = (0..dx).map(|_| 0.01 * randn(rng)).collect();
        let x0 = (0..dx).map(|_| randn(rng)).collect();
        Self {
            dx,
            du,
            a,
            b,
            c,
            x0,
            x0_std: 0.01,
            proc_std: 0.01,
        }
    }

    /// The plant as time-varying dynamics over `t` steps (last step zero, as GPS fits).
    pub fn dynamics(&self, t: usize) -> Dynamics {
        let (dx, du) = (self.dx, self.du);
        let mut d = Dynamics::zeros(t, dx, du);
        for s in 0..t - 1 {
            let mut f = d.fm.mat_mut(s);
            for i in 0..dx {
                for j in 0..dx {
                    f[(i, j)] = self.a[(i, j)];
                }
                for j in 0..du {
                    f[(i, dx + j)] = self.b[(i, j)];
                }
            }
            d.fv.slice_mut(s).copy_from_slice(&self.c);
            for i in 0..dx {
                d.dyn_covar.slice_mut(s)[i * dx + i] = self.proc_std * self.proc_std;
            }
        }
        d
    }

    /// `n` rollouts of `pol` with unit action noise: returns `x (n,T,dX)`, `u (n,T,dU)`.
    pub fn rollout(
        &self,
        pol: &LinGaussPolicy,
        n: usize,
        rng: &mut impl Rng,
    ) -> (Vec<f64>, Vec<f64>) {
        let (t_len, dx, du) = (pol.t, self.dx, self.du);
        let mut xs = vec![0.0; n * t_len * dx];
        let mut us = vec![0.0; n * t_len * du];
        let mut noise = vec![0.0; du];
        let mut x = vec![0.0; dx];
        let mut u = vec![0.0; du];
        for s in 0..n {
            for i in 0..dx {
                x[i] = self.x0[i] + self.x0_std * randn(rng);
            }
            for t in 0..t_len {
                noise.iter_mut().for_each(|e| *e = randn(rng));
                pol.act(t, &x, &noise, &mut u);
                xs[(s * t_len + t) * dx..(s * t_len + t + 1) * dx].copy_from_slice(&x);
                us[(s * t_len + t) * du..(s * t_len + t + 1) * du].copy_from_slice(&u);
                let mut xn = vec![0.0; dx];
                for i in 0..dx {
                    let mut acc = self.c[i] + self.proc_std * randn(rng);
                    for j in 0..dx {
                        acc += self.a[(i, j)] * x[j];
                    }
                    for j in 0..du {
                        acc += self.b[(i, j)] * u[j];
                    }
                    xn[i] = acc;
                }
                x.copy_from_slice(&xn);
            }
        }
        (xs, us)
    }
}

/// Quadratic tracking cost `½ Σ wx_i (x_i − tgt_i)² + ½ Σ wu_j u_j²` (last step × `final_mult`)
/// as GPS's absolute cost model in `info.cc/cv/cm`.
pub fn quadratic_cost(info: &mut TrajInfo, tgt: &[f64], wx: &[f64], wu: &[f64], final_mult: f64) {
    let (t_len, dx, du) = (info.dynamics.t, info.dynamics.dx, info.dynamics.du);
    let d = dx + du;
    info.cm.fill(0.0);
    info.cv.fill(0.0);
    for t in 0..t_len {
        let w = if t == t_len - 1 { final_mult } else { 1.0 };
        let mut cc = 0.0;
        for i in 0..dx {
            info.cm.slice_mut(t)[i * d + i] = w * wx[i];
            info.cv.slice_mut(t)[i] = -w * wx[i] * tgt[i];
            cc += 0.5 * w * wx[i] * tgt[i] * tgt[i];
        }
        for j in 0..du {
            info.cm.slice_mut(t)[(dx + j) * d + dx + j] = w * wu[j];
        }
        info.cc[t] = cc;
    }
}

/// A random arm-sized problem: plant, initial controller (PD-like, holding x0 with variance
/// `init_var`), quadratic cost with random target. Returns `(plant, controller, info)` where
/// `info` holds the true dynamics, x0 and the cost.
pub fn random_problem(
    rng: &mut impl Rng,
    t: usize,
    dx: usize,
    du: usize,
) -> (LinearSystem, LinGaussPolicy, TrajInfo) {
    let sys = LinearSystem::random_stable(rng, dx, du);
    let mut info = TrajInfo::zeros(t, dx, du);
    info.dynamics = sys.dynamics(t);
    info.x0mu = sys.x0.clone();
    for i in 0..dx {
        info.x0sigma[(i, i)] = sys.x0_std * sys.x0_std;
    }
    let tgt: Vec<f64> = (0..dx).map(|_| randn(rng)).collect();
    let wx: Vec<f64> = (0..dx).map(|_| 2.0 + 4.0 * rng.random::<f64>()).collect();
    let wu = vec![0.01; du];
    quadratic_cost(&mut info, &tgt, &wx, &wu, 10.0);
    let mut pol = LinGaussPolicy::zeros(t, dx, du);
    let init_var = 0.1;
    for s in 0..t {
        for i in 0..du {
            for j in 0..dx {
                pol.gain.slice_mut(s)[i * dx + j] = 0.05 * randn(rng);
            }
            pol.pol_covar.slice_mut(s)[i * du + i] = init_var;
            pol.chol_pol_covar.slice_mut(s)[i * du + i] = init_var.sqrt();
            pol.inv_pol_covar.slice_mut(s)[i * du + i] = 1.0 / init_var;
        }
    }
    (sys, pol, info)
}
