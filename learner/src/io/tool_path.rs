//! Demonstrations given as tool paths (docs/design.md §4.17): a CSV file of one row per
//! sample, `episode,t,x,y,z` (t in s, the tool point in m, arm base frame) and optionally the
//! tool's orientation `rx,ry,rz` (rotation vector, rad, UR's convention), from any source (a
//! tracked pen, a motion-capture marker, another robot's log, a LASA shape placed in the
//! workspace). They become joint-state demonstrations of the configured arm:
//!
//! 1. each episode is resampled (linear in time; orientations along the shortest arc) to T
//!    samples over its own duration, T − 1 = its mean duration over the control period, rounded;
//! 2. every episode's start is blended into the episodes' mean start, the offset fading
//!    linearly by step to nothing at its end (the arm starts every episode from one pose; the
//!    ends are kept as recorded);
//! 3. the start pose is the mean start through the inverse kinematics ([`ur5_shared::ik`]),
//!    the branch nearest the model's default start (the wrist at `sim.wrist_q`); each sample
//!    is then solved nearest the previous one, so an episode stays on one branch; the goal is
//!    the episodes' mean end. Steps 2 and 3 are [`Blend`], which the freedrive playbacks of
//!    [`crate::playback`] share, fading by time;
//! 4. a sample out of reach, or a step that needs a joint faster than its limit (a jump
//!    between branches near a singularity, or a path too fast for the arm), is refused naming
//!    the episode, the time in the file and the reason;
//! 5. velocities are backward differences of the joint angles (zero at the start: the arm
//!    starts at rest), the tool point and its velocity the forward kinematics of those; the
//!    state is assembled by the layout ([`StateLayout::fill_state`]).
//!
//! Three joints (the wrist locked at `sim.wrist_q`) follow the point and ignore an
//! orientation; six joints need it. A file read by [`load`] (`--demos`) is three joints and a
//! point goal without the orientation columns, the whole arm and a pose goal with them: each
//! episode's start orientation is blended into the mean start's as its point is, and the goal
//! is the mean end pose.

use std::path::Path;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::ik::{self, IkError, UrIk};
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::layout::{StateLayout, MAX_HORIZON};
use ur5_shared::pose;

use super::lerobot::{TaskMeta, Trajectories};
use super::IoError;
use crate::error::ensure;

/// The columns of a tool-path CSV file.
pub const COLUMNS: [&str; 5] = ["episode", "t", "x", "y", "z"];
/// The optional orientation columns that may follow [`COLUMNS`].
pub const ROTATION_COLUMNS: [&str; 3] = ["rx", "ry", "rz"];

/// One demonstration's samples as read.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolPath {
    /// The episode's label in the file.
    pub episode: u64,
    /// Sample times (s), strictly increasing.
    pub t: Vec<f64>,
    /// Tool point (m, arm base frame).
    pub points: Vec<[f64; 3]>,
    /// The tool's orientation as rotation vectors (rad), when the file has them.
    pub rotations: Option<Vec<[f64; 3]>>,
}

/// Tool paths that cannot become demonstrations of the arm; each names the episode and, for a
/// sample, its time in the file.
#[derive(Debug, thiserror::Error)]
pub enum ToolPathError {
    /// No episode at all.
    #[error("no tool paths")]
    Empty,
    /// An episode's samples are unusable.
    #[error("episode {episode}: {why}")]
    Samples {
        /// The episode's label.
        episode: u64,
        /// What is wrong.
        why: String,
    },
    /// The episodes' mean duration is not a horizon the learner takes.
    #[error(
        "the paths last {duration:.3} s on average: {horizon} steps of {dt} s, the learner takes \
         2 to {MAX_HORIZON}"
    )]
    Horizon {
        /// Mean duration (s).
        duration: f64,
        /// Control period (s).
        dt: f64,
        /// The horizon it gives.
        horizon: usize,
    },
    /// The episodes' mean start is out of the arm's reach.
    #[error("the mean start {point:?} m is out of the arm's reach")]
    Start {
        /// The mean start (m).
        point: [f64; 3],
        /// Why.
        #[source]
        source: IkError,
    },
    /// A sample out of reach.
    #[error("episode {episode}, t = {t} s: the tool at {point:?} m is out of the arm's reach")]
    Unreachable {
        /// The episode's label.
        episode: u64,
        /// Time in the file (s).
        t: f64,
        /// The (blended) tool point (m).
        point: [f64; 3],
        /// Why.
        #[source]
        source: IkError,
    },
    /// A step that needs a joint faster than its limit.
    #[error(
        "episode {episode}, t = {t} s: joint {joint} would move at {speed:.3} rad/s, beyond its \
         limit {limit:.3} rad/s: a jump between inverse kinematics solutions (the path passes \
         near a singularity) or a motion too fast for the arm"
    )]
    Jump {
        /// The episode's label.
        episode: u64,
        /// Time in the file (s).
        t: f64,
        /// The joint (0 = shoulder pan).
        joint: usize,
        /// The speed it would need (rad/s).
        speed: f64,
        /// Its limit (rad/s).
        limit: f64,
    },
    /// The task's layout cannot be made from tool paths.
    #[error(
        "a task of {0} cannot be made from tool paths: 3 joints (a point) or 6 joints (a pose, \
         with rx, ry, rz), one tool point"
    )]
    Layout(StateLayout),
    /// Six joints without the tool's orientation.
    #[error("a six-joint task needs the tool's orientation: columns rx, ry, rz")]
    NeedsOrientation,
    /// An end-effector point on another link than the flange.
    #[error("the tool point is on `{0}`: tool paths are solved for a point on wrist_3_link")]
    EeLink(String),
}

