//! The critic network: a tanh MLP with a scalar linear output, and its exact derivatives.
//!
//! Notation (layer `k = 0..L−1`, `L = sizes.len() − 1`, `n_k = sizes[k]`, `n_L = 1`):
//!
//! ```text
//! z_{-1} = u                              (normalised input, n_0)
//! a_k    = W_k z_{k−1} + b_k,  z_k = tanh(a_k)     k = 0..L−2   (hidden)
//! y      = W_{L−1} z_{L−2} + b_{L−1}               (scalar, linear)
//! ```
//!
//! `W_k` is `n_{k+1} × n_k`, row-major. All parameters live in one flat vector `θ`, layer by
//! layer, `W_k` then `b_k` (see [`Mlp::weight_range`], [`Mlp::bias_range`]).
//!
//! Everything here is in the network's own (normalised) input `u`; the chain rule through the
//! input normalisation is applied by [`super::Discriminator`].
//!
//! Derivatives (with `s'_k = 1 − z_k²`, `s''_k = −2 z_k s'_k`):
//! - backward pass: `g_{L−2} = W_{L−1}ᵀ`, `δ_k = g_k ⊙ s'_k`, `g_{k−1} = W_kᵀ δ_k`, so that
//!   `∂y/∂u = W_0ᵀ δ_0`, `∂y/∂W_k = δ_k z_{k−1}ᵀ`, `∂y/∂b_k = δ_k`;
//! - input Hessian: the only curvature is in the tanh units, so
//!   `∇²_u y = Σ_k J_kᵀ diag(g_k ⊙ s''_k) J_k` with `J_k = ∂a_k/∂u` (forward mode:
//!   `J_0 = W_0`, `J_k = W_k diag(s'_{k−1}) J_{k−1}`);
//! - gradient of `φ(θ) = ρᵀ ∇_u y(u; θ)` for a fixed direction `ρ` (what the gradient penalty
//!   needs): `φ` is the tangent `ẏ` of the forward pass pushed along `u̇ = ρ`,
//!   `ȧ_k = W_k ż_{k−1}`, `ż_k = s'_k ⊙ ȧ_k`, `ẏ = W_{L−1} ż_{L−2}`, and `∂φ/∂θ` is reverse mode
//!   through the primal and tangent passes together (Pearlmutter 1994's R-operator, then
//!   backprop): with adjoints `ż̄_{L−2} = W_{L−1}ᵀ`, `z̄_{L−2} = 0`,
//!   `ǡ_k = s'_k ⊙ ż̄_k`, `ā_k = ż̄_k ⊙ ȧ_k ⊙ s''_k + z̄_k ⊙ s'_k`,
//!   `∂φ/∂W_k = ǡ_k ż_{k−1}ᵀ + ā_k z_{k−1}ᵀ`, `∂φ/∂b_k = ā_k`, `∂φ/∂W_{L−1} = ż_{L−2}ᵀ`,
//!   `ż̄_{k−1} = W_kᵀ ǡ_k`, `z̄_{k−1} = W_kᵀ ā_k` (with `ż_{−1} = ρ`, `z_{−1} = u`).

use rand::Rng;
// The one dot product, affine map and tanh of every MLP (the controller's policy_action uses
// the same, so learner and controller agree bit for bit).
use ur5_shared::kernels::{
    affine, axpy, dot, mat_t_vec, outer_acc, sym_outer_acc_upper, tanh_in_place,
};

/// A tanh MLP `R^{n_0} → R` with a flat parameter vector (layout in the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    sizes: Vec<usize>,
    params: Vec<f64>,
    /// Start of `W_k` in `params`, for `k = 0..L`, plus the total length at the end.
    offsets: Vec<usize>,
    /// Start of hidden layer `k` in the workspace's per-unit buffers, plus the total at the end.
    hidden_offsets: Vec<usize>,
}

/// Number of parameters of a net with these layer sizes.
pub(crate) fn param_count(sizes: &[usize]) -> usize {
    sizes.windows(2).map(|w| w[1] * w[0] + w[1]).sum()
}

