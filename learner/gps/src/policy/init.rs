//! Initial linear-Gaussian controllers (GPS python/gps/algorithm/policy/lin_gauss_init.py:
//! `init_lqr`, `init_pd`; `guess_dynamics` from dynamics/dynamics_utils.py).
//!
//! Both assume GPS's state packing: joint positions in `x[0..dU]`, joint velocities in
//! `x[dU..2dU]`, anything else after.

use faer::{Accum, Mat};

use crate::error::GpsError;
use crate::linalg::{gemm, llt_lower, solve_lower, solve_upper, symmetrize, Scratch};
use crate::policy::lin_gauss::LinGaussPolicy;

/// GPS `INIT_LG_LQR` hyperparameters (defaults from policy/config.py).
#[derive(Clone, Debug)]
pub struct InitLqrConfig {
    /// Action variance scale; the quadratic cost is divided by it (GPS `init_var`, default 1.0).
    pub init_var: f64,
    /// Position stiffness (default 1.0).
    pub stiffness: f64,
    /// Velocity stiffness as a multiple of `stiffness` (default 0.5).
    pub stiffness_vel: f64,
    /// Cost multiplier at the last step (default 1.0).
    pub final_weight: f64,
    /// Per-joint gains of the guessed dynamics (empty = ones, GPS default).
    pub init_gains: Vec<f64>,
    /// Per-joint accelerations of the guessed dynamics (empty = zeros, GPS default).
    pub init_acc: Vec<f64>,
    /// Time step of the guessed dynamics, s.
    pub dt: f64,
}

impl Default for InitLqrConfig {
    fn default() -> Self {
        // GPS policy/config.py INIT_LG_LQR; dt has no GPS default (agent-specific): 0.1 s is
        // this project's control period (docs/design.md §2.5).
        Self {
            init_var: 1.0,
            stiffness: 1.0,
            stiffness_vel: 0.5,
            final_weight: 1.0,
            init_gains: Vec::new(),
            init_acc: Vec::new(),
            dt: 0.1,
        }
    }
}

/// GPS `guess_dynamics`: position–velocity double integrator. Returns `Fd (dX, dX+dU)`
/// row-major and `fc (dX)`.
pub fn guess_dynamics(
    gains: &[f64],
    acc: &[f64],
    dx: usize,
    du: usize,
    dt: f64,
) -> (Mat<f64>, Vec<f64>) {
    let mut fd = Mat::<f64>::zeros(dx, dx + du);
    for i in 0..du {
        fd[(i, i)] = 1.0;
        fd[(i, du + i)] = dt;
        fd[(i, dx + i)] = dt * dt * gains[i];
        fd[(du + i, du + i)] = 1.0;
        fd[(du + i, dx + i)] = dt * gains[i];
    }
    let mut fc = vec![0.0; dx];
    for i in 0..du {
        fc[i] = acc[i] * dt * dt;
        fc[du + i] = acc[i] * dt;
    }
    (fd, fc)
}

