//! KL-bounded LQR step (GPS python/gps/algorithm/traj_opt/traj_opt_lqr_python.py,
//! `TrajOptLQRPython`, with `AlgorithmTrajOpt.compute_costs` and traj_opt_utils.py's KL
//! estimates).
//!
//! Minimises `E[cost] ` subject to `KL(p_new ‖ p_prev) ≤ ε` through the dual variable η: the
//! backward pass solves LQR on the augmented cost `(C + η · (−log p_prev)) / (η + ν)`
//! (ν = `max_ent_traj`), raising η on a non-PD `Q_uu` (η = η0 + δ, δ doubling from `del0`),
//! and the η search brackets η geometrically between `min_eta` and `max_eta` until the total KL
//! is within 10 % of ε (`_conv_check`). The per-time-step mode (`cons_per_step`) keeps one η per
//! step, uses the un-augmented cost with the KL term folded into the control solve, brackets
//! each η separately for up to 20 rounds, then runs Adam on η for up to 200 rounds.
//!
//! Only `update_in_bwd_pass = True` (GPS's default and the vectors' setting) is implemented.
//! Everything is in GPS's absolute coordinates (`u = K x + k`). Buffers live in
//! [`TrajOptLqr`]'s workspace, sized once for `(T, dX, dU)` and reused every call.

use faer::prelude::{Reborrow, ReborrowMut};
use faer::{Accum, Mat};

use crate::dynamics::Dynamics;
use crate::error::LearnerError;
use crate::linalg::{
    frob_dot, gemm, llt_lower, set_identity, solve_lower, solve_upper, symmetrize, MatSeq, Scratch,
};
use crate::policy::lin_gauss::LinGaussPolicy;

/// GPS `DGD_MAX_ITER`: η bracketing rounds (total-KL mode).
pub const DGD_MAX_ITER: usize = 50;
/// GPS `DGD_MAX_LS_ITER`: bracketing rounds in per-step mode.
pub const DGD_MAX_LS_ITER: usize = 20;
/// GPS `DGD_MAX_GD_ITER`: Adam rounds in per-step mode.
pub const DGD_MAX_GD_ITER: usize = 200;
/// GPS Adam constants `ALPHA, BETA1, BETA2, EPS` (traj_opt_utils.py).
pub const ADAM: (f64, f64, f64, f64) = (0.005, 0.9, 0.999, 1e-8);
/// GPS `eta_error_threshold`: give up raising η past this.
pub const ETA_ERROR_THRESHOLD: f64 = 1e16;

/// `TRAJ_OPT_LQR` hyperparameters (GPS traj_opt/config.py) plus the algorithm's
/// `max_ent_traj`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrajOptConfig {
    /// First η increment on a non-PD Q_uu (default 1e-4).
    pub del0: f64,
    /// Lower end of the η bracket (default 1e-8).
    pub min_eta: f64,
    /// Upper end of the η bracket (default 1e16).
    pub max_eta: f64,
    /// One KL constraint and one η per time step (default false).
    pub cons_per_step: bool,
    /// Measure the KL under the previous trajectory distribution (`traj_distr_kl_alt`).
    pub use_prev_distr: bool,
    /// Entropy bonus weight ν (GPS `ALG.max_ent_traj`, default 0.0).
    pub max_ent_traj: f64,
}

impl Default for TrajOptConfig {
    fn default() -> Self {
        // GPS traj_opt/config.py TRAJ_OPT_LQR and algorithm/config.py ALG['max_ent_traj'].
        Self {
            del0: 1e-4,
            min_eta: 1e-8,
            max_eta: 1e16,
            cons_per_step: false,
            use_prev_distr: false,
            max_ent_traj: 0.0,
        }
    }
}

/// GPS `TrajectoryInfo`: dynamics, initial-state distribution and the quadratic cost model
/// `cc[t] + cv[t]·y + ½ yᵀ Cm[t] y`, `y = [x; u]` in absolute coordinates.
#[derive(Clone, Debug)]
pub struct TrajInfo {
    pub dynamics: Dynamics,
    /// Mean of `x_0`, length dX.
    pub x0mu: Vec<f64>,
    /// Covariance of `x_0`, `dX x dX`.
    pub x0sigma: Mat<f64>,
    /// `(T)`.
    pub cc: Vec<f64>,
    /// `(T, dX+dU, 1)`.
    pub cv: MatSeq,
    /// `(T, dX+dU, dX+dU)`.
    pub cm: MatSeq,
}

impl TrajInfo {
    /// Copies every array from `other` (same size) without allocating.
    pub fn copy_from(&mut self, other: &TrajInfo) {
        self.dynamics.fm.copy_from(&other.dynamics.fm);
        self.dynamics.fv.copy_from(&other.dynamics.fv);
        self.dynamics.dyn_covar.copy_from(&other.dynamics.dyn_covar);
        self.x0mu.copy_from_slice(&other.x0mu);
        self.x0sigma.copy_from(&other.x0sigma);
        self.cc.copy_from_slice(&other.cc);
        self.cv.copy_from(&other.cv);
        self.cm.copy_from(&other.cm);
    }

    /// All-zero trajectory info of the given size.
    pub fn zeros(t: usize, dx: usize, du: usize) -> Self {
        let d = dx + du;
        Self {
            dynamics: Dynamics::zeros(t, dx, du),
            x0mu: vec![0.0; dx],
            x0sigma: Mat::zeros(dx, dx),
            cc: vec![0.0; t],
            cv: MatSeq::zeros(t, d, 1),
            cm: MatSeq::zeros(t, d, d),
        }
    }
}

