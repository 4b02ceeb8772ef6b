//! The dense arithmetic of the GMM's EM (docs/design.md §5 D33): the E-step's whitened squared
//! distances `‖L⁻¹ (x − μ)‖²` and the M-step's weighted first and second moments `Σ_p w_p x_p`,
//! `Σ_p w_p x_p x_pᵀ` (lower triangle only).
//!
//! Layout: points are **lanes**. The points are stored in blocks of [`BLOCK`], each block
//! dimension-major (`x[blk * d * BLOCK + a * BLOCK + j]` = coordinate `a` of point
//! `blk * BLOCK + j`), padding points zero. Inverse Cholesky factors are `D x D` row-major lower
//! triangles (`m[a * d + b]`, `b ≤ a`).
//!
//! Every kernel is written once, generic over a 4-lane vector ([`Lanes`]), and instantiated
//! three times ([`Isa`]): on AVX2+FMA registers, on the same 256-bit registers and instructions
//! compiled with AVX-512VL (which gives the register allocator 32 of them instead of 16, so the
//! kernels take larger tiles), and on plain `[f64; 4]` arrays whose multiply-add is the correctly
//! rounded `f64::mul_add`. A tile's shape changes which sums are in registers together, never
//! the order of any one sum, so all three give the same bits on every x86_64 machine (the tests
//! compare them); the portable one is slow where the CPU has no FMA instruction.

/// Points per block.
pub const BLOCK: usize = 32;

/// Which instantiation of the kernels runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// `[f64; 4]` with `f64::mul_add`, on any CPU.
    Portable,
    /// 256-bit AVX2+FMA, sixteen registers.
    Avx2,
    /// The same 256-bit operations compiled with AVX-512F/VL: thirty-two registers, larger
    /// tiles. Never 512-bit arithmetic (eight lanes would sum in another order).
    Avx512,
}

impl Isa {
    /// The fastest instantiation this CPU runs (std caches the CPUID check).
    #[inline]
    pub fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx2") && has!("fma") {
                if has!("avx512f") && has!("avx512vl") {
                    return Isa::Avx512;
                }
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }

    /// Whether this CPU can run `self`.
    pub fn available(self) -> bool {
        match (self, Isa::detect()) {
            (Isa::Portable, _) | (_, Isa::Avx512) => true,
            (Isa::Avx2, best) => best == Isa::Avx2,
            (Isa::Avx512, _) => false,
        }
    }
}

/// Four f64 lanes: the operations the kernels use.
trait Lanes: Copy {
    /// Whether the kernels may hold about twice as many of these in registers (32 registers
    /// instead of 16): it selects larger tiles, not other arithmetic.
    const WIDE: bool;
    fn zero() -> Self;
    /// Loads `s[0..4]`.
    fn load(s: &[f64]) -> Self;
    fn store(self, s: &mut [f64]);
    fn splat(v: f64) -> Self;
    /// `a * b + self`, fused (one rounding) in every lane.
    fn fma(self, a: Self, b: Self) -> Self;
    fn add(self, b: Self) -> Self;
    fn sub(self, b: Self) -> Self;
    fn mul(self, b: Self) -> Self;
    fn div(self, b: Self) -> Self;
    /// `self > b ? self : b` in every lane (`b` where either is NaN, as `vmaxpd`).
    fn max(self, b: Self) -> Self;
    /// `self < b ? self : b` in every lane (`b` where either is NaN, as `vminpd`).
    fn min(self, b: Self) -> Self;
    /// `2^n` for lanes holding `t = n + 1.5 · 2^52` with an integer `n` in `[−1022, 1023]`:
    /// the bits of `t` plus 1023, shifted left by 52, leave `n + 1023` in the exponent field.
    fn exp2_of_rounded(self) -> Self;
    /// `self` where `x` is not below `lim` (NaN included), else `+0`.
    fn zero_where_below(self, x: Self, lim: f64) -> Self;
    /// `(l0 + l1) + (l2 + l3)`.
    fn sum(self) -> f64 {
        let mut o = [0.0; 4];
        self.store(&mut o);
        (o[0] + o[1]) + (o[2] + o[3])
    }
}

impl Lanes for [f64; 4] {
    const WIDE: bool = false;
    #[inline(always)]
    fn zero() -> Self {
        [0.0; 4]
    }
    #[inline(always)]
    fn load(s: &[f64]) -> Self {
        [s[0], s[1], s[2], s[3]]
    }
    #[inline(always)]
    fn store(self, s: &mut [f64]) {
        s[..4].copy_from_slice(&self);
    }
    #[inline(always)]
    fn splat(v: f64) -> Self {
        [v; 4]
    }
    #[inline(always)]
    fn fma(self, a: Self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| a[j].mul_add(b[j], self[j]))
    }
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| self[j] + b[j])
    }
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| self[j] - b[j])
    }
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| self[j] * b[j])
    }
    #[inline(always)]
    fn div(self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| self[j] / b[j])
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| if self[j] > b[j] { self[j] } else { b[j] })
    }
    #[inline(always)]
    fn min(self, b: Self) -> Self {
        [0, 1, 2, 3].map(|j| if self[j] < b[j] { self[j] } else { b[j] })
    }
    #[inline(always)]
    fn exp2_of_rounded(self) -> Self {
        self.map(|t| f64::from_bits(t.to_bits().wrapping_add(1023) << 52))
    }
    #[inline(always)]
    fn zero_where_below(self, x: Self, lim: f64) -> Self {
        [0, 1, 2, 3].map(|j| if x[j] < lim { 0.0 } else { self[j] })
    }
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::*;

    /// An AVX2 register as [`Lanes`](super::Lanes) for the kernels compiled with `$wide`
    /// (`false`: `avx2,fma`; `true`: `avx2,fma,avx512f,avx512vl`, 32 registers). The
    /// operations are the same 256-bit intrinsics in both.
    macro_rules! avx_lanes {
        ($T:ident, $wide:expr) => {
            #[derive(Clone, Copy)]
            pub(super) struct $T(__m256d);

            // SAFETY (all methods): only reached from functions compiled with the target
            // features above, which run only when `Isa::detect` saw them; loads and stores are
            // of slices checked to hold four elements.
            impl super::Lanes for $T {
                const WIDE: bool = $wide;
                #[inline(always)]
                fn zero() -> Self {
                    $T(unsafe { _mm256_setzero_pd() })
                }
                #[inline(always)]
                fn load(s: &[f64]) -> Self {
                    assert!(s.len() >= 4);
                    $T(unsafe { _mm256_loadu_pd(s.as_ptr()) })
                }
                #[inline(always)]
                fn store(self, s: &mut [f64]) {
                    assert!(s.len() >= 4);
                    unsafe { _mm256_storeu_pd(s.as_mut_ptr(), self.0) }
                }
                #[inline(always)]
                fn splat(v: f64) -> Self {
                    $T(unsafe { _mm256_set1_pd(v) })
                }
                #[inline(always)]
                fn fma(self, a: Self, b: Self) -> Self {
                    $T(unsafe { _mm256_fmadd_pd(a.0, b.0, self.0) })
                }
                #[inline(always)]
                fn add(self, b: Self) -> Self {
                    $T(unsafe { _mm256_add_pd(self.0, b.0) })
                }
                #[inline(always)]
                fn sub(self, b: Self) -> Self {
                    $T(unsafe { _mm256_sub_pd(self.0, b.0) })
                }
                #[inline(always)]
                fn mul(self, b: Self) -> Self {
                    $T(unsafe { _mm256_mul_pd(self.0, b.0) })
                }
                #[inline(always)]
                fn div(self, b: Self) -> Self {
                    $T(unsafe { _mm256_div_pd(self.0, b.0) })
                }
                #[inline(always)]
                fn max(self, b: Self) -> Self {
                    $T(unsafe { _mm256_max_pd(self.0, b.0) })
                }
                #[inline(always)]
                fn min(self, b: Self) -> Self {
                    $T(unsafe { _mm256_min_pd(self.0, b.0) })
                }
                #[inline(always)]
                fn exp2_of_rounded(self) -> Self {
                    $T(unsafe {
                        let one = _mm256_set1_epi64x(1023);
                        let bits = _mm256_add_epi64(_mm256_castpd_si256(self.0), one);
                        _mm256_castsi256_pd(_mm256_slli_epi64::<52>(bits))
                    })
                }
                #[inline(always)]
                fn zero_where_below(self, x: Self, lim: f64) -> Self {
                    // NLT_UQ: true where x ≥ lim or either is NaN, so NaN keeps `self`.
                    $T(unsafe {
                        let keep = _mm256_cmp_pd::<_CMP_NLT_UQ>(x.0, _mm256_set1_pd(lim));
                        _mm256_and_pd(keep, self.0)
                    })
                }
            }
        };
    }

    avx_lanes!(Avx, false);
    avx_lanes!(Avx512, true);
}

