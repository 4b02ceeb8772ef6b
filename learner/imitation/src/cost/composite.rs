//! The composite cost of LQR+GAIfO (docs/design.md §1.3 steps 4–5): the discriminator applied to the
//! transition the learned dynamics predict,
//!
//!   C_t(s, a) = D(s, F_t [s; a] + f_t),
//!
//! expanded to second order with the chain rule. With y = [s; a] (dX + dU) and
//! M_t = [[I, 0]; F_t] ((2 dX) × (dX + dU)): ∇C = M_tᵀ ∇D, ∇²C = M_tᵀ ∇²D M_t
//! (f_t does not enter the derivatives; D is evaluated at the predicted transition).
//!
//! The last step T−1 has no fitted dynamics (GPS leaves F_{T−1} = 0). It gets a state-only
//! cost C_{T−1}(s) = D(s, s): the transition of an arm at rest in s. The expert ends at rest at
//! the goal, so D is low there; ∇C = [I I] ∇D, ∇²C = [I I] ∇²D [I I]ᵀ, and no action terms.
//!
//! The Hessians are indefinite in general (D is a tanh net). The KL-bounded LQR step raises η
//! until Q_uu is positive definite (GPS's non-PD retry); beyond that, [`CompositeWorkspace::psd`]
//! (on in LQR+GAIfO, docs/design.md §5 D3, D4)
//! projects the per-step mean of ∇²D on the PSD cone before the chain rule.

use faer::Mat;
use ur5_shared::kernels::axpy;
use ur5_shared::layout::{MAX_DU, MAX_DX};

use super::Cost;
use crate::discriminator::{Discriminator, MeanHessian, Workspace};
use crate::rollout::Episode;
use gps::algorithm::eval_cost::CostDerivs;
use gps::dynamics::Dynamics;

/// Scratch memory for the expansion; build once, reuse every iteration.
pub struct CompositeWorkspace {
    /// Replace ∇²D by its projection on the positive semi-definite cone (negative eigenvalues
    /// set to 0) before composing; see [`expand_step`].
    pub psd: bool,
    /// The critic takes the phase t/(T − 1) as its last input (2 dX + 1 inputs,
    /// docs/design.md §5 D39): a constant of each step, so it enters D's value, not the
    /// derivatives in [s; a].
    phase: bool,
    disc: Workspace,
    x: Vec<f64>,
    g: Vec<f64>,
    h: Mat<f64>,
    /// Mean ∇²D over the samples of one time step (psd mode), and its accumulator.
    h_mean: Mat<f64>,
    mean: MeanHessian,
}

impl CompositeWorkspace {
    /// Sets [`Self::psd`].
    pub fn with_psd(mut self, psd: bool) -> Self {
        self.psd = psd;
        self
    }

    /// Scratch for `disc`: a critic on [s; s'] (2 dX inputs) or [s; s'; φ] (2 dX + 1, the
    /// phase last).
    pub fn new(disc: &Discriminator) -> Self {
        let n = disc.input_dim();
        Self {
            psd: false,
            phase: n % 2 == 1,
            disc: disc.workspace(),
            x: vec![0.0; n],
            g: vec![0.0; n],
            h: Mat::zeros(n, n),
            h_mean: Mat::zeros(n, n),
            mean: disc.mean_hessian(),
        }
    }
}

/// The phase of step `t` of `horizon`: t/(T − 1), 1 at the last step (0 for T = 1).
pub fn phase(t: usize, horizon: usize) -> f64 {
    if horizon < 2 {
        0.0
    } else {
        t as f64 / (horizon - 1) as f64
    }
}

