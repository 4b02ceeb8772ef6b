//! The dense arithmetic of the GMM's EM (docs/design.md §5 D33): the E-step's whitened squared
//! distances `‖L⁻¹ (x − μ)‖²` and the M-step's weighted first and second moments `Σ_p w_p x_p`,
//! `Σ_p w_p x_p x_pᵀ` (lower triangle only).
//!
//! Layout: points are **lanes**. The points are stored in blocks of [`BLOCK`], each block
//! dimension-major (`x[blk * d * BLOCK + a * BLOCK + j]` = coordinate `a` of point
//! `blk * BLOCK + j`), padding points zero. Inverse Cholesky factors are `D x D` row-major lower
//! triangles (`m[a * d + b]`, `b ≤ a`).
//!
//! Every kernel is written once, generic over a 4-lane vector ([`Lanes`]), and instantiated twice:
//! on AVX2+FMA registers (chosen at run time when the CPU has both) and on plain `[f64; 4]` arrays
//! whose multiply-add is the correctly rounded `f64::mul_add`. Both do the same fused operations in
//! the same order, so the results are the same bits on every x86_64 machine (the tests compare
//! the two); the portable one is slow where the CPU has no FMA instruction.

/// Points per block.
pub const BLOCK: usize = 32;

/// Whether the AVX2+FMA instantiation runs on this CPU.
#[inline]
pub fn fast_path() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Four f64 lanes: the operations the kernels use.
trait Lanes: Copy {
    fn zero() -> Self;
    /// Loads `s[0..4]`.
    fn load(s: &[f64]) -> Self;
    fn store(self, s: &mut [f64]);
    fn splat(v: f64) -> Self;
    /// `a * b + self`, fused (one rounding) in every lane.
    fn fma(self, a: Self, b: Self) -> Self;
    fn add(self, b: Self) -> Self;
    fn sub(self, b: Self) -> Self;
    /// `(l0 + l1) + (l2 + l3)`.
    fn sum(self) -> f64 {
        let mut o = [0.0; 4];
        self.store(&mut o);
        (o[0] + o[1]) + (o[2] + o[3])
    }
}

impl Lanes for [f64; 4] {
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
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::*;

    /// AVX2 register; only used inside functions compiled with `avx2,fma` enabled.
    #[derive(Clone, Copy)]
    pub(super) struct Avx(__m256d);

