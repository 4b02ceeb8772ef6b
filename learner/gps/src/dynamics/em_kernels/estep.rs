//! The E-step kernels: whitened squared distances of the blocked points, `L⁻¹`, and the
//! small-N forward substitution of the per-step prior queries.

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::{Isa, Lanes, BLOCK};

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
    let job = SmallJob {
        chol,
        mu,
        d,
        k,
        xt,
        groups,
        y,
        ss,
    };
    dispatch!(
        isa,
        fn kern(job: SmallJob<'_>) {
            let SmallJob {
                chol,
                mu,
                d,
                k,
                xt,
                groups,
                y,
                ss,
            } = job;
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

/// The arguments of one [`small_norms`] call, handed to the instantiation that runs it.
struct SmallJob<'a> {
    chol: &'a [f64],
    mu: &'a [f64],
    d: usize,
    k: usize,
    xt: &'a [f64],
    groups: usize,
    y: &'a mut [f64],
    ss: &'a mut [f64],
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