/// One backward-pass call of the η search (GPS vectors' `dgd_trace` entry).
#[derive(Clone, Debug, PartialEq)]
pub struct DgdStep {
    pub eta_in: f64,
    /// Larger than `eta_in` iff non-PD retries happened.
    pub eta_out: f64,
    /// η of every cost evaluation (every retry).
    pub attempt_etas: Vec<f64>,
    /// Total KL of the resulting controller.
    pub kl: f64,
}

/// Result of the total-KL η search.
#[derive(Clone, Debug)]
pub struct DgdResult {
    /// η returned by GPS's `update` (the next bracket point if the search ran out).
    pub eta: f64,
    pub converged: bool,
    pub trace: Vec<DgdStep>,
}

/// Result of the per-time-step η search.
#[derive(Clone, Debug)]
pub struct DgdPerStepResult {
    pub eta: Vec<f64>,
    pub converged: bool,
    /// η (per step) handed to each backward call, `(calls, T)`.
    pub trace_eta_in: Vec<Vec<f64>>,
    /// KL per step after each backward call, `(calls, T)`.
    pub trace_kl: Vec<Vec<f64>>,
}

struct Workspace {
    t: usize,
    dx: usize,
    du: usize,
    prev_m: MatSeq,
    prev_v: MatSeq,
    // KL terms of the previous controller
    kl_m_prev: MatSeq,
    kl_v_prev: MatSeq,
    kl_c_prev: Vec<f64>,
    kl_logdet_prev: Vec<f64>,
    qtt: Mat<f64>,
    qt: Mat<f64>,
    vxx: Mat<f64>,
    vx: Mat<f64>,
    vxx_next: Mat<f64>,
    vx_next: Mat<f64>,
    tmp_xd: Mat<f64>,
    tmp_x: Mat<f64>,
    tmp_xd2: Mat<f64>,
    inv_term: Mat<f64>,
    chol: Mat<f64>,
    k_term: Mat<f64>,
    kk_term: Mat<f64>,
    pc: Mat<f64>,
    cpc: Mat<f64>,
    tmp_ux: Mat<f64>,
    tmp_ux2: Mat<f64>,
    tmp_xu: Mat<f64>,
    tmp_u: Mat<f64>,
    prc: Mat<f64>,
    m_new: Mat<f64>,
    v_new: Mat<f64>,
    tmp_d: Mat<f64>,
    tmp_xx: Mat<f64>,
    tmp_xx2: Mat<f64>,
    mu: MatSeq,
    sigma: MatSeq,
    kl: Vec<f64>,
    del: Vec<f64>,
    scratch: Scratch,
}

impl Workspace {
    fn new(t: usize, dx: usize, du: usize) -> Self {
        let d = dx + du;
        let z = Mat::<f64>::zeros;
        Self {
            t,
            dx,
            du,
            prev_m: MatSeq::zeros(t, d, d),
            prev_v: MatSeq::zeros(t, d, 1),
            kl_m_prev: MatSeq::zeros(t, d, d),
            kl_v_prev: MatSeq::zeros(t, d, 1),
            kl_c_prev: vec![0.0; t],
            kl_logdet_prev: vec![0.0; t],
            qtt: z(d, d),
            qt: z(d, 1),
            vxx: z(dx, dx),
            vx: z(dx, 1),
            vxx_next: z(dx, dx),
            vx_next: z(dx, 1),
            tmp_xd: z(dx, d),
            tmp_x: z(dx, 1),
            tmp_xd2: z(dx, d),
            inv_term: z(du, du),
            chol: z(du, du),
            k_term: z(du, 1),
            kk_term: z(du, dx),
            pc: z(du, du),
            cpc: z(du, du),
            tmp_ux: z(du, dx),
            tmp_ux2: z(du, dx),
            tmp_xu: z(dx, du),
            tmp_u: z(du, 1),
            prc: z(du, du),
            m_new: z(d, d),
            v_new: z(d, 1),
            tmp_d: z(1, d),
            tmp_xx: z(dx, dx),
            tmp_xx2: z(dx, dx),
            mu: MatSeq::zeros(t, d, 1),
            sigma: MatSeq::zeros(t, d, d),
            kl: vec![0.0; t],
            del: vec![0.0; t],
            scratch: Scratch::for_llt(du.max(1)),
        }
    }
}

