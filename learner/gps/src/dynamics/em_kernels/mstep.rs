//! The M-step kernel: every cluster's weighted first and second moments at once, as one dense
//! product of the weights with the points' products (docs/design.md §5 D33).
//!
//! A point's **product row** holds its coordinates and the lower triangle of `x xᵀ`:
//! column `a` is `x_a` (`a < d`), column [`product_column`]`(d, a, b)` is `x_a · x_b`
//! (`b ≤ a`), rounded once. The points do not change during one EM run, so [`products`] forms
//! the rows once per run and every M-step is then `S = Wᵀ P`: `S[i, c] = Σ_p w_pi P[p, c]`,
//! `K` clusters by [`product_columns`] columns. That is a matrix product with whole tiles in
//! registers, without the triangle's ragged edges or a weighted copy of the points per cluster.
//! Where the rows would take megabytes and EM runs few iterations, [`weighted_sums_direct`]
//! forms the same products per point inside the product instead (the same bits).

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::{Isa, Lanes, BLOCK};

/// Columns of a panel of the product rows: two 4-lane vectors.
pub const PANEL: usize = 8;

/// Clusters whose sums [`weighted_sums`] holds in registers at a time: `ROWS × 2` 4-lane sums,
/// for 16 and for 32 registers.
const ROWS: usize = 6;
const ROWS_WIDE: usize = 12;

/// Columns of a product row in dimension `d`: `d` coordinates and `d(d+1)/2` products.
pub fn product_columns(d: usize) -> usize {
    d + d * (d + 1) / 2
}

/// Panels of [`PANEL`] columns covering a product row (the last one zero-padded).
pub fn product_panels(d: usize) -> usize {
    product_columns(d).div_ceil(PANEL)
}

/// Column of `x_a · x_b` (`b ≤ a < d`) in a product row.
pub fn product_column(d: usize, a: usize, b: usize) -> usize {
    debug_assert!(b <= a && a < d);
    d + a * (a + 1) / 2 + b
}

/// The product rows of the `n` points in the blocks `x` (module layout, dimension `d`) in
/// panels: column `c` of point `p` at `prod[(c / PANEL) · n · PANEL + p · PANEL + c % PANEL]`,
/// so that one panel is `n` consecutive runs of [`PANEL`] values. Padding columns are `+0`.
/// Panel by panel (each written as one stream), four points by four columns at a time: the
/// columns' factors are rows of the points' blocks, copied into `ext` with two extra rows of ones
/// and zeros per block, multiplied and transposed into the points' rows. `pairs` and `ext` are
/// scratch.
pub fn products(
    isa: Isa,
    x: &[f64],
    n: usize,
    d: usize,
    prod: &mut Vec<f64>,
    pairs: &mut Vec<[usize; 2]>,
    ext: &mut Vec<f64>,
) {
    let blocks = n.div_ceil(BLOCK);
    assert!(x.len() >= blocks * d * BLOCK);
    let cols = product_panels(d) * PANEL;
    // Every element is written below: no clearing of a reused buffer.
    prod.resize(cols * n, 0.0);
    // The factors of each column as offsets of rows of an `ext` block: row `d` holds ones,
    // `d + 1` zeros.
    pairs.clear();
    pairs.extend((0..d).map(|a| [a, d]));
    pairs.extend((0..d).flat_map(|a| (0..=a).map(move |b| [a, b])));
    pairs.resize(cols, [d + 1, d + 1]);
    pairs.iter_mut().flatten().for_each(|a| *a *= BLOCK);
    let eb = (d + 2) * BLOCK;
    ext.resize(blocks * eb, 0.0);
    for (e, xb) in ext.chunks_exact_mut(eb).zip(x.chunks_exact(d * BLOCK)) {
        e[..d * BLOCK].copy_from_slice(xb);
        e[d * BLOCK..(d + 1) * BLOCK].fill(1.0);
        e[(d + 1) * BLOCK..].fill(0.0);
    }
    let (prod, pairs, ext) = (&mut prod[..], &pairs[..], &ext[..]);
    dispatch!(
        isa,
        fn kern(n: usize, d: usize, prod: &mut [f64], pairs: &[[usize; 2]], ext: &[f64]) {
            let eb = (d + 2) * BLOCK;
            for (pairs, panel) in pairs
                .chunks_exact(PANEL)
                .zip(prod.chunks_exact_mut(n * PANEL))
            {
                for p0 in (0..n).step_by(4) {
                    let (e, q) = (&ext[(p0 / BLOCK) * eb..][..eb], p0 % BLOCK);
                    let m = (n - p0).min(4);
                    for (h, quad) in pairs.chunks_exact(4).enumerate() {
                        let mut v = [V::zero(); 4];
                        for (vj, &[a, b]) in v.iter_mut().zip(quad) {
                            *vj = V::load(&e[a + q..]).mul(V::load(&e[b + q..]));
                        }
                        for (j, t) in V::transpose4(v).into_iter().enumerate().take(m) {
                            t.store(&mut panel[(p0 + j) * PANEL + 4 * h..]);
                        }
                    }
                }
            }
        }
    );
}

