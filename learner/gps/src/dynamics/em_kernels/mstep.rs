//! The M-step kernel: weighted first and second moments of the blocked points.

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::{Isa, Lanes, BLOCK};

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
    /// Blocks per visit of the tiles ([`GROUP`]; the same sums in the same order for any value,
    /// the speed benchmark compares them).
    group: usize,
    z: Vec<f64>,
    /// `d x 4` lane sums of `w x`.
    s1: Vec<f64>,
    tiles: Vec<f64>,
}

impl Moments {
    /// Empty scratch; it grows to the largest dimension seen and is reused.
    pub fn new() -> Self {
        Self::with_group(GROUP)
    }

    /// Empty scratch that visits the tiles once per `group` blocks.
    pub(super) fn with_group(group: usize) -> Self {
        assert!(group >= 1);
        Self {
            group,
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
    let group = scratch.group;
    assert!(x.len() >= blocks * d * BLOCK && w.len() >= blocks * BLOCK);
    assert!(s1.len() >= d && xx.len() >= d * d);
    let Moments {
        z,
        s1: lanes,
        tiles,
        ..
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
    let job = MomentsJob(group, d, blocks, x, w, z, lanes, tiles, s1, xx);
    dispatch!(
        isa,
        fn k(job: MomentsJob<'_>) {
            const W: (usize, usize) = MOMENT_TILE_WIDE;
            const N: (usize, usize) = MOMENT_TILE;
            if V::WIDE {
                moment_tiles::<V, { W.0 }, { W.1 }>(job)
            } else {
                moment_tiles::<V, { N.0 }, { N.1 }>(job)
            }
        }
    )
}

/// The arguments of one [`moments`] call, handed to the instantiation that runs it:
/// `group`, `d`, `blocks`, `x`, `w`, then the scratch `z`, `lanes`, `tiles` and the outputs `s1`,
/// `xx`.
struct MomentsJob<'a>(
    usize,
    usize,
    usize,
    &'a [f64],
    &'a [f64],
    &'a mut [f64],
    &'a mut [f64],
    &'a mut [f64],
    &'a mut [f64],
    &'a mut [f64],
);

/// The `g` blocks' points added to a tile's sums: `acc[r][c] += z_r x_c` (fused) for every
/// 4-lane vector of points in ascending order, block after block, for the rows `r < ROWS` (the
/// others are past `d`); on the diagonal (`DIAG`) only for `c <= r`. `zo`, `xo`: the tile's rows'
/// and columns' offsets in a block of `zg`, `xg` (`d * BLOCK` apart).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tile_block<V: Lanes, const TR: usize, const TC: usize, const DIAG: bool, const ROWS: usize>(
    acc: &mut [[V; TC]; TR],
    zg: &[f64],
    xg: &[f64],
    zo: &[usize; TR],
    xo: &[usize; TC],
    g: usize,
    stride: usize,
) {
    let mut a = *acc;
    for j in 0..g {
        let (zb, xb) = (&zg[j * stride..], &xg[j * stride..]);
        let zr: [&[f64; BLOCK]; TR] =
            std::array::from_fn(|r| zb[zo[r]..zo[r] + BLOCK].try_into().unwrap());
        let xr: [&[f64; BLOCK]; TC] =
            std::array::from_fn(|c| xb[xo[c]..xo[c] + BLOCK].try_into().unwrap());
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
                        a[r][c] = a[r][c].fma(zq[r], xs);
                    }
                }
            }
        }
    }
    *acc = a;
}

/// [`moments`] on tiles of `TR` rows by `TC` columns.
#[inline(always)]
fn moment_tiles<V: Lanes, const TR: usize, const TC: usize>(job: MomentsJob<'_>) {
    let MomentsJob(group, d, blocks, x, w, z, lanes, tiles, s1, xx) = job;
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
                let xo: [usize; TC] = std::array::from_fn(|c| (b0 + c).min(d - 1) * BLOCK);
                let zo: [usize; TR] = std::array::from_fn(|r| (a0 + r).min(d - 1) * BLOCK);
                // The last row group may have fewer than TR rows (d not a multiple).
                let (a, zg, st) = (&mut acc, &z[..g * d * BLOCK], d * BLOCK);
                match (diag, last + 1 - a0) {
                    (true, 1) => tile_block::<V, TR, TC, true, 1>(a, zg, xg, &zo, &xo, g, st),
                    (true, 2) => tile_block::<V, TR, TC, true, 2>(a, zg, xg, &zo, &xo, g, st),
                    (true, 3) => tile_block::<V, TR, TC, true, 3>(a, zg, xg, &zo, &xo, g, st),
                    (true, _) => tile_block::<V, TR, TC, true, TR>(a, zg, xg, &zo, &xo, g, st),
                    (false, 1) => tile_block::<V, TR, TC, false, 1>(a, zg, xg, &zo, &xo, g, st),
                    (false, 2) => tile_block::<V, TR, TC, false, 2>(a, zg, xg, &zo, &xo, g, st),
                    (false, 3) => tile_block::<V, TR, TC, false, 3>(a, zg, xg, &zo, &xo, g, st),
                    (false, _) => tile_block::<V, TR, TC, false, TR>(a, zg, xg, &zo, &xo, g, st),
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