/// Runs `$body` with `V` bound to the [`Lanes`] type of `$isa`, inside a function compiled for
/// that instruction set.
macro_rules! dispatch {
    ($isa:expr, fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {{
        #[inline(always)]
        fn generic<V: Lanes>($($arg: $ty),*) $body
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2_impl($($arg: $ty),*) {
            generic::<avx::Avx>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
        unsafe fn avx512_impl($($arg: $ty),*) {
            generic::<avx::Avx512>($($arg),*)
        }
        #[inline(never)]
        fn base_impl($($arg: $ty),*) {
            generic::<[f64; 4]>($($arg),*)
        }
        match $isa {
            // SAFETY: `Isa::Avx2` and `Isa::Avx512` are only used where `Isa::available` (the
            // callers take `Isa::detect()`, the tests check `available`).
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { avx2_impl($($arg),*) },
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { avx512_impl($($arg),*) },
            _ => base_impl($($arg),*),
        }
    }};
}

/// Row and point tiles of [`whitened_norms`]: rows of `L⁻¹` per pass and 4-lane vectors of
/// points (`4 ·` this many points) per pass, for 16 and for 32 registers.
const NORM_TILE: (usize, usize) = (3, 4);
const NORM_TILE_WIDE: (usize, usize) = (4, 4);

/// E-step of one cluster on one block: `ss[j] = ‖M (x_j − μ)‖²` for the block's `BLOCK` points
/// (`x`: one block, dimension-major), `M = L⁻¹` lower triangular (`d x d` row-major). Rows are
/// taken a few at a time ([`NORM_TILE`]) on a few 4-lane vectors of points; `ss` accumulates
/// `y_0², y_1², …` in row order. `diff` (`d x BLOCK`) is scratch.
pub fn whitened_norms(
    isa: Isa,
    m: &[f64],
    mu: &[f64],
    d: usize,
    x: &[f64],
    diff: &mut [f64],
    ss: &mut [f64; BLOCK],
) {
    assert!(m.len() >= d * d && mu.len() >= d && x.len() >= d * BLOCK && diff.len() >= d * BLOCK);
    dispatch!(
        isa,
        fn k(m: &[f64], mu: &[f64], d: usize, x: &[f64], diff: &mut [f64], ss: &mut [f64; BLOCK]) {
            for a in 0..d {
                let mua = V::splat(mu[a]);
                for q in (0..BLOCK).step_by(4) {
                    V::load(&x[a * BLOCK + q..])
                        .sub(mua)
                        .store(&mut diff[a * BLOCK + q..]);
                }
            }
            const W: (usize, usize) = NORM_TILE_WIDE;
            const N: (usize, usize) = NORM_TILE;
            if V::WIDE {
                norms::<V, { W.0 }, { W.1 }>(m, d, diff, ss)
            } else {
                norms::<V, { N.0 }, { N.1 }>(m, d, diff, ss)
            }
        }
    )
}

/// [`whitened_norms`] after the subtraction, `R` rows of `M` at a time on `NV` 4-lane vectors.
#[inline(always)]
fn norms<V: Lanes, const R: usize, const NV: usize>(
    m: &[f64],
    d: usize,
    diff: &[f64],
    ss: &mut [f64; BLOCK],
) {
    for h in (0..BLOCK).step_by(4 * NV) {
        let mut s = [V::zero(); NV];
        let mut a0 = 0;
        while a0 < d {
            // The last pass takes the rows that are left (R ≤ 6).
            match (d - a0).min(R) {
                1 => norm_rows::<V, 1, NV>(m, d, a0, diff, h, &mut s),
                2 => norm_rows::<V, 2, NV>(m, d, a0, diff, h, &mut s),
                3 => norm_rows::<V, 3, NV>(m, d, a0, diff, h, &mut s),
                4 => norm_rows::<V, 4, NV>(m, d, a0, diff, h, &mut s),
                5 => norm_rows::<V, 5, NV>(m, d, a0, diff, h, &mut s),
                _ => norm_rows::<V, 6, NV>(m, d, a0, diff, h, &mut s),
            }
            a0 += R;
        }
        for (v, sv) in s.iter().enumerate() {
            sv.store(&mut ss[h + 4 * v..]);
        }
    }
}

/// Rows `a0 … a0 + R − 1` of `y = M diff` on the `4 · NV` points `h …` of the block, added to
/// the norms as `s += y_a²` in ascending `a`. Each `y_a` is a chain of fused multiply-adds over
/// `b = 0 … a` in ascending order; `R · NV` chains share each load of `diff` and cover the
/// multiply-add latency. (Subtracting `μ` inside this loop instead of storing `diff` measured
/// slower with AVX2's sixteen registers and no faster with thirty-two.)
#[inline(always)]
fn norm_rows<V: Lanes, const R: usize, const NV: usize>(
    m: &[f64],
    d: usize,
    a0: usize,
    diff: &[f64],
    h: usize,
    s: &mut [V; NV],
) {
    let col = |b: usize| -> &[f64] { &diff[b * BLOCK + h..][..4 * NV] };
    // Row a0 + r of M up to the diagonal, sliced once (no bounds check per element below).
    let rows: [&[f64]; R] = std::array::from_fn(|r| &m[(a0 + r) * d..][..=a0 + r]);
    let mut y = [[V::zero(); NV]; R];
    for (b, c) in diff.chunks_exact(BLOCK).take(a0 + 1).enumerate() {
        let c = &c[h..h + 4 * NV];
        // Loops, not `array::from_fn`: its closure would not inherit the target features, and
        // every intrinsic inside it would become a call.
        let mut l = [V::zero(); R];
        for r in 0..R {
            l[r] = V::splat(rows[r][b]);
        }
        for v in 0..NV {
            let db = V::load(&c[4 * v..]);
            for r in 0..R {
                y[r][v] = y[r][v].fma(l[r], db);
            }
        }
    }
    // The triangle's corner: column a0 + c reaches rows c … R − 1.
    for c in 1..R {
        let b = a0 + c;
        let cb = col(b);
        for v in 0..NV {
            let db = V::load(&cb[4 * v..]);
            for r in c..R {
                y[r][v] = y[r][v].fma(V::splat(rows[r][b]), db);
            }
        }
    }
    for yr in &y {
        for v in 0..NV {
            s[v] = s[v].fma(yr[v], yr[v]);
        }
    }
}

/// `m = L⁻¹` for a lower-triangular `d x d` row-major `l`: row by row,
/// `m[a, ..] = (e_a − Σ_{c<a} l[a, c] m[c, ..]) / l[a, a]`, each row an update by the rows
/// above it in ascending `c`, over the columns `b ≤ c` where `m[c, b]` can be non-zero, a
/// product and a subtraction (not fused) per element, then the division. Each element gets the
/// operations of forward substitution on the columns of the identity, in the same order (the
/// same bits), but the lanes of a row are independent, so it vectorises. Only the lower
/// triangle of `m` is written.
pub fn invert_lower(isa: Isa, l: &[f64], m: &mut [f64], d: usize) {
    assert!(l.len() >= d * d && m.len() >= d * d);
    dispatch!(
        isa,
        fn k(l: &[f64], m: &mut [f64], d: usize) {
            if d <= 4 * INV_VECS {
                invert_rows_in_registers::<V>(l, m, d)
            } else {
                for a in 0..d {
                    let (above, rest) = m.split_at_mut(a * d);
                    let row = &mut rest[..=a];
                    row.fill(0.0);
                    row[a] = 1.0;
                    for c in 0..a {
                        let (lac, src) = (l[a * d + c], &above[c * d..=c * d + c]);
                        let (lv, n4) = (V::splat(lac), (c + 1) / 4 * 4);
                        for j in (0..n4).step_by(4) {
                            let r = V::load(&row[j..]).sub(lv.mul(V::load(&src[j..])));
                            r.store(&mut row[j..]);
                        }
                        for j in n4..=c {
                            row[j] -= lac * src[j];
                        }
                    }
                    let (laa, n4) = (l[a * d + a], (a + 1) / 4 * 4);
                    for j in (0..n4).step_by(4) {
                        V::load(&row[j..]).div(V::splat(laa)).store(&mut row[j..]);
                    }
                    for r in &mut row[n4..] {
                        *r /= laa;
                    }
                }
            }
        }
    )
}

/// 4-lane vectors of a row that [`invert_lower`] keeps in registers (rows up to 32 long).
const INV_VECS: usize = 8;

/// [`invert_lower`] for `d ≤ 4 ·` [`INV_VECS`]: each row in registers (the row updates are a
/// chain through memory otherwise, a store and a reload per step), the finished rows in a
/// zero-padded copy. Whole vectors are updated: a lane `j > c` of the update by row `c` reads
/// that row's `+0` above the diagonal and subtracts `l[a, c] · 0 = ±0` from its own `+0` (or
/// the `1` of the diagonal), which leaves it unchanged for a finite `L`, so every element gets
/// exactly the operations of the row-by-row statement.
#[inline(always)]
fn invert_rows_in_registers<V: Lanes>(l: &[f64], m: &mut [f64], d: usize) {
    const W: usize = 4 * INV_VECS;
    let mut done = [[0.0f64; W]; W];
    for a in 0..d {
        let mut acc = [V::zero(); INV_VECS];
        let mut unit = [0.0; 4];
        unit[a % 4] = 1.0;
        for v in 0..INV_VECS {
            if v == a / 4 {
                acc[v] = V::load(&unit);
            }
        }
        for c in 0..a {
            let lv = V::splat(l[a * d + c]);
            let src = &done[c];
            for v in 0..INV_VECS {
                if v <= c / 4 {
                    acc[v] = acc[v].sub(lv.mul(V::load(&src[4 * v..])));
                }
            }
        }
        let laa = V::splat(l[a * d + a]);
        for v in 0..INV_VECS {
            if v <= a / 4 {
                acc[v].div(laa).store(&mut done[a][4 * v..]);
            }
        }
        m[a * d..=a * d + a].copy_from_slice(&done[a][..=a]);
    }
}

/// Clusters whose forward substitutions [`small_norms`] interleaves (independent chains that
/// cover the latency of each row's subtractions and division), for 16 and for 32 registers.
const SMALL_CLUSTERS: usize = 4;
const SMALL_CLUSTERS_WIDE: usize = 8;

/// The E-step of a handful of points (the dynamics fit's per-step prior queries): for every
/// cluster `i < k` and every group `g` of four points, `y = L_i⁻¹ (x − μ_i)` by forward
/// substitution and `ss[(i * groups + g) * 4 + j] = Σ_a y_a²` for the group's point `j`.
/// `chol` holds the `k` lower Cholesky factors (`d x d` row-major each), `mu` the `k` means,
/// `xt` the points in groups of four, dimension-major (`xt[(g * d + a) * 4 + j]`). The
/// operations per point are those of the scalar forward substitution (reference BLAS `dtrsm`
/// order): `y_a = x_a − μ_a`, then `y_a −= l_ab y_b` for `b = 0 … a − 1` (a product and a
/// subtraction, not fused), `y_a /= l_aa`, and the norm `((y_0² + y_1²) + …)` in row order.
/// Points are lanes; [`SMALL_CLUSTERS`] clusters at a time (8 with 32 registers). `y` is
/// scratch.
#[allow(clippy::too_many_arguments)]
pub fn small_norms(
    isa: Isa,
    chol: &[f64],
    mu: &[f64],
    d: usize,
    k: usize,
    xt: &[f64],
    groups: usize,
    y: &mut Vec<f64>,
    ss: &mut [f64],
) {
    assert!(chol.len() >= k * d * d && mu.len() >= k * d && xt.len() >= groups * d * 4);
    assert!(ss.len() >= k * groups * 4);
    let most = SMALL_CLUSTERS.max(SMALL_CLUSTERS_WIDE);
    if y.len() < most * d * 4 {
        y.resize(most * d * 4, 0.0);
    }
    dispatch!(
        isa,
        fn kern(
            chol: &[f64],
            mu: &[f64],
            d: usize,
            k: usize,
            xt: &[f64],
            groups: usize,
            y: &mut [f64],
            ss: &mut [f64],
        ) {
            for g in 0..groups {
                let x = &xt[g * d * 4..(g + 1) * d * 4];
                let step = if V::WIDE {
                    SMALL_CLUSTERS_WIDE
                } else {
                    SMALL_CLUSTERS
                };
                let mut i0 = 0;
                while i0 < k {
                    match (k - i0).min(step) {
                        1 => small_pass::<V, 1>(chol, mu, d, i0, x, y, groups, g, ss),
                        2 => small_pass::<V, 2>(chol, mu, d, i0, x, y, groups, g, ss),
                        3 => small_pass::<V, 3>(chol, mu, d, i0, x, y, groups, g, ss),
                        4 => small_pass::<V, 4>(chol, mu, d, i0, x, y, groups, g, ss),
                        5 => small_pass::<V, 5>(chol, mu, d, i0, x, y, groups, g, ss),
                        6 => small_pass::<V, 6>(chol, mu, d, i0, x, y, groups, g, ss),
                        7 => small_pass::<V, 7>(chol, mu, d, i0, x, y, groups, g, ss),
                        _ => small_pass::<V, 8>(chol, mu, d, i0, x, y, groups, g, ss),
                    }
                    i0 += step;
                }
            }
        }
    )
}

/// [`small_norms`] of the clusters `i0 … i0 + C − 1` on one group of four points. `y` holds
/// the finished rows, the `C` clusters' vectors side by side (`y[(b * C + c) * 4 ..]`), so
/// that each step reads one slice of known length.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn small_pass<V: Lanes, const C: usize>(
    chol: &[f64],
    mu: &[f64],
    d: usize,
    i0: usize,
    x: &[f64],
    y: &mut [f64],
    groups: usize,
    g: usize,
    ss: &mut [f64],
) {
    let dd = d * d;
    for a in 0..d {
        let xa = V::load(&x[a * 4..]);
        let mut acc = [V::zero(); C];
        let mut lrow: [&[f64]; C] = [&[]; C];
        for c in 0..C {
            acc[c] = xa.sub(V::splat(mu[(i0 + c) * d + a]));
            lrow[c] = &chol[(i0 + c) * dd + a * d..][..=a];
        }
        let (done, cur) = y.split_at_mut(a * C * 4);
        for (b, yb) in done.chunks_exact(C * 4).enumerate() {
            for c in 0..C {
                let lab = V::splat(lrow[c][b]);
                acc[c] = acc[c].sub(lab.mul(V::load(&yb[c * 4..])));
            }
        }
        for c in 0..C {
            acc[c].div(V::splat(lrow[c][a])).store(&mut cur[c * 4..]);
        }
    }
    for c in 0..C {
        let mut s = V::zero();
        for yb in y.chunks_exact(C * 4).take(d) {
            let ya = V::load(&yb[c * 4..]);
            s = s.add(ya.mul(ya));
        }
        s.store(&mut ss[((i0 + c) * groups + g) * 4..]);
    }
}

/// Blocks of points whose weighted copies and second-moment sums the M-step keeps in L1 at a
/// time (2 × 27 × 32 × 8 B = 13.8 KB of points and as much of weighted points for the arm's
/// 27 dimensions).
const GROUP: usize = 2;

/// Second-moment tiles of [`moments`]: rows × columns of 4-lane sums held in registers, for 16
/// and for 32 registers.
const MOMENT_TILE: (usize, usize) = (2, 4);
const MOMENT_TILE_WIDE: (usize, usize) = (4, 4);

/// Scratch of the M-step's [`moments`]: the weighted points `w_p x_p` of one group of blocks,
/// and the 4-lane sums of the second-moment tiles.
pub struct Moments {
    z: Vec<f64>,
    /// `d x 4` lane sums of `w x`.
    s1: Vec<f64>,
    tiles: Vec<f64>,
}

impl Moments {
    /// Empty scratch; it grows to the largest dimension seen and is reused.
    pub fn new() -> Self {
        Self {
            z: Vec::new(),
            s1: Vec::new(),
            tiles: Vec::new(),
        }
    }
}

impl Default for Moments {
    fn default() -> Self {
        Self::new()
    }
}

/// Tiles of `tr` rows by `tc` columns covering the lower triangle: row groups `a0 = 0, tr, …`
/// by column groups `b0 = 0, tc, … ≤` the group's last row.
fn tile_count(d: usize, (tr, tc): (usize, usize)) -> usize {
    (0..d)
        .step_by(tr)
        .map(|a0| ((a0 + tr - 1).min(d - 1) + 1).div_ceil(tc))
        .sum()
}

/// One cluster's M-step sums over the points `x` (`blocks` blocks of dimension `d`, padding
/// zero) with weights `w` (`blocks · BLOCK`, padding zero): `s1[a] = Σ_p w_p x_pa` and, for
/// `b ≤ a`, `xx[a * d + b] = Σ_p w_p x_pa x_pb` (upper triangle of `xx` untouched). Each sum
/// runs over four lanes (`p mod 4`, ascending `p`) added at the end as `(l0 + l1) + (l2 + l3)`.
/// The second moments are tiles of a few rows by four columns ([`MOMENT_TILE`]; 4-lane sums in
/// registers), visited once per [`GROUP`] of blocks, whose points and weighted points stay in
/// L1.
#[allow(clippy::too_many_arguments)]
pub fn moments(
    isa: Isa,
    scratch: &mut Moments,
    d: usize,
    blocks: usize,
    x: &[f64],
    w: &[f64],
    s1: &mut [f64],
    xx: &mut [f64],
) {
    moments_in_groups(isa, GROUP, scratch, d, blocks, x, w, s1, xx)
}

/// [`moments`] with `group` blocks per visit of the tiles (the same sums in the same order for
/// any `group`; the speed benchmark compares them).
#[allow(clippy::too_many_arguments)]
fn moments_in_groups(
    isa: Isa,
    group: usize,
    scratch: &mut Moments,
    d: usize,
    blocks: usize,
    x: &[f64],
    w: &[f64],
    s1: &mut [f64],
    xx: &mut [f64],
) {
    assert!(group >= 1);
    assert!(x.len() >= blocks * d * BLOCK && w.len() >= blocks * BLOCK);
    assert!(s1.len() >= d && xx.len() >= d * d);
    let Moments {
        z,
        s1: lanes,
        tiles,
    } = scratch;
    // No clearing: the first group starts every sum from zero.
    let sums = |(tr, tc): (usize, usize)| tile_count(d, (tr, tc)) * tr * tc * 4;
    let need = sums(MOMENT_TILE).max(sums(MOMENT_TILE_WIDE));
    for (v, n) in [
        (&mut *z, group * d * BLOCK),
        (&mut *lanes, d * 4),
        (&mut *tiles, need),
    ] {
        if v.len() < n {
            v.resize(n, 0.0);
        }
    }
    dispatch!(
        isa,
        fn k(
            group: usize,
            d: usize,
            blocks: usize,
            x: &[f64],
            w: &[f64],
            z: &mut [f64],
            lanes: &mut [f64],
            tiles: &mut [f64],
            s1: &mut [f64],
            xx: &mut [f64],
        ) {
            const W: (usize, usize) = MOMENT_TILE_WIDE;
            const N: (usize, usize) = MOMENT_TILE;
            if V::WIDE {
                moment_tiles::<V, { W.0 }, { W.1 }>(group, d, blocks, x, w, z, lanes, tiles, s1, xx)
            } else {
                moment_tiles::<V, { N.0 }, { N.1 }>(group, d, blocks, x, w, z, lanes, tiles, s1, xx)
            }
        }
    )
}

/// One block's points added to a tile's sums: `acc[r][c] += z_r x_c` (fused) for every 4-lane
/// vector of points in ascending order, for the rows `r < ROWS` (the others are past `d`); on
/// the diagonal (`DIAG`) only for `c ≤ r`.
#[inline(always)]
fn tile_block<V: Lanes, const TR: usize, const TC: usize, const DIAG: bool, const ROWS: usize>(
    acc: &mut [[V; TC]; TR],
    zr: &[&[f64; BLOCK]; TR],
    xr: &[&[f64; BLOCK]; TC],
) {
    for q in (0..BLOCK).step_by(4) {
        // Loops for the vectors, not `array::from_fn` (see `norm_rows`).
        let mut zq = [V::zero(); TR];
        for r in 0..TR {
            zq[r] = V::load(&zr[r][q..]);
        }
        for c in 0..TC {
            let xs = V::load(&xr[c][q..]);
            for r in 0..TR {
                if r < ROWS && (!DIAG || c <= r) {
                    acc[r][c] = acc[r][c].fma(zq[r], xs);
                }
            }
        }
    }
}

/// [`moments_in_groups`] on tiles of `TR` rows by `TC` columns.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn moment_tiles<V: Lanes, const TR: usize, const TC: usize>(
    group: usize,
    d: usize,
    blocks: usize,
    x: &[f64],
    w: &[f64],
    z: &mut [f64],
    lanes: &mut [f64],
    tiles: &mut [f64],
    s1: &mut [f64],
    xx: &mut [f64],
) {
    fn row(m: &[f64], i: usize) -> &[f64; BLOCK] {
        m[i * BLOCK..(i + 1) * BLOCK].try_into().unwrap()
    }
    let size = TR * TC * 4;
    for g0 in (0..blocks).step_by(group) {
        let g = (blocks - g0).min(group);
        let xg = &x[g0 * d * BLOCK..(g0 + g) * d * BLOCK];
        let wg = &w[g0 * BLOCK..(g0 + g) * BLOCK];
        // z = w x, block by block, and the first moments.
        for a in 0..d {
            let mut sa = if g0 == 0 {
                V::zero()
            } else {
                V::load(&lanes[4 * a..])
            };
            for j in 0..g {
                let o = j * d * BLOCK + a * BLOCK;
                // Whole blocks sliced once: no bounds check per vector below.
                let wj: &[f64; BLOCK] = wg[j * BLOCK..(j + 1) * BLOCK].try_into().unwrap();
                let xj: &[f64; BLOCK] = xg[o..o + BLOCK].try_into().unwrap();
                let zj: &mut [f64; BLOCK] = (&mut z[o..o + BLOCK]).try_into().unwrap();
                for q in (0..BLOCK).step_by(4) {
                    let zq = V::zero().fma(V::load(&wj[q..]), V::load(&xj[q..]));
                    zq.store(&mut zj[q..]);
                    sa = sa.add(zq);
                }
            }
            sa.store(&mut lanes[4 * a..]);
        }
        let mut t = 0;
        for a0 in (0..d).step_by(TR) {
            let last = (a0 + TR - 1).min(d - 1);
            for b0 in (0..=last).step_by(TC) {
                let tile = &mut tiles[t * size..(t + 1) * size];
                // Loops for the vectors, not `array::from_fn` (see `norm_rows`).
                let mut acc = [[V::zero(); TC]; TR];
                if g0 > 0 {
                    for r in 0..TR {
                        for c in 0..TC {
                            acc[r][c] = V::load(&tile[(r * TC + c) * 4..]);
                        }
                    }
                }
                // A tile on the diagonal needs only its lower triangle (column ≤ row).
                let diag = TR == TC && b0 == a0;
                for j in 0..g {
                    let (xb, zb) = (&xg[j * d * BLOCK..], &z[j * d * BLOCK..]);
                    let xr: [&[f64; BLOCK]; TC] =
                        std::array::from_fn(|c| row(xb, (b0 + c).min(d - 1)));
                    let zr: [&[f64; BLOCK]; TR] =
                        std::array::from_fn(|r| row(zb, (a0 + r).min(d - 1)));
                    // The last row group may have fewer than TR rows (d not a multiple).
                    let (a, z, x) = (&mut acc, &zr, &xr);
                    match (diag, last + 1 - a0) {
                        (true, 1) => tile_block::<V, TR, TC, true, 1>(a, z, x),
                        (true, 2) => tile_block::<V, TR, TC, true, 2>(a, z, x),
                        (true, 3) => tile_block::<V, TR, TC, true, 3>(a, z, x),
                        (true, _) => tile_block::<V, TR, TC, true, TR>(a, z, x),
                        (false, 1) => tile_block::<V, TR, TC, false, 1>(a, z, x),
                        (false, 2) => tile_block::<V, TR, TC, false, 2>(a, z, x),
                        (false, 3) => tile_block::<V, TR, TC, false, 3>(a, z, x),
                        (false, _) => tile_block::<V, TR, TC, false, TR>(a, z, x),
                    }
                }
                for r in 0..TR {
                    for c in 0..TC {
                        acc[r][c].store(&mut tile[(r * TC + c) * 4..]);
                    }
                }
                t += 1;
            }
        }
    }
    for a in 0..d {
        s1[a] = V::load(&lanes[4 * a..]).sum();
    }
    let mut t = 0;
    for a0 in (0..d).step_by(TR) {
        let last = (a0 + TR - 1).min(d - 1);
        for b0 in (0..=last).step_by(TC) {
            for a in a0..=last {
                for b in b0..(b0 + TC).min(a + 1) {
                    let o = (t * TR * TC + (a - a0) * TC + (b - b0)) * 4;
                    xx[a * d + b] = V::load(&tiles[o..]).sum();
                }
            }
            t += 1;
        }
    }
}