impl Mlp {
    /// A net with all-zero parameters. `sizes = [n_0, h_1, ..., h_m, 1]` with `m ≥ 1`
    /// (checked by the caller, [`super::DiscriminatorConfig::validate`]).
    pub(crate) fn zeros(sizes: &[usize]) -> Self {
        assert!(sizes.len() >= 3 && *sizes.last().unwrap() == 1);
        let mut offsets = Vec::with_capacity(sizes.len());
        let mut off = 0;
        offsets.push(0);
        for w in sizes.windows(2) {
            off += w[1] * w[0] + w[1];
            offsets.push(off);
        }
        let mut hidden_offsets = vec![0];
        for &h in &sizes[1..sizes.len() - 1] {
            hidden_offsets.push(hidden_offsets.last().unwrap() + h);
        }
        Self {
            sizes: sizes.to_vec(),
            params: vec![0.0; off],
            offsets,
            hidden_offsets,
        }
    }

    /// Glorot & Bengio (2010) uniform initialisation, the usual choice for tanh units:
    /// `W_k ~ U[−a, a]`, `a = sqrt(6 / (fan_in + fan_out))`, biases zero.
    pub(crate) fn glorot(sizes: &[usize], rng: &mut impl Rng) -> Self {
        let mut net = Self::zeros(sizes);
        for k in 0..net.layers() {
            let (n_in, n_out) = (sizes[k], sizes[k + 1]);
            let a = (6.0 / (n_in + n_out) as f64).sqrt();
            let r = net.weight_range(k);
            for w in &mut net.params[r] {
                *w = rng.random_range(-a..a);
            }
        }
        net
    }

    /// Wraps a flat parameter vector (length checked by the caller).
    pub(crate) fn from_params(sizes: &[usize], params: Vec<f64>) -> Self {
        let mut net = Self::zeros(sizes);
        assert_eq!(params.len(), net.params.len());
        net.params = params;
        net
    }

    /// `[n_0, h_1, ..., 1]`.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// Number of affine layers `L` (hidden layers + the output layer).
    pub fn layers(&self) -> usize {
        self.sizes.len() - 1
    }

    /// Input dimension `n_0`.
    pub fn input_dim(&self) -> usize {
        self.sizes[0]
    }

    /// The flat parameter vector `θ`.
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    pub(crate) fn params_mut(&mut self) -> &mut [f64] {
        &mut self.params
    }

    /// Where `W_k` (row-major `n_{k+1} × n_k`) sits in `θ`.
    pub fn weight_range(&self, k: usize) -> std::ops::Range<usize> {
        let s = self.offsets[k];
        s..s + self.sizes[k + 1] * self.sizes[k]
    }

    /// Where `b_k` (`n_{k+1}`) sits in `θ`.
    pub fn bias_range(&self, k: usize) -> std::ops::Range<usize> {
        let s = self.offsets[k] + self.sizes[k + 1] * self.sizes[k];
        s..s + self.sizes[k + 1]
    }

    fn w(&self, k: usize) -> &[f64] {
        &self.params[self.weight_range(k)]
    }

    fn b(&self, k: usize) -> &[f64] {
        &self.params[self.bias_range(k)]
    }

    fn hidden(&self, k: usize) -> std::ops::Range<usize> {
        self.hidden_offsets[k]..self.hidden_offsets[k + 1]
    }

    /// Forward pass `y(u)`; `u` is read from `ws.u`. Keeps the hidden outputs `z_k` in `ws`.
    pub(crate) fn forward(&self, ws: &mut MlpWorkspace) -> f64 {
        let l = self.layers();
        for k in 0..l - 1 {
            let (prev, cur) = ws.z.split_at_mut(self.hidden_offsets[k]);
            let input: &[f64] = if k == 0 {
                &ws.u
            } else {
                &prev[self.hidden(k - 1)]
            };
            let out = &mut cur[..self.sizes[k + 1]];
            affine(self.w(k), self.b(k), input, out);
            tanh_in_place(out);
        }
        dot(self.w(l - 1), &ws.z[self.hidden(l - 2)]) + self.b(l - 1)[0]
    }

