//! Dynamics estimation: per-time-step linear-Gaussian models fitted by (Bayesian) linear
//! regression, with a GMM prior over transitions (GPS python/gps/algorithm/dynamics/).

pub mod em_kernels;
pub mod gmm;
pub mod lr;
pub mod lr_prior;
pub mod prior_gmm;

use crate::linalg::MatSeq;

/// Fitted time-varying linear-Gaussian dynamics (GPS `Dynamics.Fm/fv/dyn_covar`):
/// `x_{t+1} = Fm[t] [x_t; u_t] + fv[t] + N(0, dyn_covar[t])`, index `T−1` all zeros (never
/// fitted). Shapes `Fm (T,dX,dX+dU)`, `fv (T,dX,1)`, `dyn_covar (T,dX,dX)`; units are those of
/// the state and action.
#[derive(Clone, Debug, PartialEq)]
pub struct Dynamics {
    pub t: usize,
    pub dx: usize,
    pub du: usize,
    pub fm: MatSeq,
    pub fv: MatSeq,
    pub dyn_covar: MatSeq,
}

impl Dynamics {
    /// All-zero dynamics of the given size.
    pub fn zeros(t: usize, dx: usize, du: usize) -> Self {
        Self {
            t,
            dx,
            du,
            fm: MatSeq::zeros(t, dx, dx + du),
            fv: MatSeq::zeros(t, dx, 1),
            dyn_covar: MatSeq::zeros(t, dx, dx),
        }
    }
}