/// Below this argument [`exp`] returns `+0`: `e^-600` ≈ 2.7e-261. Terms that small change no
/// sum of the EM (a log-sum-exp shifted by its maximum adds at least 1; a cluster's weights add
/// up to 1), and flushing them keeps the M-step's products out of the subnormal range, where x86
/// multiply-adds take a microcode assist (docs/design.md §5 D33).
pub const EXP_FLOOR: f64 = -600.0;

/// `1 / k!` for `k = 0 … 13`: the Taylor polynomial of `e^r` on `|r| ≤ ln 2 / 2`, whose
/// remainder (`(ln 2 / 2)^14 / 14!` ≈ 4e-18) is below half an ulp.
const EXP_TAYLOR: [f64; 14] = [
    1.0,
    1.0,
    0.5,
    0.16666666666666666,
    0.041666666666666664,
    0.008333333333333333,
    0.001388888888888889,
    0.0001984126984126984,
    2.48015873015873e-05,
    2.7557319223985893e-06,
    2.755731922398589e-07,
    2.505210838544172e-08,
    2.08767569878681e-09,
    1.6059043836821613e-10,
];

/// `e^x` in every lane for `x ≤ 700`, within 2 ulp of the correctly rounded value (tested);
/// `+0` for `x <` [`EXP_FLOOR`] (`−∞` included), NaN for NaN. `x = n ln 2 + r` with `n` the
/// nearest integer to `x log₂e` (rounded by adding 1.5·2^52) and `r` by Cody–Waite's two-part
/// `ln 2`; `e^r` by Horner on [`EXP_TAYLOR`]; `2^n` from `n`'s bits.
#[inline(always)]
fn exp<V: Lanes>(x: V) -> V {
    const ROUND: f64 = 6_755_399_441_055_744.0;
    const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
    // Clamp into [EXP_FLOOR, 700] (NaN stays NaN: vmaxpd/vminpd return their second operand).
    let xc = V::splat(EXP_FLOOR).max(V::splat(700.0).min(x));
    let t = V::splat(ROUND).fma(xc, V::splat(std::f64::consts::LOG2_E));
    let n = t.sub(V::splat(ROUND));
    let r = xc.fma(n, V::splat(-LN2_HI)).fma(n, V::splat(-LN2_LO));
    let mut p = V::splat(EXP_TAYLOR[13]);
    for &c in EXP_TAYLOR[..13].iter().rev() {
        p = V::splat(c).fma(p, r);
    }
    p.mul(t.exp2_of_rounded()).zero_where_below(x, EXP_FLOOR)
}

