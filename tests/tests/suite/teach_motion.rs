//! Teaching a motion by hand, end to end (docs/ur.md, "Teaching a motion by hand"): a LASA
//! shape placed before a UR5e (`learner dataset lasa`), turned into a freedrive playback of
//! its drawings, each between two rests (`learner dataset playback`), played by an in-process
//! ur-sim at 10 times real time; `learner record` cuts 5 demonstrations from the RTDE stream;
//! `learner train` runs LQR+GAIfO with the motion's settings (`[path]`: the per-step tracking
//! term, docs/design.md §5 D39) for a few iterations; the last iteration's table runs over
//! RTDE on a second ur-sim (lockstep) under `rt-controller`. Its noise-free episode's tool
//! path must be within twice the recorded demonstrations' own spread of their mean path (path
//! RMSE, docs/design.md §4.15) and end within 1 cm of their goal. As in the reach test
//! (`teach.rs`), the recording runs in compressed real time, so the assertions are on
//! outcomes, not on bits.

use imitation::tool_path::{mean_path, rmse, tool_paths, Point};
use std::time::Duration;

use integration_tests::{cleanup_dead_nodes, scratch, write_config, Proc};
use ur5_shared::layout::StateLayout;
use ur5_shared::UrModel;

use hil_sim::ur_sim::Series;

use super::teach::{record_playback, run_ok, run_over_rtde, train_recorded};

/// The shape: the S, 20 cm, drawn in 5 s (half the benchmark's 10 s, to keep the test short).
const SHAPE: &str = "Sshape";
const DURATION_S: &str = "5";

/// Horizon of the recorded demonstrations (steps of 0.1 s): the longest drawing, its onset and
/// the start of its final rest fit in 7.9 s.
const T: usize = 80;

/// LQR+GAIfO iterations: fewer than the benchmark's 30 (Results 12), to keep the test short.
const ITERATIONS: usize = 15;

#[test]
fn teach_a_drawn_shape_by_hand_record_train_and_run_over_rtde() {
    let m = UrModel::Ur5e;
    let dir = scratch("teach-shape");
    let d = |p: &str| dir.join(p).display().to_string();
    let model = m.name();
    let mut lasa = Proc::spawn(
        "learner",
        "lasa",
        &[
            "dataset",
            "lasa",
            SHAPE,
            &d("shape.csv"),
            "--model",
            model,
            "--duration",
            DURATION_S,
        ],
        &dir,
    );
    let (code, _) = lasa.wait(Duration::from_secs(60));
    assert_eq!(code, Some(0), "{}", lasa.log());
    let play = run_ok(
        "learner",
        "playback",
        &[
            "dataset",
            "playback",
            &d("shape.csv"),
            &d("shape-playback.csv"),
            "--model",
            model,
            "--seed",
            "1",
            "--json",
        ],
        &dir,
    );
    assert_eq!(play["motions"], 7, "the shape's 7 drawings: {play}");

    let rec = record_playback(m, Series::E, &dir.join("shape-playback.csv"), 5, T, &dir);
    assert_eq!(rec["report"]["episodes"], 5, "{rec}");
    let demos = learner::io::demos::load(&dir.join("rec/demos.npz")).unwrap();
    assert_eq!((demos.count, demos.horizon, demos.model), (5, T, m));
    // The whole drawing was recorded, not a reach: every demonstration's path is several
    // times longer than the straight line from its start to its end, and ends at the shape's
    // end (the model's default goal) within the recorder's resolution.
    let layout = StateLayout::REACH3;
    let paths = tool_paths(&demos.states, &layout, T, &demos.goal);
    for (i, p) in paths.iter().enumerate() {
        let length: f64 = p.windows(2).map(|w| dist(&w[0], &w[1])).sum();
        let chord = dist(&p[0], &p[T - 1]);
        assert!(
            length > 2.0 * chord && length > 0.3,
            "demonstration {i}: path {length} m, start to end {chord} m"
        );
    }
    assert!(
        dist(&demos.goal, &m.default_goal()) < 0.005,
        "goal {:?}",
        demos.goal
    );
    let spread = imitation::iteration_log::demo_spread(&demos)
        .unwrap()
        .rmse_m;

    // LQR+GAIfO with the motion's settings, in process.
    let cfg = write_config(
        &dir,
        "motion.toml",
        &format!("seed = 1\n[sim]\nmodel = \"{model}\"\n[path]\ntracking_weight = 0.1\n"),
    );
    let train = train_recorded(&dir, &cfg, ITERATIONS);
    assert_eq!(train["iterations"], ITERATIONS);
    assert!(
        train["path_verdict"].is_string(),
        "a motion's summary: {train}"
    );
    let (table, _) = learner::io::table::load_table(
        &dir.join(format!("train/iter_{:03}_table.npz", ITERATIONS - 1)),
        &ur5_shared::GainBounds::default(),
    )
    .unwrap();

    // The last iteration's table over RTDE: its tool path against the demonstrations' mean.
    let episode = run_over_rtde(m, &demos, &table, &dir, "teach-shape");
    assert_eq!(episode.len(), T, "every step of the noise-free episode");
    let states: Vec<f64> = episode
        .iter()
        .flat_map(|s| s.s[..layout.dx()].iter().copied())
        .collect();
    let path = &tool_paths(&states, &layout, T, &demos.goal)[0];
    let refs: Vec<&[Point]> = paths.iter().map(Vec::as_slice).collect();
    let over_rtde = rmse(path, &mean_path(&refs).unwrap()).unwrap();
    let end = dist(&path[T - 1], &demos.goal);
    let ratio = over_rtde / spread;
    eprintln!(
        "teach a shape: {SHAPE} recorded 5 times, spread {spread:.4} m; LQR+GAIfO ({ITERATIONS} \
         iterations) in the learner's sim: path RMSE {} m ({}); over RTDE: path RMSE \
         {over_rtde:.4} m = {ratio:.2} × the spread, final distance {end:.4} m",
        train["path_rmse_m"], train["path_verdict"]
    );
    assert!(
        ratio <= 2.0,
        "over RTDE the path RMSE {over_rtde} m is {ratio:.2} × the demonstrations' spread"
    );
    assert!(end <= 0.01, "final distance over RTDE {end} m");
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}

fn dist(a: &Point, b: &Point) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}
