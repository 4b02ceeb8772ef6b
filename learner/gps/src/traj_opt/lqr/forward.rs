//! State–action marginals of a controller under the fitted dynamics (GPS `forward`).

use faer::prelude::{Reborrow, ReborrowMut};
use faer::{Accum, Mat};

use super::{TrajInfo, TrajOptLqr};
use crate::linalg::{gemm, MatSeq};
use crate::policy::lin_gauss::LinGaussPolicy;

impl TrajOptLqr {
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
}

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
