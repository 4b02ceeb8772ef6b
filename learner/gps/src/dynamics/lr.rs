//! Plain least-squares dynamics without a prior (GPS
//! python/gps/algorithm/dynamics/dynamics_lr.py, `DynamicsLR.fit`).

use faer::{Accum, Mat};

use crate::dynamics::lr_prior::{condition_plain, transitions_at, JointFitWorkspace};
use crate::dynamics::Dynamics;
use crate::error::GpsError;
use crate::linalg::gemm;

/// GPS `DynamicsLR.fit`: empirical joint covariance of `[x_t, u_t, x_{t+1}]` over the `n`
/// samples (divided by N), symmetrised, `regularization` added to every entry of the
/// `(dX+dU)` block, then conditioned. `x (N,T,dX)`, `u (N,T,dU)` row-major.
pub fn fit(
    x: &[f64],
    u: &[f64],
    n: usize,
    regularization: f64,
    out: &mut Dynamics,
) -> Result<(), GpsError> {
    let (t_len, dx, du) = (out.t, out.dx, out.du);
    if n < 2 {
        return Err(GpsError::TooFewSamples(n));
    }
    if x.len() != n * t_len * dx || u.len() != n * t_len * du {
        return Err(GpsError::Shape(format!(
            "fit expects X ({n},{t_len},{dx}) and U ({n},{t_len},{du})"
        )));
    }
    let d = 2 * dx + du;
    let mut ys = Mat::<f64>::zeros(n, d);
    let mut diff = Mat::<f64>::zeros(n, d);
    let mut sigma = Mat::<f64>::zeros(d, d);
    let mut mean = vec![0.0; d];
    let mut ws = JointFitWorkspace::new(n, dx + du, dx);
    out.fm.fill(0.0);
    out.fv.fill(0.0);
    out.dyn_covar.fill(0.0);
    for t in 0..t_len - 1 {
        transitions_at(x, u, n, t_len, dx, du, t, ys.as_mut());
        for a in 0..d {
            let mut s = 0.0;
            for p in 0..n {
                s += ys[(p, a)];
            }
            mean[a] = s / n as f64;
            for p in 0..n {
                diff[(p, a)] = ys[(p, a)] - mean[a];
            }
        }
        gemm(
            sigma.as_mut(),
            Accum::Replace,
            diff.transpose(),
            diff.as_ref(),
            1.0,
        );
        for a in 0..d {
            for b in 0..d {
                sigma[(a, b)] /= n as f64;
            }
        }
        crate::linalg::symmetrize(sigma.as_mut());
        for a in 0..dx + du {
            for b in 0..dx + du {
                sigma[(a, b)] += regularization;
            }
        }
        condition_plain(
            &mean,
            sigma.as_ref(),
            &mut ws,
            t,
            out.fm.mat_mut(t),
            out.fv.slice_mut(t),
            out.dyn_covar.mat_mut(t),
        )?;
    }
    Ok(())
}
