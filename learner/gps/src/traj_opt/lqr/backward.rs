//! The backward pass of the KL-bounded LQR step (GPS `TrajOptLQRPython.backward`,
//! `compute_costs`): the augmented-cost Riccati sweep and the non-PD η raising.

use faer::prelude::ReborrowMut;
use faer::Accum;

use super::kl::kl_terms;
use super::{TrajInfo, TrajOptLqr, ETA_ERROR_THRESHOLD};
use crate::error::GpsError;
use crate::linalg::{gemm, llt_lower, set_identity, solve_lower, solve_upper, symmetrize};
use crate::policy::lin_gauss::LinGaussPolicy;

impl TrajOptLqr {
    /// Precomputes the previous controller's KL-penalty blocks (GPS `compute_costs`).
    pub(super) fn prepare(&mut self, prev: &LinGaussPolicy) {
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
    pub(super) fn sweep(
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
    pub(super) fn backward_prepared(
        &mut self,
        prev: &LinGaussPolicy,
        info: &TrajInfo,
        eta: &mut [f64],
        out: &mut LinGaussPolicy,
        attempts: &mut Vec<f64>,
    ) -> Result<(), GpsError> {
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

    pub(super) fn overflow(&self, info: &TrajInfo, eta: f64) -> GpsError {
        let d = &info.dynamics;
        if d.fm.data.iter().chain(d.fv.data.iter()).any(|x| x.is_nan()) {
            GpsError::NanDynamics
        } else {
            GpsError::EtaOverflow { eta }
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
    ) -> Result<Vec<f64>, GpsError> {
        self.check(prev, info)?;
        self.prepare(prev);
        let mut attempts = Vec::new();
        self.backward_prepared(prev, info, eta, out, &mut attempts)?;
        Ok(attempts)
    }
}