/// Writes the KL quadratic form of a controller at step t (GPS traj_distr_kl):
/// `M = [[Kᵀ P K, −Kᵀ P], [−P K, P]]`, `v = [Kᵀ P k; −P k]`, `c = ½ kᵀ P k`, and
/// `logdet Σ`, with `P = Σ⁻¹` from the upper Cholesky factor. Returns `(c, logdet)`.
fn kl_terms(
    pol: &LinGaussPolicy,
    t: usize,
    prc: &mut Mat<f64>,
    tmp_xu: &mut Mat<f64>,
    tmp_u: &mut Mat<f64>,
    mut m: faer::MatMut<'_, f64>,
    mut v: faer::MatMut<'_, f64>,
) -> (f64, f64) {
    let (dx, du) = (pol.dx, pol.du);
    let r = pol.chol_pol_covar.mat(t);
    let logdet = 2.0 * (0..du).map(|i| r[(i, i)].ln()).fold(0.0, |a, b| a + b);
    set_identity(prc.as_mut());
    solve_lower(r.transpose(), prc.as_mut());
    solve_upper(r, prc.as_mut());
    let kg = pol.gain.mat(t);
    let k = pol.k.mat(t);
    // Kᵀ P
    gemm(
        tmp_xu.as_mut(),
        Accum::Replace,
        kg.transpose(),
        prc.as_ref(),
        1.0,
    );
    gemm(
        m.rb_mut().submatrix_mut(0, 0, dx, dx),
        Accum::Replace,
        tmp_xu.as_ref(),
        kg,
        1.0,
    );
    m.rb_mut()
        .submatrix_mut(0, dx, dx, du)
        .copy_from(tmp_xu.as_ref() * faer::Scale(-1.0));
    gemm(
        m.rb_mut().submatrix_mut(dx, 0, du, dx),
        Accum::Replace,
        prc.as_ref(),
        kg,
        -1.0,
    );
    m.rb_mut()
        .submatrix_mut(dx, dx, du, du)
        .copy_from(prc.as_ref());
    gemm(
        v.rb_mut().submatrix_mut(0, 0, dx, 1),
        Accum::Replace,
        tmp_xu.as_ref(),
        k,
        1.0,
    );
    gemm(tmp_u.as_mut(), Accum::Replace, prc.as_ref(), k, 1.0);
    let mut c = 0.0;
    for i in 0..du {
        v[(dx + i, 0)] = -tmp_u[(i, 0)];
        c += k[(i, 0)] * tmp_u[(i, 0)];
    }
    (0.5 * c, logdet)
}

/// GPS `TrajOptLQRPython`: configuration plus a workspace for one problem size.
pub struct TrajOptLqr {
    pub cfg: TrajOptConfig,
    ws: Workspace,
}

impl TrajOptLqr {
    /// Builds the optimiser and its workspace for horizon `t`, `dx` states, `du` actions.
    pub fn new(cfg: TrajOptConfig, t: usize, dx: usize, du: usize) -> Self {
        Self {
            cfg,
            ws: Workspace::new(t, dx, du),
        }
    }

    fn check(&self, pol: &LinGaussPolicy, info: &TrajInfo) -> Result<(), LearnerError> {
        let w = &self.ws;
        if (pol.t, pol.dx, pol.du) != (w.t, w.dx, w.du)
            || (info.dynamics.t, info.dynamics.dx, info.dynamics.du) != (w.t, w.dx, w.du)
        {
            return Err(LearnerError::Shape(format!(
                "TrajOptLqr built for (T,dX,dU)=({},{},{}), got policy ({},{},{}) and dynamics ({},{},{})",
                w.t, w.dx, w.du, pol.t, pol.dx, pol.du, info.dynamics.t, info.dynamics.dx, info.dynamics.du
            )));
        }
        Ok(())
    }

    /// Precomputes the previous controller's KL-penalty blocks (GPS `compute_costs`).
    fn prepare(&mut self, prev: &LinGaussPolicy) {
        let ws = &mut self.ws;
        let (dx, du) = (ws.dx, ws.du);
        for t in 0..ws.t {
            let kg = prev.gain.mat(t);
            let ipc = prev.inv_pol_covar.mat(t);
            let k = prev.k.mat(t);
            gemm(ws.tmp_xu.as_mut(), Accum::Replace, kg.transpose(), ipc, 1.0);
            let mut m = ws.prev_m.mat_mut(t);
            gemm(
                m.rb_mut().submatrix_mut(0, 0, dx, dx),
                Accum::Replace,
                ws.tmp_xu.as_ref(),
                kg,
                1.0,
            );
            m.rb_mut()
                .submatrix_mut(0, dx, dx, du)
                .copy_from(ws.tmp_xu.as_ref() * faer::Scale(-1.0));
            gemm(
                m.rb_mut().submatrix_mut(dx, 0, du, dx),
                Accum::Replace,
                ipc,
                kg,
                -1.0,
            );
            m.rb_mut().submatrix_mut(dx, dx, du, du).copy_from(ipc);
            let mut v = ws.prev_v.mat_mut(t);
            gemm(
                v.rb_mut().submatrix_mut(0, 0, dx, 1),
                Accum::Replace,
                ws.tmp_xu.as_ref(),
                k,
                1.0,
            );
            gemm(
                v.rb_mut().submatrix_mut(dx, 0, du, 1),
                Accum::Replace,
                ipc,
                k,
                -1.0,
            );
            let (c, ld) = kl_terms(
                prev,
                t,
                &mut ws.prc,
                &mut ws.tmp_xu,
                &mut ws.tmp_u,
                ws.kl_m_prev.mat_mut(t),
                ws.kl_v_prev.mat_mut(t),
            );
            ws.kl_c_prev[t] = c;
            ws.kl_logdet_prev[t] = ld;
        }
    }

