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

use faer::Mat;

use crate::dynamics::Dynamics;
use crate::error::GpsError;
use crate::linalg::{frob_dot, MatSeq, Scratch};
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::traj_opt::config::{PilqrConfig, TrajOptMethod};

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
    /// `"lqr"` (default) or `"pilqr"`: LQR followed by PI2 on the residual cost
    /// ([`crate::traj_opt::pilqr`]). Written out only when not the default, so settings
    /// hashed before the setting existed keep their hash.
    #[serde(skip_serializing_if = "TrajOptMethod::is_lqr")]
    pub method: TrajOptMethod,
    /// PILQR's PI2 and step-rule settings (`[traj_opt.pilqr]`; read only with
    /// `method = "pilqr"`; written out only when not the defaults).
    #[serde(skip_serializing_if = "PilqrConfig::is_default")]
    pub pilqr: PilqrConfig,
}

impl TrajOptConfig {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), crate::GpsError> {
        use crate::error::check;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        check(pos(self.del0), "traj_opt.del0", self.del0, "finite and > 0")?;
        check(
            pos(self.min_eta) && pos(self.max_eta) && self.min_eta < self.max_eta,
            "traj_opt.min_eta/max_eta",
            (self.min_eta, self.max_eta),
            "finite, > 0, min < max",
        )?;
        check(
            self.max_ent_traj.is_finite() && self.max_ent_traj >= 0.0,
            "traj_opt.max_ent_traj",
            self.max_ent_traj,
            "finite and >= 0",
        )?;
        self.pilqr.validate()
    }
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
            method: TrajOptMethod::Lqr,
            pilqr: PilqrConfig::default(),
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

mod backward;
mod forward;
mod kl;

pub use forward::forward_into;

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

    fn check(&self, pol: &LinGaussPolicy, info: &TrajInfo) -> Result<(), GpsError> {
        let w = &self.ws;
        if (pol.t, pol.dx, pol.du) != (w.t, w.dx, w.du)
            || (info.dynamics.t, info.dynamics.dx, info.dynamics.du) != (w.t, w.dx, w.du)
        {
            return Err(GpsError::Shape(format!(
                "TrajOptLqr built for (T,dX,dU)=({},{},{}), got policy ({},{},{}) and dynamics ({},{},{})",
                w.t, w.dx, w.du, pol.t, pol.dx, pol.du, info.dynamics.t, info.dynamics.dx, info.dynamics.du
            )));
        }
        Ok(())
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
    ) -> Result<DgdResult, GpsError> {
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
    ) -> Result<DgdPerStepResult, GpsError> {
        self.check(prev, info)?;
        let t_len = self.ws.t;
        if eta_start.len() != t_len || kl_step.len() != t_len {
            return Err(GpsError::Shape(format!(
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
    ) -> Result<(), GpsError> {
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
