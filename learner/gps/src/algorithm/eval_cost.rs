//! Quadratic cost model averaged over samples (GPS `Algorithm._eval_cost`).

use crate::linalg::MatSeq;

/// Per-sample cost derivatives in GPS layout: `l (N,T)`, `lx (N,T,dX)`, `lu (N,T,dU)`,
/// `lxx (N,T,dX,dX)`, `luu (N,T,dU,dU)`, `lux (N,T,dU,dX)`, all row-major, expanded around
/// each sample's own `(x_t, u_t)`.
#[derive(Clone, Debug, Default)]
pub struct CostDerivs {
    pub l: Vec<f64>,
    pub lx: Vec<f64>,
    pub lu: Vec<f64>,
    pub lxx: Vec<f64>,
    pub luu: Vec<f64>,
    pub lux: Vec<f64>,
}

impl CostDerivs {
    /// Sizes every array for `n` samples of horizon `t_len` (keeps the allocation when it
    /// fits).
    pub fn resize(&mut self, n: usize, t_len: usize, dx: usize, du: usize) {
        let nt = n * t_len;
        self.l.resize(nt, 0.0);
        self.lx.resize(nt * dx, 0.0);
        self.lu.resize(nt * du, 0.0);
        self.lxx.resize(nt * dx * dx, 0.0);
        self.luu.resize(nt * du * du, 0.0);
        self.lux.resize(nt * du * dx, 0.0);
    }
}

/// GPS `_eval_cost`: rewrites each sample's expansion around `ŷ = [x; u]` into absolute
/// coordinates (`cv += Cmᵀ(−ŷ)`, `cc += (−ŷ)·cv + ½ (−ŷ)·Cmᵀ(−ŷ)`) and averages over samples.
/// `x (N,T,dX)`, `u (N,T,dU)`. Writes `cc (T)`, `cv (T,D,1)`, `cm (T,D,D)`, D = dX+dU.
#[allow(clippy::too_many_arguments)]
pub fn eval_cost(
    x: &[f64],
    u: &[f64],
    derivs: &CostDerivs,
    n: usize,
    t_len: usize,
    dx: usize,
    du: usize,
    cc: &mut [f64],
    cv: &mut MatSeq,
    cm: &mut MatSeq,
) {
    let d = dx + du;
    cc.iter_mut().for_each(|v| *v = 0.0);
    cv.fill(0.0);
    cm.fill(0.0);
    let mut cm_n = vec![0.0; d * d];
    let mut cv_n = vec![0.0; d];
    let mut r = vec![0.0; d];
    let mut upd = vec![0.0; d];
    for t in 0..t_len {
        for s in 0..n {
            let nt = s * t_len + t;
            for i in 0..dx {
                cv_n[i] = derivs.lx[nt * dx + i];
                r[i] = -x[nt * dx + i];
                for j in 0..dx {
                    cm_n[i * d + j] = derivs.lxx[nt * dx * dx + i * dx + j];
                }
            }
            for i in 0..du {
                cv_n[dx + i] = derivs.lu[nt * du + i];
                r[dx + i] = -u[nt * du + i];
                for j in 0..du {
                    cm_n[(dx + i) * d + dx + j] = derivs.luu[nt * du * du + i * du + j];
                }
                for j in 0..dx {
                    let v = derivs.lux[nt * du * dx + i * dx + j];
                    cm_n[(dx + i) * d + j] = v;
                    cm_n[j * d + dx + i] = v;
                }
            }
            // cv_update[b] = Σ_a Cm[a, b] r[a]
            for b in 0..d {
                let mut acc = 0.0;
                for a in 0..d {
                    acc += cm_n[a * d + b] * r[a];
                }
                upd[b] = acc;
            }
            let mut lin = 0.0;
            let mut quad = 0.0;
            for a in 0..d {
                lin += r[a] * cv_n[a];
                quad += r[a] * upd[a];
            }
            let ccn = derivs.l[nt] + (lin + 0.5 * quad);
            cc[t] += ccn;
            let cvt = cv.slice_mut(t);
            for a in 0..d {
                cvt[a] += cv_n[a] + upd[a];
            }
            let cmt = cm.slice_mut(t);
            for a in 0..d * d {
                cmt[a] += cm_n[a];
            }
        }
        let inv = n as f64;
        cc[t] /= inv;
        cv.slice_mut(t).iter_mut().for_each(|v| *v /= inv);
        cm.slice_mut(t).iter_mut().for_each(|v| *v /= inv);
    }
}
