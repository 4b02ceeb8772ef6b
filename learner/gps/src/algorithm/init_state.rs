//! Initial-state distribution (GPS `Algorithm._update_dynamics`, the x0 part).

use faer::Mat;

use crate::dynamics::prior_gmm::NiwPrior;

/// GPS `_update_dynamics` x0 fit from the current samples' first states `x (N,T,dX)`:
/// `x0mu = mean x_0`, `x0sigma = diag(max(var x_0, initial_state_var))`, plus, with a prior
/// `(μ0, Φ, m, n0)` from `DynamicsPriorGMM.initial_state`,
/// `Φ + (N m / (N + m)) (x0mu − μ0)(x0mu − μ0)ᵀ / (N + n0)` (GPS's grouping: Φ is not divided
/// by `N + n0`). Returns `(x0mu (dX), x0sigma (dX x dX))`.
pub fn fit_x0(
    x: &[f64],
    n: usize,
    t_len: usize,
    dx: usize,
    initial_state_var: f64,
    prior: Option<&NiwPrior>,
) -> (Vec<f64>, Mat<f64>) {
    let mut mu = vec![0.0; dx];
    for s in 0..n {
        for a in 0..dx {
            mu[a] += x[s * t_len * dx + a];
        }
    }
    mu.iter_mut().for_each(|m| *m /= n as f64);
    let mut sig = Mat::<f64>::zeros(dx, dx);
    for a in 0..dx {
        let mut v = 0.0;
        for s in 0..n {
            let d = x[s * t_len * dx + a] - mu[a];
            v += d * d;
        }
        sig[(a, a)] = (v / n as f64).max(initial_state_var);
    }
    if let Some(p) = prior {
        let nf = n as f64;
        let c = (nf * p.m) / (nf + p.m);
        for a in 0..dx {
            for b in 0..dx {
                let o = (mu[a] - p.mu0[a]) * (mu[b] - p.mu0[b]);
                sig[(a, b)] += p.phi[(a, b)] + c * o / (nf + p.n0);
            }
        }
    }
    (mu, sig)
}
