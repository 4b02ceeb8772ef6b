//! The responsibilities: GPS's log-sum-exp over clusters and over points, and the M-step's
//! weights, on the EM's own vector `exp`.

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::{Isa, Lanes};

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

/// fdlibm's (`e_log.c`) minimax coefficients `Lg_i` of `R(z) = Σ_i Lg_i z^i` in
/// `ln(1 + f) = 2s + s R(s²)`, `s = f / (2 + f)`, for `|s| ≤ 0.1716` (its error there is below
/// 2^−58.45).
const LOG_LG: [f64; 7] = [
    6.666666666666735130e-01,
    3.999999999940941908e-01,
    2.857142874366239149e-01,
    2.222219843214978396e-01,
    1.818357216161805012e-01,
    1.531383769920937332e-01,
    1.479819860511658591e-01,
];

/// `ln x` in every lane for positive normal `x` (the log-sum-exp's sums, whose largest term is
/// `e^0 = 1`), within one ulp of the correctly rounded value (tested), as fdlibm's `log`:
/// `x = 2^e m` with `m` folded into `[√½, √2)`, `f = m − 1` (exact), `s = f / (2 + f)`,
/// `ln x = e ln2_hi − ((f²/2 − (s (f²/2 + R) + e ln2_lo)) − f)` with `ln 2` in two parts.
#[inline(always)]
fn ln<V: Lanes>(x: V) -> V {
    const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
    let (e, m) = x.exponent_split();
    // 1 where m ≥ √2 (then m / 2 and e + 1, both exact), else 0.
    let up = V::splat(1.0).zero_where_below(m, std::f64::consts::SQRT_2);
    let m = m.mul(V::splat(1.0).sub(V::splat(0.5).mul(up)));
    let e = e.add(up);
    let f = m.sub(V::splat(1.0));
    let s = f.div(V::splat(2.0).add(f));
    let z = s.mul(s);
    let mut r = V::splat(LOG_LG[6]);
    for &c in LOG_LG[..6].iter().rev() {
        r = V::splat(c).fma(r, z);
    }
    let r = r.mul(z);
    let hfsq = V::splat(0.5).mul(f).mul(f);
    let t = e.mul(V::splat(LN2_LO)).fma(s, hfsq.add(r));
    e.mul(V::splat(LN2_HI)).sub(hfsq.sub(t).sub(f))
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
                let mut sb = [0.0; 4];
                s.store(&mut sb);
                if sb.iter().all(|v| v.is_normal() && *v > 0.0) {
                    ln(s).add(m).store(&mut buf);
                } else {
                    // A point with every log probability −∞ (a sum of 0), or NaN: libm's `ln`.
                    let mut mb = [0.0; 4];
                    m.store(&mut mb);
                    for j in 0..4 {
                        buf[j] = sb[j].ln() + mb[j];
                    }
                }
                let c = (n - p).min(4);
                lse[p..p + c].copy_from_slice(&buf[..c]);
                if c == 4 {
                    let bv = V::load(&buf);
                    for i in 0..k {
                        let li = &mut l[i * stride + p..][..4];
                        V::load(li).sub(bv).store(li);
                    }
                } else {
                    for i in 0..k {
                        let li = &mut l[i * stride + p..][..c];
                        for (v, &b) in li.iter_mut().zip(&buf) {
                            *v -= b;
                        }
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
    let (sink, w) = (&mut out, &mut [][..]);
    dispatch!(
        isa,
        fn k(l: &[f64], w: &mut [f64], sink: &mut f64) {
            *sink = logsum_exps::<V, false>(l, w);
        }
    );
    out
}

/// [`logsum_points`] (the same value, the same bits) and, from the same pass's terms, the
/// M-step's weights of the cluster: `w[p] = e_p · (1 / S)` with `e_p = exp(l_p − m)` the sum's
/// terms (`+0` below `e^`[`EXP_FLOOR`]) and `S = Σ_p e_p`, that is `exp(l_p − logsum)` without a
/// second `exp`; `w[p] = 0` for the padding `l.len() ≤ p < w.len()`.
pub fn logsum_points_weights(isa: Isa, l: &[f64], w: &mut [f64]) -> f64 {
    assert!(w.len() >= l.len());
    let mut out = 0.0;
    let sink = &mut out;
    dispatch!(
        isa,
        fn k(l: &[f64], w: &mut [f64], sink: &mut f64) {
            *sink = logsum_exps::<V, true>(l, w);
        }
    );
    w[l.len()..].fill(0.0);
    out
}

/// [`logsum_points`], and with `WEIGHTS` the weights of [`logsum_points_weights`] into `w`.
#[inline(always)]
fn logsum_exps<V: Lanes, const WEIGHTS: bool>(l: &[f64], w: &mut [f64]) -> f64 {
    let mut m = V::splat(f64::MIN);
    for p in (0..l.len()).step_by(4) {
        m = m.max(load_or_neg_inf(l, p));
    }
    let mut mb = [0.0; 4];
    m.store(&mut mb);
    let mx = mb[0].max(mb[1]).max(mb[2].max(mb[3]));
    let mv = V::splat(mx);
    let mut s = V::zero();
    let n4 = l.len() / 4 * 4;
    for p in (0..l.len()).step_by(4) {
        let e = exp(load_or_neg_inf::<V>(l, p).sub(mv));
        s = s.add(e);
        if WEIGHTS {
            if p < n4 {
                e.store(&mut w[p..]);
            } else {
                let mut buf = [0.0; 4];
                e.store(&mut buf);
                w[p..l.len()].copy_from_slice(&buf[..l.len() - p]);
            }
        }
    }
    let total = s.sum();
    if WEIGHTS {
        let r = 1.0 / total;
        let rv = V::splat(r);
        for p in (0..n4).step_by(4) {
            V::load(&w[p..]).mul(rv).store(&mut w[p..]);
        }
        for v in &mut w[n4..l.len()] {
            *v *= r;
        }
    }
    total.ln() + mx
}

/// [`ln`] of every element of `x` (a multiple of four long) into `out`, for the tests.
#[cfg(test)]
pub(super) fn ln_slice(isa: Isa, x: &[f64], out: &mut [f64]) {
    assert!(x.len() == out.len() && x.len() % 4 == 0);
    dispatch!(
        isa,
        fn k(x: &[f64], out: &mut [f64]) {
            for (xi, oi) in x.chunks_exact(4).zip(out.chunks_exact_mut(4)) {
                ln(V::load(xi)).store(oi);
            }
        }
    )
}
