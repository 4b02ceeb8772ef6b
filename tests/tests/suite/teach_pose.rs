//! Teaching a pose by hand with the whole arm, end to end on a UR5e (docs/ur.md, "Teaching a
//! pose by hand"): `hil-sim playback-gen` with `[task] joints = 6` and a `goal_pose` writes 4
//! human-like reaches of all six joints to the pose (the wrist turning and trembling too), an
//! in-process ur-sim plays them as freedrive at 10 times real time, `learner record --pose`
//! cuts them from the RTDE stream into demonstrations of the pose task (six joints, three tool
//! points: dX = 30, dU = 6) whose goal is the mean of their last tool poses, `learner train`
//! runs LQR+GAIfO on them for a few iterations, and the learned table runs over RTDE on a
//! second ur-sim (lockstep) under `rt-controller` at six joints.
//!
//! Checked: the layout; the recorded goal pose against the poses the playback rests at after
//! each reach (forward kinematics of the file's rows: a demonstration ends at rest, padded with
//! its resting pose, so they agree to rounding), and against the generator's goal region; the
//! start pose; the expert's cost below the random policy's; and the noise-free episode over
//! RTDE of the learner's pick (the iteration of least task cost in its own sim) within
//! [`MAX_DISTANCE_M`] and [`MAX_ANGLE_DEG`] of the recorded goal pose. Those bounds are this
//! short run's, with margin, not the pose goals of docs/results.md (Results 11: 1 cm and 3° from
//! 5 demonstrations at iteration 20): measured (2026-12-06, two runs), iteration 14 of 15 ended
//! 1.2 cm and 0.4° from the goal pose over RTDE, as in the learner's sim, where iteration 0 (the
//! random initial controller) ended 22 cm and 44° away, so a table that does not imitate fails.
//! About 13 s of wall time on the shared 2-core machine (load 7). As in the reach test
//! (`teach.rs`), the recording runs in compressed real time, so the assertions are on outcomes,
//! not on bits.

use hil_sim::ur_sim::playback::Playback;
use hil_sim::ur_sim::Series;
use integration_tests::{cleanup_dead_nodes, scratch, write_config};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::layout::StateLayout;
use ur5_shared::pose::{isometry, mean_pose, orientation_error, tool_points, ur_pose};
use ur5_shared::UrModel;

use super::teach::{record_playback_with, run_ok, run_over_rtde, train_recorded};

/// The pose taught: the UR5e's flange pose at q = (0.293, −1.379, 2.092, −1.9, 1.3, 0.4) rad
/// (UR's p[x, y, z, rx, ry, rz]; Results 11's pose 0), from the default start with the wrist
/// at UR's home posture: every joint moves, the wrist by 0.27–0.4 rad.
const POSE: [f64; 6] = [-0.4383, -0.2993, 0.3748, 0.4667, -0.108, -0.8096];

/// Reaches played and recorded.
const MOTIONS: usize = 4;

/// Horizon of the demonstrations (steps of 0.1 s): a reach takes at most 2.5 s.
const T: usize = 50;

/// LQR+GAIfO iterations: fewer than the pose measurements' 20, to keep the test short.
const ITERATIONS: usize = 15;

/// The bound on the final distance over RTDE (m; module docs).
const MAX_DISTANCE_M: f64 = 0.02;

/// The bound on the final orientation error over RTDE (°; module docs).
const MAX_ANGLE_DEG: f64 = 3.0;

/// Half side of the goal region (m), `hil-sim playback-gen`'s default.
const HALF_SIDE: f64 = 0.005;

