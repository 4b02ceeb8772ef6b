//! The numerical kernels of every MLP in the project: the dot product, the affine map, tanh, and
//! the element-wise updates of the backward pass (`axpy`, `mat_t_vec`, `outer_acc`,
//! `sym_outer_acc_upper`).
//! The learner's networks (critic, PPO policy and value, MDGPS policy) and the controller's
//! [`crate::policy_action`] call these and nothing else, so a policy acts with the same bits in
//! the learner and in the real-time loop (docs/design.md §3.11).
//!
//! Every kernel gives the same bits on every x86-64 CPU: the wide paths (AVX / AVX2, chosen at
//! run time from std's cached CPUID check: no syscall, no allocation) do per lane exactly the
//! multiplications, additions and divisions of the scalar path, in the same order, and fused
//! multiply-add is never used. Tests compare the paths bit for bit.

/// `Σ a_i b_i` with four running sums in a fixed order (`s_k` takes the terms `i ≡ k mod 4`;
/// then `(s_0 + s_1) + (s_2 + s_3)`, then the last `len mod 4` terms one by one).
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    debug_assert_eq!(a.len(), b.len());
    let mut s = [0.0f64; 4];
    let (ca, ra) = a.split_at(a.len() / 4 * 4);
    let (cb, rb) = b.split_at(ca.len());
    for (x, y) in ca.chunks_exact(4).zip(cb.chunks_exact(4)) {
        s[0] += x[0] * y[0];
        s[1] += x[1] * y[1];
        s[2] += x[2] * y[2];
        s[3] += x[3] * y[3];
    }
    let mut t = (s[0] + s[1]) + (s[2] + s[3]);
    for (x, y) in ra.iter().zip(rb) {
        t += x * y;
    }
    t
}

/// `out = W x + b`, `W` row-major `out.len() × x.len()`: each row is [`dot`]`(W_i, x) + b_i`,
/// bit for bit. With AVX, four rows at a time, each row's four running sums in one 256-bit
/// register.
///
/// # Panics
/// If `w.len() < out.len() · x.len()` or `b.len() < out.len()`.
#[inline]
pub fn affine(w: &[f64], b: &[f64], x: &[f64], out: &mut [f64]) {
    assert!(w.len() >= out.len() * x.len() && b.len() >= out.len());
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present (checked above); the lengths were checked above.
        unsafe { affine_avx(w, b, x, out) };
        return;
    }
    affine_rows(w, b, x, out);
}

/// [`affine`] row by row with [`dot`] (any CPU).
fn affine_rows(w: &[f64], b: &[f64], x: &[f64], out: &mut [f64]) {
    let n_in = x.len();
    for (i, (o, &bi)) in out.iter_mut().zip(b).enumerate() {
        *o = dot(&w[i * n_in..(i + 1) * n_in], x) + bi;
    }
}

/// [`affine`] with AVX, four rows at a time (the rows left over by [`affine_rows`]).
///
/// # Safety
/// The CPU has AVX; `w.len() ≥ out.len() · x.len()`, `b.len() ≥ out.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn affine_avx(w: &[f64], b: &[f64], x: &[f64], out: &mut [f64]) {
    use core::arch::x86_64::{
        __m256d, _mm256_add_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let n = x.len();
    let n4 = n / 4 * 4;
    let rows = out.len();
    // The end of one row as in `dot`: (s0 + s1) + (s2 + s3), then the last n mod 4 terms.
    let finish = |s: __m256d, row: &[f64]| {
        let mut l = [0.0f64; 4];
        // SAFETY: `l` holds four f64.
        unsafe { _mm256_storeu_pd(l.as_mut_ptr(), s) };
        let mut t = (l[0] + l[1]) + (l[2] + l[3]);
        for k in n4..n {
            t += row[k] * x[k];
        }
        t
    };
    let mut i = 0;
    while i + 4 <= rows {
        let r = [0, 1, 2, 3].map(|d| &w[(i + d) * n..(i + d + 1) * n]);
        let mut s = [_mm256_setzero_pd(); 4];
        let mut k = 0;
        while k < n4 {
            // SAFETY: k + 4 ≤ n4 ≤ n = x.len() = r[d].len().
            unsafe {
                let xv = _mm256_loadu_pd(x.as_ptr().add(k));
                for d in 0..4 {
                    let wv = _mm256_loadu_pd(r[d].as_ptr().add(k));
                    s[d] = _mm256_add_pd(s[d], _mm256_mul_pd(wv, xv));
                }
            }
            k += 4;
        }
        for d in 0..4 {
            out[i + d] = finish(s[d], r[d]) + b[i + d];
        }
        i += 4;
    }
    affine_rows(&w[i * n..], &b[i..], x, &mut out[i..]);
}