/// GPS `init_lqr`: LQR on the guessed dynamics with a stiffness cost that holds `x0`.
/// `x0` has length dX (m, rad, or whatever the state units are).
pub fn init_lqr(
    cfg: &InitLqrConfig,
    x0: &[f64],
    t_len: usize,
    dx: usize,
    du: usize,
) -> Result<LinGaussPolicy, GpsError> {
    if dx < 2 * du {
        return Err(GpsError::Shape(format!(
            "init_lqr assumes positions and velocities of dU={du} joints in the state, but dX={dx} < 2 dU"
        )));
    }
    let d = dx + du;
    let gains = if cfg.init_gains.is_empty() {
        vec![1.0; du]
    } else {
        cfg.init_gains.clone()
    };
    let acc = if cfg.init_acc.is_empty() {
        vec![0.0; du]
    } else {
        cfg.init_acc.clone()
    };
    let (fd, fc) = guess_dynamics(&gains, &acc, dx, du, cfg.dt);

    let mut ltt = Mat::<f64>::zeros(d, d);
    for i in 0..du {
        ltt[(i, i)] = cfg.stiffness;
        ltt[(du + i, du + i)] = cfg.stiffness * cfg.stiffness_vel;
        ltt[(dx + i, dx + i)] = 1.0;
    }
    for i in 0..d {
        ltt[(i, i)] /= cfg.init_var;
    }
    // lt = -Ltt [x0; 0]
    let mut lt = Mat::<f64>::zeros(d, 1);
    for i in 0..d {
        let mut s = 0.0;
        for j in 0..dx {
            s += ltt[(i, j)] * x0[j];
        }
        lt[(i, 0)] = -s;
    }

    let mut pol = LinGaussPolicy::zeros(t_len, dx, du);
    let mut vxx = Mat::<f64>::zeros(dx, dx);
    let mut vx = Mat::<f64>::zeros(dx, 1);
    let mut scratch = Scratch::for_llt(du);
    let mut tmp = Mat::<f64>::zeros(dx, d);
    let mut tmpv = Mat::<f64>::zeros(dx, 1);
    let fcm = Mat::<f64>::from_fn(dx, 1, |i, _| fc[i]);
    for t in (0..t_len).rev() {
        let w = if t == t_len - 1 {
            cfg.final_weight
        } else {
            1.0
        };
        let mut qtt = Mat::<f64>::from_fn(d, d, |i, j| w * ltt[(i, j)]);
        let mut qt = Mat::<f64>::from_fn(d, 1, |i, _| w * lt[(i, 0)]);
        gemm(tmp.as_mut(), Accum::Replace, vxx.as_ref(), fd.as_ref(), 1.0);
        gemm(qtt.as_mut(), Accum::Add, fd.transpose(), tmp.as_ref(), 1.0);
        tmpv.copy_from(&vx);
        gemm(tmpv.as_mut(), Accum::Add, vxx.as_ref(), fcm.as_ref(), 1.0);
        gemm(qt.as_mut(), Accum::Add, fd.transpose(), tmpv.as_ref(), 1.0);

        let quu = qtt.submatrix(dx, dx, du, du).to_owned();
        let mut l = quu.clone();
        if !llt_lower(l.as_mut(), &mut scratch) {
            return Err(GpsError::NotPositiveDefinite {
                what: "init_lqr Q_uu",
                t,
            });
        }
        pol.inv_pol_covar.mat_mut(t).copy_from(&quu);
        let mut ps = Mat::<f64>::identity(du, du);
        solve_lower(l.as_ref(), ps.as_mut());
        solve_upper(l.transpose(), ps.as_mut());
        pol.pol_covar.mat_mut(t).copy_from(&ps);
        let mut cp = ps.clone();
        if !llt_lower(cp.as_mut(), &mut scratch) {
            return Err(GpsError::NotPositiveDefinite {
                what: "init_lqr pol_covar",
                t,
            });
        }
        pol.chol_pol_covar.mat_mut(t).copy_from(cp.transpose());

        let mut kg = qtt.submatrix(dx, 0, du, dx).to_owned();
        solve_lower(l.as_ref(), kg.as_mut());
        solve_upper(l.transpose(), kg.as_mut());
        let mut kk = qt.submatrix(dx, 0, du, 1).to_owned();
        solve_lower(l.as_ref(), kk.as_mut());
        solve_upper(l.transpose(), kk.as_mut());
        kg *= faer::Scale(-1.0);
        kk *= faer::Scale(-1.0);
        pol.gain.mat_mut(t).copy_from(&kg);
        pol.k.mat_mut(t).copy_from(&kk);

        // Vxx = Qxx + Qxu K ; vx = qx + Qxu k
        vxx.copy_from(qtt.submatrix(0, 0, dx, dx));
        gemm(
            vxx.as_mut(),
            Accum::Add,
            qtt.submatrix(0, dx, dx, du),
            kg.as_ref(),
            1.0,
        );
        vx.copy_from(qt.submatrix(0, 0, dx, 1));
        gemm(
            vx.as_mut(),
            Accum::Add,
            qtt.submatrix(0, dx, dx, du),
            kk.as_ref(),
            1.0,
        );
        symmetrize(vxx.as_mut());
    }
    Ok(pol)
}

/// GPS `INIT_LG_PD` hyperparameters (defaults from policy/config.py).
#[derive(Clone, Debug)]
pub struct InitPdConfig {
    /// Action variance (default 10.0).
    pub init_var: f64,
    /// Position gain (default 10.0).
    pub pos_gains: f64,
    /// Velocity gain as a multiple of `pos_gains` (default 0.01).
    pub vel_gains_mult: f64,
    /// Number of joint positions in the state (GPS `dQ`).
    pub dq: usize,
}

impl Default for InitPdConfig {
    fn default() -> Self {
        // GPS policy/config.py INIT_LG_PD; dQ = 3 actuated joints in this project (docs/design.md §2.1).
        Self {
            init_var: 10.0,
            pos_gains: 10.0,
            vel_gains_mult: 0.01,
            dq: 3,
        }
    }
}

/// GPS `init_pd`: `u = -pos_gains (x_pos + vel_gains_mult x_vel) + k`, `k` chosen so that
/// `u = 0` at `x0`. Only GPS's `dU >= dQ` branch is defined (the other branch builds a ragged
/// numpy array and fails in the reference code), so `dU < dQ` is an error here.
pub fn init_pd(
    cfg: &InitPdConfig,
    x0: &[f64],
    t_len: usize,
    dx: usize,
    du: usize,
) -> Result<LinGaussPolicy, GpsError> {
    if du < cfg.dq {
        return Err(GpsError::Shape(format!(
            "init_pd with dU={du} < dQ={}: GPS's branch for this case does not run; use dU >= dQ",
            cfg.dq
        )));
    }
    if dx < 2 * du {
        return Err(GpsError::Shape(format!(
            "init_pd needs dX >= 2 dU, got dX={dx}, dU={du}"
        )));
    }
    let mut pol = LinGaussPolicy::zeros(t_len, dx, du);
    let mut k0 = vec![0.0; dx * du];
    for i in 0..du {
        k0[i * dx + i] = -cfg.pos_gains * 1.0;
        k0[i * dx + du + i] = -cfg.pos_gains * cfg.vel_gains_mult;
    }
    let mut kff = vec![0.0; du];
    for i in 0..du {
        let mut s = 0.0;
        for j in 0..dx {
            s += k0[i * dx + j] * x0[j];
        }
        kff[i] = -s;
    }
    let sd = cfg.init_var.sqrt();
    for t in 0..t_len {
        pol.gain.slice_mut(t).copy_from_slice(&k0);
        pol.k.slice_mut(t).copy_from_slice(&kff);
        for i in 0..du {
            pol.pol_covar.slice_mut(t)[i * du + i] = cfg.init_var;
            pol.chol_pol_covar.slice_mut(t)[i * du + i] = sd;
            pol.inv_pol_covar.slice_mut(t)[i * du + i] = 1.0 / cfg.init_var;
        }
    }
    Ok(pol)
}