/// Whether `path` is a tool-path CSV file: a `.csv` whose header starts with [`COLUMNS`].
pub fn is_tool_path_csv(path: &Path) -> bool {
    use std::io::BufRead;
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    let mut first = String::new();
    if std::io::BufReader::new(f).read_line(&mut first).is_err() {
        return false;
    }
    let cols: Vec<&str> = first.trim().split(',').map(str::trim).collect();
    cols.len() >= COLUMNS.len() && cols[..COLUMNS.len()] == COLUMNS
}

/// Reads a tool-path CSV file (module docs): the header [`COLUMNS`], optionally followed by
/// [`ROTATION_COLUMNS`]; an episode's rows together and in time order.
pub fn read(path: &Path) -> Result<Vec<ToolPath>, IoError> {
    let mut r = csv::Reader::from_path(path).map_err(IoError::csv("reading", path))?;
    let header: Vec<String> = r
        .headers()
        .map_err(IoError::csv("reading", path))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect();
    let plain: Vec<&str> = COLUMNS.to_vec();
    let full: Vec<&str> = COLUMNS.iter().chain(&ROTATION_COLUMNS).copied().collect();
    let rotated = header == full;
    ensure!(
        rotated || header == plain,
        IoError::content(
            path,
            format!(
                "header {header:?}: a tool-path file has the columns {} or {}",
                plain.join(","),
                full.join(",")
            )
        )
    );
    let mut paths: Vec<ToolPath> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for (line, rec) in r.records().enumerate() {
        let row = line + 2;
        let rec = rec.map_err(|source| IoError::CsvRow {
            path: path.to_owned(),
            row,
            source,
        })?;
        let bad = |k: usize, why: &dyn std::fmt::Display| {
            IoError::content(
                path,
                format!("row {row}, column {}: `{}`: {why}", header[k], &rec[k]),
            )
        };
        let num = |k: usize| -> Result<f64, IoError> {
            let v = rec[k].trim().parse::<f64>().map_err(|e| bad(k, &e))?;
            ensure!(v.is_finite(), bad(k, &"not a finite number"));
            Ok(v)
        };
        let episode = rec[0].trim().parse::<u64>().map_err(|e| bad(0, &e))?;
        let (t, p) = (num(1)?, [num(2)?, num(3)?, num(4)?]);
        let rot = if rotated {
            Some([num(5)?, num(6)?, num(7)?])
        } else {
            None
        };
        if paths.last().is_none_or(|last| last.episode != episode) {
            ensure!(
                seen.insert(episode),
                IoError::content(
                    path,
                    format!(
                        "row {row}: episode {episode} again, after other episodes: the rows of \
                         an episode must be consecutive"
                    )
                )
            );
            paths.push(ToolPath {
                episode,
                t: Vec::new(),
                points: Vec::new(),
                rotations: rotated.then(Vec::new),
            });
        }
        let last = paths.last_mut().expect("pushed");
        last.t.push(t);
        last.points.push(p);
        if let (Some(r), Some(v)) = (last.rotations.as_mut(), rot) {
            r.push(v);
        }
    }
    ensure!(!paths.is_empty(), IoError::content(path, "no rows"));
    Ok(paths)
}

/// `path` at `n` times spread evenly over its duration: the times (s, the file's) and the
/// points and rotations there (linear in time; rotations along the shortest arc).
type Resampled = (Vec<f64>, Vec<[f64; 3]>, Option<Vec<[f64; 3]>>);

