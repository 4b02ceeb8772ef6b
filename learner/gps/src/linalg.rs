//! Dense linear-algebra plumbing shared by the learner pieces.
//!
//! Storage convention: a [`MatSeq`] is a sequence of equally sized matrices (one per time step
//! or per cluster) in one row-major buffer, exactly the layout of a C-ordered numpy array of
//! shape `(n, rows, cols)`. Views into it are faer `MatRef`/`MatMut` with row stride `cols`.
//! All products and factorisations go through faer with `Par::Seq` (one core).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::prelude::ReborrowMut;
use faer::{Accum, MatMut, MatRef, Par};

/// A stack of `n` row-major `rows x cols` matrices (numpy shape `(n, rows, cols)`).
/// Vectors are stored with `cols == 1`.
#[derive(Clone, Debug, PartialEq)]
pub struct MatSeq {
    pub n: usize,
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
}

impl MatSeq {
    /// All-zero stack of shape `(n, rows, cols)`.
    pub fn zeros(n: usize, rows: usize, cols: usize) -> Self {
        Self {
            n,
            rows,
            cols,
            data: vec![0.0; n * rows * cols],
        }
    }

    /// Wraps a row-major buffer of shape `(n, rows, cols)`.
    ///
    /// # Panics
    /// If `data.len() != n * rows * cols`.
    pub fn from_vec(n: usize, rows: usize, cols: usize, data: Vec<f64>) -> Self {
        assert_eq!(
            data.len(),
            n * rows * cols,
            "MatSeq::from_vec: wrong length"
        );
        Self {
            n,
            rows,
            cols,
            data,
        }
    }

    /// Elements per matrix.
    #[inline]
    pub fn stride(&self) -> usize {
        self.rows * self.cols
    }

    /// Row-major slice of matrix `i`.
    #[inline]
    pub fn slice(&self, i: usize) -> &[f64] {
        let s = self.stride();
        &self.data[i * s..(i + 1) * s]
    }

    /// Mutable row-major slice of matrix `i`.
    #[inline]
    pub fn slice_mut(&mut self, i: usize) -> &mut [f64] {
        let s = self.stride();
        &mut self.data[i * s..(i + 1) * s]
    }

    /// View of matrix `i`.
    #[inline]
    pub fn mat(&self, i: usize) -> MatRef<'_, f64> {
        MatRef::from_row_major_slice(self.slice(i), self.rows, self.cols)
    }

    /// Mutable view of matrix `i`.
    #[inline]
    pub fn mat_mut(&mut self, i: usize) -> MatMut<'_, f64> {
        let (r, c) = (self.rows, self.cols);
        MatMut::from_row_major_slice_mut(self.slice_mut(i), r, c)
    }

    /// Sets every entry to `v`.
    pub fn fill(&mut self, v: f64) {
        self.data.iter_mut().for_each(|x| *x = v);
    }

    /// Copies all entries from `other` (same shape).
    pub fn copy_from(&mut self, other: &MatSeq) {
        assert_eq!(
            (self.n, self.rows, self.cols),
            (other.n, other.rows, other.cols)
        );
        self.data.copy_from_slice(&other.data);
    }
}

/// `dst = alpha * a * b` (`Accum::Replace`) or `dst += alpha * a * b` (`Accum::Add`).
#[inline]
pub fn gemm(
    dst: MatMut<'_, f64>,
    accum: Accum,
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    alpha: f64,
) {
    matmul(dst, accum, a, b, alpha, Par::Seq);
}

/// Scratch memory for [`llt_lower`] on matrices up to `dim x dim`.
pub fn llt_scratch(dim: usize) -> StackReq {
    cholesky_in_place_scratch::<f64>(dim, Par::Seq, Default::default())
}

/// Owned scratch buffer for [`llt_lower`], sized once.
pub struct Scratch {
    buf: MemBuffer,
}

impl Scratch {
    /// Scratch for Cholesky factorisations up to `dim x dim`.
    pub fn for_llt(dim: usize) -> Self {
        Self {
            buf: MemBuffer::new(llt_scratch(dim)),
        }
    }

