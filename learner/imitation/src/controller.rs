//! The linear-Gaussian controller (GPS absolute form u = K x + k, `gps::policy::lin_gauss`)
//! as the gain table the real-time loop executes (a = K_t (s − ŝ_t) + k_t + â_t + L_t ε with
//! ŝ = 0, â = 0; docs/design.md §1), and the initial controller both LQR learners start from.

use gps::policy::lin_gauss::LinGaussPolicy;
use ur5_shared::config::TaskConfig;
use ur5_shared::{GainTable, StateLayout, MAX_DU};

use crate::ImitationError;

/// The initial controller: goal angles = start pose, Σ = init_var · I.
pub fn init_hold(task: &TaskConfig, init_var: f64) -> LinGaussPolicy {
    let layout = task.layout();
    let (dx, du) = (layout.dx(), layout.du());
    let mut pol = LinGaussPolicy::zeros(task.horizon, dx, du);
    let sd = init_var.sqrt();
    for t in 0..task.horizon {
        pol.k.slice_mut(t).copy_from_slice(&task.start_q);
        for j in 0..du {
            pol.pol_covar.slice_mut(t)[j * du + j] = init_var;
            pol.chol_pol_covar.slice_mut(t)[j * du + j] = sd;
            pol.inv_pol_covar.slice_mut(t)[j * du + j] = 1.0 / init_var;
        }
    }
    pol
}

/// The controller as a gain table for `ur5_shared::controller_action`: ŝ = 0, â = 0, so
/// k = GPS's k and L = Rᵀ (GPS keeps the upper factor R, the table the lower factor). The
/// table has the controller's dimensions, which must be a task's
/// (`ur5_shared::StateLayout::from_dims`).
pub fn to_gain_table(pol: &LinGaussPolicy, version: u64) -> Box<GainTable> {
    let (dx, du) = (pol.dx, pol.du);
    let layout = StateLayout::from_dims(dx, du).expect("a controller of a task's dimensions");
    let mut table = GainTable::new_boxed_for(&layout);
    table
        .set_horizon(pol.t)
        .expect("horizon within MAX_HORIZON");
    table.set_version(version);
    for t in 0..pol.t {
        let mut step = table.step_mut(t);
        let kg = pol.gain.slice(t);
        let r = pol.chol_pol_covar.slice(t);
        step.k_mat.copy_from_slice(&kg[..du * dx]);
        for i in 0..du {
            step.k_vec[i] = pol.k.slice(t)[i];
            for j in 0..=i {
                step.set_l(i, j, r[j * du + i]);
            }
        }
    }
    table.seal();
    table
}

/// The controller of a gain table written by [`to_gain_table`] (ŝ = 0, â = 0): K and k as
/// stored, GPS's upper factor R = Lᵀ, Σ = L Lᵀ and Σ⁻¹ = L⁻ᵀ L⁻¹ (recomputed, so Σ and Σ⁻¹
/// may differ from the original controller's in the last bits; K, k and L, and hence the
/// table, round-trip exactly). The controller has the table's dimensions.
pub fn policy_from_gain_table(table: &GainTable) -> Result<LinGaussPolicy, ImitationError> {
    let t_len = table.horizon();
    let (dx, du) = table.dims();
    let mut pol = LinGaussPolicy::zeros(t_len, dx, du);
    for t in 0..t_len {
        let step = table.step(t);
        if step.s_hat.iter().chain(step.a_hat).any(|v| *v != 0.0) {
            return Err(ImitationError::Table(format!(
                "gain table step {t} has a non-zero ŝ or â: not a table written by the learner"
            )));
        }
        let l = |i, j| step.l(i, j);
        // L⁻¹ by forward substitution (L is lower triangular with a positive diagonal).
        let mut li = [[0.0; MAX_DU]; MAX_DU];
        for c in 0..du {
            for r in c..du {
                let mut v = if r == c { 1.0 } else { 0.0 };
                for k in c..r {
                    v -= l(r, k) * li[k][c];
                }
                li[r][c] = v / l(r, r);
            }
        }
        pol.gain.slice_mut(t)[..du * dx].copy_from_slice(step.k_mat);
        pol.k.slice_mut(t).copy_from_slice(step.k_vec);
        for i in 0..du {
            for j in 0..du {
                pol.chol_pol_covar.slice_mut(t)[j * du + i] = if j <= i { l(i, j) } else { 0.0 };
                pol.pol_covar.slice_mut(t)[i * du + j] = (0..du).map(|k| l(i, k) * l(j, k)).sum();
                pol.inv_pol_covar.slice_mut(t)[i * du + j] =
                    (0..du).map(|k| li[k][i] * li[k][j]).sum();
            }
        }
    }
    Ok(pol)
}