fn resample(path: &ToolPath, n: usize) -> Resampled {
    let (t0, t1) = (path.t[0], *path.t.last().expect("≥ 2 samples"));
    let mut i = 0;
    let mut times = Vec::with_capacity(n);
    let mut points = Vec::with_capacity(n);
    let mut rots = path.rotations.as_ref().map(|_| Vec::with_capacity(n));
    for k in 0..n {
        let tau = if k == n - 1 {
            t1
        } else {
            t0 + (t1 - t0) * k as f64 / (n - 1) as f64
        };
        while i + 2 < path.t.len() && path.t[i + 1] <= tau {
            i += 1;
        }
        let w = ((tau - path.t[i]) / (path.t[i + 1] - path.t[i])).clamp(0.0, 1.0);
        let (a, b) = (path.points[i], path.points[i + 1]);
        points.push(core::array::from_fn(|r| a[r] + w * (b[r] - a[r])));
        if let (Some(out), Some(r)) = (rots.as_mut(), path.rotations.as_ref()) {
            out.push(ik::interpolate_rotation_vector(r[i], r[i + 1], w));
        }
        times.push(tau);
    }
    (times, points, rots)
}

/// Checks an episode's samples: at least two, the same number of each, times increasing.
fn check_samples(p: &ToolPath) -> Result<(), ToolPathError> {
    let why = if p.t.len() < 2 {
        Some(format!("{} samples, need at least 2", p.t.len()))
    } else if let Some(k) = p.t.windows(2).position(|w| w[1] <= w[0]) {
        Some(format!(
            "t = {} s after t = {} s: times must increase",
            p.t[k + 1],
            p.t[k]
        ))
    } else {
        None
    };
    match why {
        Some(why) => Err(ToolPathError::Samples {
            episode: p.episode,
            why,
        }),
        None => Ok(()),
    }
}

/// Tool paths solved into states of `layout` (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Solved {
    /// States, (D, T, dX) row-major.
    pub states: Vec<f64>,
    /// D.
    pub count: usize,
    /// T.
    pub horizon: usize,
    /// Start pose (rad, the layout's joints).
    pub start_q: Vec<f64>,
    /// Goal: the paths' mean end (m).
    pub goal: [f64; 3],
    /// A pose layout's goal: the paths' mean end pose, UR's p[x, y, z, rx, ry, rz] (m, rad).
    pub goal_pose: Option<[f64; 6]>,
}

/// The states of an arm's motion in `task`'s layout, one row of `states` (dX each) per step
/// `(q, qd)` of the six joints (rad, rad/s): the active joints, then the task's tool points
/// minus their targets and their velocities, by forward kinematics `kin`.
pub fn arm_states(
    kin: &ur5_shared::kinematics::UrKinematics,
    task: &TaskConfig,
    steps: impl Iterator<
        Item = (
            ur5_shared::kinematics::Joints6,
            ur5_shared::kinematics::Joints6,
        ),
    >,
    states: &mut [f64],
) {
    let (layout, offsets, targets) = (task.layout(), task.tool_offsets(), task.targets());
    let (n, p) = (layout.joints(), offsets.len());
    let (mut points, mut velocities) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
    for (s, (q, qd)) in states.chunks_exact_mut(layout.dx()).zip(steps) {
        kin.tool_points_velocity(&q, &qd, offsets, &mut points[..p], &mut velocities[..p]);
        layout.fill_state(
            &q[..n],
            &qd[..n],
            &points[..p],
            &velocities[..p],
            &targets,
            s,
        );
    }
}

/// The arm's six joints from the layout's `q` (three: the locked wrist added).
fn six(q: &[f64], wrist: &[f64; 3]) -> Joints6 {
    match q.len() {
        3 => [q[0], q[1], q[2], wrist[0], wrist[1], wrist[2]],
        _ => q.try_into().expect("6 joints"),
    }
}

/// The unit quaternion of the rotation vector `r` (rad, axis × angle).
fn quat(r: [f64; 3]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_scaled_axis(Vector3::from(r))
}

/// The mean of `points` (m), coordinate by coordinate. Panics on none.
pub fn mean_point(points: &[[f64; 3]]) -> [f64; 3] {
    assert!(!points.is_empty(), "the mean of no point");
    core::array::from_fn(|r| points.iter().map(|p| p[r]).sum::<f64>() / points.len() as f64)
}

/// The mean of the orientations `rotations` (rotation vectors, rad; [`pose::mean_pose`]'s
/// rotation), none without any.
pub fn mean_rotation(rotations: impl Iterator<Item = [f64; 3]>) -> Option<UnitQuaternion<f64>> {
    let poses: Vec<_> = rotations
        .map(|r| Isometry3::from_parts(Default::default(), quat(r)))
        .collect();
    (!poses.is_empty()).then(|| pose::mean_pose(&poses).rotation)
}