    /// Backward pass after [`Self::forward`]: `g_k = ∂y/∂z_k`, `δ_k = ∂y/∂a_k` for every hidden
    /// layer, and `ws.grad_u = ∂y/∂u` if `input_grad`.
    pub(crate) fn backward(&self, ws: &mut MlpWorkspace, input_grad: bool) {
        let l = self.layers();
        let top = l - 2;
        ws.g[self.hidden(top)].copy_from_slice(self.w(l - 1));
        for k in (0..=top).rev() {
            let r = self.hidden(k);
            for ((d, &g), &z) in ws.delta[r.clone()]
                .iter_mut()
                .zip(&ws.g[r.clone()])
                .zip(&ws.z[r.clone()])
            {
                *d = g * (1.0 - z * z);
            }
            if k > 0 {
                let (n_out, n_in) = (self.sizes[k + 1], self.sizes[k]);
                let below = self.hidden(k - 1);
                mat_t_vec(self.w(k), n_out, n_in, &ws.delta[r], &mut ws.g[below]);
            }
        }
        if input_grad {
            let (n_out, n_in) = (self.sizes[1], self.sizes[0]);
            mat_t_vec(
                self.w(0),
                n_out,
                n_in,
                &ws.delta[self.hidden(0)],
                &mut ws.grad_u,
            );
        }
    }

    /// `grad += c ∂y/∂θ` after [`Self::forward`] and [`Self::backward`].
    pub(crate) fn accumulate_param_grad(&self, ws: &MlpWorkspace, c: f64, grad: &mut [f64]) {
        let l = self.layers();
        let top = self.hidden(l - 2);
        axpy(c, &ws.z[top], &mut grad[self.weight_range(l - 1)]);
        grad[self.bias_range(l - 1)][0] += c;
        for k in 0..l - 1 {
            let input: &[f64] = if k == 0 {
                &ws.u
            } else {
                &ws.z[self.hidden(k - 1)]
            };
            let delta = &ws.delta[self.hidden(k)];
            let wr = self.weight_range(k);
            outer_acc(c, delta, input, &mut grad[wr]);
            axpy(c, delta, &mut grad[self.bias_range(k)]);
        }
    }

    /// `∇²_u y` into `hess` (row-major `n_0 × n_0`, fully written, symmetric) after
    /// [`Self::forward`] and [`Self::backward`]: `Σ_k J_kᵀ diag(g_k ⊙ s''_k) J_k`.
    pub(crate) fn input_hessian(&self, ws: &mut MlpWorkspace, hess: &mut [f64]) {
        let n0 = self.sizes[0];
        hess.fill(0.0);
        // J_0 = W_0.
        ws.jac_a[..self.sizes[1] * n0].copy_from_slice(self.w(0));
        self.add_curvature_from(0, n0, ws, &mut hess[..n0 * n0]);
    }

    /// `∇²_{a_0} y` into `b` (row-major `h_1 × h_1`, fully written, symmetric) after
    /// [`Self::forward`] and [`Self::backward`]: the Hessian in the first layer's
    /// pre-activations, so that `∇²_u y = W_0ᵀ (∇²_{a_0} y) W_0` (`a_0 = W_0 u + b_0` is affine
    /// in u). The same sum as [`Self::input_hessian`] with `J_0 = I` in place of `W_0`:
    /// `Σ_k G_kᵀ diag(g_k ⊙ s''_k) G_k`, `G_0 = I`, `G_k = W_k diag(s'_{k−1}) G_{k−1}`; the
    /// first term is diagonal and `G_1` is `W_1` with its columns scaled, so neither takes a
    /// product. Per point `O(h² h_1)` against the input Hessian's `O(h² n_0 + h n_0²)`: cheaper
    /// when the net's input is wider than its first layer, where the mean of many points'
    /// input Hessians is `W_0ᵀ (mean ∇²_{a_0} y) W_0` ([`super::MeanHessian`]).
    pub(crate) fn first_layer_hessian(&self, ws: &mut MlpWorkspace, b: &mut [f64]) {
        let h1 = self.sizes[1];
        let b = &mut b[..h1 * h1];
        b.fill(0.0);
        let r0 = self.hidden(0);
        for (i, (&g, &z)) in ws.g[r0.clone()].iter().zip(&ws.z[r0.clone()]).enumerate() {
            b[i * h1 + i] = g * (-2.0 * z * (1.0 - z * z));
        }
        if self.layers() > 2 {
            // G_1 = W_1 diag(s'_0).
            let (n, w, z0) = (self.sizes[2], self.w(1), &ws.z[r0]);
            for i in 0..n {
                let row = &mut ws.jac_a[i * h1..(i + 1) * h1];
                for ((v, &wij), &z) in row.iter_mut().zip(&w[i * h1..(i + 1) * h1]).zip(z0) {
                    *v = wij * (1.0 - z * z);
                }
            }
            self.add_curvature_from(1, h1, ws, b);
        }
    }