/// Four values from `s[i..]`, lanes past `s.len()` filled with `−∞` (which [`exp`] maps to 0
/// and a maximum ignores).
#[inline(always)]
fn load_or_neg_inf<V: Lanes>(s: &[f64], i: usize) -> V {
    if i + 4 <= s.len() {
        V::load(&s[i..])
    } else {
        let mut t = [f64::NEG_INFINITY; 4];
        t[..s.len() - i].copy_from_slice(&s[i..]);
        V::load(&t)
    }
}

/// `e^x` of every element of `x` into `out` (same length), as the EM's [`exp`] computes it.
pub fn exp_slice(isa: Isa, x: &[f64], out: &mut [f64]) {
    assert_eq!(x.len(), out.len());
    dispatch!(
        isa,
        fn k(x: &[f64], out: &mut [f64]) {
            let mut buf = [0.0; 4];
            for i in (0..x.len()).step_by(4) {
                exp(load_or_neg_inf::<V>(x, i)).store(&mut buf);
                let m = (x.len() - i).min(4);
                out[i..i + m].copy_from_slice(&buf[..m]);
            }
        }
    )
}

/// GPS `logsum` along the clusters, then the subtraction that turns log probabilities into log
/// responsibilities: for each point `p < n` of the cluster-major `l` (cluster `i`'s values at
/// `l[i * stride ..]`), `lse[p] = log Σ_i exp(l_ip − m_p) + m_p` with `m_p` the largest `l_ip`
/// (GPS's `max = −∞ → 0` gives the same `−∞`), then `l_ip −= lse[p]`. Lanes are points; each
/// point's sum runs over `i` in ascending order.
pub fn normalise_over_clusters(
    isa: Isa,
    l: &mut [f64],
    stride: usize,
    n: usize,
    k: usize,
    lse: &mut [f64],
) {
    assert!(n <= stride && l.len() >= (k.max(1) - 1) * stride + n && lse.len() >= n);
    dispatch!(
        isa,
        fn kern(l: &mut [f64], stride: usize, n: usize, k: usize, lse: &mut [f64]) {
            let mut buf = [0.0; 4];
            for p in (0..n).step_by(4) {
                let row = |i: usize| &l[i * stride..i * stride + n];
                let mut m = V::splat(f64::MIN);
                for i in 0..k {
                    m = m.max(load_or_neg_inf(row(i), p));
                }
                let mut s = V::zero();
                for i in 0..k {
                    s = s.add(exp(load_or_neg_inf::<V>(row(i), p).sub(m)));
                }
                let (mut sb, mut mb) = ([0.0; 4], [0.0; 4]);
                s.store(&mut sb);
                m.store(&mut mb);
                for j in 0..4 {
                    buf[j] = sb[j].ln() + mb[j];
                }
                let c = (n - p).min(4);
                lse[p..p + c].copy_from_slice(&buf[..c]);
                for i in 0..k {
                    for (v, &b) in l[i * stride + p..i * stride + p + c].iter_mut().zip(&buf) {
                        *v -= b;
                    }
                }
            }
        }
    )
}