/// The M-step's weights point-major: `wt[p · k + i] = w[i · stride + p]` for the `n` points and
/// `k` clusters of the cluster-major `w` (rows `stride` apart), four clusters by four points at a
/// time.
pub fn transpose_weights(isa: Isa, w: &[f64], stride: usize, n: usize, k: usize, wt: &mut [f64]) {
    assert!(n <= stride && (k == 0 || w.len() >= (k - 1) * stride + n) && wt.len() >= n * k);
    dispatch!(
        isa,
        fn kern(w: &[f64], stride: usize, n: usize, k: usize, wt: &mut [f64]) {
            let (k4, n4) = (k / 4 * 4, n / 4 * 4);
            for i0 in (0..k4).step_by(4) {
                for p0 in (0..n4).step_by(4) {
                    let mut r = [V::zero(); 4];
                    for (j, rj) in r.iter_mut().enumerate() {
                        *rj = V::load(&w[(i0 + j) * stride + p0..]);
                    }
                    for (j, c) in V::transpose4(r).into_iter().enumerate() {
                        c.store(&mut wt[(p0 + j) * k + i0..]);
                    }
                }
                for p in n4..n {
                    for i in i0..i0 + 4 {
                        wt[p * k + i] = w[i * stride + p];
                    }
                }
            }
            for i in k4..k {
                for (row, &wp) in wt.chunks_exact_mut(k).zip(&w[i * stride..][..n]) {
                    row[i] = wp;
                }
            }
        }
    )
}

/// Every cluster's M-step sums: `out[i · cols + c] = Σ_p w[p · k + i] · P[p, c]` for the `k`
/// clusters and every column `c < cols = panels · PANEL` of the product rows `prod`
/// ([`products`] of `n` points). `w` holds the weights point-major (`n × k`). Each sum runs
/// over the points in ascending order from `+0`, one fused multiply-add per point; the tiles
/// (a few clusters by one panel) change which sums are in registers together, never the order
/// of any one of them.
pub fn weighted_sums(
    isa: Isa,
    n: usize,
    k: usize,
    w: &[f64],
    prod: &[f64],
    panels: usize,
    out: &mut [f64],
) {
    let cols = panels * PANEL;
    assert!(w.len() >= n * k && prod.len() >= panels * n * PANEL && out.len() >= k * cols);
    dispatch!(
        isa,
        fn kernel(n: usize, k: usize, w: &[f64], prod: &[f64], panels: usize, out: &mut [f64]) {
            let (cols, w) = (panels * PANEL, &w[..n * k]);
            for j in 0..panels {
                let panel = &prod[j * n * PANEL..][..n * PANEL];
                tiles::<V>(Source::Panel(panel), w, k, &mut *out, cols, j * PANEL);
            }
        }
    )
}

