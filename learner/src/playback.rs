//! Tool paths as motions taught by hand (`learner dataset playback`, docs/ur.md "Teaching a
//! motion by hand"): a tool-path file (docs/design.md §4.17; a LASA shape placed by `learner
//! dataset lasa`, a tracked pen, another arm's log) becomes a freedrive playback for `hil-sim
//! ur-sim --playback`, each path a motion between two rests
//! ([`hil_sim::ur_sim::playback_motions`]), so that `learner record` can be tried on any motion,
//! not only reaches.
//!
//! The paths are solved on the arm by the routine that solves `--demos` ([`Blend`], §4.17
//! steps 2–3), at the file's own samples instead of the control period: every path's start
//! blended into the paths' mean start (the offset fading linearly in time to nothing at its
//! end), the mean start solved nearest the model's default start (the wrist at
//! `sim.wrist_q`), every sample nearest the previous solution. A point path (`episode,t,x,y,z`) keeps the wrist locked at
//! `sim.wrist_q` (a three-joint task's demonstrations); a pose path (with the tool's
//! orientation `rx,ry,rz`) moves the whole arm, the six joints by the pose's inverse
//! kinematics, its start's orientation blended too (the rotation from the path's first
//! orientation to the starts' mean, [`mean_rotation`], by the same fading weight), for
//! `learner record --pose` with `[task] joints = 6`. Every motion thus starts from one pose,
//! the one a recorder takes for the start pose.

use std::path::Path;

use hil_sim::ur_sim::playback::{Playback, PlaybackError};
use hil_sim::ur_sim::playback_motions::{play_motions, Motion, MotionsConfig};
use ur5_shared::config::SimConfig;

use crate::io::tool_path::{self, mean_point, mean_rotation, Blend, ToolPath, ToolPathError};
use crate::io::IoError;