    /// The curvature of hidden layers `start..`, `Σ_k J_kᵀ diag(g_k ⊙ s''_k) J_k`, added into
    /// `hess` (row-major `cols × cols`, then mirrored from its upper triangle), with
    /// `J_start` (`n_{start+1} × cols`, row-major) in `ws.jac_a` and
    /// `J_k = W_k diag(s'_{k−1}) J_{k−1}` after it: the recursion of [`Self::input_hessian`]
    /// (from `J_0 = W_0`) and of [`Self::first_layer_hessian`] (from `G_1`).
    fn add_curvature_from(
        &self,
        start: usize,
        cols: usize,
        ws: &mut MlpWorkspace,
        hess: &mut [f64],
    ) {
        for k in start..self.layers() - 1 {
            let n = self.sizes[k + 1];
            if k > start {
                // J_k = W_k diag(s'_{k−1}) J_{k−1}; J_{k−1} (in jac_a) has had its rows scaled.
                let n_in = self.sizes[k];
                let w = self.w(k);
                let (prev, cur) = (&ws.jac_a[..n_in * cols], &mut ws.jac_b[..n * cols]);
                for i in 0..n {
                    let row = &mut cur[i * cols..(i + 1) * cols];
                    mat_t_vec(prev, n_in, cols, &w[i * n_in..(i + 1) * n_in], row);
                }
                std::mem::swap(&mut ws.jac_a, &mut ws.jac_b);
            }
            let r = self.hidden(k);
            let jac = &mut ws.jac_a[..n * cols];
            for (i, (&g, &z)) in ws.g[r.clone()].iter().zip(&ws.z[r]).enumerate() {
                let sp = 1.0 - z * z;
                let c = g * (-2.0 * z * sp);
                let row = &mut jac[i * cols..(i + 1) * cols];
                // Upper triangle of c · row rowᵀ.
                sym_outer_acc_upper(c, row, &mut hess[..cols * cols]);
                // Scale the row by s'_k for the next layer's Jacobian.
                for v in row.iter_mut() {
                    *v *= sp;
                }
            }
        }
        for p in 0..cols {
            for q in 0..p {
                hess[p * cols + q] = hess[q * cols + p];
            }
        }
    }

    /// The first layer's weights `W_0` (row-major `h_1 × n_0`).
    pub(crate) fn first_weights(&self) -> &[f64] {
        self.w(0)
    }