/// GPS `logsum` of the `n` values `l` (one cluster's log responsibilities over the points):
/// `log Σ_p exp(l_p − m) + m`, `m` the largest value (`−∞` for an empty or all-`−∞` row, as
/// GPS's `max = −∞ → 0` gives). The sum runs in four lanes (`p mod 4`, ascending `p`), added as
/// `(l0 + l1) + (l2 + l3)`.
pub fn logsum_points(isa: Isa, l: &[f64]) -> f64 {
    let mut out = 0.0;
    let sink = &mut out;
    dispatch!(
        isa,
        fn k(l: &[f64], sink: &mut f64) {
            let mut m = V::splat(f64::MIN);
            for p in (0..l.len()).step_by(4) {
                m = m.max(load_or_neg_inf(l, p));
            }
            let mut mb = [0.0; 4];
            m.store(&mut mb);
            let mx = mb[0].max(mb[1]).max(mb[2].max(mb[3]));
            let mv = V::splat(mx);
            let mut s = V::zero();
            for p in (0..l.len()).step_by(4) {
                s = s.add(exp(load_or_neg_inf::<V>(l, p).sub(mv)));
            }
            *sink = s.sum().ln() + mx;
        }
    );
    out
}

/// The M-step's weights of one cluster: `w[p] = exp(l[p] − c)` for `p < l.len()` (`+0` below
/// `e^`[`EXP_FLOOR`]), `w[p] = 0` for the padding `l.len() ≤ p < w.len()`.
pub fn weights(isa: Isa, l: &[f64], c: f64, w: &mut [f64]) {
    assert!(w.len() >= l.len());
    dispatch!(
        isa,
        fn k(l: &[f64], c: f64, w: &mut [f64]) {
            let cv = V::splat(c);
            let mut buf = [0.0; 4];
            for p in (0..l.len()).step_by(4) {
                exp(load_or_neg_inf::<V>(l, p).sub(cv)).store(&mut buf);
                let m = (l.len() - p).min(4);
                w[p..p + m].copy_from_slice(&buf[..m]);
            }
        }
    );
    w[l.len()..].fill(0.0);
}

