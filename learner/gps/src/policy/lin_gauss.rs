//! Time-varying linear-Gaussian controller in GPS's absolute form
//! (GPS `LinearGaussianPolicy`, python/gps/algorithm/policy/lin_gauss_policy.py).
//!
//! `u_t = K_t x_t + k_t + Rᵀ_t ε`, `ε ~ N(0, I)`, with `R_t = chol_pol_covar[t]` the **upper**
//! Cholesky factor of `pol_covar[t] = Rᵀ R` and `inv_pol_covar[t]` its inverse (the Q_uu block
//! of the last backward pass). Units follow the state and action: `K` is (action unit)/(state
//! unit), `k` is in action units.

use crate::linalg::MatSeq;

/// GPS `LinearGaussianPolicy`. Shapes: `K (T,dU,dX)`, `k (T,dU,1)`, the three covariance
/// arrays `(T,dU,dU)`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinGaussPolicy {
    pub t: usize,
    pub dx: usize,
    pub du: usize,
    /// Feedback gains `K_t`, `(T, dU, dX)`.
    pub gain: MatSeq,
    /// Feed-forward term `k_t` in absolute coordinates, `(T, dU, 1)`.
    pub k: MatSeq,
    /// Action covariance `Σ_t`, `(T, dU, dU)`.
    pub pol_covar: MatSeq,
    /// Upper Cholesky factor `R_t` with `Σ_t = Rᵀ R`, `(T, dU, dU)`.
    pub chol_pol_covar: MatSeq,
    /// `Σ_t⁻¹` (the symmetrised Q_uu block), `(T, dU, dU)`.
    pub inv_pol_covar: MatSeq,
}

impl LinGaussPolicy {
    /// All-zero policy of the given size.
    pub fn zeros(t: usize, dx: usize, du: usize) -> Self {
        Self {
            t,
            dx,
            du,
            gain: MatSeq::zeros(t, du, dx),
            k: MatSeq::zeros(t, du, 1),
            pol_covar: MatSeq::zeros(t, du, du),
            chol_pol_covar: MatSeq::zeros(t, du, du),
            inv_pol_covar: MatSeq::zeros(t, du, du),
        }
    }

    /// GPS `nans_like`: every entry NaN (what a backward pass starts from).
    pub fn fill_nan(&mut self) {
        for m in [
            &mut self.gain,
            &mut self.k,
            &mut self.pol_covar,
            &mut self.chol_pol_covar,
            &mut self.inv_pol_covar,
        ] {
            m.fill(f64::NAN);
        }
    }

    /// Copies every array from `other` (same size), without allocating.
    pub fn copy_from(&mut self, other: &LinGaussPolicy) {
        self.gain.copy_from(&other.gain);
        self.k.copy_from(&other.k);
        self.pol_covar.copy_from(&other.pol_covar);
        self.chol_pol_covar.copy_from(&other.chol_pol_covar);
        self.inv_pol_covar.copy_from(&other.inv_pol_covar);
    }

    /// GPS `LinearGaussianPolicy.act`: `u = K x + k + Rᵀ noise`, written into `u` (length dU).
    pub fn act(&self, t: usize, x: &[f64], noise: &[f64], u: &mut [f64]) {
        let (dx, du) = (self.dx, self.du);
        let kg = self.gain.slice(t);
        let k = self.k.slice(t);
        let r = self.chol_pol_covar.slice(t);
        for i in 0..du {
            let mut s = k[i];
            for j in 0..dx {
                s += kg[i * dx + j] * x[j];
            }
            for j in 0..du {
                // (Rᵀ noise)_i = sum_j R[j, i] noise_j
                s += r[j * du + i] * noise[j];
            }
            u[i] = s;
        }
    }
}

/// Absolute -> project form: `k' = k − â + K ŝ` for one time step, so that
/// `a = K (s − ŝ) + k' + â` equals GPS's `u = K s + k`.
///
/// Shapes: `gain` row-major `(dU, dX)`, `k`, `a_hat`, `k_rel` length dU, `s_hat` length dX.
pub fn k_abs_to_rel(gain: &[f64], k: &[f64], s_hat: &[f64], a_hat: &[f64], k_rel: &mut [f64]) {
    let dx = s_hat.len();
    for i in 0..k.len() {
        let mut ks = 0.0;
        for j in 0..dx {
            ks += gain[i * dx + j] * s_hat[j];
        }
        k_rel[i] = k[i] - a_hat[i] + ks;
    }
}

/// Project form -> absolute: `k = k' + â − K ŝ` (inverse of [`k_abs_to_rel`]).
pub fn k_rel_to_abs(gain: &[f64], k_rel: &[f64], s_hat: &[f64], a_hat: &[f64], k: &mut [f64]) {
    let dx = s_hat.len();
    for i in 0..k_rel.len() {
        let mut ks = 0.0;
        for j in 0..dx {
            ks += gain[i * dx + j] * s_hat[j];
        }
        k[i] = k_rel[i] + a_hat[i] - ks;
    }
}

/// Whole-table version of [`k_abs_to_rel`]: `gain (T,dU,dX)`, `k (T,dU)`, `s_hat (T,dX)`,
/// `a_hat (T,dU)`, output `k_rel (T,dU)`, all row-major.
pub fn table_abs_to_rel(
    gain: &[f64],
    k: &[f64],
    s_hat: &[f64],
    a_hat: &[f64],
    dx: usize,
    du: usize,
    k_rel: &mut [f64],
) {
    let t_len = k.len() / du;
    for t in 0..t_len {
        k_abs_to_rel(
            &gain[t * du * dx..(t + 1) * du * dx],
            &k[t * du..(t + 1) * du],
            &s_hat[t * dx..(t + 1) * dx],
            &a_hat[t * du..(t + 1) * du],
            &mut k_rel[t * du..(t + 1) * du],
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn abs_rel_roundtrip_gives_same_action() {
        let gain = [0.5, -1.0, 2.0, 0.25, 0.0, 3.0]; // 2 x 3
        let k = [0.1, -0.2];
        let s_hat = [1.0, 2.0, -1.0];
        let a_hat = [0.3, 0.7];
        let mut kr = [0.0; 2];
        k_abs_to_rel(&gain, &k, &s_hat, &a_hat, &mut kr);
        let s = [0.2, -0.4, 1.5];
        for i in 0..2 {
            let abs: f64 = (0..3).map(|j| gain[i * 3 + j] * s[j]).sum::<f64>() + k[i];
            let rel: f64 = (0..3)
                .map(|j| gain[i * 3 + j] * (s[j] - s_hat[j]))
                .sum::<f64>()
                + kr[i]
                + a_hat[i];
            assert!((abs - rel).abs() < 1e-12);
        }
        let mut back = [0.0; 2];
        k_rel_to_abs(&gain, &kr, &s_hat, &a_hat, &mut back);
        assert!((back[0] - k[0]).abs() < 1e-15 && (back[1] - k[1]).abs() < 1e-15);
    }
}
