//! Bayesian linear regression of the dynamics with a normal-inverse-Wishart prior per time
//! step (GPS python/gps/algorithm/dynamics/dynamics_lr_prior.py `DynamicsLRPrior.fit` and
//! algorithm_utils.py `gauss_fit_joint_prior`).

use faer::prelude::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef};

use crate::dynamics::prior_gmm::{DynamicsPriorGmm, NiwPrior};
use crate::dynamics::Dynamics;
use crate::error::GpsError;
use crate::linalg::{gemm, LuSolver};

/// GPS `DynamicsLRPrior` hyperparameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LrPriorConfig {
    /// Added to **every** entry of the `(dX+dU) x (dX+dU)` block of the joint covariance
    /// before conditioning (GPS `sig_reg[it, it] = regularization`; default 1e-6 as in the GPS
    /// examples and gps-vectors).
    pub regularization: f64,
}

impl LrPriorConfig {
    /// Checks the setting's range.
    pub fn validate(&self) -> Result<(), crate::GpsError> {
        crate::error::check(
            self.regularization.is_finite() && self.regularization >= 0.0,
            "fit.regularization",
            self.regularization,
            "finite and >= 0",
        )
    }
}

impl Default for LrPriorConfig {
    fn default() -> Self {
        Self {
            regularization: 1e-6,
        }
    }
}

/// Preallocated scratch for a joint Gaussian fit of `D = dxu + dx` dimensional points.
pub struct JointFitWorkspace {
    dxu: usize,
    dx: usize,
    mun: Vec<f64>,
    diff: Mat<f64>,
    empsig: Mat<f64>,
    sigma: Mat<f64>,
    sol: Mat<f64>,
    tmp: Mat<f64>,
    lu: LuSolver,
}

impl JointFitWorkspace {
    /// Workspace for `n` points of dimension `dxu + dx`.
    pub fn new(n: usize, dxu: usize, dx: usize) -> Self {
        let d = dxu + dx;
        Self {
            dxu,
            dx,
            mun: vec![0.0; d],
            diff: Mat::zeros(n, d),
            empsig: Mat::zeros(d, d),
            sigma: Mat::zeros(d, d),
            sol: Mat::zeros(dxu, dx),
            tmp: Mat::zeros(dx, dxu),
            lu: LuSolver::new(dxu, dx),
        }
    }
}

/// Conditions the joint Gaussian `N(mu, sigma)` over `[y_in (dxu); y_out (dx)]` on `y_in`
/// (regularisation already in `sigma`): `fd = Σ_oi Σ_ii⁻¹`, `fc = μ_o − fd μ_i`,
/// `dynsig = sym(Σ_oo − fd Σ_ii fdᵀ)`.
fn condition(
    ws: &mut JointFitWorkspace,
    t: usize,
    mut fd: MatMut<'_, f64>,
    fc: &mut [f64],
    mut dynsig: MatMut<'_, f64>,
) -> Result<(), GpsError> {
    let (dxu, dx) = (ws.dxu, ws.dx);
    // np.linalg.solve (LU with partial pivoting): the block is only PSD + regularisation in
    // DynamicsLR with N <= dX+dU, where a Cholesky would refuse what numpy still solves.
    ws.sol
        .copy_from(ws.sigma.as_ref().submatrix(0, dxu, dxu, dx));
    if !ws
        .lu
        .solve(ws.sigma.as_ref().submatrix(0, 0, dxu, dxu), ws.sol.as_mut())
    {
        return Err(GpsError::NotPositiveDefinite {
            what: "regression covariance Σ_[xu][xu] (singular)",
            t,
        });
    }
    fd.copy_from(ws.sol.transpose());
    for a in 0..dx {
        let mut s = 0.0;
        for b in 0..dxu {
            s += fd[(a, b)] * ws.mun[b];
        }
        fc[a] = ws.mun[dxu + a] - s;
    }
    gemm(
        ws.tmp.as_mut(),
        Accum::Replace,
        fd.rb(),
        ws.sigma.as_ref().submatrix(0, 0, dxu, dxu),
        1.0,
    );
    dynsig.copy_from(ws.sigma.as_ref().submatrix(dxu, dxu, dx, dx));
    gemm(
        dynsig.rb_mut(),
        Accum::Add,
        ws.tmp.as_ref(),
        fd.rb().transpose(),
        -1.0,
    );
    crate::linalg::symmetrize(dynsig);
    Ok(())
}