/// `y += a x`, element by element (`y_i ← y_i + a · x_i`: one multiplication, one addition).
/// With AVX four elements at a time, the same two operations per element, so the same bits.
///
/// # Panics
/// If `y.len() < x.len()` (only `x.len()` elements of `y` are updated).
#[inline]
pub fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    let y = &mut y[..x.len()];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present (checked above).
        unsafe { axpy_avx(a, x, y) };
        return;
    }
    axpy_lanes(a, x, y);
}

/// `out[..cols] = Wᵀ y`, `W` row-major `rows × cols`: zero, then [`axpy`]`(y_i, W_i, out)` for
/// `i = 0..rows` in order (so each `out_j` sums its terms in row order), bit for bit.
///
/// # Panics
/// If `w.len() < rows · cols`, `y.len() < rows` or `out.len() < cols`.
#[inline]
pub fn mat_t_vec(w: &[f64], rows: usize, cols: usize, y: &[f64], out: &mut [f64]) {
    assert!(w.len() >= rows * cols && y.len() >= rows && out.len() >= cols);
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present (checked above); the lengths were checked above.
        unsafe { mat_t_vec_avx(w, rows, cols, y, out) };
        return;
    }
    mat_t_vec_rows(w, rows, cols, y, out);
}

/// `M += c u vᵀ`, `M` row-major `u.len() × v.len()`: row i is [`axpy`]`(c · u_i, v, M_i)`, bit
/// for bit.
///
/// # Panics
/// If `m.len() < u.len() · v.len()`.
#[inline]
pub fn outer_acc(c: f64, u: &[f64], v: &[f64], m: &mut [f64]) {
    assert!(m.len() >= u.len() * v.len());
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present (checked above); the length was checked above.
        unsafe { outer_acc_avx(c, u, v, m) };
        return;
    }
    outer_acc_rows(c, u, v, m);
}

/// The upper triangle (diagonal included) of `M += c v vᵀ`, `M` row-major `v.len() × v.len()`:
/// row p is [`axpy`]`(c · v_p, v[p..], M[p, p..])`, bit for bit; the strict lower triangle is
/// left as it is (a symmetric accumulation mirrors it once at the end).
///
/// # Panics
/// If `m.len() < v.len()²`.
#[inline]
pub fn sym_outer_acc_upper(c: f64, v: &[f64], m: &mut [f64]) {
    assert!(m.len() >= v.len() * v.len());
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present (checked above); the length was checked above.
        unsafe { sym_outer_acc_upper_avx(c, v, m) };
        return;
    }
    sym_outer_acc_upper_rows(c, v, m);
}