/// The transition the dynamics predict, written into `x` (`2 dX`, or `2 dX + 1` with the
/// phase of step t last): `[s; F_t [s; a] + f_t]`, or `[s; s]` at the last step
/// (`t + 1 >= horizon`).
fn predicted_transition(
    dyn_: &Dynamics,
    t: usize,
    horizon: usize,
    s: &[f64],
    a: &[f64],
    x: &mut [f64],
) {
    let (dx, du) = (dyn_.dx, dyn_.du);
    let dy = dx + du;
    x[..dx].copy_from_slice(s);
    if x.len() > 2 * dx {
        x[2 * dx] = phase(t, horizon);
    }
    if t + 1 >= horizon {
        x[dx..2 * dx].copy_from_slice(s);
        return;
    }
    let f = dyn_.fm.slice(t);
    let fv = dyn_.fv.slice(t);
    for i in 0..dx {
        let mut v = fv[i];
        for j in 0..dx {
            v += f[i * dy + j] * s[j];
        }
        for j in 0..du {
            v += f[i * dy + dx + j] * a[j];
        }
        x[dx + i] = v;
    }
}

/// `∇C = M_tᵀ g` into `lx` (dX) and `lu` (dU; zero at the last step, where `M = [I; I]`).
fn compose_gradient(
    dyn_: &Dynamics,
    t: usize,
    horizon: usize,
    g: &[f64],
    lx: &mut [f64],
    lu: &mut [f64],
) {
    let (dx, du) = (dyn_.dx, dyn_.du);
    let dy = dx + du;
    if t + 1 >= horizon {
        for i in 0..dx {
            lx[i] = g[i] + g[dx + i];
        }
        lu.fill(0.0);
        return;
    }
    let f = dyn_.fm.slice(t);
    for c in 0..dy {
        let mut v = if c < dx { g[c] } else { 0.0 };
        for k in 0..dx {
            v += f[k * dy + c] * g[dx + k];
        }
        if c < dx {
            lx[c] = v;
        } else {
            lu[c - dx] = v;
        }
    }
}

/// `∇²C = M_tᵀ h M_t` (`h` = ∇²D, `2dX × 2dX`, symmetric) into `lxx` (dX×dX), `luu` (dU×dU),
/// `lux` (dU×dX), row-major, symmetrised against round-off; at the last step
/// `∇²C = [I I] h [I I]ᵀ` and no action terms.
fn compose_hessian(
    dyn_: &Dynamics,
    t: usize,
    horizon: usize,
    h: &Mat<f64>,
    lxx: &mut [f64],
    luu: &mut [f64],
    lux: &mut [f64],
) {
    let (dx, du) = (dyn_.dx, dyn_.du);
    let (dy, n_in) = (dx + du, 2 * dx);
    luu.fill(0.0);
    lux.fill(0.0);
    if t + 1 >= horizon {
        for i in 0..dx {
            for j in 0..dx {
                lxx[i * dx + j] = h[(i, j)] + h[(i, dx + j)] + h[(dx + i, j)] + h[(dx + i, dx + j)];
            }
        }
        return;
    }
    let f = dyn_.fm.slice(t);
    // HM = h M (2dX × dY), M = [[I, 0]; F_t]; row-major scratch of at most 2 MAX_DX × MAX_DY.
    // Row r: h[r, :dX] (0 in the action columns) + Σ_k h[r, dX + k] F_t[k, :], the terms of each
    // entry added in the order of k ([`axpy`]: the scalar sum's bits, a row at a time).
    let mut hm = [0.0; 2 * MAX_DX * (MAX_DX + MAX_DU)];
    for r in 0..n_in {
        let row = &mut hm[r * dy..(r + 1) * dy];
        for c in 0..dx {
            row[c] = h[(r, c)];
        }
        for k in 0..dx {
            axpy(h[(r, dx + k)], &f[k * dy..(k + 1) * dy], row);
        }
    }
    // Mᵀ (HM): row i of Mᵀ is e_i (i < dX) in the first block plus F_t[:, i] in the second.
    let mut hess = [0.0; (MAX_DX + MAX_DU) * (MAX_DX + MAX_DU)];
    for i in 0..dy {
        let row = &mut hess[i * dy..(i + 1) * dy];
        if i < dx {
            row.copy_from_slice(&hm[i * dy..(i + 1) * dy]);
        }
        for k in 0..dx {
            axpy(f[k * dy + i], &hm[(dx + k) * dy..(dx + k + 1) * dy], row);
        }
    }
    for i in 0..dx {
        for j in 0..dx {
            lxx[i * dx + j] = 0.5 * (hess[i * dy + j] + hess[j * dy + i]);
        }
    }
    for i in 0..du {
        for j in 0..du {
            luu[i * du + j] = 0.5 * (hess[(dx + i) * dy + dx + j] + hess[(dx + j) * dy + dx + i]);
        }
        for j in 0..dx {
            lux[i * dx + j] = 0.5 * (hess[(dx + i) * dy + j] + hess[j * dy + dx + i]);
        }
    }
}