/// Tool paths blended into their mean start and solved on the arm (module docs, steps 2–4
/// but the speed check): the one routine by which demonstrations ([`solve`], samples at the
/// control period) and motions taught by hand ([`crate::playback::motions_of`], the file's
/// own samples) become joint paths.
///
/// Three joints (the wrist locked at `sim.wrist_q`) follow the tool point; six follow its
/// pose. The mean start is solved nearest the model's default start with the wrist at
/// `sim.wrist_q` (a six-joint task's default start pose, docs/design.md §2.5); every sample
/// of a path is then moved by the path's offset to the mean start, scaled by the sample's
/// fade (1 at the start, 0 at the end, the caller's choice in between): the tool point by
/// fade × the translation, the orientation by the rotation taking the path's first
/// orientation to the mean start's raised to the power fade (the same axis, fade × the
/// angle), before it; and solved nearest the previous sample's joints.
#[derive(Clone, Debug)]
pub struct Blend {
    ik: UrIk,
    wrist: [f64; 3],
    point: [f64; 3],
    rotation: UnitQuaternion<f64>,
    start_q: Vec<f64>,
}

impl Blend {
    /// The mean start at tool point `point` (m, base frame) and, for six joints, orientation
    /// `rotation` (base frame), solved for `joints` of the arm of `sim`. Panics unless
    /// `joints` is 3 or 6.
    pub fn new(
        sim: &SimConfig,
        joints: usize,
        point: [f64; 3],
        rotation: Option<UnitQuaternion<f64>>,
    ) -> Result<Self, ToolPathError> {
        assert!(matches!(joints, 3 | 6), "3 or 6 joints, not {joints}");
        if sim.ee_link != "wrist_3_link" {
            return Err(ToolPathError::EeLink(sim.ee_link.clone()));
        }
        let ik = UrIk::new(sim.model, sim.ee_offset);
        let (wrist, near) = (sim.wrist_q, sim.model.default_start_q());
        let start_q = match (joints, rotation) {
            (3, _) => ik.nearest_point(point, wrist, &near).map(|q| q.to_vec()),
            (_, Some(r)) => ik
                .nearest_pose(
                    &Isometry3::from_parts(Vector3::from(point).into(), r),
                    &six(&near, &wrist),
                )
                .map(|q| q.to_vec()),
            (_, None) => return Err(ToolPathError::NeedsOrientation),
        }
        .map_err(|source| ToolPathError::Start { point, source })?;
        Ok(Self {
            ik,
            wrist,
            point,
            rotation: rotation.unwrap_or_else(UnitQuaternion::identity),
            start_q,
        })
    }

    /// The joints at the mean start (rad; three or six).
    pub fn start_q(&self) -> &[f64] {
        &self.start_q
    }

    /// The arm's six joints from the blend's `q` (three: the locked wrist added).
    pub fn six(&self, q: &[f64]) -> Joints6 {
        six(q, &self.wrist)
    }

    /// Blends and solves one path (type docs): episode `episode`'s samples at times `t` (s,
    /// the file's, for errors), tool points `points` (m) and, for six joints, orientations
    /// `rotations` (rotation vectors, rad), sample k faded by `fade(k)`. Calls `each(k, q)`
    /// with each sample's joints (rad) in order, the first the mean start's; stops at the
    /// first error, a sample out of reach or one `each` returns.
    pub fn follow(
        &self,
        episode: u64,
        t: &[f64],
        points: &[[f64; 3]],
        rotations: Option<&[[f64; 3]]>,
        fade: impl Fn(usize) -> f64,
        mut each: impl FnMut(usize, &[f64]) -> Result<(), ToolPathError>,
    ) -> Result<(), ToolPathError> {
        let offset: [f64; 3] = core::array::from_fn(|r| self.point[r] - points[0][r]);
        let rotations = (self.start_q.len() == 6).then(|| rotations.expect("six joints"));
        // The rotation taking this path's first orientation to the mean start's.
        let turn = rotations.map(|r| self.rotation * quat(r[0]).inverse());
        let mut q = self.start_q.clone();
        each(0, &q)?;
        for k in 1..points.len() {
            let f = fade(k);
            let p: [f64; 3] = core::array::from_fn(|r| points[k][r] + f * offset[r]);
            let solved = match (turn, rotations) {
                (Some(turn), Some(r)) => {
                    let pose =
                        Isometry3::from_parts(Vector3::from(p).into(), turn.powf(f) * quat(r[k]));
                    self.ik
                        .nearest_pose(&pose, &six(&q, &self.wrist))
                        .map(|q| q.to_vec())
                }
                _ => self
                    .ik
                    .nearest_point(p, self.wrist, &[q[0], q[1], q[2]])
                    .map(|q| q.to_vec()),
            };
            q = solved.map_err(|source| ToolPathError::Unreachable {
                episode,
                t: t[k],
                point: p,
                source,
            })?;
            each(k, &q)?;
        }
        Ok(())
    }
}