/// The element loop of [`axpy`] (any CPU; inlined into the AVX versions, where the compiler
/// vectorises it: no fused multiply-add, per element the same two operations).
#[inline(always)]
fn axpy_lanes(a: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

#[inline(always)]
fn mat_t_vec_rows(w: &[f64], rows: usize, cols: usize, y: &[f64], out: &mut [f64]) {
    let out = &mut out[..cols];
    out.fill(0.0);
    for (i, &yi) in y[..rows].iter().enumerate() {
        axpy_lanes(yi, &w[i * cols..(i + 1) * cols], out);
    }
}

#[inline(always)]
fn outer_acc_rows(c: f64, u: &[f64], v: &[f64], m: &mut [f64]) {
    let n = v.len();
    for (i, &ui) in u.iter().enumerate() {
        axpy_lanes(c * ui, v, &mut m[i * n..(i + 1) * n]);
    }
}

#[inline(always)]
fn sym_outer_acc_upper_rows(c: f64, v: &[f64], m: &mut [f64]) {
    let n = v.len();
    for (p, &vp) in v.iter().enumerate() {
        axpy_lanes(c * vp, &v[p..], &mut m[p * n + p..(p + 1) * n]);
    }
}

/// [`sym_outer_acc_upper`] compiled for AVX.
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn sym_outer_acc_upper_avx(c: f64, v: &[f64], m: &mut [f64]) {
    sym_outer_acc_upper_rows(c, v, m);
}

/// [`axpy`] compiled for AVX.
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn axpy_avx(a: f64, x: &[f64], y: &mut [f64]) {
    axpy_lanes(a, x, y);
}

/// [`mat_t_vec`] compiled for AVX.
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn mat_t_vec_avx(w: &[f64], rows: usize, cols: usize, y: &[f64], out: &mut [f64]) {
    mat_t_vec_rows(w, rows, cols, y, out);
}

/// [`outer_acc`] compiled for AVX.
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn outer_acc_avx(c: f64, u: &[f64], v: &[f64], m: &mut [f64]) {
    outer_acc_rows(c, u, v, m);
}

/// ln 2 split in two (the high part has its last 32 bits zero, so `k · LN2_HI` is exact for
/// the |k| ≤ 58 used here): Cody & Waite's argument reduction.
const LN2_HI: f64 = 6.931_471_803_691_238_164_9e-1;
const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;
/// 1.5 · 2^52: adding and subtracting it rounds a float of magnitude < 2^51 to the nearest
/// integer (ties to even), and the sum's low bits hold that integer.
const ROUND: f64 = 6_755_399_441_055_744.0;
/// Beyond |x| = 20, tanh(x) rounds to ±1 (1 − tanh 20 ≈ 8.5e-18 < 2^-54).
const SATURATE: f64 = 40.0;

/// tanh(x) from exp(−2|x|) − 1 (module docs: the same bits on every path). With y = 2|x|
/// (at most 40), `expm1(−y) = 2^k (1 + p) − 1` where `−y = k ln 2 + r`, |r| ≤ ln 2 / 2, and
/// `p = expm1(r)` is its Taylor polynomial to degree 14 (truncation below 2e-17 relative);
/// then `tanh |x| = −t / (t + 2)` with `t = expm1(−y)`, and the sign of x. Within 3 ulp of the
/// correctly rounded tanh (tested over ±40 and the tiny and saturated ends); NaN in, NaN out.
#[inline(always)]
pub fn tanh(x: f64) -> f64 {
    let y = 2.0 * x.abs();
    // NaN fails the comparison and stays NaN.
    let y = if y > SATURATE { SATURATE } else { y };
    let z = -y * core::f64::consts::LOG2_E;
    let shifted = z + ROUND;
    let kf = shifted - ROUND;
    let r = (-y - kf * LN2_HI) - kf * LN2_LO;
    // p = r + r² (1/2! + r (1/3! + … + r/14!)).
    let mut q = 1.0 / 87_178_291_200.0;
    for c in [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
    ] {
        q = q * r + c;
    }
    let p = r + (r * r) * q;
    // 2^k from the rounded sum's low bits (k in [−58, 0]).
    let k = shifted.to_bits().wrapping_sub(ROUND.to_bits());
    let two_k = f64::from_bits(k.wrapping_add(1023) << 52);
    let t = two_k * p + (two_k - 1.0);
    let m = -t / (t + 2.0);
    f64::from_bits(m.abs().to_bits() | (x.to_bits() & (1 << 63)))
}

/// `v_i ← tanh(v_i)` ([`tanh`], bit for bit), four at a time with AVX2.
#[inline]
pub fn tanh_in_place(v: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is present (checked above).
        unsafe { tanh_avx2(v) };
        return;
    }
    for x in v {
        *x = tanh(*x);
    }
}

