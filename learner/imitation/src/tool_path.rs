//! Measures of a tool path against demonstrated ones: how closely a motion follows the
//! demonstrated path, not only where it ends (docs/design.md §4.15).
//!
//! A tool path is a sequence of points `[x, y, z]` (m, arm base frame) sampled at a constant
//! period; two paths may have different numbers of samples. Three measures, each in metres:
//!
//! - **per-step RMSE** ([`rmse`]): both paths resampled to the longer one's number of samples
//!   (linear interpolation over normalised time, [`resample`]), then √(mean_t ‖a_t − b_t‖²).
//!   It compares the points at the same phase of the motion: a path that visits the right
//!   places in the wrong order or at the wrong pace scores badly.
//! - **dynamic time warping per path length** ([`dtw`]): the sum of ‖a_i − b_j‖ over the
//!   monotone pairing of the samples (every sample paired at least once, starts with starts,
//!   ends with ends) that minimises that sum, divided by the number of pairs (among pairings of
//!   equal sum, the one with fewest pairs). Forgives pace, not shape.
//! - **discrete Fréchet distance** ([`frechet`], Eiter and Mannila 1994): the smallest, over the
//!   same monotone pairings, of the largest ‖a_i − b_j‖ paired: the worst deviation of the best
//!   synchronisation.
//!
//! The demonstrations' own spread ([`spread`]) is the floor an imitation is measured against:
//! each demonstration against the mean of the others ([`mean_path`]), in the same measures,
//! averaged over the demonstrations: an imitation as close as another demonstration would be.
//!
//! With a pose goal the tool carries three points ([`Frame`]), and the orientation is measured
//! too: [`orientation_rmse`], the per-step angle between the tool's orientations (rad), RMSE
//! over the steps after the same resampling, against the step-wise mean of the demonstrated
//! frames ([`mean_frames`]).
//!
//! Pure functions; [`tool_paths`] extracts the paths from states of any
//! [`StateLayout`] (its tool point 0 plus its target), [`tool_frames`] the three points of a
//! pose layout.

use ur5_shared::layout::StateLayout;

/// A point of a tool path (m, arm base frame).
pub type Point = [f64; 3];

/// The three tool points of a pose layout at one step (m, base frame): not on one line, they
/// give the tool's orientation (`ur5_shared::pose::orientation_error`).
pub type Frame = [Point; 3];

/// Inputs the measures cannot be taken of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PathError {
    /// A path without samples.
    #[error("a tool path without samples")]
    Empty,
    /// A spread needs at least two demonstrations.
    #[error("the spread of demonstrations needs at least 2 of them, got {0}")]
    TooFewPaths(usize),
    /// A point with a NaN or infinite coordinate.
    #[error("tool path sample {0} is not finite")]
    NotFinite(usize),
    /// Three tool points on one line: no orientation.
    #[error("tool frame sample {0}: its three points are on one line")]
    Collinear(usize),
}

/// The three measures of one path against another (module docs), m.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PathMeasures {
    /// Per-step RMSE after resampling to a common length (m).
    pub rmse_m: f64,
    /// Dynamic time warping per pair of the optimal pairing (m).
    pub dtw_m: f64,
    /// Discrete Fréchet distance (m).
    pub frechet_m: f64,
}

fn dist(a: &Point, b: &Point) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn check(path: &[Point]) -> Result<(), PathError> {
    if path.is_empty() {
        return Err(PathError::Empty);
    }
    match path.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        Some(i) => Err(PathError::NotFinite(i)),
        None => Ok(()),
    }
}

/// `path` resampled to `n` samples by linear interpolation over normalised time: sample k of
/// the result is the path at fraction k / (n − 1) of its duration (the first and last samples
/// are kept exactly). A one-sample path stays where it is. Panics if `path` is empty or `n` is 0.
pub fn resample(path: &[Point], n: usize) -> Vec<Point> {
    assert!(!path.is_empty() && n > 0, "resample needs samples");
    let m = path.len();
    if m == 1 || n == 1 {
        return vec![path[0]; n];
    }
    (0..n)
        .map(|k| {
            if k == n - 1 {
                return path[m - 1];
            }
            let x = k as f64 * (m - 1) as f64 / (n - 1) as f64;
            let i = (x.floor() as usize).min(m - 2);
            let w = x - i as f64;
            core::array::from_fn(|r| path[i][r] + w * (path[i + 1][r] - path[i][r]))
        })
        .collect()
}