#[test]
fn teach_a_pose_by_hand_with_the_whole_arm_record_train_and_run_over_rtde() {
    let m = UrModel::Ur5e;
    let dir = scratch("teach-pose");
    let d = |p: &str| dir.join(p).display().to_string();
    let task = TaskConfig::pose_for_model(m, POSE);
    let start: Vec<String> = task.start_q.iter().map(|q| q.to_string()).collect();
    let pose: Vec<String> = POSE.iter().map(|v| v.to_string()).collect();
    let gen_cfg = write_config(
        &dir,
        "pose.toml",
        &format!(
            "[task]\njoints = 6\nstart_q = [{}]\ngoal_pose = [{}]\n[sim]\nmodel = \"{}\"\n",
            start.join(", "),
            pose.join(", "),
            m.name()
        ),
    );
    let gen = run_ok(
        "hil-sim",
        "playback-gen",
        &[
            "--model",
            m.name(),
            "playback-gen",
            "--config",
            &gen_cfg,
            "--motions",
            &MOTIONS.to_string(),
            "--seed",
            "1",
            "--out",
            &d("reaches.csv"),
        ],
        &dir,
    );
    assert_eq!(gen["motions"], MOTIONS);

    // The poses the playback reaches: its rests of at least 1 s away from the start pose.
    let playback = Playback::load(&dir.join("reaches.csv"), m).unwrap();
    let start6: Joints6 = core::array::from_fn(|j| task.start_q[j]);
    let rests = rests_away_from(&playback, &start6);
    assert_eq!(rests.len(), MOTIONS, "one rest at the pose per reach");
    let sim = SimConfig::for_model(m);
    let kin = UrKinematics::new(m, sim.ee_offset);
    let ends: Vec<_> = rests.iter().map(|q| kin.tool_pose(q)).collect();
    let played = ur_pose(&mean_pose(&ends));

    let rec = record_playback_with(
        m,
        Series::E,
        &dir.join("reaches.csv"),
        MOTIONS,
        T,
        ("joints = 6\n", &["--pose"]),
        &dir,
    );
    assert_eq!(rec["report"]["episodes"], MOTIONS, "{rec}");
    let demos = learner::io::demos::load(&dir.join("rec/demos.npz")).unwrap();
    let layout = demos.layout();
    assert_eq!(layout, StateLayout::POSE6);
    assert_eq!((layout.dx(), layout.du()), (30, 6));
    assert_eq!((demos.count, demos.horizon, demos.model), (MOTIONS, T, m));
    assert_eq!(demos.states.len(), MOTIONS * T * 30);
    assert!(
        (0..6).all(|j| (demos.start_q[j] - start6[j]).abs() < 1e-9),
        "the start pose is the playback's: {:?}",
        demos.start_q
    );
    // The recorded goal: the mean of the demonstrations' last tool poses, which are the
    // playback's rests (a demonstration ends at rest, padded with its resting pose).
    let goal = demos.goal_pose.expect("a pose goal");
    let (dp, da) = pose_error(&goal, &played);
    eprintln!(
        "teach a pose: recorded goal p{goal:.4?}, the playback's rests' mean p{:.4?}: {:.2e} m, \
         {:.2e}°",
        played,
        dp,
        da.to_degrees()
    );
    assert!(
        dp < 1e-4 && da.to_degrees() < 0.01,
        "recorded goal {dp} m, {}° from the playback's",
        da.to_degrees()
    );
    // … and within the generator's goal region around the pose taught.
    let (dp, da) = pose_error(&goal, &POSE);
    assert!(
        dp <= HALF_SIDE * 3f64.sqrt()
            && da <= 3f64.sqrt() * hil_sim::ur_sim::playback::POSE_TILT_RAD,
        "recorded goal {dp} m, {da} rad from the pose taught"
    );
    assert!(demos.cost_expert < demos.cost_random, "{rec}");

    // LQR+GAIfO on the UR5e model, in process. The learner's pick: the table of the iteration
    // whose noise-free episode (in the learner's sim) had the least task cost (all three tool
    // points: position and orientation); row i ran `iter_{i}_table.npz`.
    let cfg = write_config(&dir, "gaifo.toml", "seed = 1\n[sim]\nmodel = \"ur5e\"\n");
    let train = train_recorded(&dir, &cfg, ITERATIONS);
    assert_eq!(train["iterations"], ITERATIONS);
    let log = std::fs::read_to_string(dir.join("train/gaifo_log.csv")).unwrap();
    let header: Vec<&str> = log.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let (cost, dist_col, angle_col) = (
        col("task_cost"),
        col("final_distance_m"),
        col("final_orientation_error_deg"),
    );
    let rows: Vec<Vec<f64>> = log
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let best = (0..rows.len())
        .min_by(|&a, &b| rows[a][cost].total_cmp(&rows[b][cost]))
        .unwrap();
    let (table, _) = learner::io::table::load_table(
        &dir.join(format!("train/iter_{best:03}_table.npz")),
        &ur5_shared::GainBounds::default(),
    )
    .unwrap();
    let episode = run_over_rtde(m, &demos, &table, &dir, "teach-pose");
    assert_eq!(episode.len(), T, "every step of the noise-free episode");
    let last = episode.last().unwrap();
    assert_eq!(last.dx as usize, layout.dx());
    // The tool points from the state (each its position minus its target) and the targets.
    let goal_task = TaskConfig {
        goal_pose: Some(goal),
        tool_points: demos.tool_points,
        ..task
    };
    let mut targets = [[0.0; 3]; 3];
    tool_points(&isometry(&goal), goal_task.tool_offsets(), &mut targets);
    let points: [[f64; 3]; 3] = core::array::from_fn(|i| {
        let e = &last.s[layout.point(i)];
        core::array::from_fn(|k| e[k] + targets[i][k])
    });
    let dist = (0..3)
        .map(|k| (points[0][k] - targets[0][k]).powi(2))
        .sum::<f64>()
        .sqrt();
    let angle = orientation_error(&points, &targets).unwrap().to_degrees();
    eprintln!(
        "teach a pose: {MOTIONS} reaches recorded; LQR+GAIfO: iteration 0 ends {:.4} m, {:.2}° \
         from the goal pose in the learner's sim; the table of iteration {best} (of \
         {ITERATIONS}) {:.4} m, {:.2}° there, {dist:.4} m, {angle:.2}° over RTDE",
        rows[0][dist_col], rows[0][angle_col], rows[best][dist_col], rows[best][angle_col]
    );
    assert!(dist <= MAX_DISTANCE_M, "final distance over RTDE {dist} m");
    assert!(
        angle <= MAX_ANGLE_DEG,
        "final orientation error over RTDE {angle}°"
    );
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}

/// The poses `p` holds for at least 1 s (100 rows) away from `start` (a joint more than
/// 0.1 rad from it), in order.
fn rests_away_from(p: &Playback, start: &Joints6) -> Vec<Joints6> {
    let mut rests = Vec::new();
    let mut k = 0;
    while k < p.q.len() {
        let run = p.q[k..].iter().take_while(|q| **q == p.q[k]).count();
        let held = p.t[k + run - 1] - p.t[k];
        if held >= 1.0 && (0..6).any(|j| (p.q[k][j] - start[j]).abs() > 0.1) {
            rests.push(p.q[k]);
        }
        k += run;
    }
    rests
}

/// Position error (m) and rotation angle (rad) between two poses (UR's p[x, y, z, rx, ry, rz]).
fn pose_error(a: &[f64; 6], b: &[f64; 6]) -> (f64, f64) {
    let (a, b) = (isometry(a), isometry(b));
    (
        (a.translation.vector - b.translation.vector).norm(),
        a.rotation.angle_to(&b.rotation),
    )
}