/// [`tanh_in_place`] compiled for AVX2 (the compiler vectorises the branch-free [`tanh`]).
///
/// # Safety
/// The CPU has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn tanh_avx2(v: &mut [f64]) {
    for x in v {
        *x = tanh(*x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// `affine` (AVX four rows at a time where the CPU has it) equals `dot` row by row bit
    /// for bit, for every row count and input length around the four-wide blocks, with
    /// magnitudes spread over many binades so that any change of summation order would show.
    #[test]
    fn affine_is_dot_row_by_row_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let big = |rng: &mut ChaCha8Rng| {
            rng.random_range(-1.0..1.0) * 2f64.powi(rng.random_range(-30..30))
        };
        for rows in 0..=13 {
            for n in 0..=19 {
                let w: Vec<f64> = (0..rows * n).map(|_| big(&mut rng)).collect();
                let b: Vec<f64> = (0..rows).map(|_| big(&mut rng)).collect();
                let x: Vec<f64> = (0..n).map(|_| big(&mut rng)).collect();
                let mut fast = vec![f64::NAN; rows];
                affine(&w, &b, &x, &mut fast);
                let mut slow = vec![f64::NAN; rows];
                affine_rows(&w, &b, &x, &mut slow);
                assert_eq!(bits(&fast), bits(&slow), "rows {rows}, n {n}");
                for (i, o) in slow.iter().enumerate() {
                    assert_eq!(
                        o.to_bits(),
                        (dot(&w[i * n..(i + 1) * n], &x) + b[i]).to_bits()
                    );
                }
            }
        }
    }

    /// `axpy`, `mat_t_vec`, `outer_acc` and `sym_outer_acc_upper` (AVX where the CPU has it) equal their
    /// element-by-element scalar loops bit for bit, for lengths around the four-wide blocks
    /// and magnitudes over many binades.
    #[test]
    fn axpy_kernels_are_the_scalar_loops_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let big = |rng: &mut ChaCha8Rng| {
            rng.random_range(-1.0..1.0) * 2f64.powi(rng.random_range(-30..30))
        };
        for rows in 0..=9 {
            for n in 0..=19 {
                let w: Vec<f64> = (0..rows * n).map(|_| big(&mut rng)).collect();
                let u: Vec<f64> = (0..rows).map(|_| big(&mut rng)).collect();
                let v: Vec<f64> = (0..n).map(|_| big(&mut rng)).collect();
                let c = big(&mut rng);
                // axpy on the first row, the rest of `y` untouched.
                if rows > 0 {
                    let mut fast = w.clone();
                    axpy(c, &v, &mut fast);
                    let mut slow = w.clone();
                    for j in 0..n {
                        slow[j] += c * v[j];
                    }
                    assert_eq!(bits(&fast), bits(&slow), "axpy n {n}");
                }
                // Wᵀ u.
                let mut fast = vec![f64::NAN; n + 1];
                mat_t_vec(&w, rows, n, &u, &mut fast);
                let mut slow = vec![f64::NAN; n + 1];
                slow[..n].fill(0.0);
                for i in 0..rows {
                    for j in 0..n {
                        slow[j] += u[i] * w[i * n + j];
                    }
                }
                assert_eq!(bits(&fast), bits(&slow), "mat_t_vec rows {rows}, n {n}");
                // W += c u vᵀ.
                let mut fast = w.clone();
                outer_acc(c, &u, &v, &mut fast);
                let mut slow = w.clone();
                for i in 0..rows {
                    for j in 0..n {
                        slow[i * n + j] += (c * u[i]) * v[j];
                    }
                }
                assert_eq!(bits(&fast), bits(&slow), "outer_acc rows {rows}, n {n}");
                // Upper triangle of M += c v vᵀ (n × n).
                let mut fast: Vec<f64> = (0..n * n).map(|_| big(&mut rng)).collect();
                let mut slow = fast.clone();
                sym_outer_acc_upper(c, &v, &mut fast);
                for p in 0..n {
                    for q in p..n {
                        slow[p * n + q] += (c * v[p]) * v[q];
                    }
                }
                assert_eq!(bits(&fast), bits(&slow), "sym_outer_acc_upper n {n}");
            }
        }
    }

    /// Distance in units in the last place between two finite floats of the same sign.
    fn ulps(a: f64, b: f64) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    /// Against the platform's libm tanh: within 3 ulp over ±40 (uniform, and log-uniform
    /// magnitudes from 1e-300 to 40), exact at 0 and ±∞ (saturated), NaN for NaN.
    #[test]
    fn tanh_is_within_three_ulp_of_libm() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut worst = (0, 0.0);
        for i in 0..400_000 {
            let x: f64 = if i % 2 == 0 {
                rng.random_range(-40.0..40.0)
            } else {
                let m = 10f64.powf(rng.random_range(-300.0..1.61));
                if rng.random::<bool>() {
                    m
                } else {
                    -m
                }
            };
            let e = ulps(tanh(x), x.tanh());
            if e > worst.0 {
                worst = (e, x);
            }
        }
        assert!(worst.0 <= 3, "{} ulp at x = {:e}", worst.0, worst.1);
        assert_eq!(tanh(0.0).to_bits(), 0.0f64.to_bits());
        assert_eq!(tanh(-0.0).to_bits(), (-0.0f64).to_bits());
        assert_eq!((tanh(f64::INFINITY), tanh(-1e308)), (1.0, -1.0));
        assert!(tanh(f64::NAN).is_nan());
    }

    /// `tanh_in_place` (AVX2 where the CPU has it) equals [`tanh`] bit for bit.
    #[test]
    fn tanh_in_place_is_tanh_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for n in 0..=37 {
            let x: Vec<f64> = (0..n)
                .map(|_| rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-20..3)))
                .collect();
            let mut fast = x.clone();
            tanh_in_place(&mut fast);
            let slow: Vec<f64> = x.iter().map(|&v| tanh(v)).collect();
            assert_eq!(bits(&fast), bits(&slow), "n = {n}");
        }
    }
}
