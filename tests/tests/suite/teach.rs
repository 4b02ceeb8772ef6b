//! Teaching by hand, end to end on a UR5e (docs/ur.md, "Teaching by hand"): `hil-sim
//! playback-gen` writes 5 human-like reaches, an in-process ur-sim plays them as freedrive
//! (real time, compressed), `learner record` cuts them from the RTDE stream into
//! demonstrations, `learner train` runs LQR+GAIfO on them on the UR5e model, and the learned
//! table runs over RTDE on a second ur-sim (lockstep) under `rt-controller`: its noise-free
//! episode ends within 1 cm of the demonstrations' goal. The recording runs in compressed
//! real time, so which packages the recorder sees varies from run to run; the demonstrations
//! are resampled by the packages' timestamps and the assertions are on outcomes, not on
//! timing or bits. Waits are bounded only to catch a hang.

use std::path::Path;
use std::time::{Duration, Instant};

use hil_sim::ur_sim::{self, Series, UrSimConfig};
use integration_tests::{
    cleanup_dead_nodes, json_summary, scratch, unique_prefix, write_config, Proc, TestLearner,
};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::msg::StepSample;
use ur5_shared::UrModel;

const LONG: Duration = Duration::from_secs(120);

/// Horizon of the demonstrations (steps of 0.1 s): a reach takes at most 2.5 s.
const T: usize = 50;

/// LQR+GAIfO iterations (the arm-model measurements' count).
const ITERATIONS: usize = 20;

/// `hil-sim playback-gen` writes `motions` human-like reaches (seed `seed`) of model `m` to
/// `dir/reaches.csv`.
pub(crate) fn generate_reaches(m: UrModel, motions: usize, seed: u64, dir: &Path) {
    let out = dir.join("reaches.csv").display().to_string();
    let (n, seed) = (motions.to_string(), seed.to_string());
    let gen = run_ok(
        "hil-sim",
        "playback-gen",
        &[
            "--model",
            m.name(),
            "playback-gen",
            "--motions",
            &n,
            "--seed",
            &seed,
            "--out",
            &out,
        ],
        dir,
    );
    assert_eq!(gen["motions"], motions);
}

pub(crate) fn run_ok(name: &str, label: &str, args: &[&str], dir: &Path) -> serde_json::Value {
    let mut p = Proc::spawn(name, label, args, dir);
    let (code, out) = p.wait(LONG);
    let log = p.log();
    assert_eq!(code, Some(0), "{label}:\n{log}");
    eprintln!("{label}:\n{log}");
    json_summary(&out, &log)
}

#[test]
fn teach_by_hand_record_train_and_run_over_rtde_on_a_ur5e() {
    let m = UrModel::Ur5e;
    let dir = scratch("teach");
    let (demos, spread) = record_played_back(m, Series::E, 5, 1, &dir);

    // LQR+GAIfO on the UR5e model, in process.
    let train_cfg = write_config(&dir, "gaifo.toml", "seed = 1\n[sim]\nmodel = \"ur5e\"\n");
    let train = train_recorded(&dir, &train_cfg, ITERATIONS);
    assert_eq!(train["iterations"], ITERATIONS);
    // The learner's pick: the table of the iteration whose noise-free episode (in the
    // learner's sim) ended closest to the goal; row i ran `iter_{i}_table.npz`.
    let log = std::fs::read_to_string(dir.join("train/gaifo_log.csv")).unwrap();
    let col = log
        .lines()
        .next()
        .unwrap()
        .split(',')
        .position(|c| c == "final_distance_m")
        .unwrap();
    let (best, sim_distance) = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(col).unwrap().parse::<f64>().unwrap())
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap();
    let (table, _) = learner::io::table::load_table(
        &dir.join(format!("train/iter_{best:03}_table.npz")),
        &ur5_shared::GainBounds::default(),
    )
    .unwrap();

    // The learned table over RTDE on a UR5e ur-sim (lockstep), the demonstrations' task.
    let episode = run_over_rtde(m, &demos, &table, &dir, "teach");
    let last = episode.last().expect("the noise-free episode's samples");
    assert_eq!(last.t as usize, T - 1);
    let e = &last.s[ur5_shared::layout::EE_MINUS_GOAL];
    let dist = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    eprintln!(
        "teach: recorded goal spread {spread:.4} m; the table of iteration {best} (of \
         {ITERATIONS}) ends {sim_distance:.4} m from the goal in the learner's sim, {dist:.4} m \
         over RTDE"
    );
    assert!(dist <= 0.01, "final distance over RTDE {dist} m");
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}