/// ℓ and its derivatives at one (t, s, a) in GPS layout (lx dX, lu dU, lxx dX×dX, luu dU×dU,
/// lux dU×dX, row-major), written into the given slices. With `ws.psd` the ∇²D of this one
/// point is projected ([`project_psd`]).
#[allow(clippy::too_many_arguments)]
pub fn expand_step(
    disc: &Discriminator,
    dyn_: &Dynamics,
    t: usize,
    horizon: usize,
    s: &[f64],
    a: &[f64],
    ws: &mut CompositeWorkspace,
    lx: &mut [f64],
    lu: &mut [f64],
    lxx: &mut [f64],
    luu: &mut [f64],
    lux: &mut [f64],
) -> f64 {
    predicted_transition(dyn_, t, horizon, s, a, &mut ws.x);
    let value = disc.value_gradient_hessian(&ws.x, &mut ws.disc, &mut ws.g, ws.h.as_mut());
    if ws.psd {
        drop_phase(ws.phase, &mut ws.h);
        project_psd(&mut ws.h);
    }
    compose_gradient(dyn_, t, horizon, &ws.g, lx, lu);
    compose_hessian(dyn_, t, horizon, &ws.h, lxx, luu, lux);
    value
}

/// With the phase input, zeroes its row and column of ∇²D (the last), so that the PSD
/// projection sees the curvature in [s; s'] only: the phase is no variable of the cost.
fn drop_phase(phase: bool, h: &mut Mat<f64>) {
    if phase {
        let n = h.nrows() - 1;
        for k in 0..=n {
            h[(n, k)] = 0.0;
            h[(k, n)] = 0.0;
        }
    }
}

/// Projects a symmetric matrix on the PSD cone: U max(Λ, 0) Uᵀ. The eigendecomposition (of the
/// lower triangle) runs on the calling thread: faer's default would hand parts of it to the
/// episodes' thread pool, a third slower at 60 × 60 on two cores and unseen by the learner's
/// CPU clock; its results are the same.
pub fn project_psd(h: &mut Mat<f64>) {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::evd::{self, ComputeEigenvectors};
    let n = h.nrows();
    let (mut u, mut s) = (Mat::<f64>::zeros(n, n), faer::diag::Diag::<f64>::zeros(n));
    let par = faer::Par::Seq;
    let scratch =
        evd::self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, par, Default::default());
    let mut mem = MemBuffer::new(scratch);
    let stack = MemStack::new(&mut mem);
    if evd::self_adjoint_evd(
        h.as_ref(),
        s.as_mut(),
        Some(u.as_mut()),
        par,
        stack,
        Default::default(),
    )
    .is_err()
    {
        return;
    }
    let (u, lam) = (u.as_ref(), s.as_ref().column_vector());
    if (0..lam.nrows()).all(|i| lam[i] >= 0.0) {
        return;
    }
    // Entry (i, j) is Σ_{k: λ_k > 0} (u_ik λ_k) u_jk, the terms added in the order of k: row i
    // as [`axpy`]s of U's columns (the scalar triple loop's bits, a row at a time).
    let n = h.nrows();
    let mut cols = Vec::with_capacity(n * n);
    let mut keep = Vec::with_capacity(n);
    for k in (0..n).filter(|&k| lam[k] > 0.0) {
        cols.extend((0..n).map(|j| u[(j, k)]));
        keep.push(k);
    }
    let mut row = vec![0.0; n];
    for i in 0..n {
        row.fill(0.0);
        for (m, &k) in keep.iter().enumerate() {
            axpy(u[(i, k)] * lam[k], &cols[m * n..(m + 1) * n], &mut row);
        }
        for (j, &v) in row.iter().enumerate() {
            h[(i, j)] = v;
        }
    }
}