    // SAFETY (all methods): only reached from `#[target_feature(enable = "avx2,fma")]`
    // functions, which run only when `fast_path()` saw both features; loads and stores are
    // of slices checked to hold four elements.
    impl super::Lanes for Avx {
        #[inline(always)]
        fn zero() -> Self {
            Avx(unsafe { _mm256_setzero_pd() })
        }
        #[inline(always)]
        fn load(s: &[f64]) -> Self {
            assert!(s.len() >= 4);
            Avx(unsafe { _mm256_loadu_pd(s.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, s: &mut [f64]) {
            assert!(s.len() >= 4);
            unsafe { _mm256_storeu_pd(s.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn splat(v: f64) -> Self {
            Avx(unsafe { _mm256_set1_pd(v) })
        }
        #[inline(always)]
        fn fma(self, a: Self, b: Self) -> Self {
            Avx(unsafe { _mm256_fmadd_pd(a.0, b.0, self.0) })
        }
        #[inline(always)]
        fn add(self, b: Self) -> Self {
            Avx(unsafe { _mm256_add_pd(self.0, b.0) })
        }
        #[inline(always)]
        fn sub(self, b: Self) -> Self {
            Avx(unsafe { _mm256_sub_pd(self.0, b.0) })
        }
    }
}

/// Runs `$body` with `$V` bound to the fastest [`Lanes`] type: inside a function compiled for
/// AVX2+FMA when `$fast`, else on `[f64; 4]`.
macro_rules! dispatch {
    ($fast:expr, fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {{
        #[inline(always)]
        fn generic<V: Lanes>($($arg: $ty),*) $body
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn fast_impl($($arg: $ty),*) {
            generic::<avx::Avx>($($arg),*)
        }
        #[inline(never)]
        fn base_impl($($arg: $ty),*) {
            generic::<[f64; 4]>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        if $fast {
            // SAFETY: `$fast` is only true when the CPU has AVX2 and FMA (`fast_path`).
            unsafe { fast_impl($($arg),*) }
        } else {
            base_impl($($arg),*)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = $fast;
            base_impl($($arg),*)
        }
    }};
}

/// E-step of one cluster on one block: `ss[j] = ‖M (x_j − μ)‖²` for the block's `BLOCK` points
/// (`x`: one block, dimension-major), `M = L⁻¹` lower triangular (`d x d` row-major). Rows are
/// taken two at a time on sixteen points; `ss` accumulates `y_0², y_1², …` in row order.
/// `diff` (`d x BLOCK`) is scratch.
pub fn whitened_norms(
    fast: bool,
    m: &[f64],
    mu: &[f64],
    d: usize,
    x: &[f64],
    diff: &mut [f64],
    ss: &mut [f64; BLOCK],
) {
    assert!(m.len() >= d * d && mu.len() >= d && x.len() >= d * BLOCK && diff.len() >= d * BLOCK);
    dispatch!(
        fast,
        fn k(m: &[f64], mu: &[f64], d: usize, x: &[f64], diff: &mut [f64], ss: &mut [f64; BLOCK]) {
            for a in 0..d {
                let mua = V::splat(mu[a]);
                for q in (0..BLOCK).step_by(4) {
                    V::load(&x[a * BLOCK + q..])
                        .sub(mua)
                        .store(&mut diff[a * BLOCK + q..]);
                }
            }
            for h in (0..BLOCK).step_by(16) {
                let mut s = [V::zero(); 4];
                let mut a = 0;
                while a < d {
                    let two = a + 1 < d;
                    let (r0, r1) = (&m[a * d..a * d + a + 1], &m[(a + 1).min(d - 1) * d..]);
                    let mut y0 = [V::zero(); 4];
                    let mut y1 = [V::zero(); 4];
                    for b in 0..=a {
                        let (l0, l1) = (V::splat(r0[b]), V::splat(if two { r1[b] } else { 0.0 }));
                        let row: &[f64; BLOCK] =
                            diff[b * BLOCK..(b + 1) * BLOCK].try_into().unwrap();
                        for v in 0..4 {
                            let db = V::load(&row[h + 4 * v..]);
                            y0[v] = y0[v].fma(l0, db);
                            y1[v] = y1[v].fma(l1, db);
                        }
                    }
                    for v in 0..4 {
                        s[v] = s[v].fma(y0[v], y0[v]);
                    }
                    if two {
                        let l1 = V::splat(r1[a + 1]);
                        let row: &[f64; BLOCK] =
                            diff[(a + 1) * BLOCK..(a + 2) * BLOCK].try_into().unwrap();
                        for v in 0..4 {
                            let db = V::load(&row[h + 4 * v..]);
                            y1[v] = y1[v].fma(l1, db);
                            s[v] = s[v].fma(y1[v], y1[v]);
                        }
                    }
                    a += 2;
                }
                for v in 0..4 {
                    s[v].store(&mut ss[h + 4 * v..]);
                }
            }
        }
    )
}

/// Running sums of one cluster's M-step over blocks of points: [`moments_block`] adds one
/// block, [`Moments::finish`] writes `s1[a] = Σ_p w_p x_pa` and, for `b ≤ a`,
/// `xx[a * d + b] = Σ_p w_p x_pa x_pb`. Each sum runs over four lanes (`p mod 4`, ascending `p`)
/// added at the end as `(l0 + l1) + (l2 + l3)`.
pub struct Moments {
    d: usize,
    /// `d x 4` lane sums of `w x`.
    s1: Vec<f64>,
    /// Two rows by four columns of 4-lane sums per tile, tiles in `(a0, b0)` order.
    tiles: Vec<f64>,
    /// `d x BLOCK` weighted block `w_j x_j`.
    z: Vec<f64>,
}

/// Tiles of the lower triangle: row pairs `a0 = 0, 2, …` by column quads `b0 = 0, 4, … ≤ a0 + 1`.
fn tile_count(d: usize) -> usize {
    (0..d)
        .step_by(2)
        .map(|a0| ((a0 + 1).min(d - 1) + 1).div_ceil(4))
        .sum()
}

impl Moments {
    /// Sums for points of dimension `d`, all zero.
    pub fn new(d: usize) -> Self {
        Self {
            d,
            s1: vec![0.0; d * 4],
            tiles: vec![0.0; tile_count(d) * 32],
            z: vec![0.0; d * BLOCK],
        }
    }

    /// Sets all sums to zero.
    pub fn clear(&mut self) {
        self.s1.fill(0.0);
        self.tiles.fill(0.0);
    }

    /// Writes the moments (upper triangle of `xx` untouched).
    pub fn finish(&self, s1: &mut [f64], xx: &mut [f64]) {
        let d = self.d;
        for a in 0..d {
            s1[a] = <[f64; 4] as Lanes>::load(&self.s1[4 * a..]).sum();
        }
        let mut t = 0;
        for a0 in (0..d).step_by(2) {
            let a1 = (a0 + 1).min(d - 1);
            for b0 in (0..=a1).step_by(4) {
                for (r, a) in [a0, a1].into_iter().enumerate() {
                    for c in 0..4 {
                        let b = b0 + c;
                        if (r == 0 || a1 != a0) && b <= a {
                            let o = t * 32 + (r * 4 + c) * 4;
                            xx[a * d + b] = <[f64; 4] as Lanes>::load(&self.tiles[o..]).sum();
                        }
                    }
                }
                t += 1;
            }
        }
    }
}

/// Adds one block of points (`x`, dimension-major, padding zero) with weights `w` (`BLOCK`,
/// padding zero) to the sums.
pub fn moments_block(fast: bool, acc: &mut Moments, x: &[f64], w: &[f64; BLOCK]) {
    let d = acc.d;
    assert!(x.len() >= d * BLOCK);
    let Moments { s1, tiles, z, .. } = acc;
    dispatch!(
        fast,
        fn k(
            d: usize,
            x: &[f64],
            w: &[f64; BLOCK],
            s1: &mut [f64],
            tiles: &mut [f64],
            z: &mut [f64],
        ) {
            for a in 0..d {
                let mut s = V::load(&s1[4 * a..]);
                for q in (0..BLOCK).step_by(4) {
                    let zq = V::zero().fma(V::load(&w[q..]), V::load(&x[a * BLOCK + q..]));
                    zq.store(&mut z[a * BLOCK + q..]);
                    s = s.add(zq);
                }
                s.store(&mut s1[4 * a..]);
            }
            let mut t = 0;
            for a0 in (0..d).step_by(2) {
                let a1 = (a0 + 1).min(d - 1);
                for b0 in (0..=a1).step_by(4) {
                    fn row(m: &[f64], i: usize) -> &[f64; BLOCK] {
                        m[i * BLOCK..(i + 1) * BLOCK].try_into().unwrap()
                    }
                    let xr = [0, 1, 2, 3].map(|c| row(x, (b0 + c).min(d - 1)));
                    let (zr0, zr1) = (row(&z[..], a0), row(&z[..], a1));
                    let tile = &mut tiles[t * 32..(t + 1) * 32];
                    let mut acc = [V::zero(); 8];
                    for (r, o) in acc.iter_mut().enumerate() {
                        *o = V::load(&tile[4 * r..]);
                    }
                    for q in (0..BLOCK).step_by(4) {
                        let z0 = V::load(&zr0[q..]);
                        let z1 = V::load(&zr1[q..]);
                        for c in 0..4 {
                            let xs = V::load(&xr[c][q..]);
                            acc[c] = acc[c].fma(z0, xs);
                            acc[4 + c] = acc[4 + c].fma(z1, xs);
                        }
                    }
                    for (r, o) in acc.iter().enumerate() {
                        o.store(&mut tile[4 * r..]);
                    }
                    t += 1;
                }
            }
        }
    )
}

/// Flops of the E-step's dense arithmetic on `n` points, `k` clusters, dimension `d`, as
/// [`whitened_norms`] does it (padding excluded; a multiply-add counted as two): per cluster and
/// point, `d` subtractions, `d(d+1)/2` multiply-adds of `L⁻¹ (x − μ)` and `d` of the norm.
pub fn estep_flops(n: usize, d: usize, k: usize) -> f64 {
    (n * k * (d + d * (d + 1) + 2 * d)) as f64
}

/// Flops of the M-step's dense arithmetic, as [`moments_block`] does it: per cluster and point,
/// `d` weightings, `d` sums and `d(d+1)/2` multiply-adds of the second moment.
pub fn mstep_flops(n: usize, d: usize, k: usize) -> f64 {
    (n * k * (2 * d + d * (d + 1))) as f64
}

/// One core's f64 multiply-add peak, to be timed by the caller: `rounds` rounds of 48
/// independent fused multiply-adds (twelve 4-lane chains, enough to cover the FMA latency on two
/// pipes) on the instantiation [`fast_path`] selects. Returns the flops done, 2 × 48 × `rounds`.
pub fn fma_peak(rounds: usize) -> f64 {
    let mut out = 0.0;
    let sink = &mut out;
    let (m, c) = (
        std::hint::black_box(0.999_999_9),
        std::hint::black_box(1e-7),
    );
    dispatch!(
        fast_path(),
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

    #[test]
    fn whitened_norms_match_direct_sums_and_both_builds_agree_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for d in [1, 2, 5, 27] {
            let m = random_lower(&mut rng, d);
            let mu: Vec<f64> = (0..d).map(|_| rng.random_range(-1.0..1.0)).collect();
            let x: Vec<f64> = (0..d * BLOCK)
                .map(|_| rng.random_range(-3.0..3.0))
                .collect();
            let mut diff = vec![0.0; d * BLOCK];
            let mut ss = [0.0; BLOCK];
            whitened_norms(fast_path(), &m, &mu, d, &x, &mut diff, &mut ss);
            for j in 0..BLOCK {
                let norm: f64 = (0..d)
                    .map(|a| {
                        let y: f64 = (0..=a)
                            .map(|b| m[a * d + b] * (x[b * BLOCK + j] - mu[b]))
                            .sum();
                        y * y
                    })
                    .sum();
                assert!((ss[j] - norm).abs() <= 1e-12 * norm.max(1.0), "d={d} j={j}");
            }
            let mut ss2 = [0.0; BLOCK];
            whitened_norms(false, &m, &mu, d, &x, &mut diff, &mut ss2);
            assert_eq!(
                bits(&ss),
                bits(&ss2),
                "d={d}: the two instantiations differ"
            );
        }
    }

    #[test]
    fn moments_match_direct_sums_and_both_builds_agree_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for (d, blocks) in [(1, 1), (2, 2), (5, 1), (27, 16)] {
            let np = blocks * BLOCK;
            let x: Vec<f64> = (0..d * np).map(|_| rng.random_range(-2.0..2.0)).collect();
            let w: Vec<f64> = (0..np).map(|_| rng.random_range(0.0..1.0)).collect();
            let run = |fast: bool| {
                let mut acc = Moments::new(d);
                for blk in 0..blocks {
                    let wb: [f64; BLOCK] = w[blk * BLOCK..(blk + 1) * BLOCK].try_into().unwrap();
                    moments_block(fast, &mut acc, &x[blk * d * BLOCK..], &wb);
                }
                let (mut s1, mut xx) = (vec![0.0; d], vec![f64::NAN; d * d]);
                acc.finish(&mut s1, &mut xx);
                (s1, xx)
            };
            let (s1, xx) = run(fast_path());
            let at = |a: usize, p: usize| x[(p / BLOCK) * d * BLOCK + a * BLOCK + p % BLOCK];
            for a in 0..d {
                let s: f64 = (0..np).map(|p| w[p] * at(a, p)).sum();
                assert!((s1[a] - s).abs() < 1e-11, "d={d} a={a}");
                for b in 0..d {
                    if b <= a {
                        let s: f64 = (0..np).map(|p| w[p] * at(a, p) * at(b, p)).sum();
                        assert!((xx[a * d + b] - s).abs() < 1e-11, "d={d} ({a},{b})");
                    } else {
                        assert!(xx[a * d + b].is_nan(), "upper triangle written");
                    }
                }
            }
            let (s1b, xxb) = run(false);
            assert_eq!(bits(&s1), bits(&s1b));
            assert_eq!(bits(&xx), bits(&xxb));
        }
    }

    /// Prints the kernels' speed beside the peak (`--ignored --nocapture`); measures, checks nothing.
    #[test]
    #[ignore]
    fn kernel_speed() {
        let t0 = std::time::Instant::now();
        let f = fma_peak(20_000_000);
        println!("peak {:.1} GFLOP/s", f / t0.elapsed().as_secs_f64() / 1e9);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let d = 27;
        let m = random_lower(&mut rng, d);
        let mu = vec![0.1; d];
        let x: Vec<f64> = (0..d * BLOCK)
            .map(|_| rng.random_range(-3.0..3.0))
            .collect();
        let mut diff = vec![0.0; d * BLOCK];
        let reps = 20_000;
        let t0 = std::time::Instant::now();
        let mut ss = [0.0; BLOCK];
        for _ in 0..reps {
            whitened_norms(fast_path(), &m, &mu, d, &x, &mut diff, &mut ss);
        }
        let dt = t0.elapsed().as_secs_f64();
        let fl = reps as f64 * estep_flops(BLOCK, d, 1);
        println!("whitened_norms {:.1} GFLOP/s", fl / dt / 1e9);
        let w = [0.5; BLOCK];
        let mut acc = Moments::new(d);
        let t0 = std::time::Instant::now();
        for _ in 0..reps {
            moments_block(fast_path(), &mut acc, &x, &w);
        }
        let dt = t0.elapsed().as_secs_f64();
        let fl = reps as f64 * mstep_flops(BLOCK, d, 1);
        println!("moments_block {:.1} GFLOP/s", fl / dt / 1e9);
    }
}
