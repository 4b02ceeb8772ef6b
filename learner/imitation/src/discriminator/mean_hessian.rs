//! The mean of the critic's input Hessian over many points, `(1/N) Σ_n ∇²ₓD(x_n)`: what the
//! composite cost's PSD mode needs at each time step (docs/design.md §5 D4).
//!
//! Two routes, the same quantity:
//! - **per point**: each point's `∇²ₓD` ([`Discriminator::value_gradient_hessian`]), summed,
//!   then divided by N. `O(h² n_0 + h n_0²)` a point (n_0 the net's inputs, h its widths).
//! - **through the first layer** (when the net's input is wider than its first layer,
//!   n_0 > h_1): with `a_0 = W_0 u + b_0` and u(x) the normalised, warped inputs,
//!   `∇²ₓD = Vᵀ B V + diag(∂D/∂u_p g''_p/σ_p)`, `B = ∇²_{a_0} D` (h_1 × h_1,
//!   [`Mlp::first_layer_hessian`]) and `V = W_0 J` (h_1 × d), J = ∂u/∂x. V's column p is
//!   `W_0[:, p] g'_p/σ_p` plus `W_0[:, d + k]/σ_{d+k}` where input p has a raw copy d + k
//!   ([`DiscriminatorConfig::near_goal_keep_raw`]). The columns of inputs that are neither
//!   warped nor copied (C) are the same at every point; only the others (P, the tool points'
//!   under the near-goal warp) vary. So
//!   - `mean[C, C] = V_Cᵀ (Σ_n B_n) V_C / N`: one product a step,
//!   - `mean[P, C] = (Σ_n B_n V_{P,n})ᵀ V_C / N`,
//!   - `mean[P, P] = Σ_n V_{P,n}ᵀ B_n V_{P,n} / N`,
//!
//!   at `O(h² h_1 + h_1² |P|)` a point. Equal to the per-point route up to rounding (tested);
//!   the per-point route is kept where it is the cheaper one (n_0 ≤ h_1, e.g. every
//!   three-joint critic), so its results keep their bits.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

use super::{raw_copy, Discriminator, Mlp, Workspace};
use ur5_shared::kernels::axpy;

/// Accumulates `∇²ₓD` over points, [`MeanHessian::add`], and gives their mean,
/// [`MeanHessian::mean_into`]. Build once per critic shape ([`Discriminator::mean_hessian`]);
/// [`MeanHessian::prepare`] before each expansion (the critic's weights may have changed).
pub struct MeanHessian {
    /// Through the first layer (module docs) rather than per point.
    factored: bool,
    /// Transition inputs d and first-layer width h_1.
    d: usize,
    h1: usize,
    /// Points added since the last [`Self::mean_into`].
    n: usize,
    /// Per point: the running sum of ∇²ₓD (d × d) and one point's.
    sum: Mat<f64>,
    one: Mat<f64>,
    /// Through the first layer: the inputs whose column of V is fixed (C) and those whose
    /// column varies (P), each P with its raw copy's net input if it has one.
    fixed: Vec<usize>,
    varying: Vec<(usize, Option<usize>)>,
    /// Wᵀ_0 (n_0 × h_1, a column of W_0 a row), V_C (|C| × h_1, a column a row).
    w0t: Vec<f64>,
    v_fixed: Vec<f64>,
    /// Σ B_n (h_1 × h_1), Σ B_n V_{P,n} (h_1 × |P|), Σ V_{P,n}ᵀ B_n V_{P,n} (|P| × |P|),
    /// Σ of the diagonal warp term (d). The matrices here are column-major (B is symmetric).
    b_sum: Vec<f64>,
    bv_sum: Vec<f64>,
    pp_sum: Vec<f64>,
    diag_sum: Vec<f64>,
    /// One point's B, V_P (h_1 × |P|) and B V_P; at the mean, (Σ B) V_C (h_1 × |C|), its
    /// product with V_Cᵀ (|C| × |C|) and (Σ B V_P)ᵀ V_C (|P| × |C|).
    b: Vec<f64>,
    v: Vec<f64>,
    bv: Vec<f64>,
    t: Vec<f64>,
    cc: Vec<f64>,
    pc: Vec<f64>,
}

/// The column-major `rows × cols` matrix in `v`.
fn mat(v: &[f64], rows: usize, cols: usize) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(&v[..rows * cols], rows, cols)
}