    /// One dynamic-programming sweep at fixed η. `Err(t)` if the Q_uu-type matrix at step t
    /// is not PD (nothing at steps ≤ t written).
    fn sweep(
        &mut self,
        prev: &LinGaussPolicy,
        info: &TrajInfo,
        eta: &[f64],
        out: &mut LinGaussPolicy,
    ) -> Result<(), usize> {
        let cons = self.cfg.cons_per_step;
        let nu = self.cfg.max_ent_traj;
        let ws = &mut self.ws;
        let (t_len, dx, du) = (ws.t, ws.dx, ws.du);
        let d = dx + du;
        let dynm = &info.dynamics;
        for t in (0..t_len).rev() {
            // Cost term (GPS compute_costs; augment = !cons_per_step).
            let cm = info.cm.mat(t);
            let cv = info.cv.mat(t);
            if cons {
                ws.qtt.copy_from(cm);
                ws.qt.copy_from(cv);
            } else {
                let e = eta[0];
                let den = e + nu;
                let c = e / den;
                let pm = ws.prev_m.mat(t);
                let pv = ws.prev_v.mat(t);
                for j in 0..d {
                    for i in 0..d {
                        ws.qtt[(i, j)] = cm[(i, j)] / den + c * pm[(i, j)];
                    }
                    ws.qt[(j, 0)] = cv[(j, 0)] / den + c * pv[(j, 0)];
                }
            }
            if t < t_len - 1 {
                let fm = dynm.fm.mat(t);
                gemm(
                    ws.tmp_xd.as_mut(),
                    Accum::Replace,
                    ws.vxx_next.as_ref(),
                    fm,
                    1.0,
                );
                gemm(
                    ws.qtt.as_mut(),
                    Accum::Add,
                    fm.transpose(),
                    ws.tmp_xd.as_ref(),
                    1.0,
                );
                ws.tmp_x.copy_from(&ws.vx_next);
                gemm(
                    ws.tmp_x.as_mut(),
                    Accum::Add,
                    ws.vxx_next.as_ref(),
                    dynm.fv.mat(t),
                    1.0,
                );
                gemm(
                    ws.qt.as_mut(),
                    Accum::Add,
                    fm.transpose(),
                    ws.tmp_x.as_ref(),
                    1.0,
                );
            }
            symmetrize(ws.qtt.as_mut());

            let quu = ws.qtt.as_ref().submatrix(dx, dx, du, du);
            let qux = ws.qtt.as_ref().submatrix(dx, 0, du, dx);
            let qu = ws.qt.as_ref().submatrix(dx, 0, du, 1);
            if cons {
                let e = eta[t];
                let ipc = prev.inv_pol_covar.mat(t);
                for j in 0..du {
                    for i in 0..du {
                        ws.inv_term[(i, j)] = (1.0 / e) * quu[(i, j)] + ipc[(i, j)];
                    }
                }
                gemm(ws.tmp_u.as_mut(), Accum::Replace, ipc, prev.k.mat(t), 1.0);
                for i in 0..du {
                    ws.k_term[(i, 0)] = (1.0 / e) * qu[(i, 0)] - ws.tmp_u[(i, 0)];
                }
                gemm(
                    ws.tmp_ux.as_mut(),
                    Accum::Replace,
                    ipc,
                    prev.gain.mat(t),
                    1.0,
                );
                for j in 0..dx {
                    for i in 0..du {
                        ws.kk_term[(i, j)] = (1.0 / e) * qux[(i, j)] - ws.tmp_ux[(i, j)];
                    }
                }
            } else {
                ws.inv_term.copy_from(quu);
                ws.k_term.copy_from(qu);
                ws.kk_term.copy_from(qux);
            }
            ws.chol.copy_from(&ws.inv_term);
            if !llt_lower(ws.chol.as_mut(), &mut ws.scratch) {
                return Err(t);
            }
            let l = ws.chol.as_ref();
            out.inv_pol_covar.mat_mut(t).copy_from(&ws.inv_term);
            set_identity(ws.pc.as_mut());
            solve_lower(l, ws.pc.as_mut());
            solve_upper(l.transpose(), ws.pc.as_mut());
            out.pol_covar.mat_mut(t).copy_from(&ws.pc);
            // scipy cholesky (upper) of pol_covar; symmetric up to rounding.
            ws.cpc.copy_from(&ws.pc);
            if !llt_lower(ws.cpc.as_mut(), &mut ws.scratch) {
                return Err(t);
            }
            out.chol_pol_covar.mat_mut(t).copy_from(ws.cpc.transpose());
            solve_lower(l, ws.k_term.as_mut());
            solve_upper(l.transpose(), ws.k_term.as_mut());
            solve_lower(l, ws.kk_term.as_mut());
            solve_upper(l.transpose(), ws.kk_term.as_mut());
            {
                let mut kg = out.gain.mat_mut(t);
                let mut kf = out.k.mat_mut(t);
                for i in 0..du {
                    for j in 0..dx {
                        kg[(i, j)] = -ws.kk_term[(i, j)];
                    }
                    kf[(i, 0)] = -ws.k_term[(i, 0)];
                }
            }
            let kg = out.gain.mat(t);
            let kf = out.k.mat(t);
            let qxx = ws.qtt.as_ref().submatrix(0, 0, dx, dx);
            let qxu = ws.qtt.as_ref().submatrix(0, dx, dx, du);
            let qx = ws.qt.as_ref().submatrix(0, 0, dx, 1);
            ws.vxx.copy_from(qxx);
            ws.vx.copy_from(qx);
            if cons {
                // Vxx = Qxx + Kᵀ Quu K + 2 Qxu K ; Vx = Qx + Kᵀ Qu + Kᵀ Quu k + Qxu k
                gemm(ws.tmp_ux.as_mut(), Accum::Replace, quu, kg, 1.0);
                gemm(
                    ws.vxx.as_mut(),
                    Accum::Add,
                    kg.transpose(),
                    ws.tmp_ux.as_ref(),
                    1.0,
                );
                gemm(ws.vxx.as_mut(), Accum::Add, qxu, kg, 2.0);
                gemm(ws.vx.as_mut(), Accum::Add, kg.transpose(), qu, 1.0);
                gemm(ws.tmp_u.as_mut(), Accum::Replace, quu, kf, 1.0);
                gemm(
                    ws.vx.as_mut(),
                    Accum::Add,
                    kg.transpose(),
                    ws.tmp_u.as_ref(),
                    1.0,
                );
                gemm(ws.vx.as_mut(), Accum::Add, qxu, kf, 1.0);
            } else {
                gemm(ws.vxx.as_mut(), Accum::Add, qxu, kg, 1.0);
                gemm(ws.vx.as_mut(), Accum::Add, qxu, kf, 1.0);
            }
            symmetrize(ws.vxx.as_mut());
            std::mem::swap(&mut ws.vxx, &mut ws.vxx_next);
            std::mem::swap(&mut ws.vx, &mut ws.vx_next);
        }
        Ok(())
    }