/// The mean of `paths`, step by step, each resampled to the longest one's number of samples.
pub fn mean_path(paths: &[&[Point]]) -> Result<Vec<Point>, PathError> {
    for p in paths {
        check(p)?;
    }
    let n = paths
        .iter()
        .map(|p| p.len())
        .max()
        .ok_or(PathError::Empty)?;
    let mut mean = vec![[0.0; 3]; n];
    for p in paths {
        for (m, q) in mean.iter_mut().zip(resample(p, n)) {
            for r in 0..3 {
                m[r] += q[r];
            }
        }
    }
    let k = paths.len() as f64;
    for m in &mut mean {
        for v in m.iter_mut() {
            *v /= k;
        }
    }
    Ok(mean)
}

/// Point `i` of every frame of `frames`.
fn frame_point(frames: &[Frame], i: usize) -> Vec<Point> {
    frames.iter().map(|f| f[i]).collect()
}

/// The step-wise mean of `frames` (each of the three points as [`mean_path`] takes it).
pub fn mean_frames(frames: &[&[Frame]]) -> Result<Vec<Frame>, PathError> {
    let mut means = Vec::with_capacity(3);
    for i in 0..3 {
        let paths: Vec<Vec<Point>> = frames.iter().map(|f| frame_point(f, i)).collect();
        let refs: Vec<&[Point]> = paths.iter().map(Vec::as_slice).collect();
        means.push(mean_path(&refs)?);
    }
    Ok((0..means[0].len())
        .map(|k| [means[0][k], means[1][k], means[2][k]])
        .collect())
}

/// Per-step orientation error of the tool frames `a` against `b` (rad), RMSE over the steps,
/// both resampled (point by point) to the longer one's length.
pub fn orientation_rmse(a: &[Frame], b: &[Frame]) -> Result<f64, PathError> {
    let n = a.len().max(b.len());
    let mut resampled = Vec::with_capacity(6);
    for f in [a, b] {
        for i in 0..3 {
            let p = frame_point(f, i);
            check(&p)?;
            resampled.push(resample(&p, n));
        }
    }
    let mut sq = 0.0;
    for k in 0..n {
        let fa = [resampled[0][k], resampled[1][k], resampled[2][k]];
        let fb = [resampled[3][k], resampled[4][k], resampled[5][k]];
        let e = ur5_shared::pose::orientation_error(&fa, &fb).ok_or(PathError::Collinear(k))?;
        sq += e * e;
    }
    Ok((sq / n as f64).sqrt())
}

/// Per-step RMSE of `a` against `b` (m), both resampled to the longer one's length.
pub fn rmse(a: &[Point], b: &[Point]) -> Result<f64, PathError> {
    check(a)?;
    check(b)?;
    let n = a.len().max(b.len());
    let (ra, rb) = (resample(a, n), resample(b, n));
    let sq: f64 = ra.iter().zip(&rb).map(|(p, q)| dist(p, q).powi(2)).sum();
    Ok((sq / n as f64).sqrt())
}

/// Dynamic time warping of `a` and `b` per pair of the optimal pairing (m; module docs).
/// O(len a × len b) time, O(len b) memory.
pub fn dtw(a: &[Point], b: &[Point]) -> Result<f64, PathError> {
    check(a)?;
    check(b)?;
    // (sum, pairs) of the best pairing ending at (i, j); lexicographic: sum first, then pairs.
    let inf = (f64::INFINITY, usize::MAX);
    let mut prev = vec![inf; b.len()];
    let mut row = vec![inf; b.len()];
    for (i, p) in a.iter().enumerate() {
        for (j, q) in b.iter().enumerate() {
            let best = if i == 0 && j == 0 {
                (0.0, 0)
            } else {
                let mut c = inf;
                for cand in [
                    if i > 0 && j > 0 { prev[j - 1] } else { inf },
                    if i > 0 { prev[j] } else { inf },
                    if j > 0 { row[j - 1] } else { inf },
                ] {
                    if cand.0 < c.0 || (cand.0 == c.0 && cand.1 < c.1) {
                        c = cand;
                    }
                }
                c
            };
            row[j] = (best.0 + dist(p, q), best.1 + 1);
        }
        std::mem::swap(&mut prev, &mut row);
    }
    let (sum, pairs) = prev[b.len() - 1];
    Ok(sum / pairs as f64)
}