/// GPS `gauss_fit_joint_prior` with uniform weights `1/N`: MAP joint Gaussian of the rows of
/// `pts (N x (dxu+dx))` under the NIW prior, then conditioned on the first `dxu` coordinates.
/// Writes `fd (dx, dxu)`, `fc (dx)`, `dynsig (dx, dx)`.
pub fn gauss_fit_joint_prior(
    pts: MatRef<'_, f64>,
    prior: &NiwPrior,
    regularization: f64,
    ws: &mut JointFitWorkspace,
    t: usize,
    fd: MatMut<'_, f64>,
    fc: &mut [f64],
    dynsig: MatMut<'_, f64>,
) -> Result<(), GpsError> {
    let (n, d) = (pts.nrows(), pts.ncols());
    let dxu = ws.dxu;
    let w = 1.0 / n as f64;
    for a in 0..d {
        let mut s = 0.0;
        for p in 0..n {
            s += pts[(p, a)] * w;
        }
        ws.mun[a] = s;
    }
    if ws.diff.nrows() != n {
        ws.diff = Mat::zeros(n, d);
    }
    for a in 0..d {
        for p in 0..n {
            ws.diff[(p, a)] = pts[(p, a)] - ws.mun[a];
        }
    }
    // empsig = diffᵀ diag(w) diff, symmetrised
    gemm(
        ws.empsig.as_mut(),
        Accum::Replace,
        ws.diff.transpose(),
        ws.diff.as_ref(),
        w,
    );
    crate::linalg::symmetrize(ws.empsig.as_mut());
    let nf = n as f64;
    let (m, n0) = (prior.m, prior.n0);
    let c = (nf * m) / (nf + m);
    // Column by column (faer's storage order); every entry its own expression.
    for b in 0..d {
        let db = ws.mun[b] - prior.mu0[b];
        for a in 0..d {
            let da = ws.mun[a] - prior.mu0[a];
            ws.sigma[(a, b)] =
                (nf * ws.empsig[(a, b)] + prior.phi[(a, b)] + c * (da * db)) / (nf + n0);
        }
    }
    crate::linalg::symmetrize(ws.sigma.as_mut());
    for a in 0..dxu {
        for b in 0..dxu {
            ws.sigma[(a, b)] += regularization;
        }
    }
    condition(ws, t, fd, fc, dynsig)
}

/// Preallocated state of a [`fit`] for `N` samples of length `T`.
pub struct FitWorkspace {
    ys: Mat<f64>,
    prior: NiwPrior,
    joint: JointFitWorkspace,
}

impl FitWorkspace {
    /// Workspace for `n` samples with `dx` states and `du` actions.
    pub fn new(n: usize, dx: usize, du: usize) -> Self {
        Self {
            ys: Mat::zeros(n, 2 * dx + du),
            prior: NiwPrior::zeros(2 * dx + du),
            joint: JointFitWorkspace::new(n, dx + du, dx),
        }
    }
}

/// Fills `ys (N x (2dX+dU))` with the transitions `[x_t, u_t, x_{t+1}]` of all samples.
pub fn transitions_at(
    x: &[f64],
    u: &[f64],
    n: usize,
    t_len: usize,
    dx: usize,
    du: usize,
    t: usize,
    mut ys: MatMut<'_, f64>,
) {
    for s in 0..n {
        let xs = &x[(s * t_len + t) * dx..(s * t_len + t + 1) * dx];
        let xn = &x[(s * t_len + t + 1) * dx..(s * t_len + t + 2) * dx];
        let us = &u[(s * t_len + t) * du..(s * t_len + t + 1) * du];
        for a in 0..dx {
            ys[(s, a)] = xs[a];
            ys[(s, dx + du + a)] = xn[a];
        }
        for a in 0..du {
            ys[(s, dx + a)] = us[a];
        }
    }
}

/// GPS `DynamicsLRPrior.fit`: for `t < T−1`, prior from `prior.eval` on the samples'
/// transitions, then [`gauss_fit_joint_prior`]. `x (N,T,dX)`, `u (N,T,dU)` row-major; writes
/// every time step of `out` (index `T−1` zeroed).
pub fn fit(
    x: &[f64],
    u: &[f64],
    n: usize,
    prior: &mut DynamicsPriorGmm,
    cfg: &LrPriorConfig,
    ws: &mut FitWorkspace,
    out: &mut Dynamics,
) -> Result<(), GpsError> {
    fit_with(x, u, n, cfg, ws, out, |ys, p| prior.eval(ys, p))
}

/// [`fit`] with any prior evaluator `eval(Ys_t, out)` (e.g. a recorded prior per step).
pub fn fit_with(
    x: &[f64],
    u: &[f64],
    n: usize,
    cfg: &LrPriorConfig,
    ws: &mut FitWorkspace,
    out: &mut Dynamics,
    mut eval: impl FnMut(MatRef<'_, f64>, &mut NiwPrior) -> Result<(), GpsError>,
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
    if ws.ys.nrows() != n {
        *ws = FitWorkspace::new(n, dx, du);
    }
    out.fm.fill(0.0);
    out.fv.fill(0.0);
    out.dyn_covar.fill(0.0);
    for t in 0..t_len - 1 {
        transitions_at(x, u, n, t_len, dx, du, t, ws.ys.as_mut());
        eval(ws.ys.as_ref(), &mut ws.prior)?;
        gauss_fit_joint_prior(
            ws.ys.as_ref(),
            &ws.prior,
            cfg.regularization,
            &mut ws.joint,
            t,
            out.fm.mat_mut(t),
            out.fv.slice_mut(t),
            out.dyn_covar.mat_mut(t),
        )?;
    }
    Ok(())
}

/// No-prior conditioning used by [`crate::dynamics::lr`]: `sigma` and `mun` given.
pub(crate) fn condition_plain(
    mun: &[f64],
    sigma: MatRef<'_, f64>,
    ws: &mut JointFitWorkspace,
    t: usize,
    fd: MatMut<'_, f64>,
    fc: &mut [f64],
    dynsig: MatMut<'_, f64>,
) -> Result<(), GpsError> {
    ws.mun.copy_from_slice(mun);
    ws.sigma.copy_from(sigma);
    condition(ws, t, fd, fc, dynsig)
}
