//! The E-step kernels: whitened squared distances of the blocked points, `L⁻¹`, and the
//! small-N forward substitution of the per-step prior queries.

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::{Isa, Lanes, BLOCK};

/// Clusters × 4-lane vectors of points of [`whitened_norms`]'s tiles (a row's sums and the
/// norms of `R · 4 NV` point-cluster pairs in registers), for 16 and for 32 registers.
const NORM_TILE: (usize, usize) = (3, 2);
const NORM_TILE_WIDE: (usize, usize) = (3, 4);

/// The clusters' whitening packed for [`whitened_norms`]: from the `k` inverse Cholesky factors
/// `minv` (`M_i = L_i⁻¹`, `d x d` row-major lower triangles) and the means `mu` (`k x d`),
/// `mt[(a(a+1)/2 + b) · k + i] = M_i[a, b]` for `b ≤ a` (the clusters side by side, so a tile's
/// clusters are neighbours) and `c[a · k + i] = (M_i μ_i)_a`, a fused multiply-add chain over
/// `b = 0 … a` from `+0`.
pub fn pack_whitening(
    isa: Isa,
    minv: &[f64],
    mu: &[f64],
    d: usize,
    k: usize,
    mt: &mut Vec<f64>,
    c: &mut Vec<f64>,
) {
    assert!(minv.len() >= k * d * d && mu.len() >= k * d);
    mt.resize(d * (d + 1) / 2 * k, 0.0);
    c.resize(d * k, 0.0);
    let (mt, c) = (&mut mt[..], &mut c[..]);
    // Dispatched for `mul_add`: a fused instruction where the CPU has one, not libm's `fma`
    // (the same bits).
    dispatch!(
        isa,
        fn kern(minv: &[f64], mu: &[f64], d: usize, k: usize, mt: &mut [f64], c: &mut [f64]) {
            for i in 0..k {
                let (m, mui) = (&minv[i * d * d..(i + 1) * d * d], &mu[i * d..(i + 1) * d]);
                let mut t = 0;
                for a in 0..d {
                    let row = &m[a * d..=a * d + a];
                    let mut ca = 0.0f64;
                    for (b, (&mab, &mub)) in row.iter().zip(mui).enumerate() {
                        mt[(t + b) * k + i] = mab;
                        ca = mab.mul_add(mub, ca);
                    }
                    c[a * k + i] = ca;
                    t += a + 1;
                }
            }
        }
    );
}

/// The E-step's log probabilities of every point under every cluster: for the `k` clusters and
/// the points of the `blocks` blocks `x` (module layout), `out[i · stride + p] = base_i − ½ s`
/// with `s = ‖M_i x_p − M_i μ_i‖²` (packed by [`pack_whitening`]): each coordinate
/// `y_a = −c_a + Σ_{b ≤ a} M_i[a, b] x_b` is a fused multiply-add chain over ascending `b`
/// starting from `−c_a`, and `s` a fused chain `y_a²` over ascending `a` from `+0`; the last
/// step is one fused `base_i − ½ s`. Tiles of a few clusters by a few vectors of points
/// ([`NORM_TILE`]) share each load of the points and of `M` across the tile and never change
/// the order of a sum. Padding points get values too.
#[allow(clippy::too_many_arguments)]
pub fn whitened_norms(
    isa: Isa,
    mt: &[f64],
    c: &[f64],
    base: &[f64],
    d: usize,
    k: usize,
    x: &[f64],
    blocks: usize,
    out: &mut [f64],
    stride: usize,
) {
    assert!(mt.len() >= d * (d + 1) / 2 * k && c.len() >= d * k && base.len() >= k);
    assert!(x.len() >= blocks * d * BLOCK && stride >= blocks * BLOCK);
    assert!(k == 0 || out.len() >= (k - 1) * stride + blocks * BLOCK);
    let job = NormJob(mt, c, base, d, k, x, blocks, out, stride);
    dispatch!(
        isa,
        fn kern(job: NormJob<'_>) {
            const W: (usize, usize) = NORM_TILE_WIDE;
            const N: (usize, usize) = NORM_TILE;
            if V::WIDE {
                norms::<V, { W.0 }, { W.1 }>(job)
            } else {
                norms::<V, { N.0 }, { N.1 }>(job)
            }
        }
    )
}