    /// `grad += ∂/∂θ (ρᵀ ∇_u y(u; θ))` for the direction `ρ = ws.rho`, after
    /// [`Self::forward`] and [`Self::backward`] (the tangent/adjoint recursion in the module
    /// docs). Returns `ρᵀ ∇_u y` (the tangent output `ẏ`).
    pub(crate) fn accumulate_directional_grad_param_grad(
        &self,
        ws: &mut MlpWorkspace,
        grad: &mut [f64],
    ) -> f64 {
        let l = self.layers();
        let top = l - 2;
        // Tangent forward pass.
        for k in 0..=top {
            let (n_out, n_in) = (self.sizes[k + 1], self.sizes[k]);
            let r = self.hidden(k);
            let (prev, cur) = ws.tz.split_at_mut(self.hidden_offsets[k]);
            let tin: &[f64] = if k == 0 {
                &ws.rho
            } else {
                &prev[self.hidden(k - 1)]
            };
            let ta = &mut ws.ta[r.clone()];
            mat_vec(self.w(k), n_out, n_in, tin, ta);
            for ((tz, &ta), &z) in cur[..n_out].iter_mut().zip(ta.iter()).zip(&ws.z[r]) {
                *tz = (1.0 - z * z) * ta;
            }
        }
        let ydot = dot(self.w(l - 1), &ws.tz[self.hidden(top)]);

        // Reverse pass through the primal and tangent computations together.
        axpy(
            1.0,
            &ws.tz[self.hidden(top)],
            &mut grad[self.weight_range(l - 1)],
        );
        let n_top = self.sizes[top + 1];
        ws.bar_tz[..n_top].copy_from_slice(self.w(l - 1));
        ws.bar_z[..n_top].fill(0.0);
        for k in (0..=top).rev() {
            let (n_out, n_in) = (self.sizes[k + 1], self.sizes[k]);
            let r = self.hidden(k);
            for i in 0..n_out {
                let z = ws.z[r.start + i];
                let sp = 1.0 - z * z;
                let spp = -2.0 * z * sp;
                let btz = ws.bar_tz[i];
                ws.bar_ta[i] = sp * btz;
                ws.bar_a[i] = btz * ws.ta[r.start + i] * spp + ws.bar_z[i] * sp;
            }
            let (input, tin): (&[f64], &[f64]) = if k == 0 {
                (&ws.u, &ws.rho)
            } else {
                let rb = self.hidden(k - 1);
                (&ws.z[rb.clone()], &ws.tz[rb])
            };
            let wr = self.weight_range(k);
            outer_acc(1.0, &ws.bar_ta[..n_out], tin, &mut grad[wr.clone()]);
            outer_acc(1.0, &ws.bar_a[..n_out], input, &mut grad[wr]);
            axpy(1.0, &ws.bar_a[..n_out], &mut grad[self.bias_range(k)]);
            if k > 0 {
                mat_t_vec(
                    self.w(k),
                    n_out,
                    n_in,
                    &ws.bar_ta[..n_out],
                    &mut ws.bar_tz[..n_in],
                );
                mat_t_vec(
                    self.w(k),
                    n_out,
                    n_in,
                    &ws.bar_a[..n_out],
                    &mut ws.bar_z[..n_in],
                );
            }
        }
        ydot
    }
}

/// Scratch space for one [`Mlp`] size: built once, reused for every sample (no allocation in
/// the passes).
#[derive(Clone, Debug)]
pub struct MlpWorkspace {
    sizes: Vec<usize>,
    /// Network input `u` (`n_0`).
    pub(crate) u: Vec<f64>,
    /// `∂y/∂u` (`n_0`).
    pub(crate) grad_u: Vec<f64>,
    /// Tangent direction `ρ` at the input (`n_0`).
    pub(crate) rho: Vec<f64>,
    /// Per hidden unit, all hidden layers stacked: `z_k`, `g_k`, `δ_k`, `ȧ_k`, `ż_k`.
    z: Vec<f64>,
    g: Vec<f64>,
    delta: Vec<f64>,
    ta: Vec<f64>,
    tz: Vec<f64>,
    /// One layer's adjoints (`max h`).
    bar_tz: Vec<f64>,
    bar_z: Vec<f64>,
    bar_ta: Vec<f64>,
    bar_a: Vec<f64>,
    /// Two `max h × n_0` Jacobian buffers for the input Hessian.
    jac_a: Vec<f64>,
    jac_b: Vec<f64>,
}

impl MlpWorkspace {
    pub(crate) fn new(sizes: &[usize]) -> Self {
        let n0 = sizes[0];
        let hidden = &sizes[1..sizes.len() - 1];
        let total: usize = hidden.iter().sum();
        let max_h = hidden.iter().copied().max().unwrap_or(0);
        Self {
            sizes: sizes.to_vec(),
            u: vec![0.0; n0],
            grad_u: vec![0.0; n0],
            rho: vec![0.0; n0],
            z: vec![0.0; total],
            g: vec![0.0; total],
            delta: vec![0.0; total],
            ta: vec![0.0; total],
            tz: vec![0.0; total],
            bar_tz: vec![0.0; max_h],
            bar_z: vec![0.0; max_h],
            bar_ta: vec![0.0; max_h],
            bar_a: vec![0.0; max_h],
            // J_k of the input Hessian (n_0 columns) or of the first layer's (h_1 columns).
            jac_a: vec![0.0; max_h * n0.max(max_h)],
            jac_b: vec![0.0; max_h * n0.max(max_h)],
        }
    }

    /// Layer sizes this workspace was built for.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }
}

/// `out = W x`, `W` row-major `rows × cols`.
#[inline]
fn mat_vec(w: &[f64], rows: usize, cols: usize, x: &[f64], out: &mut [f64]) {
    for i in 0..rows {
        out[i] = dot(&w[i * cols..(i + 1) * cols], x);
    }
}