    /// The stack view handed to faer.
    pub fn stack(&mut self) -> &mut MemStack {
        MemStack::new(&mut self.buf)
    }
}

/// In-place Cholesky `A = L Lᵀ` reading the lower triangle of `a`; on success the lower
/// triangle holds `L` and the strict upper triangle is zeroed. Returns `false` when `a` is
/// not positive definite (LAPACK `potrf` / scipy `cholesky` raise `LinAlgError` there).
pub fn llt_lower(mut a: MatMut<'_, f64>, scratch: &mut Scratch) -> bool {
    let n = a.nrows();
    if n <= SMALL_LLT {
        return llt_small(a);
    }
    let ok = cholesky_in_place(
        a.rb_mut(),
        Default::default(),
        Par::Seq,
        scratch.stack(),
        Default::default(),
    )
    .is_ok();
    if !ok {
        return false;
    }
    for j in 1..n {
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    // faer reports only non-positive pivots; a NaN pivot must fail as in LAPACK.
    (0..n).all(|i| a[(i, i)].is_finite() && a[(i, i)] > 0.0)
}

/// Up to this size [`llt_lower`] uses the unblocked algorithm below (faer's blocked
/// factorisation costs more in dispatch than in flops for the 2x2/3x3 Q_uu blocks).
const SMALL_LLT: usize = 8;

/// Unblocked Cholesky (LAPACK `dpotf2` order) on the lower triangle.
fn llt_small(mut a: MatMut<'_, f64>) -> bool {
    let n = a.nrows();
    for j in 0..n {
        let mut ajj = a[(j, j)];
        for k in 0..j {
            ajj -= a[(j, k)] * a[(j, k)];
        }
        if !(ajj > 0.0) || !ajj.is_finite() {
            return false;
        }
        let ljj = ajj.sqrt();
        a[(j, j)] = ljj;
        for i in j + 1..n {
            let mut aij = a[(i, j)];
            for k in 0..j {
                aij -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = aij / ljj;
        }
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    true
}

/// Solves `L X = B` in place (`L` lower triangular; only its lower triangle is read).
#[inline]
pub fn solve_lower(l: MatRef<'_, f64>, b: MatMut<'_, f64>) {
    solve_lower_triangular_in_place(l, b, Par::Seq);
}

/// Solves `U X = B` in place (`U` upper triangular; only its upper triangle is read).
#[inline]
pub fn solve_upper(u: MatRef<'_, f64>, b: MatMut<'_, f64>) {
    solve_upper_triangular_in_place(u, b, Par::Seq);
}

/// LU with partial pivoting for `A X = B` (numpy `np.linalg.solve`, LAPACK `gesv`), with its
/// buffers sized once for `n x n` systems with up to `max_rhs` right-hand sides.
pub struct LuSolver {
    lu: faer::Mat<f64>,
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    buf: MemBuffer,
}

impl LuSolver {
    pub fn new(n: usize, max_rhs: usize) -> Self {
        use faer::linalg::lu::partial_pivoting::{factor, solve};
        let req = factor::lu_in_place_scratch::<usize, f64>(n, n, Par::Seq, Default::default()).or(
            solve::solve_in_place_scratch::<usize, f64>(n, max_rhs, Par::Seq),
        );
        Self {
            lu: faer::Mat::zeros(n, n),
            perm: vec![0; n],
            perm_inv: vec![0; n],
            buf: MemBuffer::new(req),
        }
    }

    /// Overwrites `b` with `A⁻¹ b`. Returns `false` if a pivot is exactly zero or the result
    /// is not finite (where LAPACK reports a singular matrix).
    pub fn solve(&mut self, a: MatRef<'_, f64>, mut b: MatMut<'_, f64>) -> bool {
        use faer::linalg::lu::partial_pivoting::{factor, solve};
        self.lu.copy_from(a);
        let (_, perm) = factor::lu_in_place(
            self.lu.as_mut(),
            &mut self.perm,
            &mut self.perm_inv,
            Par::Seq,
            MemStack::new(&mut self.buf),
            Default::default(),
        );
        let n = self.lu.nrows();
        if (0..n).any(|i| self.lu[(i, i)] == 0.0) {
            return false;
        }
        solve::solve_in_place(
            self.lu.as_ref(),
            self.lu.as_ref(),
            perm,
            b.rb_mut(),
            Par::Seq,
            MemStack::new(&mut self.buf),
        );
        (0..b.nrows()).all(|i| (0..b.ncols()).all(|j| b[(i, j)].is_finite()))
    }
}

/// `a = 0.5 (a + aᵀ)` for a square matrix.
pub fn symmetrize(mut a: MatMut<'_, f64>) {
    let n = a.nrows();
    // Column by column (faer's storage order); each pair once, from its own two entries.
    for j in 0..n {
        for i in j + 1..n {
            let v = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

/// Copies `src` into `dst` (same shape).
#[inline]
pub fn copy(mut dst: MatMut<'_, f64>, src: MatRef<'_, f64>) {
    dst.copy_from(src);
}

/// Sets `a` to the identity (square or not: ones on the main diagonal).
pub fn set_identity(mut a: MatMut<'_, f64>) {
    a.fill(0.0);
    for i in 0..a.nrows().min(a.ncols()) {
        a[(i, i)] = 1.0;
    }
}

/// `sum_ij a_ij b_ij` (numpy `np.sum(a * b)`).
pub fn frob_dot(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> f64 {
    let mut s = 0.0;
    for i in 0..a.nrows() {
        for j in 0..a.ncols() {
            s += a[(i, j)] * b[(i, j)];
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    #[test]
    fn llt_and_solves_match_definition() {
        let a = faer::mat![[4.0, 2.0, 0.4], [2.0, 5.0, 1.0], [0.4, 1.0, 3.0f64]];
        let mut l = a.clone();
        let mut s = Scratch::for_llt(3);
        assert!(llt_lower(l.as_mut(), &mut s));
        let mut rec = Mat::<f64>::zeros(3, 3);
        gemm(rec.as_mut(), Accum::Replace, l.as_ref(), l.transpose(), 1.0);
        assert!((&rec - &a).norm_max() < 1e-14);
        assert_eq!(l[(0, 2)], 0.0);
        // Solve A x = b by two triangular solves.
        let mut x = faer::mat![[1.0], [2.0], [3.0f64]];
        solve_lower(l.as_ref(), x.as_mut());
        solve_upper(l.transpose(), x.as_mut());
        let mut ax = Mat::<f64>::zeros(3, 1);
        gemm(ax.as_mut(), Accum::Replace, a.as_ref(), x.as_ref(), 1.0);
        assert!((ax[(2, 0)] - 3.0).abs() < 1e-13 && (ax[(0, 0)] - 1.0).abs() < 1e-13);
    }

    #[test]
    fn small_and_blocked_llt_agree() {
        let n = 12;
        let b = Mat::<f64>::from_fn(n, n, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 2.0 + if i == j { 9.0 } else { 0.0 }
        });
        let mut a = Mat::<f64>::zeros(n, n);
        gemm(a.as_mut(), Accum::Replace, b.as_ref(), b.transpose(), 1.0);
        for m in [2, 3, 8] {
            let sub = a.as_ref().submatrix(0, 0, m, m).to_owned();
            let mut s1 = sub.clone();
            assert!(llt_small(s1.as_mut()));
            let mut s2 = sub.clone();
            let mut sc = Scratch::for_llt(m);
            assert!(cholesky_in_place(
                s2.as_mut(),
                Default::default(),
                Par::Seq,
                sc.stack(),
                Default::default()
            )
            .is_ok());
            for j in 0..m {
                for i in j..m {
                    assert!((s1[(i, j)] - s2[(i, j)]).abs() < 1e-12 * s2[(0, 0)].abs());
                }
            }
        }
        let mut nan = faer::mat![[f64::NAN, 0.0], [0.0, 1.0]];
        assert!(!llt_small(nan.as_mut()));
    }

    #[test]
    fn llt_rejects_indefinite() {
        let mut a = faer::mat![[1.0, 2.0], [2.0, 1.0f64]];
        let mut s = Scratch::for_llt(2);
        assert!(!llt_lower(a.as_mut(), &mut s));
    }
}