/// The arguments of one [`whitened_norms`] call: `mt`, `c`, `base`, `d`, `k`, `x`, `blocks`,
/// `out`, `stride`.
struct NormJob<'a>(
    &'a [f64],
    &'a [f64],
    &'a [f64],
    usize,
    usize,
    &'a [f64],
    usize,
    &'a mut [f64],
    usize,
);

/// [`whitened_norms`] on tiles of up to `R` clusters by `NV` 4-lane vectors of points.
#[inline(always)]
fn norms<V: Lanes, const R: usize, const NV: usize>(job: NormJob<'_>) {
    // The match below has arms for tiles of up to three clusters.
    const { assert!(R <= 3) };
    let NormJob(mt, c, base, d, k, x, blocks, out, stride) = job;
    for (blk, xb) in x.chunks_exact(d * BLOCK).take(blocks).enumerate() {
        for h in (0..BLOCK).step_by(4 * NV) {
            let p0 = blk * BLOCK + h;
            let mut i0 = 0;
            while i0 < k {
                let r = (k - i0).min(R);
                let t = NormTile(mt, c, base, d, k, i0, xb, h, out, stride, p0);
                match r {
                    1 => norm_tile::<V, 1, NV>(t),
                    2 => norm_tile::<V, 2, NV>(t),
                    _ => norm_tile::<V, R, NV>(t),
                }
                i0 += r;
            }
        }
    }
}

/// One tile's arguments: as [`NormJob`], then the tile's first cluster, the block, the tile's
/// first point in the block and in `out`.
struct NormTile<'a, 'b>(
    &'a [f64],
    &'a [f64],
    &'a [f64],
    usize,
    usize,
    usize,
    &'a [f64],
    usize,
    &'b mut [f64],
    usize,
    usize,
);

/// The clusters `i0 … i0 + C − 1` on the `4 · NV` points `h …` of one block.
#[inline(always)]
fn norm_tile<V: Lanes, const C: usize, const NV: usize>(t: NormTile<'_, '_>) {
    let NormTile(mt, c, base, d, k, i0, xb, h, out, stride, p0) = t;
    let mut s = [[V::zero(); NV]; C];
    let mut tri = 0;
    for a in 0..d {
        // Loops for the vectors, not `array::from_fn`: its closure would not inherit the
        // target features, and every intrinsic inside it would become a call.
        let mut y = [[V::zero(); NV]; C];
        let ca: &[f64; C] = c[a * k + i0..][..C].try_into().unwrap();
        for r in 0..C {
            let v0 = V::splat(-ca[r]);
            for v in 0..NV {
                y[r][v] = v0;
            }
        }
        // Row a of every M, sliced once: no bounds check per element below.
        let rows = &mt[tri * k..(tri + a + 1) * k];
        for (mb, xc) in rows.chunks_exact(k).zip(xb.chunks_exact(BLOCK)) {
            let m: &[f64; C] = mb[i0..i0 + C].try_into().unwrap();
            let xc = &xc[h..h + 4 * NV];
            let mut xv = [V::zero(); NV];
            for v in 0..NV {
                xv[v] = V::load(&xc[4 * v..]);
            }
            for r in 0..C {
                let mv = V::splat(m[r]);
                for v in 0..NV {
                    y[r][v] = y[r][v].fma(mv, xv[v]);
                }
            }
        }
        for r in 0..C {
            for v in 0..NV {
                s[r][v] = s[r][v].fma(y[r][v], y[r][v]);
            }
        }
        tri += a + 1;
    }
    let half = V::splat(-0.5);
    for r in 0..C {
        let (b, o) = (V::splat(base[i0 + r]), &mut out[(i0 + r) * stride + p0..]);
        for v in 0..NV {
            b.fma(half, s[r][v]).store(&mut o[4 * v..]);
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