    /// GPS `TrajOptLQRPython.backward` on prepared prev terms. `eta` has length 1 (total-KL
    /// mode) or T (per-step mode) and is raised in place on non-PD retries. Every attempted
    /// η (total-KL mode) is appended to `attempts`.
    fn backward_prepared(
        &mut self,
        prev: &LinGaussPolicy,
        info: &TrajInfo,
        eta: &mut [f64],
        out: &mut LinGaussPolicy,
        attempts: &mut Vec<f64>,
    ) -> Result<(), LearnerError> {
        out.fill_nan();
        let del0 = self.cfg.del0;
        if !self.cfg.cons_per_step {
            let eta0 = eta[0];
            let mut del = del0;
            loop {
                attempts.push(eta[0]);
                match self.sweep(prev, info, eta, out) {
                    Ok(()) => return Ok(()),
                    Err(_) => {
                        eta[0] = eta0 + del;
                        del *= 2.0;
                        if eta[0] >= ETA_ERROR_THRESHOLD {
                            return Err(self.overflow(info, eta[0]));
                        }
                    }
                }
            }
        } else {
            self.ws.del.iter_mut().for_each(|x| *x = del0);
            loop {
                match self.sweep(prev, info, eta, out) {
                    Ok(()) => return Ok(()),
                    // GPS stores `fail = t`; a failure at t = 0 is falsy and ends the loop with
                    // step 0 left as it was (NaN on the first attempt).
                    Err(0) => return Ok(()),
                    Err(t) => {
                        // eta0 aliases eta in GPS, so increments accumulate.
                        eta[t] += self.ws.del[t];
                        self.ws.del[t] *= 2.0;
                        if eta[t] >= ETA_ERROR_THRESHOLD {
                            return Err(self.overflow(info, eta[t]));
                        }
                    }
                }
            }
        }
    }

    fn overflow(&self, info: &TrajInfo, eta: f64) -> LearnerError {
        let d = &info.dynamics;
        if d.fm.data.iter().chain(d.fv.data.iter()).any(|x| x.is_nan()) {
            LearnerError::NanDynamics
        } else {
            LearnerError::EtaOverflow { eta }
        }
    }

    /// GPS `TrajOptLQRPython.backward`: new controller into `out` for the dual variable(s)
    /// `eta` (length 1, or T in per-step mode; raised in place on non-PD Q_uu). Returns the η
    /// of every attempt (total-KL mode).
    pub fn backward(
        &mut self,
        prev: &LinGaussPolicy,
        info: &TrajInfo,
        eta: &mut [f64],
        out: &mut LinGaussPolicy,
    ) -> Result<Vec<f64>, LearnerError> {
        self.check(prev, info)?;
        self.prepare(prev);
        let mut attempts = Vec::new();
        self.backward_prepared(prev, info, eta, out, &mut attempts)?;
        Ok(attempts)
    }

    /// GPS `TrajOptLQRPython.forward`: state–action marginals `mu (T, dX+dU, 1)`,
    /// `sigma (T, dX+dU, dX+dU)` of `pol` under `info`'s dynamics, in the workspace.
    pub fn forward(&mut self, pol: &LinGaussPolicy, info: &TrajInfo) -> (&MatSeq, &MatSeq) {
        let ws = &mut self.ws;
        forward_into(
            pol,
            info,
            &mut ws.mu,
            &mut ws.sigma,
            &mut ws.tmp_xd,
            &mut ws.tmp_xd2,
            &mut ws.tmp_ux,
        );
        (&ws.mu, &ws.sigma)
    }

    /// KL per step into the workspace, from the marginals already in it.
    fn kl_prepared(&mut self, new: &LinGaussPolicy, prev: &LinGaussPolicy, alt: bool) -> f64 {
        let ws = &mut self.ws;
        let (dx, du) = (ws.dx, ws.du);
        let d = dx + du;
        for t in 0..ws.t {
            let kl = if alt {
                kl_alt_step(
                    new,
                    prev,
                    t,
                    ws.mu.slice(t),
                    ws.sigma.mat(t),
                    &mut ws.tmp_ux,
                    &mut ws.tmp_xx,
                    &mut ws.tmp_xx2,
                    &mut ws.prc,
                    &mut ws.tmp_u,
                    &mut ws.tmp_ux2,
                )
            } else {
                let (c_new, ld_new) = kl_terms(
                    new,
                    t,
                    &mut ws.prc,
                    &mut ws.tmp_xu,
                    &mut ws.tmp_u,
                    ws.m_new.as_mut(),
                    ws.v_new.as_mut(),
                );
                let mp = ws.kl_m_prev.mat(t);
                let vp = ws.kl_v_prev.mat(t);
                // dM = M_new − M_prev, dv = v_new − v_prev
                for j in 0..d {
                    for i in 0..d {
                        ws.m_new[(i, j)] -= mp[(i, j)];
                    }
                    ws.v_new[(j, 0)] -= vp[(j, 0)];
                }
                let mu = MatSeqCol(ws.mu.slice(t));
                // (muᵀ dM) mu
                let mut quad = 0.0;
                for j in 0..d {
                    let mut s = 0.0;
                    for i in 0..d {
                        s += mu.0[i] * ws.m_new[(i, j)];
                    }
                    ws.tmp_d[(0, j)] = s;
                }
                for j in 0..d {
                    quad += ws.tmp_d[(0, j)] * mu.0[j];
                }
                let mut lin = 0.0;
                for i in 0..d {
                    lin += mu.0[i] * ws.v_new[(i, 0)];
                }
                let tr = frob_dot(ws.sigma.mat(t), ws.m_new.as_ref());
                let v = -0.5 * quad - lin - c_new + ws.kl_c_prev[t] - 0.5 * tr - 0.5 * ld_new
                    + 0.5 * ws.kl_logdet_prev[t];
                v.max(0.0)
            };
            ws.kl[t] = kl;
        }
        ws.kl.iter().sum()
    }