/// The composite cost of critic `disc` as a [`Cost`], with its scratch memory.
pub struct CompositeCost<'a> {
    /// The critic D(s, s').
    pub disc: &'a Discriminator,
    /// Scratch (and the PSD switch).
    pub ws: &'a mut CompositeWorkspace,
}

impl Cost for CompositeCost<'_> {
    fn expand(&mut self, episodes: &[Episode], dynamics: &Dynamics, out: &mut CostDerivs) {
        composite_cost_derivs(self.disc, dynamics, episodes, self.ws, out);
    }

    /// The critic on the transitions the arm made, D(s_t, s_{t+1}), and D(s, s) at the last
    /// step: what each sample incurred, where the expansion used the model's predicted s'
    /// (PILQR's residual is the difference, docs/design.md §5 D34).
    fn sampled(&mut self, episodes: &[Episode], _: &CostDerivs, out: &mut Vec<f64>) {
        out.clear();
        for ep in episodes {
            let t_len = ep.horizon();
            let dx = ep.dx();
            for t in 0..t_len {
                let next = (t + 1).min(t_len - 1);
                self.ws.x[..dx].copy_from_slice(ep.state(t));
                self.ws.x[dx..2 * dx].copy_from_slice(ep.state(next));
                if self.ws.phase {
                    self.ws.x[2 * dx] = phase(t, t_len);
                }
                out.push(self.disc.value(&self.ws.x, &mut self.ws.disc));
            }
        }
    }
}