/// [`mat`], writable.
fn mat_mut(v: &mut [f64], rows: usize, cols: usize) -> MatMut<'_, f64> {
    MatMut::from_column_major_slice_mut(&mut v[..rows * cols], rows, cols)
}

impl Discriminator {
    /// An accumulator of this critic's mean input Hessian, on the cheaper route for its shape
    /// (module docs of [`MeanHessian`]).
    pub fn mean_hessian(&self) -> MeanHessian {
        self.mean_hessian_on(self.net.input_dim() > self.net.sizes()[1])
    }

    /// [`Self::mean_hessian`] on the route asked for (`factored`: through the first layer).
    pub(crate) fn mean_hessian_on(&self, factored: bool) -> MeanHessian {
        let (d, n0, h1) = (self.input_dim(), self.net.input_dim(), self.net.sizes()[1]);
        let mut copy = vec![None; d];
        for k in 0..self.extra_inputs() {
            copy[raw_copy(k, d)] = Some(d + k);
        }
        let (mut fixed, mut varying) = (Vec::new(), Vec::new());
        for (p, &c) in copy.iter().enumerate() {
            if self.config.warps(p, d) || c.is_some() {
                varying.push((p, c));
            } else {
                fixed.push(p);
            }
        }
        let (nc, np) = (fixed.len(), varying.len());
        // Buffers of the route taken; the other's stay empty.
        let big = |n: usize| if factored { n } else { 0 };
        let small = |n: usize| if factored { 0 } else { n };
        MeanHessian {
            factored,
            d,
            h1,
            n: 0,
            sum: Mat::zeros(small(d), small(d)),
            one: Mat::zeros(small(d), small(d)),
            fixed,
            varying,
            w0t: vec![0.0; big(n0 * h1)],
            v_fixed: vec![0.0; big(nc * h1)],
            b_sum: vec![0.0; big(h1 * h1)],
            bv_sum: vec![0.0; big(np * h1)],
            pp_sum: vec![0.0; big(np * np)],
            diag_sum: vec![0.0; big(d)],
            b: vec![0.0; big(h1 * h1)],
            v: vec![0.0; big(np * h1)],
            bv: vec![0.0; big(np * h1)],
            t: vec![0.0; big(h1 * nc)],
            cc: vec![0.0; big(nc * nc)],
            pc: vec![0.0; big(np * nc)],
        }
    }

    /// `D(x)`, `∇ₓD(x)` into `grad` (as [`Self::value_gradient`]), and `∇²ₓD(x)` added to
    /// `acc`.
    pub fn value_gradient_add_hessian(
        &self,
        x: &[f64],
        ws: &mut Workspace,
        grad: &mut [f64],
        acc: &mut MeanHessian,
    ) -> f64 {
        assert_eq!(
            acc.d,
            self.input_dim(),
            "accumulator built for another critic"
        );
        acc.n += 1;
        if !acc.factored {
            let y = self.value_gradient_hessian(x, ws, grad, acc.one.as_mut());
            acc.sum += &acc.one;
            return y;
        }
        let y = self.value_gradient(x, ws, grad);
        self.net.first_layer_hessian(&mut ws.mlp, &mut acc.b);
        let (d, h1, s) = (acc.d, acc.h1, &self.norm.std);
        axpy(1.0, &acc.b, &mut acc.b_sum);
        for (i, &(p, copy)) in acc.varying.iter().enumerate() {
            let (g1, g2) = self.config.warp_derivatives(p, d, x[p]);
            let col = &mut acc.v[i * h1..(i + 1) * h1];
            col.fill(0.0);
            axpy(g1 / s[p], &acc.w0t[p * h1..(p + 1) * h1], col);
            if let Some(c) = copy {
                axpy(1.0 / s[c], &acc.w0t[c * h1..(c + 1) * h1], col);
            }
            acc.diag_sum[p] += ws.mlp.grad_u[p] / s[p] * g2;
        }
        let np = acc.varying.len();
        if np > 0 {
            // B V_P, then Σ B V_P and Σ V_Pᵀ (B V_P).
            let (b, v) = (mat(&acc.b, h1, h1), mat(&acc.v, h1, np));
            matmul(
                mat_mut(&mut acc.bv, h1, np),
                Accum::Replace,
                b,
                v,
                1.0,
                Par::Seq,
            );
            axpy(1.0, &acc.bv[..np * h1], &mut acc.bv_sum);
            let bv = mat(&acc.bv, h1, np);
            let pp = mat_mut(&mut acc.pp_sum, np, np);
            matmul(pp, Accum::Add, v.transpose(), bv, 1.0, Par::Seq);
        }
        y
    }
}