/// `learner train` on the recording in `dir/rec/demos.npz` with config `cfg` for `iterations`
/// iterations, into `dir/train`; its `--json` line.
pub(crate) fn train_recorded(dir: &Path, cfg: &str, iterations: usize) -> serde_json::Value {
    let d = |p: &str| dir.join(p).display().to_string();
    let its = iterations.to_string();
    run_ok(
        "learner",
        "train",
        &[
            "train",
            "--demos",
            &d("rec/demos.npz"),
            "--config",
            cfg,
            "--iterations",
            &its,
            "--out",
            &d("train"),
            "--json",
        ],
        dir,
    )
}

/// Runs `table` over RTDE on a ur-sim of model `m` (lockstep) under `rt-controller` on the
/// task of `demos` (its active joints, start pose, goal point or pose, horizon and period), a
/// noisy episode and the noise-free one; checks that the controller ended well and no
/// protective stop happened. Returns the noise-free episode's samples in time order.
pub(crate) fn run_over_rtde(
    m: UrModel,
    demos: &imitation::demos::Demos,
    table: &ur5_shared::GainTable,
    dir: &Path,
    tag: &str,
) -> Vec<StepSample> {
    let run_sim = ur_sim::spawn(
        &TaskConfig::for_model(m),
        &SimConfig::for_model(m),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            // The controller asks the robot's model there (a UR5e: "UR5" on PolyScope 5).
            dashboard_port: Some(0),
            lockstep: true,
            // A six-joint task's servoj moves the wrist too.
            joints: demos.start_q.len(),
            ..UrSimConfig::default()
        },
    )
    .expect("ur-sim");
    let dashboard = run_sim.dashboard_addr.expect("dashboard").port();
    let f = |v: &[f64]| {
        let v: Vec<String> = v.iter().map(|x| x.to_string()).collect();
        format!("[{}]", v.join(", "))
    };
    // A six-joint task names its joints, a pose goal its pose and tool points.
    let mut whole_arm = String::new();
    if demos.start_q.len() == 6 {
        whole_arm.push_str("joints = 6\n");
    }
    if let Some(p) = demos.goal_pose {
        let points: Vec<String> = demos.tool_points.iter().map(|o| f(o)).collect();
        whole_arm.push_str(&format!(
            "goal_pose = {}\ntool_points = [{}]\n",
            f(&p),
            points.join(", ")
        ));
    }
    let ctl_cfg = write_config(
        dir,
        "ctl.toml",
        &format!(
            "seed = 3\nnoisy_episodes = 1\neval_episodes = 1\nmode = \"lockstep\"\n\
             [task]\nhorizon = {}\ndt = {}\nstart_q = {}\ngoal = {}\n{whole_arm}\
             [arm]\nbackend = \"ur\"\n[arm.ur]\nmodel = \"{}\"\nhost = \"127.0.0.1\"\n\
             rtde_port = {}\nsecondary_port = {}\ndashboard_port = {dashboard}\nreverse_port = 0\n\
             receive_timeout_ms = 1000\n",
            demos.horizon,
            demos.dt,
            f(demos.start_q.as_slice()),
            f(&demos.goal),
            m.name(),
            run_sim.rtde_addr.port(),
            run_sim.secondary_addr.port()
        ),
    );
    let prefix = unique_prefix(tag);
    let mut learner = TestLearner::learner_only(&prefix);
    learner.publish(table);
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &[
            "run",
            "--config",
            &ctl_cfg,
            "--prefix",
            &prefix,
            "--json",
            "--episodes",
            "2",
        ],
        dir,
    );
    let t0 = Instant::now();
    while ctl.running() && t0.elapsed() < LONG {
        learner.poll();
        std::thread::sleep(Duration::from_millis(5));
    }
    let (code, _) = ctl.wait(LONG);
    learner.poll();
    assert_eq!(code, Some(0), "controller:\n{}", ctl.log());
    let summary = run_sim.stop();
    assert_eq!(summary.protective_stops, 0, "{summary:?}");
    let mut episode: Vec<StepSample> = learner
        .received
        .into_iter()
        .filter(|s| s.noise == 0)
        .collect();
    episode.sort_by_key(|s| s.t);
    episode.dedup_by_key(|s| s.t);
    episode
}