/// Where a tile's two vectors of products per point come from: a panel of [`products`]
/// (`n × PANEL`), or the points' rows ([`point_rows`], row length) and the panel's two
/// factor pairs ([`direct_factors`]).
#[derive(Clone, Copy)]
enum Source<'a> {
    Panel(&'a [f64]),
    Rows(&'a [f64], usize, [[usize; 2]; 2]),
}

/// One tile's arguments: the products' source, the weights (`n × k`), `k`, the tile's first
/// cluster, the output, its row length and the panel's first column.
struct Tile<'a>(
    Source<'a>,
    &'a [f64],
    usize,
    usize,
    &'a mut [f64],
    usize,
    usize,
);

/// The sums of the clusters `i0 … i0 + R − 1` on one panel, in `R × 2` registers: per point,
/// the panel's two vectors (loaded, or formed as `x_a · x_b..b+4`) and the `R` weights
/// broadcast, `2R` fused multiply-adds.
#[inline(always)]
fn tile<V: Lanes, const R: usize>(t: Tile<'_>) {
    let Tile(src, w, k, i0, out, cols, c0) = t;
    let mut acc = [[V::zero(); 2]; R];
    match src {
        Source::Panel(panel) => {
            for (pv, wp) in panel.chunks_exact(PANEL).zip(w.chunks_exact(k)) {
                let (p0, p1) = (V::load(&pv[..4]), V::load(&pv[4..]));
                tile_step::<V, R>(&mut acc, &wp[i0..i0 + R], p0, p1);
            }
        }
        Source::Rows(rows, rl, [[m0, b0], [m1, b1]]) => {
            assert!(m0.max(m1) < rl && b0.max(b1) + 4 <= rl);
            for (xp, wp) in rows.chunks_exact(rl).zip(w.chunks_exact(k)) {
                let p0 = V::splat(xp[m0]).mul(V::load(&xp[b0..]));
                let p1 = V::splat(xp[m1]).mul(V::load(&xp[b1..]));
                tile_step::<V, R>(&mut acc, &wp[i0..i0 + R], p0, p1);
            }
        }
    }
    for (r, a) in acc.iter().enumerate() {
        let o = &mut out[(i0 + r) * cols + c0..][..PANEL];
        a[0].store(&mut o[..4]);
        a[1].store(&mut o[4..]);
    }
}

/// One point's step of a tile: `acc[r] += w_r · (p0, p1)`.
#[inline(always)]
fn tile_step<V: Lanes, const R: usize>(acc: &mut [[V; 2]; R], w: &[f64], p0: V, p1: V) {
    let wr: &[f64; R] = w.try_into().unwrap();
    // Loops for the vectors, not `array::from_fn` (see `norm_tile`).
    for r in 0..R {
        let b = V::splat(wr[r]);
        acc[r][0] = acc[r][0].fma(b, p0);
        acc[r][1] = acc[r][1].fma(b, p1);
    }
}

/// Runs [`tile`] over the clusters in tiles of up to 12 (32 registers) or 6 (16 registers).
#[inline(always)]
fn tiles<V: Lanes>(src: Source<'_>, w: &[f64], k: usize, out: &mut [f64], cols: usize, c0: usize) {
    let mut i0 = 0;
    while i0 < k {
        let r = (k - i0).min(if V::WIDE { ROWS_WIDE } else { ROWS });
        let t = Tile(src, w, k, i0, &mut *out, cols, c0);
        match r {
            1 => tile::<V, 1>(t),
            2 => tile::<V, 2>(t),
            3 => tile::<V, 3>(t),
            4 => tile::<V, 4>(t),
            5 => tile::<V, 5>(t),
            6 => tile::<V, 6>(t),
            7 => tile::<V, 7>(t),
            8 => tile::<V, 8>(t),
            9 => tile::<V, 9>(t),
            10 => tile::<V, 10>(t),
            11 => tile::<V, 11>(t),
            _ => tile::<V, 12>(t),
        }
        i0 += r;
    }
}

/// Row length of [`point_rows`] in dimension `d`: the coordinates padded to whole vectors, then
/// a one, a zero and padding.
pub fn point_row_len(d: usize) -> usize {
    d.div_ceil(4) * 4 + 4
}

