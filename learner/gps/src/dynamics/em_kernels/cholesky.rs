//! The Cholesky factor of a cluster covariance, once per EM iteration and cluster: small
//! (`D = 27`) factorisations, where a library's blocked algorithm costs more in dispatch and
//! scratch handling than in flops.

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::{Isa, Lanes, MANTISSA, ONE_EXPONENT};

/// 4-lane vectors of a column that [`cholesky`] keeps in registers (columns up to 32 long).
const COL_VECS: usize = 8;

/// `l = L` with `A = L Lᵀ`, reading the lower triangle of `a` (`d x d` row-major); `l` is
/// row-major with its strict upper triangle zeroed. Returns `false` (and leaves `l`
/// unspecified) when a pivot is not positive or not finite: `A` is not positive definite.
///
/// The order (right-looking, column by column, as LAPACK's unblocked `dpotf2` with the updates
/// fused): for `j = 0 … d − 1`, `l_jj = √a_jj`, `l_ij = a_ij / l_jj` for `i > j`, then every
/// trailing element `a_ik` (`j < k ≤ i`) becomes `fma(−l_kj, l_ij, a_ik)`. Each element thus
/// gets its updates in ascending `j`, one rounding each. The columns are stored transposed
/// (column-major, zero-padded to whole vectors) in `work`, so that a column is a few 4-lane
/// vectors over its rows; lanes above the diagonal take meaningless values that no element on or
/// below it reads.
pub fn cholesky(isa: Isa, a: &[f64], l: &mut [f64], d: usize, work: &mut Vec<f64>) -> bool {
    assert!(a.len() >= d * d && l.len() >= d * d);
    let ld = d.div_ceil(4) * 4;
    // Every element the kernel reads is written here (above the diagonal and in the padding
    // rows, +0): no clearing of a reused buffer.
    work.resize(ld * d, 0.0);
    for (k, col) in work.chunks_exact_mut(ld).enumerate() {
        col[..k].fill(0.0);
        for (i, c) in col[k..d].iter_mut().enumerate() {
            *c = a[(k + i) * d + k];
        }
        col[d..].fill(0.0);
    }
    let mut pd = true;
    let (w, ok) = (&mut work[..], &mut pd);
    dispatch!(
        isa,
        fn k(w: &mut [f64], d: usize, ld: usize, ok: &mut bool) {
            for j in 0..d {
                let ajj = w[j * ld + j];
                if !(ajj > 0.0) || !ajj.is_finite() {
                    *ok = false;
                    return;
                }
                let ljj = ajj.sqrt();
                let (head, tail) = w.split_at_mut((j + 1) * ld);
                let cj = &mut head[j * ld..];
                let v0 = j / 4;
                if ld <= 4 * COL_VECS {
                    // Column j in registers for its updates of the trailing columns.
                    let mut c = [V::zero(); COL_VECS];
                    let lv = V::splat(ljj);
                    for v in 0..COL_VECS {
                        if v >= v0 && 4 * v < ld {
                            c[v] = V::load(&cj[4 * v..]).div(lv);
                            c[v].store(&mut cj[4 * v..]);
                        }
                    }
                    cj[j] = ljj;
                    for (k, ck) in tail.chunks_exact_mut(ld).enumerate() {
                        let k = j + 1 + k;
                        let (lk, vk) = (V::splat(-cj[k]), k / 4);
                        for v in 0..COL_VECS {
                            if v >= vk && 4 * v < ld {
                                let s = &mut ck[4 * v..];
                                V::load(s).fma(lk, c[v]).store(s);
                            }
                        }
                    }
                } else {
                    let lv = V::splat(ljj);
                    for i in (4 * v0..ld).step_by(4) {
                        V::load(&cj[i..]).div(lv).store(&mut cj[i..]);
                    }
                    cj[j] = ljj;
                    for (k, ck) in tail.chunks_exact_mut(ld).enumerate() {
                        let k = j + 1 + k;
                        let lk = V::splat(-cj[k]);
                        for i in (k / 4 * 4..ld).step_by(4) {
                            let s = &mut ck[i..];
                            V::load(s).fma(lk, V::load(&cj[i..])).store(s);
                        }
                    }
                }
            }
        }
    );
    if !pd {
        return false;
    }
    for (i, row) in l.chunks_exact_mut(d).take(d).enumerate() {
        for (k, v) in row[..=i].iter_mut().enumerate() {
            *v = work[k * ld + i];
        }
        row[i + 1..].fill(0.0);
    }
    true
}

/// `Σ_j ln l_jj = ½ ln det A` for a Cholesky factor `l` (`d x d` row-major) with one logarithm
/// instead of `d`: the diagonal's binary exponents are summed as integers and its mantissas
/// (in `[1, 2)`) multiplied, renormalised to `[1, 2)` after every product (exact), so
/// `ln Π m_j + E ln 2` carries at most `d` roundings of the product, as many as the sum of
/// logarithms. A diagonal with a zero, subnormal or non-finite entry takes the sum of logarithms.
pub fn half_log_det(l: &[f64], d: usize) -> f64 {
    let diag = |j: usize| l[j * d + j];
    if !(0..d).all(|j| diag(j).is_normal() && diag(j) > 0.0) {
        return (0..d).map(|j| diag(j).ln()).sum();
    }
    let (mut m, mut e) = (1.0f64, 0i64);
    for j in 0..d {
        let b = diag(j).to_bits();
        e += (b >> 52) as i64 - 1023;
        let pm = (m * f64::from_bits((b & MANTISSA) | ONE_EXPONENT)).to_bits();
        e += (pm >> 52) as i64 - 1023;
        m = f64::from_bits((pm & MANTISSA) | ONE_EXPONENT);
    }
    m.ln() + e as f64 * std::f64::consts::LN_2
}