    /// GPS `traj_distr_kl` (or `traj_distr_kl_alt` if `alt`) of `new` against `prev` under the
    /// marginals of `marg_pol` (GPS: `new` itself, or `prev` for the alt form). Returns the
    /// per-step KL (nats) and the total.
    pub fn kl(
        &mut self,
        marg_pol: &LinGaussPolicy,
        info: &TrajInfo,
        new: &LinGaussPolicy,
        prev: &LinGaussPolicy,
        alt: bool,
    ) -> Result<(Vec<f64>, f64), LearnerError> {
        self.check(new, info)?;
        self.prepare(prev);
        self.forward(marg_pol, info);
        let tot = self.kl_prepared(new, prev, alt);
        Ok((self.ws.kl.clone(), tot))
    }

    /// GPS `TrajOptLQRPython.update` in total-KL mode: η search for
    /// `KL ≈ kl_step` (`kl_step = base_kl_step · step_mult · T`), new controller into `out`.
    pub fn update(
        &mut self,
        prev: &LinGaussPolicy,
        info: &TrajInfo,
        eta_start: f64,
        kl_step: f64,
        out: &mut LinGaussPolicy,
    ) -> Result<DgdResult, LearnerError> {
        self.check(prev, info)?;
        self.prepare(prev);
        let alt = self.cfg.use_prev_distr;
        let (mut min_eta, mut max_eta) = (self.cfg.min_eta, self.cfg.max_eta);
        let mut eta = [eta_start];
        let mut res = DgdResult {
            eta: eta_start,
            converged: false,
            trace: Vec::new(),
        };
        for _itr in 0..DGD_MAX_ITER {
            let eta_in = eta[0];
            let mut attempts = Vec::new();
            self.backward_prepared(prev, info, &mut eta, out, &mut attempts)?;
            let ws = &mut self.ws;
            let marg = if alt { prev } else { &*out };
            forward_into(
                marg,
                info,
                &mut ws.mu,
                &mut ws.sigma,
                &mut ws.tmp_xd,
                &mut ws.tmp_xd2,
                &mut ws.tmp_ux,
            );
            let kl = self.kl_prepared(out, prev, alt);
            res.trace.push(DgdStep {
                eta_in,
                eta_out: eta[0],
                attempt_etas: attempts,
                kl,
            });
            let con = kl - kl_step;
            if con.abs() < 0.1 * kl_step {
                res.converged = true;
                break;
            }
            if con < 0.0 {
                max_eta = eta[0];
                let geom = (min_eta * max_eta).sqrt();
                eta[0] = geom.max(0.1 * max_eta);
            } else {
                min_eta = eta[0];
                let geom = (min_eta * max_eta).sqrt();
                eta[0] = geom.min(10.0 * min_eta);
            }
        }
        res.eta = eta[0];
        Ok(res)
    }

