//! `learner experiment` on tiny configurations: the outputs are produced and well formed,
//! LQR+GAIfO learns, and the results do not depend on the number of worker threads.

use crate::common;

use std::path::{Path, PathBuf};

use common::rows_without_times;
use learner::experiment::{run, ExperimentConfig, ExperimentName};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("learner-exp-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{} is not a PNG",
        path.display()
    );
    assert!(bytes.len() > 10_000, "{} looks empty", path.display());
}

#[test]
fn comparison_outputs_learning_and_thread_independence() {
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Comparison);
    cfg.seeds = 2;
    cfg.iterations = 4;
    cfg.threads = 2;
    // The converged-budget PPO variant with 6 episodes per iteration, to keep the test short.
    cfg.ppo_converged_samples = 6;
    let out2 = tmp("cmp2");
    let (runs, rows) = run(ExperimentName::Comparison, &cfg, &out2, None).unwrap();
    assert_eq!(runs.len(), 6, "3 algorithms x 2 seeds");
    let csv = out2.join("comparison.csv");
    let rows2 = rows_without_times(&csv);
    assert_eq!(rows2.len(), 3 * 2 * 4);
    let converged = rows.iter().find(|r| r.variant == "gaifo-ppo-6ep").unwrap();
    assert_eq!(converged.episodes_per_iteration, 6);
    assert_eq!(converged.to_performance_0_9.seeds, 2);
    let text = std::fs::read_to_string(out2.join("summary.txt")).unwrap();
    assert!(
        text.contains("to threshold") && text.contains("ratio to lqr-gaifo"),
        "{text}"
    );
    // A point task has no orientation measure (the six-joint test below has).
    assert!(!text.contains("orientation"), "{text}");
    assert!(rows.iter().all(|r| r.final_orientation_error_deg.is_none()));
    assert_png(&out2.join("comparison.png"));
    assert!(out2.join("summary.txt").exists() && out2.join("demos.npz").exists());
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out2.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 3);
    assert_eq!(rows.len(), 3);
    let lqr = rows.iter().find(|r| r.variant == "lqr-gaifo").unwrap();
    let (first, last) = (lqr.performance[0].1, lqr.performance.last().unwrap().1);
    eprintln!("LQR+GAIfO mean normalised performance {first:.3} -> {last:.3}");
    assert!(
        last > first + 0.1,
        "LQR+GAIfO should learn: {first:.3} -> {last:.3}"
    );
    for r in &runs {
        assert!(r
            .logs
            .iter()
            .all(|l| l.task_cost.is_finite() && l.performance.is_finite()));
    }

    // The same runs on one thread: identical rows (bar wall times), in the same order.
    cfg.threads = 1;
    let out1 = tmp("cmp1");
    run(
        ExperimentName::Comparison,
        &cfg,
        &out1,
        Some(&out2.join("demos.npz")),
    )
    .unwrap();
    assert_eq!(rows_without_times(&out1.join("comparison.csv")), rows2);
    let _ = std::fs::remove_dir_all(&out1);
    let _ = std::fs::remove_dir_all(&out2);
}