/// Per-sample composite-cost derivatives for N episodes (GPS layout), ready for `eval_cost`:
/// value and gradient around each sample's own executed (s, a).
///
/// Hessians: without `ws.psd`, each sample's exact `M_tᵀ ∇²D M_t`. With `ws.psd`, the
/// samples' ∇²D at step t are averaged first, the average is projected on the PSD cone once
/// and every sample gets the same `M_tᵀ proj(mean ∇²D) M_t`: the nearest convex curvature
/// (Frobenius norm) to the averaged expansion that GPS's `eval_cost` forms anyway, at one
/// eigendecomposition per time step instead of one per sample (docs/design.md §5 D4). The
/// mean is formed by [`MeanHessian`]: through the critic's first layer when its input is
/// wider than that layer (a pose task's), else per sample.
pub fn composite_cost_derivs(
    disc: &Discriminator,
    dyn_: &Dynamics,
    episodes: &[Episode],
    ws: &mut CompositeWorkspace,
    out: &mut CostDerivs,
) {
    let n = episodes.len();
    let t_len = episodes[0].horizon();
    let (dx, du) = (dyn_.dx, dyn_.du);
    out.resize(n, t_len, dx, du);
    if ws.psd {
        ws.mean.prepare(disc);
    }
    for t in 0..t_len {
        for (i, ep) in episodes.iter().enumerate() {
            let nt = i * t_len + t;
            let (s, a) = (ep.state(t), ep.action(t));
            predicted_transition(dyn_, t, t_len, s, a, &mut ws.x);
            out.l[nt] = if ws.psd {
                disc.value_gradient_add_hessian(&ws.x, &mut ws.disc, &mut ws.g, &mut ws.mean)
            } else {
                disc.value_gradient_hessian(&ws.x, &mut ws.disc, &mut ws.g, ws.h.as_mut())
            };
            compose_gradient(
                dyn_,
                t,
                t_len,
                &ws.g,
                &mut out.lx[nt * dx..(nt + 1) * dx],
                &mut out.lu[nt * du..(nt + 1) * du],
            );
            if !ws.psd {
                compose_hessian(
                    dyn_,
                    t,
                    t_len,
                    &ws.h,
                    &mut out.lxx[nt * dx * dx..(nt + 1) * dx * dx],
                    &mut out.luu[nt * du * du..(nt + 1) * du * du],
                    &mut out.lux[nt * du * dx..(nt + 1) * du * dx],
                );
            }
        }
        if ws.psd {
            ws.mean.mean_into(ws.h_mean.as_mut());
            drop_phase(ws.phase, &mut ws.h_mean);
            project_psd(&mut ws.h_mean);
            compose_hessian(
                dyn_,
                t,
                t_len,
                &ws.h_mean,
                &mut out.lxx[t * dx * dx..(t + 1) * dx * dx],
                &mut out.luu[t * du * du..(t + 1) * du * du],
                &mut out.lux[t * du * dx..(t + 1) * du * dx],
            );
            for i in 1..n {
                let nt = i * t_len + t;
                out.lxx
                    .copy_within(t * dx * dx..(t + 1) * dx * dx, nt * dx * dx);
                out.luu
                    .copy_within(t * du * du..(t + 1) * du * du, nt * du * du);
                out.lux
                    .copy_within(t * du * dx..(t + 1) * du * dx, nt * du * dx);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::layout::{DU, DX};

    const DY: usize = DX + DU;
    const D_IN: usize = 2 * DX;
    use crate::discriminator::{DiscriminatorConfig, Normalizer};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The composed function C(y) = D(s, F y + f) (or D(s, F y + f, t/(T − 1)) with a critic
    /// of 2 dX + 1 inputs) evaluated directly.
    fn composed(
        disc: &Discriminator,
        dyn_: &Dynamics,
        t: usize,
        horizon: usize,
        y: &[f64],
        ws: &mut Workspace,
    ) -> f64 {
        let mut x = vec![0.0; disc.input_dim()];
        if x.len() > D_IN {
            x[D_IN] = t as f64 / (horizon - 1) as f64;
        }
        x[..DX].copy_from_slice(&y[..DX]);
        if t + 1 >= horizon {
            x[DX..D_IN].copy_from_slice(&y[..DX]);
        } else {
            let f = dyn_.fm.slice(t);
            for i in 0..DX {
                x[DX + i] =
                    dyn_.fv.slice(t)[i] + (0..DY).map(|j| f[i * DY + j] * y[j]).sum::<f64>();
            }
        }
        disc.value(&x, ws)
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences_of_the_composed_function() {
        composed_function_check(D_IN);
    }

    /// With the phase as the critic's last input: its value enters C, its derivatives do not
    /// (the phase is a constant of the step).
    #[test]
    fn with_the_phase_input_gradient_and_hessian_match_finite_differences() {
        composed_function_check(D_IN + 1);
    }

    fn composed_function_check(d_in: usize) {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let cfg = DiscriminatorConfig {
            hidden: vec![16, 16],
            seed: 2,
            ..DiscriminatorConfig::default()
        };
        let mut norm = Normalizer::identity(d_in);
        for (j, s) in norm.std.iter_mut().enumerate() {
            *s = 0.5 + 0.1 * j as f64;
        }
        let disc = Discriminator::new(d_in, cfg, norm).unwrap();
        let horizon = 4;
        let mut dyn_ = Dynamics::zeros(horizon, DX, DU);
        for v in dyn_.fm.data.iter_mut() {
            *v = rng.random_range(-0.5..0.5);
        }
        for v in dyn_.fv.data.iter_mut() {
            *v = rng.random_range(-0.2..0.2);
        }
        let mut ws = CompositeWorkspace::new(&disc);
        let mut dws = disc.workspace();
        let h = 1e-5;
        let (mut worst_g, mut worst_h) = (0.0f64, 0.0f64);
        for t in [0, 2, 3] {
            let y: Vec<f64> = (0..DY).map(|_| rng.random_range(-1.0..1.0)).collect();
            let (mut lx, mut lu) = (vec![0.0; DX], vec![0.0; DU]);
            let (mut lxx, mut luu, mut lux) =
                (vec![0.0; DX * DX], vec![0.0; DU * DU], vec![0.0; DU * DX]);
            let v = expand_step(
                &disc,
                &dyn_,
                t,
                horizon,
                &y[..DX],
                &y[DX..],
                &mut ws,
                &mut lx,
                &mut lu,
                &mut lxx,
                &mut luu,
                &mut lux,
            );
            assert!((v - composed(&disc, &dyn_, t, horizon, &y, &mut dws)).abs() < 1e-14);
            let grad: Vec<f64> = lx.iter().chain(lu.iter()).copied().collect();
            let hess = |i: usize, j: usize| match (i < DX, j < DX) {
                (true, true) => lxx[i * DX + j],
                (false, false) => luu[(i - DX) * DU + j - DX],
                (false, true) => lux[(i - DX) * DX + j],
                (true, false) => lux[(j - DX) * DX + i],
            };
            let scale_g = grad.iter().fold(1e-3f64, |m, g| m.max(g.abs()));
            let mut scale_h = 1e-3f64;
            for i in 0..DY {
                for j in 0..DY {
                    scale_h = scale_h.max(hess(i, j).abs());
                }
            }
            for i in 0..DY {
                let (mut yp, mut ym) = (y.clone(), y.clone());
                yp[i] += h;
                ym[i] -= h;
                let fd = (composed(&disc, &dyn_, t, horizon, &yp, &mut dws)
                    - composed(&disc, &dyn_, t, horizon, &ym, &mut dws))
                    / (2.0 * h);
                worst_g = worst_g.max((fd - grad[i]).abs() / scale_g);
                for j in 0..DY {
                    let mut f = |di: f64, dj: f64| {
                        let mut z = y.clone();
                        z[i] += di;
                        z[j] += dj;
                        composed(&disc, &dyn_, t, horizon, &z, &mut dws)
                    };
                    let hh = 1e-4;
                    let fd2 = (f(hh, hh) - f(hh, -hh) - f(-hh, hh) + f(-hh, -hh)) / (4.0 * hh * hh);
                    worst_h = worst_h.max((fd2 - hess(i, j)).abs() / scale_h);
                }
            }
            if t + 1 >= horizon {
                assert!(
                    lu.iter()
                        .chain(luu.iter())
                        .chain(lux.iter())
                        .all(|v| *v == 0.0),
                    "last step is state-only"
                );
            }
        }
        eprintln!("composite cost: worst FD error gradient {worst_g:.2e}, Hessian {worst_h:.2e} (relative to the largest entry)");
        assert!(worst_g < 1e-8, "gradient FD error {worst_g:.2e}");
        assert!(worst_h < 1e-5, "Hessian FD error {worst_h:.2e}");
    }
}

#[cfg(test)]
mod psd_tests {
    use super::*;
    use ur5_shared::layout::{StateLayout, DU, DX};

    const DY: usize = DX + DU;
    const D_IN: usize = 2 * DX;
    use crate::discriminator::{DiscriminatorConfig, Normalizer};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn projection_is_psd_and_leaves_psd_matrices_alone() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let n = 6;
        let a = Mat::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
        let mut sym = Mat::from_fn(n, n, |i, j| a[(i, j)] + a[(j, i)]);
        let before = sym.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
        assert!(before[0] < 0.0, "test matrix should be indefinite");
        project_psd(&mut sym);
        let after = sym.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
        assert!(after[0] > -1e-12, "projection left eigenvalue {}", after[0]);
        // The positive eigenvalues are kept.
        let kept: Vec<f64> = before.iter().copied().filter(|l| *l > 0.0).collect();
        for (k, l) in kept.iter().rev().zip(after.iter().rev()) {
            assert!((k - l).abs() < 1e-10);
        }
        // A PSD matrix is unchanged.
        let psd = Mat::from_fn(n, n, |i, j| {
            (0..n).map(|k| a[(i, k)] * a[(j, k)]).sum::<f64>()
        });
        let mut copy = psd.clone();
        project_psd(&mut copy);
        assert_eq!(copy, psd);
    }

    /// Without projection the batch expansion is each sample's own [`expand_step`]; with it,
    /// every sample at step t carries `M_tᵀ proj(mean_i ∇²D_i) M_t`, which is PSD.
    #[test]
    fn batch_expansion_matches_per_sample_and_projects_the_mean() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let cfg = DiscriminatorConfig {
            hidden: vec![16, 16],
            seed: 3,
            ..DiscriminatorConfig::default()
        };
        let disc = Discriminator::new(D_IN, cfg, Normalizer::identity(D_IN)).unwrap();
        let (horizon, n) = (3, 4);
        let mut dyn_ = Dynamics::zeros(horizon, DX, DU);
        for v in dyn_.fm.data.iter_mut() {
            *v = rng.random_range(-0.5..0.5);
        }
        let episodes: Vec<Episode> = (0..n)
            .map(|_| {
                let mut draw = |len: usize| -> Vec<f64> {
                    (0..len).map(|_| rng.random_range(-1.0..1.0)).collect()
                };
                Episode {
                    layout: StateLayout::REACH3,
                    x: draw(horizon * DX),
                    u: draw(horizon * DU),
                    u_policy: vec![0.0; horizon * DU],
                    eps: vec![0.0; horizon * DU],
                    noisy: true,
                }
            })
            .collect();
        let mut ws = CompositeWorkspace::new(&disc);
        let mut exact = CostDerivs::default();
        composite_cost_derivs(&disc, &dyn_, &episodes, &mut ws, &mut exact);
        let (mut lx, mut lu) = (vec![0.0; DX], vec![0.0; DU]);
        let (mut lxx, mut luu, mut lux) =
            (vec![0.0; DX * DX], vec![0.0; DU * DU], vec![0.0; DU * DX]);
        for (i, ep) in episodes.iter().enumerate() {
            for t in 0..horizon {
                let nt = i * horizon + t;
                let l = expand_step(
                    &disc,
                    &dyn_,
                    t,
                    horizon,
                    &ep.x[t * DX..(t + 1) * DX],
                    &ep.u[t * DU..(t + 1) * DU],
                    &mut ws,
                    &mut lx,
                    &mut lu,
                    &mut lxx,
                    &mut luu,
                    &mut lux,
                );
                assert_eq!(l, exact.l[nt]);
                assert_eq!(lx, exact.lx[nt * DX..(nt + 1) * DX]);
                assert_eq!(lu, exact.lu[nt * DU..(nt + 1) * DU]);
                assert_eq!(lxx, exact.lxx[nt * DX * DX..(nt + 1) * DX * DX]);
                assert_eq!(luu, exact.luu[nt * DU * DU..(nt + 1) * DU * DU]);
                assert_eq!(lux, exact.lux[nt * DU * DX..(nt + 1) * DU * DX]);
            }
        }
        let mut ws = CompositeWorkspace::new(&disc).with_psd(true);
        let mut proj = CostDerivs::default();
        composite_cost_derivs(&disc, &dyn_, &episodes, &mut ws, &mut proj);
        assert_eq!(proj.l, exact.l);
        assert_eq!(proj.lx, exact.lx);
        assert_eq!(proj.lu, exact.lu);
        let mut some_changed = false;
        for t in 0..horizon {
            // The full (dX + dU) Hessian of sample 0 at t, and of the exact mean.
            let full = |d: &CostDerivs, nt: usize| {
                Mat::from_fn(DY, DY, |i, j| match (i < DX, j < DX) {
                    (true, true) => d.lxx[nt * DX * DX + i * DX + j],
                    (false, false) => d.luu[nt * DU * DU + (i - DX) * DU + j - DX],
                    (false, true) => d.lux[nt * DU * DX + (i - DX) * DX + j],
                    (true, false) => d.lux[nt * DU * DX + (j - DX) * DX + i],
                })
            };
            let p0 = full(&proj, t);
            for i in 1..n {
                assert_eq!(
                    full(&proj, i * horizon + t),
                    p0,
                    "same Hessian for every sample"
                );
            }
            let lam = p0.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
            assert!(
                lam[0] > -1e-10 * lam[DY - 1].abs().max(1.0),
                "not PSD: {}",
                lam[0]
            );
            let mut mean = Mat::<f64>::zeros(DY, DY);
            for i in 0..n {
                mean += full(&exact, i * horizon + t);
            }
            mean *= faer::Scale(1.0 / n as f64);
            let e = mean.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
            some_changed |= e[0] < -1e-8;
        }
        assert!(
            some_changed,
            "test data should have an indefinite mean Hessian"
        );
    }
}