    /// GPS `TrajOptLQRPython.update` with `cons_per_step = True`: one η and one KL bound per
    /// time step (`kl_step` of length T, already multiplied by the step multiplier);
    /// bracketing for up to 20 rounds, then Adam on η[..T−1] for up to 200.
    pub fn update_per_step(
        &mut self,
        prev: &LinGaussPolicy,
        info: &TrajInfo,
        eta_start: &[f64],
        kl_step: &[f64],
        out: &mut LinGaussPolicy,
    ) -> Result<DgdPerStepResult, LearnerError> {
        self.check(prev, info)?;
        let t_len = self.ws.t;
        if eta_start.len() != t_len || kl_step.len() != t_len {
            return Err(LearnerError::Shape(format!(
                "per-step eta and kl_step need length T={t_len}"
            )));
        }
        self.prepare(prev);
        let alt = self.cfg.use_prev_distr;
        let mut eta = eta_start.to_vec();
        let mut min_eta = vec![self.cfg.min_eta; t_len];
        let mut max_eta = vec![self.cfg.max_eta; t_len];
        let mut res = DgdPerStepResult {
            eta: Vec::new(),
            converged: false,
            trace_eta_in: Vec::new(),
            trace_kl: Vec::new(),
        };
        let mut con = vec![0.0; t_len];
        let mut attempts = Vec::new();
        let conv = |con: &[f64]| con.iter().zip(kl_step).all(|(c, k)| c.abs() < 0.1 * k);
        for _itr in 0..DGD_MAX_LS_ITER {
            res.trace_eta_in.push(eta.clone());
            self.backward_prepared(prev, info, &mut eta, out, &mut attempts)?;
            let ws = &mut self.ws;
            let marg = if alt { prev } else { &*out };
            forward_into(
                marg,
                info,
                &mut ws.mu,
                &mut ws.sigma,
                &mut ws.tmp_xd,
                &mut ws.tmp_xd2,
                &mut ws.tmp_ux,
            );
            self.kl_prepared(out, prev, alt);
            res.trace_kl.push(self.ws.kl.clone());
            for t in 0..t_len {
                con[t] = self.ws.kl[t] - kl_step[t];
            }
            if conv(&con) {
                res.converged = true;
                break;
            }
            for t in 0..t_len {
                if con[t] < 0.0 {
                    max_eta[t] = eta[t];
                    let geom = (min_eta[t] * max_eta[t]).sqrt();
                    eta[t] = geom.max(0.1 * max_eta[t]);
                } else {
                    min_eta[t] = eta[t];
                    let geom = (min_eta[t] * max_eta[t]).sqrt();
                    eta[t] = geom.min(10.0 * min_eta[t]);
                }
            }
        }
        if !res.converged {
            let (alpha, beta1, beta2, eps) = ADAM;
            let n = t_len - 1;
            let mut m_b = vec![0.0; n];
            let mut v_b = vec![0.0; n];
            for itr in 0..DGD_MAX_GD_ITER {
                res.trace_eta_in.push(eta.clone());
                self.backward_prepared(prev, info, &mut eta, out, &mut attempts)?;
                let ws = &mut self.ws;
                let marg = if alt { prev } else { &*out };
                forward_into(
                    marg,
                    info,
                    &mut ws.mu,
                    &mut ws.sigma,
                    &mut ws.tmp_xd,
                    &mut ws.tmp_xd2,
                    &mut ws.tmp_ux,
                );
                self.kl_prepared(out, prev, alt);
                res.trace_kl.push(self.ws.kl.clone());
                for t in 0..t_len {
                    con[t] = self.ws.kl[t] - kl_step[t];
                }
                if conv(&con) {
                    res.converged = true;
                    break;
                }
                let p = (itr + 1) as i32;
                for t in 0..n {
                    m_b[t] = beta1 * m_b[t] + (1.0 - beta1) * con[t];
                    let m_u = m_b[t] / (1.0 - beta1.powi(p));
                    v_b[t] = beta2 * v_b[t] + (1.0 - beta2) * (con[t] * con[t]);
                    let v_u = v_b[t] / (1.0 - beta2.powi(p));
                    eta[t] = (eta[t] + alpha * m_u / (v_u.sqrt() + eps))
                        .max(self.cfg.min_eta)
                        .min(self.cfg.max_eta);
                }
            }
        }
        res.eta = eta;
        Ok(res)
    }

    /// GPS `TrajOptLQRPython.estimate_cost`: Laplace estimate of the expected cost per step,
    /// `cc + ½ tr(Σ Cm) + ½ μᵀ Cm μ + μᵀ cv`, under `info`'s dynamics. Writes `out (T)`.
    pub fn estimate_cost(
        &mut self,
        pol: &LinGaussPolicy,
        info: &TrajInfo,
        out: &mut [f64],
    ) -> Result<(), LearnerError> {
        self.check(pol, info)?;
        self.forward(pol, info);
        let ws = &self.ws;
        let d = ws.dx + ws.du;
        for t in 0..ws.t {
            let cm = info.cm.mat(t);
            let mu = ws.mu.slice(t);
            let cv = info.cv.slice(t);
            let tr = frob_dot(ws.sigma.mat(t), cm);
            let mut quad = 0.0;
            for j in 0..d {
                let mut s = 0.0;
                for i in 0..d {
                    s += mu[i] * cm[(i, j)];
                }
                quad += s * mu[j];
            }
            let mut lin = 0.0;
            for i in 0..d {
                lin += mu[i] * cv[i];
            }
            out[t] = info.cc[t] + 0.5 * tr + 0.5 * quad + lin;
        }
        Ok(())
    }
}

struct MatSeqCol<'a>(&'a [f64]);