/// The `n` points of the blocks `x` as rows for [`weighted_sums_direct`]:
/// `rows[p · rl + a] = x_pa` (`rl =` [`point_row_len`]), then `+0` up to whole vectors, `1` at
/// `rl − 4` and `+0` after.
pub fn point_rows(x: &[f64], n: usize, d: usize, rows: &mut Vec<f64>) {
    assert!(x.len() >= n.div_ceil(BLOCK) * d * BLOCK);
    let rl = point_row_len(d);
    rows.clear();
    rows.resize(n * rl, 0.0);
    for (p, row) in rows.chunks_exact_mut(rl).enumerate() {
        let xb = &x[(p / BLOCK) * d * BLOCK + p % BLOCK..];
        for (a, v) in row[..d].iter_mut().enumerate() {
            *v = xb[a * BLOCK];
        }
        row[rl - 4] = 1.0;
    }
}

/// The panels of [`weighted_sums_direct`] in dimension `d`: two vectors of four columns each,
/// a vector `[m, b]` being `x_m · x_b … x_{b+3}` of a point's row. First the coordinates
/// (`m` the row's one), then row `a` of `x xᵀ` from `b = 0` in whole vectors (their columns
/// past `a` are products too, never read), then a zero vector if the count is odd.
pub fn direct_factors(d: usize) -> Vec<[[usize; 2]; 2]> {
    let rl = point_row_len(d);
    let (one, zero) = (rl - 4, rl - 3);
    let mut v: Vec<[usize; 2]> = (0..d.div_ceil(4)).map(|u| [one, 4 * u]).collect();
    for a in 0..d {
        v.extend((0..(a + 1).div_ceil(4)).map(|u| [a, 4 * u]));
    }
    if v.len() % 2 == 1 {
        v.push([zero, 0]);
    }
    v.chunks_exact(2).map(|c| [c[0], c[1]]).collect()
}

/// Column of `x_a · x_b` (`b ≤ a < d`) in the sums of [`weighted_sums_direct`]; the
/// coordinates are columns `0 … d − 1` as in [`weighted_sums`].
pub fn direct_column(d: usize, a: usize, b: usize) -> usize {
    debug_assert!(b <= a && a < d);
    4 * (d.div_ceil(4) + (0..a).map(|r| (r + 1).div_ceil(4)).sum::<usize>()) + b
}

/// [`weighted_sums`] without the products formed beforehand: each panel's two vectors are
/// formed per point from the points' rows ([`point_rows`]) as `x_m · x_b..b+4`
/// ([`direct_factors`]), the same rounded products, so every sum gets the same operations in
/// the same order, the same bits (tested); the columns are laid out by [`direct_column`]
/// (`out`: `k × 8 · factors.len()`). For sets whose products would not stay in cache: no
/// memory beyond the rows, about a tenth more multiply-adds (the triangle's rows padded to
/// whole vectors) and a multiplication per vector.
#[allow(clippy::too_many_arguments)]
pub fn weighted_sums_direct(
    isa: Isa,
    n: usize,
    k: usize,
    w: &[f64],
    rows: &[f64],
    d: usize,
    factors: &[[[usize; 2]; 2]],
    out: &mut [f64],
) {
    let (rl, cols) = (point_row_len(d), factors.len() * PANEL);
    assert!(w.len() >= n * k && rows.len() >= n * rl && out.len() >= k * cols);
    dispatch!(
        isa,
        fn kernel(
            n: usize,
            k: usize,
            w: &[f64],
            rows: &[f64],
            rl: usize,
            factors: &[[[usize; 2]; 2]],
            out: &mut [f64],
        ) {
            let (w, rows, cols) = (&w[..n * k], &rows[..n * rl], factors.len() * PANEL);
            for (j, &f) in factors.iter().enumerate() {
                tiles::<V>(Source::Rows(rows, rl, f), w, k, &mut *out, cols, j * PANEL);
            }
        }
    )
}