/// The comparison at six joints and a pose goal from a settings file as one writes it
/// (`[expert.task] joints = 6` and a `goal_pose` on the UR5e; `learner experiment comparison
/// --config`): the settings take the model's and the pose task's defaults, every algorithm runs
/// at the task's layout (dX = 30, dU = 6), and the outputs carry the final orientation error: the
/// CSV's last column, a table of the summary, the JSON's fields. Seconds: T = 20, 2 iterations.
#[test]
fn comparison_at_six_joints_reports_the_orientation_error() {
    use ur5_shared::config::SimConfig;
    use ur5_shared::{StateLayout, UrModel};
    let dir = tmp("cmp6");
    std::fs::create_dir_all(&dir).unwrap();
    let settings = dir.join("pose.toml");
    std::fs::write(
        &settings,
        format!(
            "seeds = 1\niterations = 2\nthreads = 1\n\
             algorithms = [\"lqr-gaifo\", \"gaifo-ppo\", \"replay-mean\"]\n\
             [expert]\niterations = 2\nrandom_episodes = 2\ndemos = 2\n\
             [expert.sim]\nmodel = \"ur5e\"\n\
             [expert.task]\njoints = 6\nhorizon = 20\ngoal_pose = {:?}\n\
             [lqr_gaifo.sim]\nmodel = \"ur5e\"\n[gaifo_ppo.sim]\nmodel = \"ur5e\"\n",
            crate::six_joints::POSE
        ),
    )
    .unwrap();
    let cfg: ExperimentConfig = ur5_shared::config::from_toml_file_over(
        &settings,
        ExperimentConfig::defaults(ExperimentName::Comparison),
    )
    .unwrap();
    assert_eq!(cfg.expert.task.layout(), StateLayout::POSE6);
    assert_eq!(cfg.expert.task.goal, [-0.4383, -0.2993, 0.3748]);
    assert_eq!(cfg.expert.sim, SimConfig::for_model(UrModel::Ur5e));
    assert_eq!(cfg.lqr_gaifo.sim, cfg.expert.sim);

    let out = dir.join("out");
    let (ok, err) = common::learner(&[
        "experiment",
        "comparison",
        "--config",
        settings.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let demos = learner::io::demos::load(&out.join("demos.npz")).unwrap();
    assert_eq!(demos.layout(), StateLayout::POSE6);
    let csv = std::fs::read_to_string(out.join("comparison.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        format!(
            "{},{}",
            learner::experiment::csv_header(),
            learner::io::log::ORIENTATION_COLUMN
        )
    );
    let degrees: Vec<f64> = lines
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(degrees.len(), 3 * 2, "3 algorithms x 2 iterations");
    assert!(
        degrees
            .iter()
            .all(|d| d.is_finite() && *d >= 0.0 && *d <= 180.0),
        "{degrees:?}"
    );
    let text = std::fs::read_to_string(out.join("summary.txt")).unwrap();
    assert!(text.contains("\norientation, deg"), "{text}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    for row in json.as_array().unwrap() {
        let o = row["final_orientation_error_deg"].as_array().unwrap();
        assert_eq!(o.len(), 2, "{row}");
        assert!(
            o.iter().all(|p| p[1].as_f64().unwrap().is_finite()),
            "{row}"
        );
        assert!(row["last10_final_orientation_error_deg"][0]
            .as_f64()
            .is_some());
    }
    assert_png(&out.join("comparison.png"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn generalisation_trains_the_square_experts_and_targets_the_centre() {
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Generalisation);
    cfg.seeds = 1;
    cfg.iterations = 3;
    cfg.threads = 2;
    cfg.subset_sizes = vec![2];
    cfg.demos_per_point = 1;
    cfg.expert.iterations = 6;
    let out = tmp("gen");
    let (runs, rows) = run(ExperimentName::Generalisation, &cfg, &out, None).unwrap();
    assert_eq!(runs.len(), 1);
    assert_eq!(rows[0].variant, "2 points");
    for f in ["centre.npz", "point_0.npz", "point_7.npz"] {
        assert!(out.join("experts").join(f).exists(), "{f}");
    }
    let centre = learner::io::demos::load(&out.join("experts/centre.npz")).unwrap();
    assert_eq!(centre.goal, cfg.expert.task.goal);
    assert_eq!(rows_without_times(&out.join("generalisation.csv")).len(), 3);
    assert_png(&out.join("generalisation.png"));
    let p: Vec<f64> = runs[0].logs.iter().map(|l| l.performance).collect();
    eprintln!("generalisation (2 points): {p:?}");
    assert!(p[2] > p[0], "moves towards the centre: {p:?}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn bad_settings_are_refused_with_a_reason() {
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Generalisation);
    cfg.subset_sizes = vec![9];
    let e = run(ExperimentName::Generalisation, &cfg, &tmp("bad"), None).unwrap_err();
    assert!(e.to_string().contains("subset_sizes"), "{e}");
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Comparison);
    cfg.algorithms = vec!["dagger".into()];
    let e = run(ExperimentName::Comparison, &cfg, &tmp("bad2"), None).unwrap_err();
    assert!(e.to_string().contains("dagger"), "{e}");
    // The workspace goals are points: refused for a pose task before anything runs.
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Comparison);
    cfg.expert.task = crate::six_joints::pose_task(20);
    cfg.comparison_workspace_goals = true;
    let e = run(ExperimentName::Comparison, &cfg, &tmp("bad4"), None).unwrap_err();
    assert!(e.to_string().contains("comparison_workspace_goals"), "{e}");
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Ablation);
    cfg.ablation_variants = vec!["default".into(), "no-critic".into()];
    let e = run(ExperimentName::Ablation, &cfg, &tmp("bad3"), None).unwrap_err();
    assert!(e.to_string().contains("no-critic"), "{e}");
}

#[test]
fn ablation_runs_each_variant_and_reports_final_distance() {
    let mut cfg = ExperimentConfig::defaults(ExperimentName::Ablation);
    cfg.seeds = 1;
    cfg.iterations = 3;
    cfg.threads = 2;
    cfg.expert.iterations = 6;
    let out = tmp("ablation");
    let (runs, rows) = run(ExperimentName::Ablation, &cfg, &out, None).unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r.variant.as_str()).collect();
    assert_eq!(
        names,
        [
            "default",
            "no-near-goal",
            "raw-penalty",
            "constant-critic-lr",
            "before-d25"
        ]
    );
    assert_png(&out.join("ablation.png"));
    let text = std::fs::read_to_string(out.join("summary.txt")).unwrap();
    assert!(text.contains("final distance, cm"), "{text}");
    for r in &rows {
        assert_eq!(r.final_distance_m.len(), r.performance.len());
        assert!(r.final_distance_m.iter().all(|d| d.1 > 0.0 && d.1 < 1.0));
    }
    // Every variant executes the same initial controller; the critic settings change the
    // first LQR step, so the second iteration's episode differs from the default's.
    let log = |v: &str, i: usize| &runs.iter().find(|r| r.variant == v).unwrap().logs[i];
    for v in ["raw-penalty", "before-d25"] {
        assert_eq!(log(v, 0).task_cost, log("default", 0).task_cost, "{v}");
        assert_ne!(log(v, 1).task_cost, log("default", 1).task_cost, "{v}");
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// `learner experiment shapes` (docs/design.md §5 D39): shards write each job's file into one
/// folder, the table counts the jobs not done yet, a second run of a finished list runs
/// nothing (and redraws the picture), the sharded jobs equal the unsharded ones, and a job file
/// keeps the tool path its last path RMSE measures.
#[test]
fn shapes_shards_resume_and_tabulate_the_path() {
    let (a, b) = (tmp("shapes-a"), tmp("shapes-b"));
    let cfg_file = tmp("shapes-cfg");
    std::fs::create_dir_all(&cfg_file).unwrap();
    let cfg = cfg_file.join("c.toml");
    std::fs::write(&cfg, "[shapes]\nshapes = [\"Worm\"]\n").unwrap();
    let args = |out: &Path, shard: Option<&str>| {
        let mut v: Vec<String> = [
            "experiment",
            "shapes",
            "--seeds",
            "2",
            "--iterations",
            "2",
            "--threads",
            "1",
            "--json",
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        if let Some(s) = shard {
            v.extend(["--shard".into(), s.into()]);
        }
        v
    };
    let call = |v: Vec<String>| {
        let a: Vec<&str> = v.iter().map(String::as_str).collect();
        let (ok, out, err) = common::learner_output(&a);
        assert!(ok, "{err}");
        (
            serde_json::from_str::<serde_json::Value>(out.trim()).unwrap(),
            err,
        )
    };
    let (v, err) = call(args(&a, Some("1/2")));
    assert_eq!(v["summary"]["jobs_missing"], 1, "{v}");
    assert!(err.contains("1 job(s) of the list not done yet"), "{err}");
    let (v, _) = call(args(&a, Some("2/2")));
    assert_eq!(v["summary"]["jobs_missing"], 0, "{v}");
    let row = &v["summary"]["rows"][0];
    assert_eq!(
        (row["shape"].as_str(), row["seeds"].as_u64()),
        (Some("Worm"), Some(2))
    );
    let (_, err) = call(args(&a, None));
    assert!(
        err.contains("0 to run"),
        "a finished list runs nothing: {err}"
    );
    call(args(&b, None));
    for s in 0..2 {
        let f = format!("runs/Worm_lqr-gaifo_s{s}.json");
        let read = |d: &Path| -> serde_json::Value {
            serde_json::from_slice(&std::fs::read(d.join(&f)).unwrap()).unwrap()
        };
        let (x, y) = (read(&a), read(&b));
        assert_eq!(x["path_rmse_m"], y["path_rmse_m"], "{f}");
        assert_eq!(x["final_distance_m"], y["final_distance_m"], "{f}");
        assert_eq!(x["path_rmse_m"].as_array().unwrap().len(), 2);
    }
    assert!(a.join("demos/Worm.csv").is_file());
    // Each job file keeps its last noise-free tool path: against the drawings' mean path it
    // measures the last path RMSE of the file.
    let demos = learner::io::demos::load_checked(
        &a.join("demos/Worm.csv"),
        &ur5_shared::config::SimConfig::default(),
    )
    .unwrap();
    let paths = imitation::tool_path::tool_paths(
        &demos.states,
        &demos.layout(),
        demos.horizon,
        &demos.goal,
    );
    let refs: Vec<&[imitation::tool_path::Point]> = paths.iter().map(Vec::as_slice).collect();
    let mean = imitation::tool_path::mean_path(&refs).unwrap();
    let job: serde_json::Value =
        serde_json::from_slice(&std::fs::read(a.join("runs/Worm_lqr-gaifo_s1.json")).unwrap())
            .unwrap();
    let kept: Vec<imitation::tool_path::Point> =
        serde_json::from_value(job["path_m"].clone()).unwrap();
    assert_eq!(kept.len(), demos.horizon);
    let last = job["path_rmse_m"][1].as_f64().unwrap();
    let rmse = imitation::tool_path::rmse(&kept, &mean).unwrap();
    assert!((rmse - last).abs() <= 1e-12 * last, "{rmse} against {last}");
    // The picture is drawn from the job files: gone, a run that runs nothing draws it again.
    let png = a.join("shapes_lqr-gaifo.png");
    assert!(png.is_file());
    std::fs::remove_file(&png).unwrap();
    call(args(&a, None));
    assert!(png.is_file(), "redrawn");
    let text = std::fs::read_to_string(a.join("shapes.txt")).unwrap();
    assert!(
        text.contains("Worm") && text.contains("lqr-gaifo"),
        "{text}"
    );
    std::fs::write(&cfg, "[shapes]\nshapes = [\"Wormm\"]\n").unwrap();
    let v = args(&tmp("shapes-c"), None);
    let a2: Vec<&str> = v.iter().map(String::as_str).collect();
    let (ok, _, err) = common::learner_output(&a2);
    assert!(
        !ok && err.contains("Wormm") && err.contains("Worm"),
        "{err}"
    );
    for d in [a, b, cfg_file] {
        std::fs::remove_dir_all(d).ok();
    }
}

/// `learner experiment shapes` with the whole arm (`joints = 6`): the drawings carry the held
/// orientation (the three-joint arm's at the end), become demonstrations of the pose layout,
/// and every job reports the final orientation error and the orientation RMSE along the path,
/// in its file and in the table; a rotation with three joints is refused naming the keys.
#[test]
fn shapes_with_the_whole_arm_hold_the_tool_and_measure_its_orientation() {
    let out = tmp("shapes-six");
    std::fs::create_dir_all(&out).unwrap();
    let cfg = out.join("c.toml");
    std::fs::write(
        &cfg,
        "[shapes]\nshapes = [\"Worm\"]\njoints = 6\n\n[lqr_gaifo.sim]\nmodel = \"ur5e\"\n",
    )
    .unwrap();
    let run = out.join("run");
    let (c, r) = (cfg.to_str().unwrap(), run.to_str().unwrap());
    let args = [
        "experiment",
        "shapes",
        "--seeds",
        "1",
        "--iterations",
        "2",
        "--threads",
        "1",
        "--json",
        "--config",
        c,
        "--out",
        r,
    ];
    let (ok, stdout, err) = common::learner_output(&args);
    assert!(ok, "{err}");
    let csv = std::fs::read_to_string(run.join("demos/Worm.csv")).unwrap();
    assert!(
        csv.starts_with("episode,t,x,y,z,rx,ry,rz\n"),
        "{}",
        &csv[..60]
    );
    let demos = learner::io::demos::load_checked(
        &run.join("demos/Worm.csv"),
        &ur5_shared::config::SimConfig::for_model(ur5_shared::UrModel::Ur5e),
    )
    .unwrap();
    assert_eq!(demos.layout(), ur5_shared::layout::StateLayout::POSE6);
    assert!(demos.goal_pose.is_some());
    let job: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("runs/Worm_lqr-gaifo_s0.json")).unwrap())
            .unwrap();
    let fin = job["final_orientation_error_deg"].as_array().unwrap();
    assert_eq!(fin.len(), 2, "{job}");
    assert!(fin.iter().all(|v| v.as_f64().unwrap() >= 0.0));
    let path_deg = job["orientation_rmse_deg"].as_f64().unwrap();
    assert!(path_deg.is_finite() && path_deg >= 0.0, "{path_deg}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let row = &v["summary"]["rows"][0];
    assert_eq!(
        row["orientation_rmse_mean_deg"].as_f64(),
        Some(path_deg),
        "{row}"
    );
    let text = std::fs::read_to_string(run.join("shapes.txt")).unwrap();
    assert!(text.contains("path_deg m/max"), "{text}");
    std::fs::write(&cfg, "[shapes]\nrotation = [0.0, 3.1, 0.0]\n").unwrap();
    let (ok, _, err) = common::learner_output(&args);
    assert!(
        !ok && err.contains("shapes.rotation") && err.contains("joints"),
        "{err}"
    );
    std::fs::remove_dir_all(&out).ok();
}
