//! KL divergences between linear-Gaussian controllers (GPS traj_opt_utils.py `traj_distr_kl`,
//! `traj_distr_kl_alt`).

use faer::prelude::ReborrowMut;
use faer::{Accum, Mat};

use super::{TrajInfo, TrajOptLqr};
use crate::error::GpsError;
use crate::linalg::{frob_dot, gemm, set_identity, solve_lower, solve_upper};
use crate::policy::lin_gauss::LinGaussPolicy;

/// Writes the KL quadratic form of a controller at step t (GPS traj_distr_kl):
/// `M = [[Kᵀ P K, −Kᵀ P], [−P K, P]]`, `v = [Kᵀ P k; −P k]`, `c = ½ kᵀ P k`, and
/// `logdet Σ`, with `P = Σ⁻¹` from the upper Cholesky factor. Returns `(c, logdet)`.
pub(super) fn kl_terms(
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

/// One step's marginal mean, as a slice.
struct MatSeqCol<'a>(&'a [f64]);

impl TrajOptLqr {
    /// KL per step into the workspace, from the marginals already in it.
    pub(super) fn kl_prepared(
        &mut self,
        new: &LinGaussPolicy,
        prev: &LinGaussPolicy,
        alt: bool,
    ) -> f64 {
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
    ) -> Result<(Vec<f64>, f64), GpsError> {
        self.check(new, info)?;
        self.prepare(prev);
        self.forward(marg_pol, info);
        let tot = self.kl_prepared(new, prev, alt);
        Ok((self.ws.kl.clone(), tot))
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