/// Flops of the E-step's dense arithmetic on `n` points, `k` clusters, dimension `d`, as
/// [`whitened_norms`] does it (padding excluded; a multiply-add counted as two): per cluster and
/// point, `d` subtractions, `d(d+1)/2` multiply-adds of `L⁻¹ (x − μ)` and `d` of the norm.
pub fn estep_flops(n: usize, d: usize, k: usize) -> f64 {
    (n * k * (d + d * (d + 1) + 2 * d)) as f64
}

/// Flops of the M-step's dense arithmetic, as [`moments`] does it: per cluster and point,
/// `d` weightings, `d` sums and `d(d+1)/2` multiply-adds of the second moment.
pub fn mstep_flops(n: usize, d: usize, k: usize) -> f64 {
    (n * k * (2 * d + d * (d + 1))) as f64
}

/// One core's f64 multiply-add peak, to be timed by the caller: `rounds` rounds of 48
/// independent fused multiply-adds (twelve 4-lane chains, enough to cover the FMA latency on two
/// pipes) on the AVX2 instantiation where the CPU has it (also on CPUs with AVX-512: the peak of
/// the kernels' 4-lane instructions, not of 8-lane ones), else the portable one. Returns the
/// flops done, 2 × 48 × `rounds`.
pub fn fma_peak(rounds: usize) -> f64 {
    let mut out = 0.0;
    let sink = &mut out;
    let (m, c) = (
        std::hint::black_box(0.999_999_9),
        std::hint::black_box(1e-7),
    );
    let isa = match Isa::detect() {
        Isa::Avx512 => Isa::Avx2,
        isa => isa,
    };
    dispatch!(
        isa,
        fn k(rounds: usize, m: f64, c: f64, sink: &mut f64) {
            let mut acc = [V::zero(); 12];
            let (m, c) = (V::splat(m), V::splat(c));
            for _ in 0..rounds {
                for a in acc.iter_mut() {
                    *a = c.fma(m, *a);
                }
            }
            *sink = acc.iter().map(|a| a.sum()).sum();
        }
    );
    std::hint::black_box(out);
    2.0 * 48.0 * rounds as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A random lower-triangular `d x d` matrix (row-major) with a positive diagonal.
    fn random_lower(rng: &mut impl Rng, d: usize) -> Vec<f64> {
        let mut m = vec![0.0; d * d];
        for a in 0..d {
            for b in 0..a {
                m[a * d + b] = rng.random_range(-0.5..0.5);
            }
            m[a * d + a] = rng.random_range(0.5..2.0);
        }
        m
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Every instantiation this CPU runs, the portable one first; prints a note for the others.
    fn isas() -> Vec<Isa> {
        [Isa::Portable, Isa::Avx2, Isa::Avx512]
            .into_iter()
            .filter(|&isa| {
                let ok = isa.available();
                if !ok {
                    println!("note: this CPU cannot run the {isa:?} instantiation; not tested");
                }
                ok
            })
            .collect()
    }

    #[test]
    fn whitened_norms_follow_their_documented_order_bit_for_bit_on_every_build() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for d in [1, 2, 3, 4, 5, 6, 7, 8, 13, 27] {
            let m = random_lower(&mut rng, d);
            let mu: Vec<f64> = (0..d).map(|_| rng.random_range(-1.0..1.0)).collect();
            let x: Vec<f64> = (0..d * BLOCK)
                .map(|_| rng.random_range(-3.0..3.0))
                .collect();
            let mut diff = vec![0.0; d * BLOCK];
            for isa in isas() {
                let mut ss = [0.0; BLOCK];
                whitened_norms(isa, &m, &mu, d, &x, &mut diff, &mut ss);
                for j in 0..BLOCK {
                    // The documented order: y_a a fused chain over ascending b from 0, the norm
                    // a fused chain over ascending a.
                    let mut norm = 0.0f64;
                    for a in 0..d {
                        let mut y = 0.0f64;
                        for b in 0..=a {
                            y = m[a * d + b].mul_add(x[b * BLOCK + j] - mu[b], y);
                        }
                        norm = y.mul_add(y, norm);
                    }
                    assert_eq!(ss[j].to_bits(), norm.to_bits(), "{isa:?} d={d} j={j}");
                }
            }
        }
    }

    #[test]
    fn moments_follow_their_documented_order_bit_for_bit_on_every_build() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for (d, blocks) in [
            (1, 1),
            (2, 2),
            (3, 3),
            (4, 1),
            (5, 1),
            (6, 2),
            (9, 5),
            (27, 16),
        ] {
            let np = blocks * BLOCK;
            let x: Vec<f64> = (0..d * np).map(|_| rng.random_range(-2.0..2.0)).collect();
            let w: Vec<f64> = (0..np).map(|_| rng.random_range(0.0..1.0)).collect();
            let run = |isa: Isa| {
                let (mut s1, mut xx) = (vec![0.0; d], vec![f64::NAN; d * d]);
                moments(
                    isa,
                    &mut Moments::new(),
                    d,
                    blocks,
                    &x,
                    &w,
                    &mut s1,
                    &mut xx,
                );
                (s1, xx)
            };
            let (s1, xx) = run(Isa::Portable);
            let at = |a: usize, p: usize| x[(p / BLOCK) * d * BLOCK + a * BLOCK + p % BLOCK];
            // The documented order: four lane sums over p ≡ j (mod 4) in ascending p, of the
            // rounded z_p = w_p x_pa, fused into the second moments; (l0 + l1) + (l2 + l3).
            let lanes = |f: &dyn Fn(usize, f64) -> f64| {
                let l: Vec<f64> = (0..4)
                    .map(|j| (j..np).step_by(4).fold(0.0, |acc, p| f(p, acc)))
                    .collect();
                (l[0] + l[1]) + (l[2] + l[3])
            };
            for a in 0..d {
                let s = lanes(&|p, acc| acc + w[p] * at(a, p));
                assert_eq!(s1[a].to_bits(), s.to_bits(), "d={d} a={a}");
                for b in 0..d {
                    if b <= a {
                        let s = lanes(&|p, acc| (w[p] * at(a, p)).mul_add(at(b, p), acc));
                        assert_eq!(xx[a * d + b].to_bits(), s.to_bits(), "d={d} ({a},{b})");
                    } else {
                        assert!(xx[a * d + b].is_nan(), "upper triangle written");
                    }
                }
            }
            for isa in isas() {
                let (s1b, xxb) = run(isa);
                assert_eq!(bits(&s1), bits(&s1b), "{isa:?} d={d}");
                assert_eq!(bits(&xx), bits(&xxb), "{isa:?} d={d}");
            }
        }
    }

    #[test]
    fn small_norms_follow_forward_substitution_bit_for_bit_on_every_build() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for (d, k, n) in [(1, 1, 1), (3, 2, 4), (5, 5, 7), (27, 12, 5), (27, 9, 13)] {
            let chol: Vec<f64> = (0..k).flat_map(|_| random_lower(&mut rng, d)).collect();
            let mu: Vec<f64> = (0..k * d).map(|_| rng.random_range(-1.0..1.0)).collect();
            let pts: Vec<f64> = (0..n * d).map(|_| rng.random_range(-3.0..3.0)).collect();
            let groups = n.div_ceil(4);
            let mut xt = vec![0.0; groups * d * 4];
            for p in 0..n {
                for a in 0..d {
                    xt[((p / 4) * d + a) * 4 + p % 4] = pts[p * d + a];
                }
            }
            for isa in isas() {
                let (mut y, mut ss) = (Vec::new(), vec![f64::NAN; k * groups * 4]);
                small_norms(isa, &chol, &mu, d, k, &xt, groups, &mut y, &mut ss);
                for i in 0..k {
                    let l = &chol[i * d * d..];
                    for p in 0..n {
                        // Forward substitution written out, then the norm in row order.
                        let mut yv = vec![0.0; d];
                        for a in 0..d {
                            let mut acc = pts[p * d + a] - mu[i * d + a];
                            for b in 0..a {
                                acc -= l[a * d + b] * yv[b];
                            }
                            yv[a] = acc / l[a * d + a];
                        }
                        let want = yv.iter().fold(0.0, |s, v| s + v * v);
                        let got = ss[(i * groups + p / 4) * 4 + p % 4];
                        assert_eq!(got.to_bits(), want.to_bits(), "{isa:?} d={d} i={i} p={p}");
                    }
                }
            }
        }
    }

    /// Distance in units in the last place between two finite positive doubles.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    #[test]
    fn exp_is_within_two_ulp_of_libm_flushes_below_the_floor_and_every_build_agrees() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut x: Vec<f64> = (0..20_000)
            .map(|i| match i % 4 {
                0 => rng.random_range(EXP_FLOOR..0.0),
                1 => rng.random_range(-1.0..1.0),
                2 => rng.random_range(-40.0..0.0),
                _ => rng.random_range(0.0..700.0),
            })
            .collect();
        // Halfway points of the rounding to n, both ends of the range, exact cases.
        x.extend([
            0.0,
            -0.0,
            1.0,
            -1.0,
            EXP_FLOOR,
            700.0,
            0.5 * std::f64::consts::LN_2,
        ]);
        x.extend((1..20).map(|n| -(n as f64 + 0.5) * std::f64::consts::LN_2));
        let mut y = vec![0.0; x.len()];
        exp_slice(Isa::Portable, &x, &mut y);
        let worst = x
            .iter()
            .zip(&y)
            .map(|(&xi, &yi)| (ulps(yi, xi.exp()), xi))
            .max_by_key(|&(u, _)| u)
            .unwrap();
        assert!(
            worst.0 <= 2,
            "exp off by {} ulp at x = {:e}",
            worst.0,
            worst.1
        );
        assert_eq!(y[20_000], 1.0, "e^0");
        for isa in isas() {
            let mut y2 = vec![0.0; x.len()];
            exp_slice(isa, &x, &mut y2);
            assert_eq!(
                bits(&y),
                bits(&y2),
                "{isa:?} differs from the portable build"
            );
        }

        let special = [
            EXP_FLOOR - 1e-9,
            -601.0,
            -1e300,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for isa in isas() {
            let mut z = [1.0; 5];
            exp_slice(isa, &special, &mut z);
            assert_eq!(
                bits(&z[..4]),
                bits(&[0.0; 4]),
                "{isa:?} below the floor: +0"
            );
            assert!(z[4].is_nan(), "{isa:?}: NaN stays NaN");
        }
    }

    /// GPS `logsum` written out (max-shifted, `−∞` max replaced by 0), on libm's `exp`.
    fn logsum_ref(v: &[f64]) -> f64 {
        let mut m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if m == f64::NEG_INFINITY {
            m = 0.0;
        }
        v.iter().map(|x| (x - m).exp()).sum::<f64>().ln() + m
    }

    #[test]
    fn responsibilities_match_gps_logsum_and_every_build_agrees_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
        for (n, k) in [(1usize, 1usize), (5, 3), (37, 12), (64, 2)] {
            let stride = n.div_ceil(BLOCK) * BLOCK;
            let mut l = vec![f64::NAN; stride * k];
            for i in 0..k {
                for p in 0..n {
                    l[i * stride + p] = rng.random_range(-900.0..10.0);
                }
            }
            if n > 1 {
                // A point far from every cluster and a cluster no point belongs to.
                l[1] = f64::NEG_INFINITY;
                for p in 0..n {
                    l[(k - 1) * stride + p] -= 2000.0;
                }
            }
            let run = |isa: Isa| {
                let mut l = l.clone();
                let mut lse = vec![0.0; n];
                normalise_over_clusters(isa, &mut l, stride, n, k, &mut lse);
                let col: Vec<f64> = (0..k)
                    .map(|i| logsum_points(isa, &l[i * stride..][..n]))
                    .collect();
                let mut w = vec![f64::NAN; stride * k];
                for i in 0..k {
                    let wi = &mut w[i * stride..(i + 1) * stride];
                    weights(isa, &l[i * stride..][..n], col[i], wi);
                }
                (l, lse, col, w)
            };
            let (lr, lse, col, w) = run(Isa::Portable);
            for p in 0..n {
                let v: Vec<f64> = (0..k).map(|i| l[i * stride + p]).collect();
                let want = logsum_ref(&v);
                assert!(
                    (lse[p] - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "n={n} p={p}"
                );
                for i in 0..k {
                    assert_eq!(lr[i * stride + p], l[i * stride + p] - lse[p]);
                }
            }
            for i in 0..k {
                let row = &lr[i * stride..][..n];
                let want = logsum_ref(row);
                assert!(
                    (col[i] - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "n={n} i={i}"
                );
                for p in 0..stride {
                    let wp = w[i * stride + p];
                    if p >= n {
                        assert_eq!(wp.to_bits(), 0, "padding weighs +0");
                    } else if row[p] - col[i] < EXP_FLOOR {
                        assert_eq!(wp.to_bits(), 0, "below the floor: +0");
                    } else {
                        let want = (row[p] - col[i]).exp();
                        assert!(ulps(wp, want) <= 2, "n={n} i={i} p={p}");
                        assert!(wp.is_normal(), "no subnormal weight");
                    }
                }
            }
            for isa in isas() {
                let (lr2, lse2, col2, w2) = run(isa);
                assert_eq!(bits(&lr), bits(&lr2), "{isa:?}");
                assert_eq!(bits(&lse), bits(&lse2), "{isa:?}");
                assert_eq!(bits(&col), bits(&col2), "{isa:?}");
                assert_eq!(bits(&w), bits(&w2), "{isa:?}");
            }
        }
    }

    /// Prints the kernels' speed beside the peak (`--ignored --nocapture`); measures, checks nothing.
    #[test]
    #[ignore]
    fn kernel_speed() {
        // Best of five runs of each, the peak measured between them (a loaded machine).
        let best = |f: &mut dyn FnMut() -> f64| {
            (0..5)
                .map(|_| {
                    let t0 = std::time::Instant::now();
                    let fl = f();
                    fl / t0.elapsed().as_secs_f64() / 1e9
                })
                .fold(0.0, f64::max)
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (d, blocks, k) = (27, 16, 12);
        let m = random_lower(&mut rng, d);
        let mu = vec![0.1; d];
        let x: Vec<f64> = (0..blocks * d * BLOCK)
            .map(|_| rng.random_range(-3.0..3.0))
            .collect();
        let w: Vec<f64> = (0..blocks * BLOCK)
            .map(|_| rng.random_range(0.0..1.0))
            .collect();
        let mut diff = vec![0.0; d * BLOCK];
        let (mut acc, mut s1, mut xx) = (Moments::new(), vec![0.0; d], vec![0.0; d * d]);
        let reps = 200;
        let peak = best(&mut || fma_peak(2_000_000));
        println!("peak {peak:.1} GFLOP/s");
        for isa in isas().into_iter().filter(|&isa| isa != Isa::Portable) {
            let e = best(&mut || {
                let mut ss = [0.0; BLOCK];
                for _ in 0..reps {
                    for blk in 0..blocks {
                        for _ in 0..k {
                            let xb = &x[blk * d * BLOCK..];
                            whitened_norms(isa, &m, &mu, d, xb, &mut diff, &mut ss);
                        }
                    }
                }
                reps as f64 * estep_flops(blocks * BLOCK, d, k)
            });
            println!(
                "{isa:?}: whitened_norms {e:.1} GFLOP/s ({:.0} %)",
                100.0 * e / peak
            );
            for group in [1, 2, 4, blocks] {
                let mm = best(&mut || {
                    for _ in 0..reps * k {
                        let (a, b) = (&mut s1, &mut xx);
                        moments_in_groups(isa, group, &mut acc, d, blocks, &x, &w, a, b);
                    }
                    (reps * k) as f64 * mstep_flops(blocks * BLOCK, d, 1)
                });
                println!(
                    "{isa:?}: moments, {group} blocks per visit: {mm:.1} GFLOP/s ({:.0} %)",
                    100.0 * mm / peak
                );
            }
        }
    }
}