impl MeanHessian {
    /// Whether this accumulator goes through the first layer (module docs).
    pub fn factored(&self) -> bool {
        self.factored
    }

    /// Takes the fixed parts from `disc`'s current weights and normalisation and empties the
    /// sums. Call before the points of each expansion.
    pub fn prepare(&mut self, disc: &Discriminator) {
        assert_eq!(
            self.d,
            disc.input_dim(),
            "accumulator built for another critic"
        );
        self.clear();
        if !self.factored {
            return;
        }
        let net: &Mlp = disc.net();
        let (n0, h1) = (net.input_dim(), self.h1);
        let w0 = net.first_weights();
        for r in 0..h1 {
            for c in 0..n0 {
                self.w0t[c * h1 + r] = w0[r * n0 + c];
            }
        }
        let s = &disc.normalizer().std;
        for (i, &p) in self.fixed.iter().enumerate() {
            let col = &mut self.v_fixed[i * h1..(i + 1) * h1];
            col.fill(0.0);
            axpy(1.0 / s[p], &self.w0t[p * h1..(p + 1) * h1], col);
        }
    }

    fn clear(&mut self) {
        self.n = 0;
        if self.factored {
            self.b_sum.fill(0.0);
            self.bv_sum.fill(0.0);
            self.pp_sum.fill(0.0);
            self.diag_sum.fill(0.0);
        } else {
            self.sum.fill(0.0);
        }
    }

    /// The mean of the Hessians added since the last call (or [`Self::prepare`]) into `out`
    /// (d × d, symmetric), and empties the sums.
    pub fn mean_into(&mut self, mut out: MatMut<'_, f64>) {
        assert!(self.n > 0, "no point added");
        assert!(
            out.nrows() == self.d && out.ncols() == self.d,
            "mean Hessian must be d × d"
        );
        let inv_n = 1.0 / self.n as f64;
        if !self.factored {
            for j in 0..self.d {
                for i in 0..self.d {
                    out[(i, j)] = self.sum[(i, j)] * inv_n;
                }
            }
            self.clear();
            return;
        }
        let (h1, nc, np) = (self.h1, self.fixed.len(), self.varying.len());
        let vc = mat(&self.v_fixed, h1, nc);
        // mean[C, C] = V_Cᵀ (Σ B) V_C / N.
        let b_sum = mat(&self.b_sum, h1, h1);
        matmul(
            mat_mut(&mut self.t, h1, nc),
            Accum::Replace,
            b_sum,
            vc,
            1.0,
            Par::Seq,
        );
        let t = mat(&self.t, h1, nc);
        matmul(
            mat_mut(&mut self.cc, nc, nc),
            Accum::Replace,
            vc.transpose(),
            t,
            inv_n,
            Par::Seq,
        );
        // mean[P, C] = (Σ B V_P)ᵀ V_C / N.
        let bv_sum = mat(&self.bv_sum, h1, np);
        matmul(
            mat_mut(&mut self.pc, np, nc),
            Accum::Replace,
            bv_sum.transpose(),
            vc,
            inv_n,
            Par::Seq,
        );
        let (cc, pc, pp) = (
            mat(&self.cc, nc, nc),
            mat(&self.pc, np, nc),
            mat(&self.pp_sum, np, np),
        );
        // Each symmetric block from its upper triangle, so that the mean is symmetric bit for bit.
        for (a, &p) in self.fixed.iter().enumerate() {
            for (c, &q) in self.fixed.iter().enumerate().skip(a) {
                out[(p, q)] = cc[(a, c)];
                out[(q, p)] = cc[(a, c)];
            }
        }
        for (i, &(p, _)) in self.varying.iter().enumerate() {
            for (c, &q) in self.fixed.iter().enumerate() {
                out[(p, q)] = pc[(i, c)];
                out[(q, p)] = pc[(i, c)];
            }
            for (j, &(q, _)) in self.varying.iter().enumerate().skip(i) {
                let h = pp[(i, j)] * inv_n;
                out[(p, q)] = h;
                out[(q, p)] = h;
            }
            out[(p, p)] += self.diag_sum[p] * inv_n;
        }
        self.clear();
    }
}