/// Solves `paths` into demonstrations of `layout` on the arm of `sim` at the control period
/// `dt` (s) (module docs, steps 1–5).
pub fn solve(
    paths: &[ToolPath],
    sim: &SimConfig,
    layout: StateLayout,
    dt: f64,
) -> Result<Solved, ToolPathError> {
    let (n, p_count) = (layout.joints(), layout.tool_points());
    if !matches!((n, p_count), (3, 1) | (6, 1) | (6, 3)) {
        return Err(ToolPathError::Layout(layout));
    }
    if sim.ee_link != "wrist_3_link" {
        return Err(ToolPathError::EeLink(sim.ee_link.clone()));
    }
    if paths.is_empty() {
        return Err(ToolPathError::Empty);
    }
    for p in paths {
        check_samples(p)?;
        if n == 6 && p.rotations.is_none() {
            return Err(ToolPathError::NeedsOrientation);
        }
    }
    let duration = paths
        .iter()
        .map(|p| p.t.last().expect("checked") - p.t[0])
        .sum::<f64>()
        / paths.len() as f64;
    let horizon = (duration / dt).round() as usize + 1;
    if !(2..=MAX_HORIZON).contains(&horizon) {
        return Err(ToolPathError::Horizon {
            duration,
            dt,
            horizon,
        });
    }
    let sampled: Vec<Resampled> = paths.iter().map(|p| resample(p, horizon)).collect();
    let mean =
        |k: usize| -> [f64; 3] { mean_point(&sampled.iter().map(|s| s.1[k]).collect::<Vec<_>>()) };
    let (start, goal) = (mean(0), mean(horizon - 1));
    let kin = UrKinematics::new(sim.model, sim.ee_offset);
    let wrist = sim.wrist_q;
    // Six joints: the mean start and end orientations (each episode's start rotation is
    // blended into the mean start's as its point is), the goal pose the mean end pose.
    let mean_rot =
        |k: usize| mean_rotation(sampled.iter().filter_map(|s| s.2.as_ref().map(|r| r[k])));
    let (start_rot, end_rot) = (mean_rot(0), mean_rot(horizon - 1));
    let goal_pose = match (p_count, end_rot) {
        (3, Some(r)) => Some({
            let v = pose::rotation_vector(&r);
            [goal[0], goal[1], goal[2], v[0], v[1], v[2]]
        }),
        _ => None,
    };
    // A pose layout's tool points: as a pose task of that goal has them.
    let pose_task = goal_pose.map(|g| TaskConfig::pose_for_model(sim.model, g));
    let blend = Blend::new(sim, n, start, start_rot)?;
    let start_q = blend.start_q().to_vec();
    let limits = sim.model.joint_limits().velocity;
    let dx = layout.dx();
    let mut states = vec![0.0; paths.len() * horizon * dx];
    // A pose layout's episode, step by step (six joints, rad and rad/s), for [`arm_states`].
    let mut steps: Vec<(Joints6, Joints6)> = Vec::with_capacity(horizon);
    for (d, (path, (times, points, rots))) in paths.iter().zip(&sampled).enumerate() {
        let mut prev = start_q.clone();
        let fade = |k: usize| 1.0 - k as f64 / (horizon - 1) as f64;
        blend.follow(
            path.episode,
            times,
            points,
            rots.as_deref(),
            fade,
            |k, q| {
                let qd: Vec<f64> = (0..n)
                    .map(|j| if k == 0 { 0.0 } else { (q[j] - prev[j]) / dt })
                    .collect();
                if let Some(j) = (0..n).find(|&j| qd[j].abs() > limits[j]) {
                    return Err(ToolPathError::Jump {
                        episode: path.episode,
                        t: times[k],
                        joint: j,
                        speed: qd[j].abs(),
                        limit: limits[j],
                    });
                }
                if pose_task.is_some() {
                    steps.push((six(q, &wrist), six(&qd, &[0.0; 3])));
                } else {
                    // The locked wrist does not move.
                    let (ee, v) = kin.ee_point_velocity(&six(q, &wrist), &six(&qd, &[0.0; 3]));
                    let at = (d * horizon + k) * dx;
                    layout.fill_state(q, &qd, &[ee], &[v], &[goal], &mut states[at..at + dx]);
                }
                prev = q.to_vec();
                Ok(())
            },
        )?;
        if let Some(task) = &pose_task {
            let episode = &mut states[d * horizon * dx..(d + 1) * horizon * dx];
            arm_states(&kin, task, steps.drain(..), episode);
        }
    }
    Ok(Solved {
        states,
        count: paths.len(),
        horizon,
        start_q,
        goal,
        goal_pose,
    })
}