/// Recording from a CB3 controller (125 Hz, the UR5 of the paper): the recorder takes the
/// arm's rate from the stream and cuts, resamples and checks the taught reaches as on an
/// e-Series arm.
#[test]
fn teach_by_hand_records_from_a_cb3_at_125_hz() {
    record_played_back(UrModel::Ur5, Series::Cb3, 3, 2, &scratch("teach-cb3"));
}

/// `hil-sim playback-gen` writes `motions` human-like reaches (seed `seed`) of model `m`, an
/// in-process ur-sim of `series` plays them as freedrive at 10 times real time, and `learner
/// record` cuts as many demonstrations of T steps from its RTDE stream into `dir/rec`. Checks
/// the recording: the arm's rate taken from the stream, every reach kept, the model named, the
/// end points within 1 cm of each other and of the taught goal, the expert's cost below the
/// random policy's. Returns the demonstrations and the end points' largest distance from their
/// mean (m).
fn record_played_back(
    m: UrModel,
    series: Series,
    motions: usize,
    seed: u64,
    dir: &Path,
) -> (imitation::demos::Demos, f64) {
    generate_reaches(m, motions, seed, dir);

    let rec = record_playback(m, series, &dir.join("reaches.csv"), motions, T, dir);
    let rate = rec["rate_hz"].as_f64().unwrap();
    assert!(
        (rate - 1.0 / series.cycle_s()).abs() < 1.0,
        "the arm's rate from the stream: {rec}"
    );
    let r = &rec["report"];
    assert_eq!(r["episodes"], motions, "{rec}");
    // The goal region is a cube of half side 5 mm: the ends lie within its diagonal.
    let spread = r["goal_spread_max_m"].as_f64().unwrap();
    assert!(spread < 0.01, "{rec}");
    let demos = learner::io::demos::load(&dir.join("rec/demos.npz")).unwrap();
    assert_eq!((demos.count, demos.horizon, demos.model), (motions, T, m));
    let dg = (0..3)
        .map(|k| (demos.goal[k] - m.default_goal()[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        dg < 0.01,
        "the recorded goal {:?} is the taught region's",
        demos.goal
    );
    assert!(demos.cost_expert < demos.cost_random, "{rec}");
    (demos, spread)
}

/// An in-process ur-sim of model `m` and `series` plays the file `playback` as freedrive at 10
/// times real time, and `learner record` cuts `episodes` demonstrations of `horizon` steps
/// from its RTDE stream into `dir/rec`. Returns the recorder's JSON summary.
pub(crate) fn record_playback(
    m: UrModel,
    series: Series,
    playback: &Path,
    episodes: usize,
    horizon: usize,
    dir: &Path,
) -> serde_json::Value {
    record_playback_with(m, series, playback, episodes, horizon, ("", &[]), dir)
}

/// [`record_playback`] with `task` more lines of the recorder's `[task]` table (e.g.
/// `joints = 6`) and `args` more arguments of `learner record` (e.g. `--pose`).
pub(crate) fn record_playback_with(
    m: UrModel,
    series: Series,
    playback: &Path,
    episodes: usize,
    horizon: usize,
    (task, args): (&str, &[&str]),
    dir: &Path,
) -> serde_json::Value {
    let d = |p: &str| dir.join(p).display().to_string();
    let model = m.name();
    // The recorder reads every package it is sent.
    let sim = ur_sim::spawn(
        &TaskConfig::for_model(m),
        &SimConfig::for_model(m),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            series,
            time_compression: 10.0,
            playback: Some(playback.to_owned()),
            // The recorder asks the robot's model there.
            dashboard_port: Some(0),
            ..UrSimConfig::default()
        },
    )
    .expect("ur-sim plays");
    let port = sim.rtde_addr.port().to_string();
    let dashboard = sim.dashboard_addr.expect("dashboard").port().to_string();
    let rec_cfg = write_config(
        dir,
        "record.toml",
        &format!("[task]\nhorizon = {horizon}\n{task}[sim]\nmodel = \"{model}\"\n"),
    );
    let (episodes, out) = (episodes.to_string(), d("rec"));
    let mut argv = vec![
        "record",
        "--ur",
        "127.0.0.1",
        "--rtde-port",
        &port,
        "--dashboard-port",
        &dashboard,
        "--episodes",
        &episodes,
        "--config",
        &rec_cfg,
        "--out",
        &out,
        "--max-time-s",
        "100",
        "--json",
    ];
    argv.extend_from_slice(args);
    let rec = run_ok("learner", "record", &argv, dir);
    sim.stop();
    rec
}