/// Discrete Fréchet distance of `a` and `b` (m; module docs). O(len a × len b).
pub fn frechet(a: &[Point], b: &[Point]) -> Result<f64, PathError> {
    check(a)?;
    check(b)?;
    let mut prev = vec![f64::INFINITY; b.len()];
    let mut row = vec![f64::INFINITY; b.len()];
    for (i, p) in a.iter().enumerate() {
        for (j, q) in b.iter().enumerate() {
            let before = match (i, j) {
                (0, 0) => 0.0,
                (0, _) => row[j - 1],
                (_, 0) => prev[j],
                _ => prev[j - 1].min(prev[j]).min(row[j - 1]),
            };
            row[j] = before.max(dist(p, q));
        }
        std::mem::swap(&mut prev, &mut row);
    }
    Ok(prev[b.len() - 1])
}

/// All three measures of `path` against `reference`.
pub fn measure(path: &[Point], reference: &[Point]) -> Result<PathMeasures, PathError> {
    Ok(PathMeasures {
        rmse_m: rmse(path, reference)?,
        dtw_m: dtw(path, reference)?,
        frechet_m: frechet(path, reference)?,
    })
}

/// The demonstrations' own spread: each of `demos` measured against the mean path of the
/// others, each measure averaged over the demonstrations (module docs). Needs at least two.
pub fn spread(demos: &[&[Point]]) -> Result<PathMeasures, PathError> {
    if demos.len() < 2 {
        return Err(PathError::TooFewPaths(demos.len()));
    }
    let mut total = PathMeasures::default();
    for (d, path) in demos.iter().enumerate() {
        let others: Vec<&[Point]> = demos
            .iter()
            .enumerate()
            .filter(|(k, _)| *k != d)
            .map(|(_, p)| *p)
            .collect();
        let m = measure(path, &mean_path(&others)?)?;
        total.rmse_m += m.rmse_m;
        total.dtw_m += m.dtw_m;
        total.frechet_m += m.frechet_m;
    }
    let k = demos.len() as f64;
    Ok(PathMeasures {
        rmse_m: total.rmse_m / k,
        dtw_m: total.dtw_m / k,
        frechet_m: total.frechet_m / k,
    })
}

/// `states` as whole trajectories of `horizon` states of `dx` values each. Panics if `states`
/// is not a whole number of them.
fn trajectories(states: &[f64], dx: usize, horizon: usize) -> core::slice::Chunks<'_, f64> {
    assert!(
        horizon > 0 && states.len() % (horizon * dx) == 0,
        "states of {} values are not whole trajectories of {horizon} × {dx}",
        states.len()
    );
    states.chunks(horizon * dx)
}

/// The tool paths in `states`: `count` trajectories of `horizon` states of `layout`
/// ((count, horizon, dX) row-major), the path of tool point 0 (its entries minus target, plus
/// `target`, m). Panics if `states` is not count × horizon × dX long.
pub fn tool_paths(
    states: &[f64],
    layout: &StateLayout,
    horizon: usize,
    target: &Point,
) -> Vec<Vec<Point>> {
    let dx = layout.dx();
    let r = layout.point(0);
    trajectories(states, dx, horizon)
        .map(|ep| {
            ep.chunks(dx)
                .map(|s| core::array::from_fn(|k| s[r.start + k] + target[k]))
                .collect()
        })
        .collect()
}