/// The tool paths of the file `path` as trajectories on the arm of `sim` at the control
/// period `dt` (s), their task noted with `seed` (costs left to derive): the three-joint
/// reaching layout for tool points alone, the whole arm and a pose goal
/// ([`StateLayout::POSE6`]: the three default tool points, the goal the paths' mean end pose)
/// when the file gives the tool's orientation.
pub fn load(path: &Path, sim: &SimConfig, dt: f64, seed: u64) -> Result<Trajectories, IoError> {
    let paths = read(path)?;
    let layout = if paths.iter().all(|p| p.rotations.is_some()) {
        StateLayout::POSE6
    } else {
        StateLayout::REACH3
    };
    let s = solve(&paths, sim, layout, dt).map_err(|source| IoError::ToolPath {
        path: path.to_owned(),
        source,
    })?;
    Ok(Trajectories {
        layout,
        states: s.states,
        actions: None,
        count: s.count,
        horizon: s.horizon,
        dt,
        task: Some(TaskMeta {
            goal: s.goal,
            start_q: ur5_shared::joints::Joints::from_slice(&s.start_q),
            seed,
            cost_random: None,
            cost_expert: None,
            goal_pose: s.goal_pose,
            tool_points: None,
        }),
        model: Some(sim.model),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::config::DEFAULT_TOOL_POINTS;
    use ur5_shared::UrModel;

    const DT: f64 = 0.1;

    /// A smooth three-joint motion of 2 s, `bend` changing its middle, and its tool path
    /// sampled every 0.02 s.
    fn motion(bend: f64) -> impl Fn(f64) -> [f64; 3] {
        move |t: f64| {
            let s = t / 2.0;
            let mid = (core::f64::consts::PI * s).sin();
            [0.1 + 0.4 * s, -1.9 + 0.5 * s + bend * mid, 2.3 - 0.6 * s]
        }
    }

    fn path_of(episode: u64, q: impl Fn(f64) -> [f64; 3], sim: &SimConfig) -> ToolPath {
        let kin = UrKinematics::new(sim.model, sim.ee_offset);
        let t: Vec<f64> = (0..=100).map(|i| i as f64 * 0.02).collect();
        let points = t
            .iter()
            .map(|&t| kin.ee_point(&six(&q(t), &sim.wrist_q)))
            .collect();
        ToolPath {
            episode,
            t,
            points,
            rotations: None,
        }
    }

    /// Tool paths made by forward kinematics of known motions come back as those motions:
    /// the joint angles within 1e-6 rad, every state's tool point within 1e-6 m of the path,
    /// velocities the backward differences, the start the motions' start, the goal their mean
    /// end, on several models.
    #[test]
    fn a_tool_path_round_trips_through_the_inverse_kinematics() {
        for model in [UrModel::Ur5, UrModel::Ur10e, UrModel::Ur3] {
            let mut sim = SimConfig::for_model(model);
            sim.ee_offset = [0.0, 0.0, 0.05];
            let bends = [0.0, 0.1, -0.1];
            let paths: Vec<ToolPath> = bends
                .iter()
                .enumerate()
                .map(|(e, &b)| path_of(e as u64 + 3, motion(b), &sim))
                .collect();
            let l = StateLayout::REACH3;
            let s = solve(&paths, &sim, l, DT).unwrap();
            assert_eq!((s.count, s.horizon), (3, 21));
            let q0 = motion(0.0)(0.0);
            assert!(
                (0..3).all(|j| (s.start_q[j] - q0[j]).abs() < 1e-9),
                "{model}: {:?}",
                s.start_q
            );
            let kin = UrKinematics::new(model, sim.ee_offset);
            let ends: Vec<[f64; 3]> = paths.iter().map(|p| *p.points.last().unwrap()).collect();
            for r in 0..3 {
                let m = ends.iter().map(|e| e[r]).sum::<f64>() / 3.0;
                assert!((s.goal[r] - m).abs() < 1e-12);
            }
            let mut worst = (0.0f64, 0.0f64);
            for (d, &b) in bends.iter().enumerate() {
                for k in 0..21 {
                    let x = &s.states[(d * 21 + k) * l.dx()..][..l.dx()];
                    let want = motion(b)(k as f64 * DT);
                    for j in 0..3 {
                        worst.0 = worst.0.max((x[j] - want[j]).abs());
                    }
                    let p = kin.ee_point(&six(&want, &sim.wrist_q));
                    for r in 0..3 {
                        worst.1 = worst
                            .1
                            .max((x[l.point(0).start + r] + s.goal[r] - p[r]).abs());
                    }
                    if k > 0 {
                        let before = &s.states[(d * 21 + k - 1) * l.dx()..][..3];
                        for j in 0..3 {
                            assert!((x[3 + j] - (x[j] - before[j]) / DT).abs() < 1e-12);
                        }
                    } else {
                        assert_eq!(&x[3..6], &[0.0; 3]);
                    }
                }
            }
            assert!(worst.0 < 1e-6 && worst.1 < 1e-6, "{model}: {worst:?}");
        }
    }

    /// Six joints follow a pose path (position and rotation vector) back to the motion.
    #[test]
    fn a_pose_path_round_trips_with_six_joints() {
        let sim = SimConfig::for_model(UrModel::Ur5e);
        let kin = UrKinematics::new(sim.model, sim.ee_offset);
        let q = |t: f64| -> Joints6 {
            let s = t / 2.0;
            [
                0.1 + 0.4 * s,
                -1.9 + 0.5 * s,
                2.3 - 0.6 * s,
                -1.5 + 0.3 * s,
                1.5 - 0.2 * s,
                0.1 + 0.5 * s,
            ]
        };
        let t: Vec<f64> = (0..=100).map(|i| i as f64 * 0.02).collect();
        let poses: Vec<_> = t.iter().map(|&t| kin.tool_pose(&q(t))).collect();
        let path = ToolPath {
            episode: 0,
            t: t.clone(),
            points: poses.iter().map(|p| p.translation.vector.into()).collect(),
            rotations: Some(
                poses
                    .iter()
                    .map(|p| p.rotation.scaled_axis().into())
                    .collect(),
            ),
        };
        let l = StateLayout::new(6, 1).unwrap();
        // Six joints near the default start: the test starts from the motion's own pose.
        let s = solve(&[path.clone(), path.clone()], &sim, l, DT).unwrap();
        let mut worst = 0.0f64;
        for k in 0..s.horizon {
            let x = &s.states[k * l.dx()..][..6];
            let want = q(k as f64 * DT);
            worst = (0..6).fold(worst, |w, j| w.max((x[j] - want[j]).abs()));
        }
        assert!(worst < 1e-6, "{worst}");
        let mut no_rot = path.clone();
        no_rot.rotations = None;
        assert!(matches!(
            solve(&[no_rot], &sim, l, DT),
            Err(ToolPathError::NeedsOrientation)
        ));
        assert!(matches!(
            solve(&[], &sim, StateLayout::new(3, 3).unwrap(), DT),
            Err(ToolPathError::Layout(_))
        ));
        // The pose layout: the same joints, the goal pose the path's end pose, and each tool
        // point's entries its forward kinematics minus its target.
        let p = solve(&[path.clone(), path], &sim, StateLayout::POSE6, DT).unwrap();
        let g = p.goal_pose.unwrap();
        let end = kin.tool_pose(&q(2.0));
        let want = ur5_shared::pose::ur_pose(&end);
        assert!(
            (0..6).all(|k| (g[k] - want[k]).abs() < 1e-9),
            "{g:?} against {want:?}"
        );
        let lp = StateLayout::POSE6;
        let mut targets = [[0.0; 3]; 3];
        ur5_shared::pose::tool_points(&end, &DEFAULT_TOOL_POINTS, &mut targets);
        let mut worst = 0.0f64;
        for k in 0..p.horizon {
            let x = &p.states[k * lp.dx()..][..lp.dx()];
            let qk = q(k as f64 * DT);
            worst = (0..6).fold(worst, |w, j| w.max((x[j] - qk[j]).abs()));
            let mut pts = [[0.0; 3]; 3];
            ur5_shared::pose::tool_points(&kin.tool_pose(&qk), &DEFAULT_TOOL_POINTS, &mut pts);
            for i in 0..3 {
                let r = lp.point(i);
                for c in 0..3 {
                    worst = worst.max((x[r.start + c] + targets[i][c] - pts[i][c]).abs());
                }
            }
        }
        assert!(worst < 1e-6, "{worst}");
    }

    /// Different starts are blended into the mean start: every episode starts at the start
    /// pose, and the ends stay as recorded.
    #[test]
    fn starts_are_blended_into_one_pose() {
        let sim = SimConfig::default();
        let paths = vec![
            path_of(
                0,
                |t| {
                    let q = motion(0.0)(t);
                    [q[0] + 0.05, q[1], q[2]]
                },
                &sim,
            ),
            path_of(1, motion(0.0), &sim),
        ];
        let l = StateLayout::REACH3;
        let s = solve(&paths, &sim, l, DT).unwrap();
        for d in 0..2 {
            let x0 = &s.states[d * 21 * l.dx()..][..3];
            assert_eq!(x0, &s.start_q[..]);
            let end = &s.states[(d * 21 + 20) * l.dx()..][..l.dx()];
            let p = paths[d].points[100];
            assert!((0..3).all(|r| (end[l.point(0).start + r] + s.goal[r] - p[r]).abs() < 1e-6));
        }
    }

    #[test]
    fn a_sample_out_of_reach_or_a_jump_is_refused_naming_episode_and_time() {
        let sim = SimConfig::default();
        let mut far = path_of(7, motion(0.0), &sim);
        far.points[30] = [1.5, 0.0, 0.3];
        let e = solve(
            &[path_of(2, motion(0.0), &sim), far],
            &sim,
            StateLayout::REACH3,
            DT,
        )
        .unwrap_err();
        assert!(
            matches!(
                e,
                ToolPathError::Unreachable {
                    episode: 7,
                    source: IkError::Elbow { .. },
                    ..
                }
            ),
            "{e:?}"
        );
        let msg = crate::error::line(&e);
        assert!(
            msg.contains("episode 7, t = 0.6") && msg.contains("out of the arm's reach"),
            "{msg}"
        );
        assert!(msg.contains("upper arm and forearm reach"), "{msg}");
        // Within reach but 25 cm away for one sample: the joints would have to jump.
        let mut jump = path_of(4, motion(0.0), &sim);
        jump.points[50][2] += 0.25;
        let e = solve(&[jump], &sim, StateLayout::REACH3, DT).unwrap_err();
        assert!(matches!(e, ToolPathError::Jump { episode: 4, .. }), "{e:?}");
        let msg = e.to_string();
        assert!(
            msg.contains("episode 4, t = 1 s") && msg.contains("beyond its limit"),
            "{msg}"
        );
        let mut back = path_of(5, motion(0.0), &sim);
        back.t[10] = back.t[9];
        let e = solve(&[back], &sim, StateLayout::REACH3, DT).unwrap_err();
        assert!(
            e.to_string()
                .contains("episode 5: t = 0.18 s after t = 0.18 s"),
            "{e}"
        );
    }

    #[test]
    fn the_file_is_read_by_its_header() {
        let dir = std::env::temp_dir().join(format!("tool_path_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("p.csv");
        std::fs::write(&good, "episode,t,x,y,z\n0,0,0.1,0.2,0.3\n0,0.5,0.1,0.2,0.4\n1,0,0.1,0.2,0.3\n1,1,0.2,0.2,0.3\n").unwrap();
        assert!(is_tool_path_csv(&good));
        let p = read(&good).unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(p[1].points[1], [0.2, 0.2, 0.3]);
        assert!(p[0].rotations.is_none());
        let rot = dir.join("r.csv");
        std::fs::write(&rot, "episode,t,x,y,z,rx,ry,rz\n0,0,0.1,0.2,0.3,0,3.14,0\n").unwrap();
        assert_eq!(
            read(&rot).unwrap()[0].rotations,
            Some(vec![[0.0, 3.14, 0.0]])
        );
        let wrong = dir.join("w.csv");
        std::fs::write(&wrong, "episode,t,x,y,z,rx\n0,0,0.1,0.2,0.3,0\n").unwrap();
        assert!(is_tool_path_csv(&wrong));
        let e = crate::error::line(&read(&wrong).unwrap_err());
        assert!(
            e.contains("w.csv") && e.contains("episode,t,x,y,z,rx,ry,rz"),
            "{e}"
        );
        let again = dir.join("a.csv");
        std::fs::write(&again, "episode,t,x,y,z\n0,0,0,0,0\n1,0,0,0,0\n0,1,0,0,0\n").unwrap();
        let e = crate::error::line(&read(&again).unwrap_err());
        assert!(e.contains("row 4: episode 0 again"), "{e}");
        let nan = dir.join("n.csv");
        std::fs::write(&nan, "episode,t,x,y,z\n0,0,0,NaN,0\n").unwrap();
        let e = crate::error::line(&read(&nan).unwrap_err());
        assert!(e.contains("row 2, column y"), "{e}");
        let joint_states = dir.join("j.csv");
        std::fs::write(&joint_states, "episode,time_s,q_shoulder_pan\n").unwrap();
        assert!(!is_tool_path_csv(&joint_states));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