/// GPS `forward`: marginals of `pol` under `info` into `mu (T,D,1)`, `sigma (T,D,D)`.
/// `tmp_xd`, `tmp_xd2` are `dX x D`, `tmp_ux` is `dU x dX` scratch.
pub fn forward_into(
    pol: &LinGaussPolicy,
    info: &TrajInfo,
    mu: &mut MatSeq,
    sigma: &mut MatSeq,
    tmp_xd: &mut Mat<f64>,
    tmp_xd2: &mut Mat<f64>,
    tmp_ux: &mut Mat<f64>,
) {
    let (t_len, dx, du) = (pol.t, pol.dx, pol.du);
    let dynm = &info.dynamics;
    {
        let mut s0 = sigma.mat_mut(0);
        s0.fill(0.0);
        s0.submatrix_mut(0, 0, dx, dx).copy_from(&info.x0sigma);
        let m0 = mu.slice_mut(0);
        m0.iter_mut().for_each(|x| *x = 0.0);
        m0[..dx].copy_from_slice(&info.x0mu);
    }
    for t in 0..t_len {
        let kg = pol.gain.mat(t);
        {
            let mut s = sigma.mat_mut(t);
            // K Sxx (dU x dX) and Sxx Kᵀ (dX x dU), as GPS computes both.
            gemm(
                tmp_ux.as_mut(),
                Accum::Replace,
                kg,
                s.rb().submatrix(0, 0, dx, dx),
                1.0,
            );
            gemm(
                tmp_xd2.as_mut().submatrix_mut(0, 0, dx, du),
                Accum::Replace,
                s.rb().submatrix(0, 0, dx, dx),
                kg.transpose(),
                1.0,
            );
            s.rb_mut()
                .submatrix_mut(0, dx, dx, du)
                .copy_from(tmp_xd2.as_ref().submatrix(0, 0, dx, du));
            s.rb_mut()
                .submatrix_mut(dx, 0, du, dx)
                .copy_from(tmp_ux.as_ref());
            let mut suu = s.submatrix_mut(dx, dx, du, du);
            suu.copy_from(pol.pol_covar.mat(t));
            gemm(suu, Accum::Add, tmp_ux.as_ref(), kg.transpose(), 1.0);
        }
        {
            let m = mu.slice_mut(t);
            let k = pol.k.slice(t);
            for i in 0..du {
                let mut acc = 0.0;
                for j in 0..dx {
                    acc += kg[(i, j)] * m[j];
                }
                m[dx + i] = acc + k[i];
            }
        }
        if t + 1 < t_len {
            let fm = dynm.fm.mat(t);
            gemm(tmp_xd.as_mut(), Accum::Replace, fm, sigma.mat(t), 1.0);
            {
                let mut sn = sigma.mat_mut(t + 1);
                sn.fill(0.0);
                let mut sxx = sn.submatrix_mut(0, 0, dx, dx);
                sxx.copy_from(dynm.dyn_covar.mat(t));
                gemm(sxx, Accum::Add, tmp_xd.as_ref(), fm.transpose(), 1.0);
            }
            let fv = dynm.fv.slice(t);
            let (cur, next) = mu.data.split_at_mut((t + 1) * (dx + du));
            let mcur = &cur[t * (dx + du)..];
            let mnext = &mut next[..dx + du];
            mnext.iter_mut().for_each(|x| *x = 0.0);
            for i in 0..dx {
                let mut acc = 0.0;
                for j in 0..dx + du {
                    acc += fm[(i, j)] * mcur[j];
                }
                mnext[i] = acc + fv[i];
            }
        }
    }
}

/// GPS `traj_distr_kl_alt` at step t, with `mu` the marginal mean (length ≥ dX) and `sigma`
/// the marginal covariance (top-left `dX x dX` used).
#[allow(clippy::too_many_arguments)]
fn kl_alt_step(
    new: &LinGaussPolicy,
    prev: &LinGaussPolicy,
    t: usize,
    mu: &[f64],
    sigma: faer::MatRef<'_, f64>,
    kdiff: &mut Mat<f64>,
    tmp_xx: &mut Mat<f64>,
    tmp_xx2: &mut Mat<f64>,
    tmp_uu: &mut Mat<f64>,
    kd: &mut Mat<f64>,
    ipk: &mut Mat<f64>,
) -> f64 {
    let (dx, du) = (new.dx, new.du);
    let rp = prev.chol_pol_covar.mat(t);
    let rn = new.chol_pol_covar.mat(t);
    let logdet_prev = 2.0 * (0..du).map(|i| rp[(i, i)].ln()).fold(0.0, |a, b| a + b);
    let logdet_new = 2.0 * (0..du).map(|i| rn[(i, i)].ln()).fold(0.0, |a, b| a + b);
    let inv_prev = prev.inv_pol_covar.mat(t);
    let sig_new = new.pol_covar.mat(t);
    for i in 0..du {
        for j in 0..dx {
            kdiff[(i, j)] = prev.gain.mat(t)[(i, j)] - new.gain.mat(t)[(i, j)];
        }
    }
    let kp = prev.k.slice(t);
    let kn = new.k.slice(t);
    for i in 0..du {
        kd[(i, 0)] = kp[i] - kn[i];
    }
    let kd = kd.col(0);
    // tr(inv_prev sig_new)
    gemm(tmp_uu.as_mut(), Accum::Replace, inv_prev, sig_new, 1.0);
    let tr1: f64 = (0..du).map(|i| tmp_uu[(i, i)]).fold(0.0, |a, b| a + b);
    // kdᵀ inv_prev kd
    let mut q1 = 0.0;
    for j in 0..du {
        let mut s = 0.0;
        for i in 0..du {
            s += kd[i] * inv_prev[(i, j)];
        }
        q1 += s * kd[j];
    }
    // A = Kdᵀ inv_prev Kd (dX x dX)
    gemm(ipk.as_mut(), Accum::Replace, inv_prev, kdiff.as_ref(), 1.0);
    gemm(
        tmp_xx.as_mut(),
        Accum::Replace,
        kdiff.transpose(),
        ipk.as_ref(),
        1.0,
    );
    let mut q2 = 0.0;
    for j in 0..dx {
        let mut s = 0.0;
        for i in 0..dx {
            s += mu[i] * tmp_xx[(i, j)];
        }
        q2 += s * mu[j];
    }
    gemm(
        tmp_xx2.as_mut(),
        Accum::Replace,
        tmp_xx.as_ref(),
        sigma.submatrix(0, 0, dx, dx),
        1.0,
    );
    let tr2: f64 = (0..dx).map(|i| tmp_xx2[(i, i)]).fold(0.0, |a, b| a + b);
    // 2 kdᵀ inv_prev Kd mu
    let mut q3 = 0.0;
    for j in 0..dx {
        let mut s = 0.0;
        for i in 0..du {
            s += kd[i] * ipk[(i, j)];
        }
        q3 += s * mu[j];
    }
    let v = 0.5 * (logdet_prev - logdet_new - du as f64 + tr1 + q1 + q2 + tr2 + 2.0 * q3);
    v.max(0.0)
}