#[cfg(test)]
mod tests {
    use super::super::tests::{bits, isas};
    use super::*;
    use crate::linalg::{llt_lower, Scratch};
    use faer::MatMut;
    use rand::{Rng, SeedableRng};

    /// A random symmetric positive definite `d x d` matrix (row-major), `B Bᵀ + d I`-like with
    /// a spread of scales; its upper triangle NaN when `nan_upper` (it must not be read).
    fn random_spd(rng: &mut impl Rng, d: usize, nan_upper: bool) -> Vec<f64> {
        let b: Vec<f64> = (0..d * d).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut a = vec![0.0; d * d];
        for i in 0..d {
            for k in 0..d {
                let s: f64 = (0..d).map(|c| b[i * d + c] * b[k * d + c]).sum();
                a[i * d + k] = s + if i == k { 0.1 * d as f64 } else { 0.0 };
                if nan_upper && k > i {
                    a[i * d + k] = f64::NAN;
                }
            }
        }
        a
    }

    #[test]
    fn cholesky_follows_its_documented_order_bit_for_bit_on_every_build() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for d in [1, 2, 3, 4, 5, 7, 8, 9, 13, 27, 32, 33, 40] {
            let a = random_spd(&mut rng, d, true);
            // The documented order written out on a full copy of the lower triangle.
            let mut s = a.clone();
            for j in 0..d {
                let ljj = s[j * d + j].sqrt();
                s[j * d + j] = ljj;
                for i in j + 1..d {
                    s[i * d + j] /= ljj;
                }
                for k in j + 1..d {
                    for i in k..d {
                        s[i * d + k] = (-s[k * d + j]).mul_add(s[i * d + j], s[i * d + k]);
                    }
                }
            }
            for i in 0..d {
                for k in i + 1..d {
                    s[i * d + k] = 0.0;
                }
            }
            let mut work = Vec::new();
            for isa in isas() {
                let mut l = vec![f64::NAN; d * d];
                assert!(cholesky(isa, &a, &mut l, d, &mut work), "{isa:?} d={d}");
                assert_eq!(bits(&l), bits(&s), "{isa:?} d={d}");
            }
        }
    }

    #[test]
    fn cholesky_matches_faer_and_rejects_what_is_not_positive_definite() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let mut work = Vec::new();
        for d in [1, 3, 6, 27, 36] {
            let a = random_spd(&mut rng, d, false);
            let mut want = a.clone();
            let mut scratch = Scratch::for_llt(d);
            assert!(llt_lower(
                MatMut::from_row_major_slice_mut(&mut want, d, d),
                &mut scratch
            ));
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for isa in isas() {
                let mut l = vec![f64::NAN; d * d];
                assert!(cholesky(isa, &a, &mut l, d, &mut work));
                for (x, y) in l.iter().zip(&want) {
                    assert!((x - y).abs() <= 1e-12 * scale, "{isa:?} d={d}: {x} vs {y}");
                }
            }
            // Not positive definite: a negative direction, a zero pivot, a NaN.
            let mut bad = a.clone();
            for i in 0..d {
                bad[i * d + i] -= 1e3 * d as f64;
            }
            let mut zero = a.clone();
            zero[(d - 1) * d + d - 1] = 0.0;
            for i in 0..d - 1 {
                zero[(d - 1) * d + i] = 0.0;
            }
            let mut nan = a.clone();
            nan[(d - 1) * d] = f64::NAN;
            for (what, m) in [("negative", bad), ("zero", zero), ("NaN", nan)] {
                for isa in isas() {
                    let mut l = vec![0.0; d * d];
                    assert!(
                        !cholesky(isa, &m, &mut l, d, &mut work),
                        "{isa:?} d={d}: {what} pivot accepted"
                    );
                }
            }
        }
    }

    #[test]
    fn half_log_det_matches_the_sum_of_logarithms() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for d in [1usize, 2, 5, 27, 64] {
            for scale in [1e-150, 1e-3, 1.0, 7.5, 1e150] {
                let mut l = vec![0.0f64; d * d];
                for j in 0..d {
                    l[j * d + j] = scale * rng.random_range(0.01..100.0);
                }
                let want: f64 = (0..d).map(|j| l[j * d + j].ln()).sum();
                let got = half_log_det(&l, d);
                assert!(
                    (got - want).abs() <= 4.0 * d as f64 * f64::EPSILON * want.abs().max(1.0),
                    "d={d} scale={scale}: {got} against {want}"
                );
            }
        }
        // A subnormal or zero pivot: the sum of logarithms, as ln would give.
        let l = [4.0f64, 0.0, 0.0, 1e-310];
        assert_eq!(half_log_det(&l, 2), 4.0f64.ln() + 1e-310f64.ln());
        assert_eq!(half_log_det(&[0.0], 1), f64::NEG_INFINITY);
    }
}
