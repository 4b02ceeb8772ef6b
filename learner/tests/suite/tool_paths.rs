//! Demonstrations as tool paths (docs/design.md §4.17): a CSV file of tool points loads
//! through `--demos` like the other formats, passes the arm's checks, trains, and a sample
//! out of reach is refused naming the file, the episode and the time.

use crate::common::{learner, learner_output};

use std::path::PathBuf;

use ur5_shared::config::SimConfig;
use ur5_shared::kinematics::UrKinematics;

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("toolpaths-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Three strokes of 1 s sampled at 50 Hz (T = 11 at the 0.1 s control period), made by the
/// UR5's forward kinematics of a smooth joint motion; `far` replaces episode 2's sample at
/// t = 0.5 s with a point out of reach.
fn strokes_csv(far: bool) -> String {
    let sim = SimConfig::default();
    let kin = UrKinematics::new(sim.model, sim.ee_offset);
    let mut text = String::from("episode,t,x,y,z\n");
    for e in 0..3 {
        for i in 0..=50 {
            let t = i as f64 * 0.02;
            let s = t * t * (3.0 - 2.0 * t);
            let q = [
                0.0 + 0.3 * s,
                -2.0 + 0.5 * s + 0.02 * e as f64 * (std::f64::consts::PI * t).sin(),
                2.4 - 0.4 * s,
            ];
            let mut p = kin.ee_point(&UrKinematics::six(&q, &sim.wrist_q));
            if far && e == 2 && i == 25 {
                p = [2.0, 0.0, 0.4];
            }
            text += &format!("{e},{t},{},{},{}\n", p[0], p[1], p[2]);
        }
    }
    text
}

#[test]
fn a_tool_path_file_loads_checks_and_trains() {
    let dir = scratch("train");
    let csv = dir.join("strokes.csv");
    std::fs::write(&csv, strokes_csv(false)).unwrap();
    let d = learner::io::demos::load_checked(&csv, &SimConfig::default()).unwrap();
    assert_eq!((d.count, d.horizon, d.dt), (3, 11, 0.1));
    assert!(
        (0..3).all(|j| (d.start_q[j] - [0.0, -2.0, 2.4][j]).abs() < 1e-6),
        "the start through the inverse kinematics: {:?}",
        d.start_q
    );
    let (ok, out, err) = learner_output(&["dataset", "check", "--json", csv.to_str().unwrap()]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["count"], 3);
    // The strokes differ by 0.02 rad of shoulder lift at most, mid-stroke: a spread of a few
    // millimetres, not zero.
    let spread = v["demo_spread_rmse_m"].as_f64().unwrap();
    assert!(spread > 1e-4 && spread < 0.02, "{spread}");
    let run = dir.join("run");
    let (ok, err) = learner(&[
        "train",
        "--demos",
        csv.to_str().unwrap(),
        "--iterations",
        "1",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("final distance"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_sample_out_of_reach_is_refused_naming_file_episode_and_time() {
    let dir = scratch("far");
    let csv = dir.join("far.csv");
    std::fs::write(&csv, strokes_csv(true)).unwrap();
    let e = learner::io::demos::load_checked(&csv, &SimConfig::default()).unwrap_err();
    let msg = learner::error::line(&e);
    assert!(
        msg.contains("far.csv") && msg.contains("episode 2, t = 0.5 s") && msg.contains("reach"),
        "{msg}"
    );
    let (ok, err) = learner(&["dataset", "check", csv.to_str().unwrap()]);
    assert!(!ok && err.contains("episode 2, t = 0.5 s"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A motion's run reports the path first (docs/design.md §5 D39): the verdict and the ratio
/// to the demonstrations' spread on the summary line, `path/spr` on the progress line,
/// `path_ratio` and `path_verdict` in `--json`; it takes the tracking term unless `--config`
/// has a `[path]` table, and then takes that table.
#[test]
fn a_motion_reports_the_path_first_and_takes_the_tracking_term() {
    let dir = scratch("motion");
    let csv = dir.join("strokes.csv");
    std::fs::write(&csv, strokes_csv(false)).unwrap();
    let run = |out: &str, config: Option<&str>| {
        let out = dir.join(out);
        let mut args = vec![
            "train".to_string(),
            "--demos".into(),
            csv.to_str().unwrap().into(),
            "--iterations".into(),
            "2".into(),
            "--json".into(),
            "--out".into(),
            out.to_str().unwrap().into(),
        ];
        if let Some(text) = config {
            let p = dir.join("path.toml");
            std::fs::write(&p, text).unwrap();
            args.extend(["--config".into(), p.to_str().unwrap().into()]);
        }
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, stdout, err) = learner_output(&a);
        assert!(ok, "{err}");
        let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
        (v, err)
    };
    let (v, err) = run("default", None);
    assert!(err.contains("tracking_weight = 0.1"), "{err}");
    assert!(err.contains("path/spr"), "{err}");
    let ratio = v["path_ratio"].as_f64().unwrap();
    let (path, spread) = (
        v["path_rmse_m"].as_f64().unwrap(),
        v["demo_spread_rmse_m"].as_f64().unwrap(),
    );
    assert!((ratio - path / spread).abs() < 1e-12 * ratio, "{v}");
    let verdict = v["path_verdict"].as_str().unwrap();
    let expected = if ratio <= 1.0 {
        "on the path"
    } else if ratio <= 2.0 {
        "near the path"
    } else {
        "off the path"
    };
    assert_eq!(verdict, expected, "{v}");
    let done = err.lines().find(|l| l.starts_with("done: ")).unwrap();
    assert!(
        done.starts_with(&format!("done: {verdict}")) && done.contains("spread"),
        "{done}"
    );
    let (v2, err) = run("paper", Some("[path]\ntracking_weight = 0.0\n"));
    assert!(err.contains("tracking_weight = 0 ("), "{err}");
    assert_ne!(
        v2["path_rmse_m"], v["path_rmse_m"],
        "the tracking term changes the run"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The baselines' front ends (BCO, GAIfO (TD3), the mean path) report a motion's path first
/// as LQR+GAIfO does; MDGPS, whose conditions are reaches, refuses the path's terms with the
/// way out.
#[test]
fn the_baselines_report_a_motions_path_and_mdgps_refuses_its_terms() {
    let dir = scratch("motion-baselines");
    let csv = dir.join("strokes.csv");
    std::fs::write(&csv, strokes_csv(false)).unwrap();
    for algo in ["bco", "gaifo-td3", "replay-mean"] {
        let out = dir.join(algo);
        let (ok, stdout, err) = learner_output(&[
            "train",
            "--algo",
            algo,
            "--demos",
            csv.to_str().unwrap(),
            "--iterations",
            "1",
            "--json",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{algo}: {err}");
        let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
        let ratio = v["path_ratio"].as_f64().unwrap();
        let spread = v["demo_spread_rmse_m"].as_f64().unwrap();
        assert!(
            (ratio - v["path_rmse_m"].as_f64().unwrap() / spread).abs() < 1e-12 * ratio,
            "{algo}: {v}"
        );
        let verdict = v["path_verdict"].as_str().unwrap();
        let done = err.lines().find(|l| l.starts_with("done: ")).unwrap();
        assert!(
            done.starts_with(&format!("done: {verdict}")) && done.contains("spread"),
            "{algo}: {done}"
        );
    }
    let goals = dir.join("goals");
    std::fs::create_dir_all(&goals).unwrap();
    let cfg = dir.join("mdgps.toml");
    std::fs::write(&cfg, "[lqr_gaifo.path]\ntracking_weight = 0.1\n").unwrap();
    let (ok, _, err) = learner_output(&[
        "train",
        "--algo",
        "mdgps",
        "--demos",
        goals.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        dir.join("mdgps").to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("lqr_gaifo.path") && err.contains("--algo lqr-gaifo"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// FNV-1a (64 bits) of the bits of `values`: a digest that changes with any bit of any value.
fn digest<'a>(values: impl IntoIterator<Item = &'a f64>) -> u64 {
    values.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, v| {
        v.to_bits()
            .to_le_bytes()
            .iter()
            .fold(h, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
    })
}

/// The LASA shape `name` placed as `learner dataset lasa` places it by default on `model`
/// (facing the arm, ending at the default goal, 0.2 m, 10 s), tool points alone.
fn lasa_points(name: &str, model: ur5_shared::UrModel) -> Vec<learner::io::tool_path::ToolPath> {
    use learner::io::lasa;
    let placement = lasa::Placement {
        plane: lasa::Plane::Facing,
        end: model.default_goal(),
        size: 0.2,
        duration: 10.0,
        rotation: None,
    };
    lasa::place(&lasa::shape(name).unwrap(), &placement).unwrap()
}

/// Three-joint demonstrations (`--demos`, the control period) and freedrive motions
/// (`dataset playback`, the file's own times) of LASA shapes are bit for bit those of the
/// code before both were solved by one blend-and-solve routine: the digests below were
/// recorded from that code (two solvers, one a caller), and any bit of any joint angle,
/// velocity, tool point, start or goal changes them.
#[test]
fn three_joint_paths_solve_bit_for_bit_as_recorded() {
    use learner::io::tool_path::solve;
    use ur5_shared::layout::StateLayout;
    use ur5_shared::UrModel;
    let mut got = Vec::new();
    for (name, model, dt) in [
        ("Worm", UrModel::Ur5, 0.1),
        ("Sshape", UrModel::Ur10e, 0.05),
    ] {
        let mut sim = SimConfig::for_model(model);
        sim.wrist_q = [-1.4, 1.7, 0.3];
        let paths = lasa_points(name, model);
        let s = solve(&paths, &sim, StateLayout::REACH3, dt).unwrap();
        got.push(digest(s.states.iter().chain(&s.start_q).chain(&s.goal)));
        let motions = learner::playback::motions_of(&paths, &sim).unwrap();
        got.push(digest(
            motions
                .iter()
                .flat_map(|m| m.t.iter().chain(m.q.iter().flatten())),
        ));
    }
    let want: [u64; 4] = [
        0xcd1b3d5b2bb54a4f,
        0xdff3314819394556,
        0xfd75fce2eda0362c,
        0xc88bbfccba3c153f,
    ];
    assert_eq!(got, want, "{got:#x?}");
}
