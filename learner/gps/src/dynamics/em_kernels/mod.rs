//! The dense arithmetic of the GMM's EM (docs/design.md §5 D33): the E-step's whitened squared
//! distances `‖L⁻¹ (x − μ)‖²` and the M-step's weighted first and second moments `Σ_p w_p x_p`,
//! `Σ_p w_p x_p x_pᵀ` (lower triangle only), and the clusters' Cholesky factors.
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

/// The mantissa bits of an f64, and the exponent field of 1.0.
const MANTISSA: u64 = (1 << 52) - 1;
const ONE_EXPONENT: u64 = 1023 << 52;

/// Which instantiation of the kernels runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// `[f64; 4]` with `f64::mul_add`, on any CPU.
    Portable,
    /// 256-bit AVX2+FMA, sixteen registers.
    Avx2,
    /// The same 256-bit operations compiled with AVX-512F/VL: thirty-two registers, larger
    /// tiles. The kernels' sums stay 4-lane (eight lanes would sum in another order); where the
    /// compiler widens independent element-wise work it keeps each element's operations.
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
    /// `(e, m)` with `self = 2^e · m`, `m` in `[1, 2)`, for positive normal lanes (`e` as an
    /// f64 integer): the exponent field less 1023, and the mantissa with the exponent of 1.
    fn exponent_split(self) -> (Self, Self);
    /// The 4 x 4 transpose: lane `j` of row `r` becomes lane `r` of row `j`.
    fn transpose4(rows: [Self; 4]) -> [Self; 4];
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
    #[inline(always)]
    fn transpose4(r: [Self; 4]) -> [Self; 4] {
        [0, 1, 2, 3].map(|j| [r[0][j], r[1][j], r[2][j], r[3][j]])
    }
    #[inline(always)]
    fn exponent_split(self) -> (Self, Self) {
        (
            self.map(|v| ((v.to_bits() >> 52) as i64 - 1023) as f64),
            self.map(|v| f64::from_bits(v.to_bits() & MANTISSA | ONE_EXPONENT)),
        )
    }
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::*;

    /// A lane-wise `fn $name(self, b) -> Self` of the type `$T` on the AVX intrinsic `$op`.
    macro_rules! binary {
        ($T:ident, $name:ident, $op:ident) => {
            #[inline(always)]
            fn $name(self, b: Self) -> Self {
                $T(unsafe { $op(self.0, b.0) })
            }
        };
    }

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
                binary!($T, add, _mm256_add_pd);
                binary!($T, sub, _mm256_sub_pd);
                binary!($T, mul, _mm256_mul_pd);
                binary!($T, div, _mm256_div_pd);
                binary!($T, max, _mm256_max_pd);
                binary!($T, min, _mm256_min_pd);
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
                #[inline(always)]
                fn transpose4(r: [Self; 4]) -> [Self; 4] {
                    unsafe {
                        // [a0 b0 a2 b2], [a1 b1 a3 b3], [c0 d0 c2 d2], [c1 d1 c3 d3], then the
                        // 128-bit halves paired.
                        let t0 = _mm256_unpacklo_pd(r[0].0, r[1].0);
                        let t1 = _mm256_unpackhi_pd(r[0].0, r[1].0);
                        let t2 = _mm256_unpacklo_pd(r[2].0, r[3].0);
                        let t3 = _mm256_unpackhi_pd(r[2].0, r[3].0);
                        [
                            $T(_mm256_permute2f128_pd::<0x20>(t0, t2)),
                            $T(_mm256_permute2f128_pd::<0x20>(t1, t3)),
                            $T(_mm256_permute2f128_pd::<0x31>(t0, t2)),
                            $T(_mm256_permute2f128_pd::<0x31>(t1, t3)),
                        ]
                    }
                }
                #[inline(always)]
                fn exponent_split(self) -> (Self, Self) {
                    // The exponent field as the integer bits of 2^52 + field, less 2^52 + 1023.
                    const BIAS: f64 = 4_503_599_627_370_496.0 + 1023.0;
                    unsafe {
                        let bits = _mm256_castpd_si256(self.0);
                        let field = _mm256_srli_epi64::<52>(bits);
                        let big = _mm256_or_si256(field, _mm256_set1_epi64x(0x4330 << 48));
                        let e = _mm256_sub_pd(_mm256_castsi256_pd(big), _mm256_set1_pd(BIAS));
                        let m = _mm256_or_si256(
                            _mm256_and_si256(bits, _mm256_set1_epi64x(super::MANTISSA as i64)),
                            _mm256_set1_epi64x(super::ONE_EXPONENT as i64),
                        );
                        ($T(e), $T(_mm256_castsi256_pd(m)))
                    }
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

mod cholesky;
mod estep;
mod mstep;
mod responsibilities;

pub use cholesky::{cholesky, half_log_det};
pub use estep::{invert_lower, pack_whitening, small_norms, whitened_norms};
pub use mstep::{
    direct_column, direct_factors, point_row_len, point_rows, product_column, product_columns,
    product_panels, products, transpose_weights, weighted_sums, weighted_sums_direct, PANEL,
};
pub use responsibilities::{
    exp_slice, logsum_points, logsum_points_weights, normalise_over_clusters, EXP_FLOOR,
};

/// Flops of the E-step's dense arithmetic on `n` points, `k` clusters, dimension `d`, as
/// [`whitened_norms`] does it (padding excluded; a multiply-add counted as two): per cluster and
/// point, `d(d+1)/2` multiply-adds of `L⁻¹ x − L⁻¹ μ` and `d` of the norm (the final
/// `base − ½ s` and the per-cluster `L⁻¹ μ` of [`pack_whitening`] not counted).
pub fn estep_flops(n: usize, d: usize, k: usize) -> f64 {
    (n * k * (d * (d + 1) + 2 * d)) as f64
}

/// Flops of the M-step's dense arithmetic, as [`weighted_sums`] does it: per cluster and point,
/// `d` multiply-adds of the first moment and `d(d+1)/2` of the second (the padding columns of
/// the last panel excluded, and the points' products, formed once per EM run by [`products`],
/// not counted).
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

    pub(super) fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Every instantiation this CPU runs, the portable one first; prints a note for the others.
    pub(super) fn isas() -> Vec<Isa> {
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
        for (d, k, blocks) in [
            (1, 1, 1),
            (2, 2, 1),
            (3, 4, 2),
            (4, 5, 1),
            (5, 7, 1),
            (8, 3, 2),
            (13, 11, 1),
            (14, 11, 2),
            (27usize, 12usize, 2usize),
        ] {
            let minv: Vec<f64> = (0..k).flat_map(|_| random_lower(&mut rng, d)).collect();
            let mu: Vec<f64> = (0..k * d).map(|_| rng.random_range(-1.0..1.0)).collect();
            let base: Vec<f64> = (0..k).map(|_| rng.random_range(-30.0..0.0)).collect();
            let x: Vec<f64> = (0..blocks * d * BLOCK)
                .map(|_| rng.random_range(-3.0..3.0))
                .collect();
            let stride = blocks * BLOCK + 4;
            for isa in isas() {
                let (mut mt, mut c) = (Vec::new(), Vec::new());
                pack_whitening(isa, &minv, &mu, d, k, &mut mt, &mut c);
                let mut out = vec![f64::NAN; k * stride];
                whitened_norms(isa, &mt, &c, &base, d, k, &x, blocks, &mut out, stride);
                for i in 0..k {
                    let m = &minv[i * d * d..];
                    for p in 0..blocks * BLOCK {
                        // The documented order: c_a = (M μ)_a a fused chain from +0, y_a a
                        // fused chain over ascending b from −c_a, the norm a fused chain over
                        // ascending a, then base − s/2 fused.
                        let xp = |b: usize| x[(p / BLOCK) * d * BLOCK + b * BLOCK + p % BLOCK];
                        let mut norm = 0.0f64;
                        for a in 0..d {
                            let ca =
                                (0..=a).fold(0.0f64, |s, b| m[a * d + b].mul_add(mu[i * d + b], s));
                            let y = (0..=a).fold(-ca, |s, b| m[a * d + b].mul_add(xp(b), s));
                            norm = y.mul_add(y, norm);
                        }
                        let want = (-0.5f64).mul_add(norm, base[i]);
                        let got = out[i * stride + p];
                        assert_eq!(got.to_bits(), want.to_bits(), "{isa:?} d={d} i={i} p={p}");
                    }
                    assert!(
                        out[i * stride + blocks * BLOCK..(i + 1) * stride]
                            .iter()
                            .all(|v| v.is_nan()),
                        "nothing written past the blocks"
                    );
                }
            }
        }
    }

    /// `n` random points of dimension `d` in blocks (coordinates in `±span`), random weights for
    /// `k` clusters point-major, and the points' [`products`].
    fn points_weights_products(
        rng: &mut impl Rng,
        d: usize,
        n: usize,
        k: usize,
        span: f64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let x: Vec<f64> = (0..n.div_ceil(BLOCK) * d * BLOCK)
            .map(|_| rng.random_range(-span..span))
            .collect();
        let w: Vec<f64> = (0..n * k).map(|_| rng.random_range(0.0..1.0)).collect();
        let mut prod = Vec::new();
        products(
            Isa::detect(),
            &x,
            n,
            d,
            &mut prod,
            &mut Vec::new(),
            &mut Vec::new(),
        );
        (x, w, prod)
    }

    #[test]
    fn products_hold_each_product_once_rounded_in_panels() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for (d, n) in [(1, 1), (2, 5), (3, 33), (5, 40), (27usize, 70usize)] {
            let blocks = n.div_ceil(BLOCK);
            let x: Vec<f64> = (0..blocks * d * BLOCK)
                .map(|_| rng.random_range(-2.0..2.0))
                .collect();
            let panels = product_panels(d);
            let xv = |p: usize, a: usize| x[(p / BLOCK) * d * BLOCK + a * BLOCK + p % BLOCK];
            for isa in isas() {
                let (mut prod, mut pairs) = (vec![f64::NAN; 3], Vec::new());
                products(isa, &x, n, d, &mut prod, &mut pairs, &mut Vec::new());
                assert_eq!(prod.len(), panels * n * PANEL);
                let at = |p: usize, c: usize| prod[((c / PANEL) * n + p) * PANEL + c % PANEL];
                for p in 0..n {
                    for a in 0..d {
                        assert_eq!(at(p, a).to_bits(), xv(p, a).to_bits(), "{isa:?}");
                        for b in 0..=a {
                            let want = xv(p, a) * xv(p, b);
                            let got = at(p, product_column(d, a, b));
                            assert_eq!(got.to_bits(), want.to_bits(), "{isa:?}");
                        }
                    }
                    for c in product_columns(d)..panels * PANEL {
                        assert_eq!(at(p, c).to_bits(), 0, "{isa:?}: padding +0");
                    }
                }
            }
        }
    }

    #[test]
    fn transpose_weights_moves_every_weight() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
        for (n, k) in [
            (1usize, 1usize),
            (3, 2),
            (4, 4),
            (7, 5),
            (33, 11),
            (64, 12),
            (45, 20),
        ] {
            let stride = n.div_ceil(BLOCK) * BLOCK;
            let w: Vec<f64> = (0..k * stride)
                .map(|_| rng.random_range(0.0..1.0))
                .collect();
            for isa in isas() {
                let mut wt = vec![f64::NAN; n * k];
                transpose_weights(isa, &w, stride, n, k, &mut wt);
                for p in 0..n {
                    for i in 0..k {
                        assert_eq!(wt[p * k + i].to_bits(), w[i * stride + p].to_bits());
                    }
                }
            }
        }
    }

    #[test]
    fn weighted_sums_follow_their_documented_order_bit_for_bit_on_every_build() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for (d, n, k) in [
            (1, 1, 1),
            (2, 7, 2),
            (3, 33, 3),
            (4, 32, 5),
            (5, 9, 7),
            (6, 64, 13),
            (9, 150, 20),
            (27, 495usize, 12),
        ] {
            let (x, w, prod) = points_weights_products(&mut rng, d, n, k, 2.0);
            let panels = product_panels(d);
            let cols = panels * PANEL;
            let run = |isa: Isa| {
                let mut out = vec![f64::NAN; k * cols];
                weighted_sums(isa, n, k, &w, &prod, panels, &mut out);
                out
            };
            let out = run(Isa::Portable);
            // The documented order: ascending points from +0, one fused multiply-add each.
            for i in 0..k {
                for c in 0..cols {
                    let pc = |p: usize| prod[((c / PANEL) * n + p) * PANEL + c % PANEL];
                    let s = (0..n).fold(0.0f64, |acc, p| w[p * k + i].mul_add(pc(p), acc));
                    assert_eq!(
                        out[i * cols + c].to_bits(),
                        s.to_bits(),
                        "d={d} i={i} c={c}"
                    );
                }
            }
            let (mut rows, factors) = (Vec::new(), direct_factors(d));
            point_rows(&x, n, d, &mut rows);
            let dcols = factors.len() * PANEL;
            for isa in isas() {
                assert_eq!(bits(&out), bits(&run(isa)), "{isa:?} d={d} k={k}");
                // The products formed per point instead: the same bits in their own columns.
                let mut direct = vec![f64::NAN; k * dcols];
                weighted_sums_direct(isa, n, k, &w, &rows, d, &factors, &mut direct);
                for i in 0..k {
                    let (o, g) = (&out[i * cols..], &direct[i * dcols..]);
                    for a in 0..d {
                        assert_eq!(o[a].to_bits(), g[a].to_bits(), "{isa:?} d={d} i={i} a={a}");
                        for b in 0..=a {
                            let (pc, dc) = (product_column(d, a, b), direct_column(d, a, b));
                            assert_eq!(o[pc].to_bits(), g[dc].to_bits(), "{isa:?} d={d} ({a},{b})");
                        }
                    }
                }
            }
        }
        // No points: every sum is +0.
        let mut out = vec![f64::NAN; 2 * PANEL];
        weighted_sums(Isa::detect(), 0, 2, &[], &[], 1, &mut out);
        assert!(out.iter().all(|v| v.to_bits() == 0));
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
    #[test]
    fn ln_is_within_one_ulp_of_libm_and_every_build_agrees() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let mut x: Vec<f64> = (0..4000).map(|_| rng.random_range(1.0..12.0)).collect();
        x.extend((0..2000).map(|_| 10f64.powf(rng.random_range(-300.0..300.0))));
        x.extend((0..1000).map(|_| rng.random_range(0.99..1.01)));
        let sqrt2 = std::f64::consts::SQRT_2;
        for v in [
            1.0,
            2.0,
            0.5,
            1e-300,
            1e300,
            f64::MIN_POSITIVE,
            f64::MAX,
            sqrt2,
        ] {
            x.extend(
                [v, v.next_up(), v.next_down()]
                    .iter()
                    .filter(|w| w.is_normal()),
            );
        }
        while x.len() % 4 != 0 {
            x.push(1.0);
        }
        let mut want = vec![0.0; x.len()];
        responsibilities::ln_slice(Isa::Portable, &x, &mut want);
        for (&xi, &w) in x.iter().zip(&want) {
            assert!(
                ulps(w, xi.ln()) <= 1,
                "ln({xi:e}) = {w:e}, libm {:e}",
                xi.ln()
            );
        }
        assert_eq!(
            want[x.iter().position(|&v| v == 1.0).unwrap()].to_bits(),
            0,
            "ln 1 = +0"
        );
        for isa in isas() {
            let mut got = vec![0.0; x.len()];
            responsibilities::ln_slice(isa, &x, &mut got);
            assert_eq!(bits(&got), bits(&want), "{isa:?}");
        }
    }

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
                let mut w = vec![f64::NAN; stride * k];
                let col: Vec<f64> = (0..k)
                    .map(|i| {
                        let (li, wi) = (&l[i * stride..][..n], &mut w[i * stride..][..stride]);
                        let c = logsum_points_weights(isa, li, wi);
                        assert_eq!(c.to_bits(), logsum_points(isa, li).to_bits());
                        c
                    })
                    .collect();
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
                let top = row.iter().copied().fold(f64::MIN, f64::max);
                for p in 0..stride {
                    let wp = w[i * stride + p];
                    if p >= n {
                        assert_eq!(wp.to_bits(), 0, "padding weighs +0");
                    } else if row[p] - top < EXP_FLOOR {
                        assert_eq!(wp.to_bits(), 0, "below the floor: +0");
                    } else {
                        // exp(l − logsum); the reference's own argument is rounded to an ulp
                        // of up to ~600, hence a relative tolerance, not a few ulp.
                        let want = (row[p] - col[i]).exp();
                        assert!((wp - want).abs() <= 1e-12 * want, "n={n} i={i} p={p}");
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
        let reps = 200;
        let peak = best(&mut || fma_peak(2_000_000));
        println!("peak {peak:.1} GFLOP/s");
        // The bench's problem, the default prior's largest (19 samples of T = 100, K = 20), and
        // problem B's second iteration (dX = 6, dU = 2, 464 points, K = 11).
        for (d, blocks, k) in [(27, 16, 12), (27, 59, 20), (14, 15, 11)] {
            let n = blocks * BLOCK;
            let minv: Vec<f64> = (0..k).flat_map(|_| random_lower(&mut rng, d)).collect();
            let mu = vec![0.1; k * d];
            let base = vec![-20.0; k];
            let (mut mt, mut c) = (Vec::new(), Vec::new());
            pack_whitening(Isa::detect(), &minv, &mu, d, k, &mut mt, &mut c);
            let (x, wt, prod) = points_weights_products(&mut rng, d, n, k, 3.0);
            let panels = product_panels(d);
            let mut out = vec![0.0; k * panels * PANEL];
            let (mut rows, factors) = (Vec::new(), direct_factors(d));
            point_rows(&x, n, d, &mut rows);
            let mut dout = vec![0.0; k * factors.len() * PANEL];
            let mut logobs = vec![0.0; k * n];
            for isa in isas().into_iter().filter(|&isa| isa != Isa::Portable) {
                let e = best(&mut || {
                    for _ in 0..reps {
                        let o = &mut logobs;
                        whitened_norms(isa, &mt, &c, &base, d, k, &x, blocks, o, n);
                    }
                    reps as f64 * estep_flops(n, d, k)
                });
                let mm = best(&mut || {
                    for _ in 0..reps {
                        weighted_sums(isa, n, k, &wt, &prod, panels, &mut out);
                    }
                    reps as f64 * mstep_flops(n, d, k)
                });
                let md = best(&mut || {
                    for _ in 0..reps {
                        let o = &mut dout;
                        weighted_sums_direct(isa, n, k, &wt, &rows, d, &factors, o);
                    }
                    reps as f64 * mstep_flops(n, d, k)
                });
                println!(
                    "{isa:?}, d = {d}, {n} points, K = {k}: whitened_norms {e:.1} GFLOP/s \
                     ({:.0} %), weighted_sums {mm:.1} GFLOP/s ({:.0} %), direct {md:.1} GFLOP/s \
                     ({:.0} %)",
                    100.0 * e / peak,
                    100.0 * mm / peak,
                    100.0 * md / peak
                );
            }
        }
    }
}