/// The tool's three points at every step of `states` ((count, horizon, dX) row-major) of a
/// layout with three tool points, each entry minus its target plus `targets[i]` (m): one
/// `Vec` of frames a trajectory; `None` for a layout of one tool point. Panics as
/// [`tool_paths`].
pub fn tool_frames(
    states: &[f64],
    layout: &StateLayout,
    horizon: usize,
    targets: &[Point],
) -> Option<Vec<Vec<Frame>>> {
    if layout.tool_points() != 3 || targets.len() != 3 {
        return None;
    }
    let dx = layout.dx();
    let frame = |s: &[f64]| -> Frame {
        core::array::from_fn(|i| {
            let r = layout.point(i);
            core::array::from_fn(|k| s[r.start + k] + targets[i][k])
        })
    };
    Some(
        trajectories(states, dx, horizon)
            .map(|ep| ep.chunks(dx).map(frame).collect())
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(xs: &[f64]) -> Vec<Point> {
        xs.iter().map(|&x| [x, 0.0, 0.0]).collect()
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn resampling_interpolates_over_normalised_time() {
        let p = line(&[0.0, 1.0, 2.0]);
        let r = resample(&p, 5);
        let want = [0.0, 0.5, 1.0, 1.5, 2.0];
        for (q, w) in r.iter().zip(want) {
            assert!(close(q[0], w), "{r:?}");
        }
        // Down: 5 → 3 takes samples 0, 2, 4.
        let back = resample(&r, 3);
        assert_eq!(back, p);
        assert_eq!(resample(&[[1.0, 2.0, 3.0]], 4), vec![[1.0, 2.0, 3.0]; 4]);
    }

    /// Hand-computed: a = (0, 2), b = (0, 1, 2) on a line. RMSE: a resampled to (0, 1, 2) is b,
    /// so 0. DTW: the pairing (0,0), (0,1)|(2,1), (2,2) costs 0 + 1 + 0 = 1 over 3 pairs: 1/3.
    /// Fréchet: every pairing holds a pair at distance 1 (sample 1 of b is 1 from both of a's),
    /// so 1.
    #[test]
    fn hand_computed_line() {
        let (a, b) = (line(&[0.0, 2.0]), line(&[0.0, 1.0, 2.0]));
        assert!(close(rmse(&a, &b).unwrap(), 0.0));
        assert!(close(dtw(&a, &b).unwrap(), 1.0 / 3.0));
        assert!(close(frechet(&a, &b).unwrap(), 1.0));
    }

    /// Hand-computed: a = (0, 10) and b = (10, 0) visit the same points in opposite order.
    /// Starts pair with starts: Fréchet 10; DTW (0,10), (10,0): 20 over 2 pairs = 10; RMSE
    /// √((100 + 100) / 2) = 10. (Their Hausdorff distance would be 0: the measures see order.)
    #[test]
    fn hand_computed_reversal() {
        let (a, b) = (line(&[0.0, 10.0]), line(&[10.0, 0.0]));
        assert!(close(frechet(&a, &b).unwrap(), 10.0));
        assert!(close(dtw(&a, &b).unwrap(), 10.0));
        assert!(close(rmse(&a, &b).unwrap(), 10.0));
    }

    /// Hand-computed in the plane: a = (0,0), (1,0), (2,0), (3,0) and b = (0,1), (3,1), the
    /// same line 1 higher and sampled coarser. RMSE: b resampled to 4 samples is (0,1), (1,1),
    /// (2,1), (3,1), so 1. DTW: the cheapest pairing gives (0,0)–(0,1) 1, (1,0)–(0,1) √2,
    /// (2,0)–(3,1) √2, (3,0)–(3,1) 1: (2 + 2√2) / 4. Fréchet: (1,0) pairs with (0,1) or
    /// (3,1), at least √2 away: √2.
    #[test]
    fn hand_computed_offset_and_coarser() {
        let a: Vec<Point> = (0..4).map(|i| [i as f64, 0.0, 0.0]).collect();
        let b = vec![[0.0, 1.0, 0.0], [3.0, 1.0, 0.0]];
        assert!(close(rmse(&a, &b).unwrap(), 1.0));
        let s2 = 2f64.sqrt();
        assert!(close(dtw(&a, &b).unwrap(), (2.0 + 2.0 * s2) / 4.0));
        assert!(close(frechet(&a, &b).unwrap(), s2));
    }

    /// Hand-computed: DTW's pair count comes from the cheapest pairing. a = (0, 0, 0), b =
    /// (1, 1): every pairing costs 1 a pair, the shortest has 3 pairs: 3 / 3 = 1.
    #[test]
    fn dtw_divides_by_the_optimal_pairings_length() {
        let (a, b) = (line(&[0.0, 0.0, 0.0]), line(&[1.0, 1.0]));
        assert!(close(dtw(&a, &b).unwrap(), 1.0));
        // Repeating samples costs DTW nothing: (0, 1, 2) and (0, 0, 1, 1, 2, 2).
        let (c, d) = (
            line(&[0.0, 1.0, 2.0]),
            line(&[0.0, 0.0, 1.0, 1.0, 2.0, 2.0]),
        );
        assert!(close(dtw(&c, &d).unwrap(), 0.0));
        assert!(rmse(&c, &d).unwrap() > 0.1, "RMSE sees the pace");
    }

    fn wavy(seed: u64, n: usize) -> Vec<Point> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (a, b) = (rng.random_range(0.5..2.0), rng.random_range(-0.1..0.1));
        (0..n)
            .map(|k| {
                let s = k as f64 / (n - 1) as f64;
                [
                    s,
                    0.1 * (a * 6.0 * s).sin() + b,
                    0.05 * s * s + rng.random_range(-0.01..0.01),
                ]
            })
            .collect()
    }

    #[test]
    fn properties_on_random_paths() {
        for seed in 0..20 {
            let (a, b, c) = (wavy(seed, 30), wavy(seed + 100, 41), wavy(seed + 200, 17));
            for f in [rmse, dtw, frechet] {
                assert_eq!(f(&a, &a).unwrap(), 0.0, "identical paths");
                let (ab, ba) = (f(&a, &b).unwrap(), f(&b, &a).unwrap());
                assert!((ab - ba).abs() < 1e-12, "symmetric: {ab} vs {ba}");
                assert!(ab > 0.0);
            }
            // Fréchet is a metric on discrete paths: the triangle inequality holds.
            let (ab, bc, ac) = (
                frechet(&a, &b).unwrap(),
                frechet(&b, &c).unwrap(),
                frechet(&a, &c).unwrap(),
            );
            assert!(ac <= ab + bc + 1e-12, "{ac} > {ab} + {bc}");
            // A path translated by v is exactly |v| from itself (the samples are further apart
            // than |v|, so no other pairing is cheaper); translating one path moves RMSE and
            // Fréchet by at most |v| (both obey the triangle inequality).
            let v = [0.003, -0.004, 0.0];
            let t: Vec<Point> = a.iter().map(|p| [p[0] + v[0], p[1] + v[1], p[2]]).collect();
            for f in [rmse, dtw, frechet] {
                assert!((f(&a, &t).unwrap() - 0.005).abs() < 1e-12);
            }
            for f in [rmse, frechet] {
                assert!(f(&t, &b).unwrap() <= f(&a, &b).unwrap() + 0.005 + 1e-12);
            }
        }
    }

    /// Hand-computed: demonstrations at heights 0, 1, 2 of the same line. Each against the
    /// mean of the others: 0 vs 1.5, 1 vs 1, 2 vs 0.5: distances 1.5, 0, 1.5, mean 1 in all
    /// three measures.
    #[test]
    fn spread_is_each_against_the_mean_of_the_others() {
        let d: Vec<Vec<Point>> = (0..3)
            .map(|h| (0..5).map(|i| [i as f64, h as f64, 0.0]).collect())
            .collect();
        let refs: Vec<&[Point]> = d.iter().map(|p| p.as_slice()).collect();
        let s = spread(&refs).unwrap();
        assert!(close(s.rmse_m, 1.0) && close(s.dtw_m, 1.0) && close(s.frechet_m, 1.0));
        assert_eq!(spread(&refs[..1]), Err(PathError::TooFewPaths(1)));
        let m = mean_path(&refs).unwrap();
        assert!(m.iter().all(|p| close(p[1], 1.0)));
    }

    #[test]
    fn refuses_empty_and_non_finite_paths() {
        let a = line(&[0.0, 1.0]);
        assert_eq!(rmse(&a, &[]), Err(PathError::Empty));
        assert_eq!(frechet(&[], &a), Err(PathError::Empty));
        let bad = vec![[0.0; 3], [f64::NAN, 0.0, 0.0]];
        assert_eq!(dtw(&a, &bad), Err(PathError::NotFinite(1)));
    }

    #[test]
    fn tool_paths_add_the_target_back() {
        let l = StateLayout::REACH3;
        let mut states = vec![0.0; 2 * 3 * l.dx()];
        // Episode 1, step 2: ee − goal = (0.1, 0.2, 0.3).
        let i = (3 + 2) * l.dx() + l.point(0).start;
        states[i..i + 3].copy_from_slice(&[0.1, 0.2, 0.3]);
        let p = tool_paths(&states, &l, 3, &[1.0, 1.0, 1.0]);
        assert_eq!(p.len(), 2);
        assert_eq!(p[0][0], [1.0; 3]);
        assert_eq!(p[1][2], [1.1, 1.2, 1.3]);
    }

    /// A frame of the tool turned by `angle` (rad) about z, at `at` (m).
    fn turned(angle: f64, at: f64) -> Frame {
        let (c, s) = (angle.cos(), angle.sin());
        [
            [at, 0.0, 0.0],
            [at + 0.1 * c, 0.1 * s, 0.0],
            [at - 0.1 * s, 0.1 * c, 0.0],
        ]
    }

    /// Hand-computed: frames turned by 0, 0.1 and 0.2 rad against unturned ones give
    /// √((0 + 0.01 + 0.04) / 3) rad wherever they are; the mean of frames turned by ±0.1 rad is
    /// unturned; collinear points are refused naming the step.
    #[test]
    fn the_orientation_rmse_of_turned_frames_is_their_angles_rms() {
        let a: Vec<Frame> = (0..3).map(|k| turned(0.1 * k as f64, k as f64)).collect();
        let b: Vec<Frame> = (0..3).map(|k| turned(0.0, 0.5 * k as f64)).collect();
        let e = orientation_rmse(&a, &b).unwrap();
        assert!((e - (0.05f64 / 3.0).sqrt()).abs() < 1e-12, "{e}");
        assert!(orientation_rmse(&a, &a).unwrap() < 1e-12);
        let (p, m) = (vec![turned(0.1, 0.0); 4], vec![turned(-0.1, 0.0); 4]);
        let mean = mean_frames(&[&p, &m]).unwrap();
        assert_eq!(mean.len(), 4);
        let unturned = vec![turned(0.0, 0.0); 4];
        assert!(orientation_rmse(&mean, &unturned).unwrap() < 1e-12);
        let line = vec![[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]; 2];
        assert_eq!(
            orientation_rmse(&line, &line[..]),
            Err(PathError::Collinear(0))
        );
    }

    /// The frames of a pose layout's states are their tool points' entries plus the targets;
    /// a layout of one tool point has none.
    #[test]
    fn tool_frames_add_the_targets_back() {
        let l = StateLayout::POSE6;
        let targets = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
        let (horizon, count) = (2, 3);
        let states: Vec<f64> = (0..count * horizon * l.dx()).map(|v| v as f64).collect();
        let f = tool_frames(&states, &l, horizon, &targets).unwrap();
        assert_eq!((f.len(), f[0].len()), (count, horizon));
        for (e, ep) in f.iter().enumerate() {
            for (t, fr) in ep.iter().enumerate() {
                let s = &states[(e * horizon + t) * l.dx()..][..l.dx()];
                for i in 0..3 {
                    let r = l.point(i);
                    for k in 0..3 {
                        assert_eq!(fr[i][k], s[r.start + k] + targets[i][k]);
                    }
                }
            }
        }
        assert!(tool_frames(&states[..2 * 12], &StateLayout::REACH3, 2, &targets[..1]).is_none());
    }
}