/// Why tool paths cannot be played as motions taught by hand.
#[derive(Debug, thiserror::Error)]
pub enum TeachPlaybackError {
    /// The file cannot be read as tool paths.
    #[error(transparent)]
    Io(#[from] IoError),
    /// A path the arm cannot follow (the episode, the time and why).
    #[error("{}", path.display())]
    Paths {
        /// The file.
        path: std::path::PathBuf,
        /// Which episode and time, and why.
        source: ToolPathError,
    },
    /// The playback cannot be made (a joint too fast, too many rows).
    #[error(transparent)]
    Playback(#[from] PlaybackError),
}

/// The joint paths of `paths` on the arm of `sim` (module docs): one motion a path, its sample
/// times kept; the wrist locked for point paths, the whole arm for pose paths.
pub fn motions_of(paths: &[ToolPath], sim: &SimConfig) -> Result<Vec<Motion>, ToolPathError> {
    if paths.is_empty() {
        return Err(ToolPathError::Empty);
    }
    let pose = paths.iter().all(|p| p.rotations.is_some());
    for p in paths {
        let rotations = p.rotations.as_ref().filter(|_| pose).map(Vec::len);
        let why = if p.t.len() < 2 || p.points.len() != p.t.len() {
            format!("{} samples: at least 2", p.t.len())
        } else if let Some(r) = rotations.filter(|&r| r != p.t.len()) {
            format!("{} samples but {r} orientations", p.t.len())
        } else {
            continue;
        };
        return Err(ToolPathError::Samples {
            episode: p.episode,
            why,
        });
    }
    let firsts: Vec<[f64; 3]> = paths.iter().map(|p| p.points[0]).collect();
    let rotation = pose
        .then(|| mean_rotation(paths.iter().filter_map(|p| Some(p.rotations.as_ref()?[0]))))
        .flatten();
    let blend = Blend::new(sim, if pose { 6 } else { 3 }, mean_point(&firsts), rotation)?;
    paths
        .iter()
        .map(|path| {
            let (t0, t1) = (path.t[0], path.t[path.t.len() - 1]);
            let fade = |k: usize| 1.0 - (path.t[k] - t0) / (t1 - t0);
            let mut q = Vec::with_capacity(path.t.len());
            let rotations = path.rotations.as_deref().filter(|_| pose);
            blend.follow(
                path.episode,
                &path.t,
                &path.points,
                rotations,
                fade,
                |_, qk| {
                    q.push(blend.six(qk));
                    Ok(())
                },
            )?;
            Ok(Motion {
                t: path.t.clone(),
                q,
            })
        })
        .collect()
}

/// The tool-path file `path` as a playback of motions taught by hand on the arm of `sim`
/// (module docs), rows at `rate_hz`, rests and tremor seeded by `seed`.
pub fn playback_of_file(
    path: &Path,
    sim: &SimConfig,
    rate_hz: f64,
    seed: u64,
) -> Result<Playback, TeachPlaybackError> {
    let paths = tool_path::read(path)?;
    let motions = motions_of(&paths, sim).map_err(|source| TeachPlaybackError::Paths {
        path: path.to_owned(),
        source,
    })?;
    Ok(play_motions(&MotionsConfig {
        model: sim.model,
        motions,
        rate_hz,
        seed,
    })?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::ik::pose_from_rotation_vector;
    use ur5_shared::kinematics::{Joints6, UrKinematics};
    use ur5_shared::UrModel;

    /// Two short strokes in a vertical plane before the default goal, starting 1 cm apart.
    fn strokes(goal: [f64; 3]) -> Vec<ToolPath> {
        (0..2)
            .map(|e| {
                let t: Vec<f64> = (0..=50).map(|k| k as f64 * 0.04).collect();
                let points = t
                    .iter()
                    .map(|&s| {
                        let u = s / 2.0;
                        let lift = 0.05 * (std::f64::consts::PI * u).sin();
                        [
                            goal[0],
                            goal[1] + 0.1 * (1.0 - u) + 0.01 * e as f64 * (1.0 - u),
                            goal[2] + lift,
                        ]
                    })
                    .collect();
                ToolPath {
                    episode: e as u64,
                    t,
                    points,
                    rotations: None,
                }
            })
            .collect()
    }

    /// The sample times of the test paths: 2 s every 0.04 s.
    fn times() -> Vec<f64> {
        (0..=50).map(|k| k as f64 * 0.04).collect()
    }

    /// A whole-arm motion of 2 s, its start moved by `d3` on wrist 3 and `d1` on wrist 1
    /// (rad), fading out by its end.
    fn whole_arm(d3: f64, d1: f64) -> impl Fn(f64) -> Joints6 {
        move |t: f64| {
            let s = t / 2.0;
            [
                0.1 + 0.2 * s,
                -1.9 + 0.4 * s,
                2.2 - 0.3 * s,
                -1.5 - 0.3 * s + d1 * (1.0 - s),
                1.5 - 0.2 * s,
                0.1 + 0.4 * s + d3 * (1.0 - s),
            ]
        }
    }

    /// The pose path of the motion `q` through the forward kinematics `kin`, at [`times`].
    fn pose_path(kin: &UrKinematics, episode: u64, q: &dyn Fn(f64) -> Joints6) -> ToolPath {
        let t = times();
        let poses: Vec<_> = t.iter().map(|&t| kin.tool_pose(&q(t))).collect();
        ToolPath {
            episode,
            t,
            points: poses.iter().map(|p| p.translation.vector.into()).collect(),
            rotations: Some(
                poses
                    .iter()
                    .map(|p| ur5_shared::pose::rotation_vector(&p.rotation))
                    .collect(),
            ),
        }
    }

    /// The motions start from one pose (the blended start), follow the paths through the
    /// forward kinematics (exactly at the end, within the blend elsewhere), keep the wrist
    /// locked and play as a valid file.
    #[test]
    fn paths_become_motions_from_one_start_pose() {
        let sim = SimConfig::for_model(UrModel::Ur5);
        let paths = strokes(sim.model.default_goal());
        let motions = motions_of(&paths, &sim).unwrap();
        let kin = UrKinematics::new(sim.model, sim.ee_offset);
        assert_eq!(motions[0].q[0], motions[1].q[0], "one start pose");
        for (m, p) in motions.iter().zip(&paths) {
            assert_eq!(m.t, p.t);
            let end = kin.ee_point(m.q.last().unwrap());
            let want = p.points.last().unwrap();
            assert!(
                (0..3).all(|r| (end[r] - want[r]).abs() < 1e-6),
                "{end:?} {want:?}"
            );
            for (k, q) in m.q.iter().enumerate() {
                assert_eq!(q[3..], sim.wrist_q[..], "wrist locked");
                let x = kin.ee_point(q);
                let blend = 0.005 * (1.0 - p.t[k] / 2.0) + 1e-6;
                let off = (0..3)
                    .map(|r| (x[r] - p.points[k][r]).abs())
                    .fold(0.0, f64::max);
                assert!(off <= blend, "episode {}, sample {k}: {off} m", p.episode);
            }
        }
        let pb = play_motions(&MotionsConfig {
            model: sim.model,
            motions,
            rate_hz: 100.0,
            seed: 0,
        })
        .unwrap();
        assert!(pb.duration() > 2.0 * 2.0 + 4.0 * 1.0, "{}", pb.duration());
    }

    /// Pose paths of two whole-arm motions whose starts differ (wrist 3 by 0.05 rad, fading
    /// out): both motions start from one pose, the blended mean start; every joint moves; each
    /// ends at its own path's end pose; a path without its blend follows the motion it was made
    /// from within 1e-6 rad; and the playback is valid.
    #[test]
    fn pose_paths_become_whole_arm_motions_from_one_start_pose() {
        let sim = SimConfig::for_model(UrModel::Ur5e);
        let kin = UrKinematics::new(sim.model, sim.ee_offset);
        let motion = |d: f64| whole_arm(d, 0.0);
        let t = times();
        let paths = [
            pose_path(&kin, 0, &motion(0.0)),
            pose_path(&kin, 1, &motion(0.05)),
        ];
        let motions = motions_of(&paths, &sim).unwrap();
        assert_eq!(motions[0].q[0], motions[1].q[0], "one start pose");
        let first = motions[0].q[0];
        let last = motions[0].q.last().unwrap();
        assert!(
            (0..6).all(|j| (last[j] - first[j]).abs() > 0.1),
            "{first:?} {last:?}"
        );
        for (m, p) in motions.iter().zip(&paths) {
            let end = kin.tool_pose(m.q.last().unwrap());
            let want = pose_from_rotation_vector(
                *p.points.last().unwrap(),
                *p.rotations.as_ref().unwrap().last().unwrap(),
            );
            assert!((end.translation.vector - want.translation.vector).norm() < 1e-9);
            assert!(end.rotation.angle_to(&want.rotation) < 1e-9);
        }
        // The same path twice: no blend, the motion itself.
        let same = motions_of(&[paths[0].clone(), paths[0].clone()], &sim).unwrap();
        let worst = same[0]
            .q
            .iter()
            .zip(&t)
            .map(|(q, &t)| {
                let want = motion(0.0)(t);
                (0..6).map(|j| (q[j] - want[j]).abs()).fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
        let pb = play_motions(&MotionsConfig {
            model: sim.model,
            motions,
            rate_hz: 100.0,
            seed: 0,
        })
        .unwrap();
        assert!(
            pb.q.iter().any(|q| (q[5] - first[5]).abs() > 0.1),
            "the wrist turns"
        );
    }

    /// The one blend-and-solve routine: paths sampled every 0.04 s become the same joint
    /// paths (within 1e-12 rad) as motions (the fade by time) and as demonstrations at a
    /// control period of 0.04 s (the fade by step), at three joints with a wrist locked away
    /// from home and at six for pose paths whose start orientations differ.
    #[test]
    fn motions_and_demonstrations_of_the_same_samples_are_the_same_joint_paths() {
        use crate::io::tool_path::solve;
        use ur5_shared::layout::StateLayout;
        let mut sim = SimConfig::for_model(UrModel::Ur5e);
        sim.wrist_q = [-1.4, 1.7, 0.3];
        let kin = UrKinematics::new(sim.model, sim.ee_offset);
        let t = times();
        let poses = vec![
            pose_path(&kin, 0, &whole_arm(0.0, 0.0)),
            pose_path(&kin, 1, &whole_arm(0.05, 0.025)),
            pose_path(&kin, 2, &whole_arm(-0.08, -0.04)),
        ];
        for (paths, layout) in [
            (strokes(sim.model.default_goal()), StateLayout::REACH3),
            (poses, StateLayout::POSE6),
        ] {
            let motions = motions_of(&paths, &sim).unwrap();
            let s = solve(&paths, &sim, layout, 0.04).unwrap();
            assert_eq!(s.horizon, t.len());
            let n = layout.joints();
            let mut worst = 0.0f64;
            for (d, m) in motions.iter().enumerate() {
                for (k, q) in m.q.iter().enumerate() {
                    let x = &s.states[(d * s.horizon + k) * layout.dx()..][..n];
                    worst = (0..n).fold(worst, |w, j| w.max((x[j] - q[j]).abs()));
                }
            }
            assert!(worst < 1e-12, "{n} joints: {worst} rad");
            assert!(
                motions.iter().all(|m| m.q[0][..n] == s.start_q[..]),
                "{n} joints: one start pose"
            );
        }
    }

    #[test]
    fn a_point_out_of_reach_is_refused_naming_episode_and_time() {
        let sim = SimConfig::for_model(UrModel::Ur5);
        let mut paths = strokes(sim.model.default_goal());
        paths[1].points[30] = [3.0, 0.0, 0.5];
        let e = motions_of(&paths, &sim).unwrap_err().to_string();
        assert!(
            e.contains("episode 1, t = 1.2 s") && e.contains("out of the arm's reach"),
            "{e}"
        );
    }
}
