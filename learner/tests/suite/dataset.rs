//! Demonstrations out and in (docs/design.md §4.12): LeRobot v3.0 export round trip,
//! CSV round trip, clear errors on a missing or wrong-sized state, a dataset made without our
//! exporter trains, and the committed pyarrow-made fixture loads and passes the arm's checks.

use crate::common;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use common::{learner, learner_output, short_expert};

use imitation::demos::Demos;
use imitation::expert::ExpertConfig;
use imitation::gaifo::GaifoConfig;
use learner::io::foreign;
use learner::io::lerobot;
use parquet::basic::{Compression, ConvertedType, LogicalType, Repetition, Type as Physical};
use parquet::data_type::{FloatType, Int32Type, Int64Type};
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::{DX, STATE_NAMES};

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("dataset-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Demonstrations of a short task (T = 10) from a 3-iteration expert: real states of the arm
/// (after 1 iteration its cost is still above the random policy's, demonstrations the
/// arm's checks refuse). Its C_random is measured with the default settings and seed, as a
/// derived one is.
fn recorded_demos() -> Demos {
    let cfg = ExpertConfig {
        random_episodes: ExpertConfig::default().random_episodes,
        ..short_expert(10, 3)
    };
    let run = learner::run::expert(&cfg, |_| {}).unwrap();
    learner::run::demos(&cfg, &run).unwrap()
}

/// Synthetic demonstrations: every state a different number, not from the arm.
fn synthetic() -> Demos {
    let (d, t) = (3, 7);
    Demos {
        states: (0..d * t * DX)
            .map(|i| (i as f64).sqrt() * 0.1 - 0.7)
            .collect(),
        actions: (0..d * t * 3).map(|i| i as f64 * 1e-3).collect(),
        model: ur5_shared::UrModel::Ur5,
        count: d,
        horizon: t,
        goal: [-0.4, -0.2, 0.3],
        goal_pose: None,
        tool_points: ur5_shared::config::DEFAULT_TOOL_POINTS,
        start_q: [0.0, -2.0, 2.4].into(),
        dt: 0.1,
        seed: 4,
        cost_random: 20.5,
        cost_expert: 3.25,
    }
}

#[test]
fn lerobot_export_then_import_gives_the_same_states_and_task() {
    let dir = scratch("roundtrip");
    let demos = synthetic();
    let traj = foreign::from_demos(&demos);
    lerobot::export(&traj, &dir).unwrap();
    for f in [
        "meta/info.json",
        "meta/stats.json",
        "meta/tasks.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "data/chunk-000/file-000.parquet",
    ] {
        assert!(dir.join(f).is_file(), "{f} written");
    }
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta/info.json")).unwrap())
            .unwrap();
    assert_eq!(info["codebase_version"], "v3.0");
    assert_eq!(info["fps"], 10);
    assert_eq!(info["total_frames"], 21);
    assert_eq!(
        info["features"]["observation.state"]["names"],
        serde_json::json!(STATE_NAMES)
    );
    assert_eq!(info["features"]["action"]["shape"], serde_json::json!([3]));
    let back = lerobot::import(&dir).unwrap();
    assert_eq!(back.states, demos.states, "bit for bit");
    assert_eq!((back.count, back.horizon), (3, 7));
    assert_eq!(back.dt, 0.1);
    assert_eq!(back.task, traj.task);
    // CSV: the same states.
    let csv = dir.join("d.csv");
    foreign::write_csv(&traj, &csv).unwrap();
    let c = foreign::read_csv(&csv).unwrap();
    assert_eq!(c.states, demos.states);
    assert_eq!((c.count, c.horizon, c.dt), (3, 7, 0.1));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_missing_or_wrong_sized_state_is_an_error_naming_the_feature() {
    let dir = scratch("bad");
    lerobot::export(&foreign::from_demos(&synthetic()), &dir).unwrap();
    let info_path = dir.join("meta/info.json");
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&info_path).unwrap()).unwrap();
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut v = info.clone();
        f(&mut v);
        std::fs::write(&info_path, v.to_string()).unwrap();
        lerobot::import(&dir).unwrap_err().to_string()
    };
    let e = edit(&|v| {
        v["features"]
            .as_object_mut()
            .unwrap()
            .remove("observation.state");
    });
    assert!(
        e.contains("`observation.state`") && e.contains("missing"),
        "{e}"
    );
    let e = edit(&|v| v["features"]["observation.state"]["shape"] = serde_json::json!([11]));
    assert!(
        e.contains("`observation.state`") && e.contains("shape [11], expected [12]"),
        "{e}"
    );
    // The data file's rows of another width.
    std::fs::write(&info_path, info.to_string()).unwrap();
    let mut d = synthetic();
    d.states.truncate(d.count * d.horizon * DX);
    write_foreign(&dir, &d.states, d.horizon, 11);
    let e = lerobot::import(&dir).unwrap_err().to_string();
    assert!(
        e.contains("`observation.state`") && e.contains("11 entries"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Writes `dir/data/chunk-000/file-000.parquet` as another tool might: float32 states in
/// `width`-wide optional lists, snappy-compressed, the index columns first, two row groups;
/// and a minimal `meta/info.json` without our `ur5_task`.
fn write_foreign(dir: &Path, states: &[f64], horizon: usize, width: usize) {
    write_foreign_indexed(dir, states, horizon, width, Index::I64);
}

/// The integer type of the index columns (`episode_index`, `frame_index`).
#[derive(Clone, Copy, Debug)]
enum Index {
    I64,
    U64,
    I8,
}

/// [`write_foreign`] with index columns of type `index`.
fn write_foreign_indexed(dir: &Path, states: &[f64], horizon: usize, width: usize, index: Index) {
    write_frames(dir, states, DX, horizon, width, index);
}

/// [`write_foreign`] of frames `width` wide (`values`: (D, T, width)), whatever a task's dX.
pub fn write_foreign_width(dir: &Path, values: &[f64], horizon: usize, width: usize) {
    write_frames(dir, values, width, horizon, width, Index::I64);
}

/// [`write_foreign_indexed`] of frames that are `stride` apart in `states`.
fn write_frames(
    dir: &Path,
    states: &[f64],
    stride: usize,
    horizon: usize,
    width: usize,
    index: Index,
) {
    let path = dir.join("data/chunk-000/file-000.parquet");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let int = |n: &str| {
        let (physical, converted) = match index {
            Index::I64 => (Physical::INT64, ConvertedType::NONE),
            Index::U64 => (Physical::INT64, ConvertedType::UINT_64),
            Index::I8 => (Physical::INT32, ConvertedType::INT_8),
        };
        Arc::new(
            Type::primitive_type_builder(n, physical)
                .with_repetition(Repetition::OPTIONAL)
                .with_converted_type(converted)
                .build()
                .unwrap(),
        )
    };
    let element = Type::primitive_type_builder("element", Physical::FLOAT)
        .with_repetition(Repetition::OPTIONAL)
        .build()
        .unwrap();
    let list = Type::group_type_builder("list")
        .with_repetition(Repetition::REPEATED)
        .with_fields(vec![Arc::new(element)])
        .build()
        .unwrap();
    let state = Type::group_type_builder("observation.state")
        .with_repetition(Repetition::OPTIONAL)
        .with_logical_type(Some(LogicalType::List))
        .with_fields(vec![Arc::new(list)])
        .build()
        .unwrap();
    let schema = Type::group_type_builder("schema")
        .with_fields(vec![
            int("episode_index"),
            int("frame_index"),
            Arc::new(state),
        ])
        .build()
        .unwrap();
    let props = parquet::file::properties::WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    let mut w = SerializedFileWriter::new(
        std::fs::File::create(&path).unwrap(),
        Arc::new(schema),
        Arc::new(props),
    )
    .unwrap();
    let frames = states.len() / stride;
    // Two row groups: frames split in the middle of an episode.
    for range in [0..frames / 2 + 1, frames / 2 + 1..frames] {
        let mut rg = w.next_row_group().unwrap();
        let n = range.len();
        let ones = vec![1i16; n];
        let e: Vec<i64> = range.clone().map(|i| (i / horizon) as i64).collect();
        let k: Vec<i64> = range.clone().map(|i| (i % horizon) as i64).collect();
        for v in [&e, &k] {
            let mut c = rg.next_column().unwrap().unwrap();
            match index {
                Index::I64 | Index::U64 => {
                    c.typed::<Int64Type>()
                        .write_batch(v, Some(&ones), None)
                        .unwrap();
                }
                Index::I8 => {
                    let v32: Vec<i32> = v.iter().map(|&x| x as i32).collect();
                    c.typed::<Int32Type>()
                        .write_batch(&v32, Some(&ones), None)
                        .unwrap();
                }
            }
            c.close().unwrap();
        }
        let vals: Vec<f32> = range
            .clone()
            .flat_map(|i| (0..width).map(move |j| (i, j)))
            .map(|(i, j)| states.get(i * stride + j).copied().unwrap_or(0.0) as f32)
            .collect();
        let def = vec![3i16; vals.len()];
        let rep: Vec<i16> = (0..vals.len()).map(|i| i16::from(i % width != 0)).collect();
        let mut c = rg.next_column().unwrap().unwrap();
        c.typed::<FloatType>()
            .write_batch(&vals, Some(&def), Some(&rep))
            .unwrap();
        c.close().unwrap();
        rg.close().unwrap();
    }
    w.close().unwrap();
}

#[test]
fn a_dataset_made_without_our_exporter_loads_passes_the_checks_and_trains() {
    let dir = scratch("foreign");
    let demos = recorded_demos();
    write_foreign(&dir, &demos.states, demos.horizon, DX);
    let info = serde_json::json!({
        "codebase_version": "v3.0", "robot_type": null, "fps": 10,
        "features": {"observation.state": {"dtype": "float32", "shape": [12], "names": null}}
    });
    std::fs::create_dir_all(dir.join("meta")).unwrap();
    std::fs::write(dir.join("meta/info.json"), info.to_string()).unwrap();
    let sim = SimConfig::default();
    let d = learner::io::demos::load_checked(&dir, &sim).unwrap();
    assert_eq!(
        (d.count, d.horizon, d.dt),
        (demos.count, demos.horizon, 0.1)
    );
    for (a, b) in d.states.iter().zip(&demos.states) {
        assert_eq!(*a, *b as f32 as f64, "float32 states as written");
    }
    for k in 0..3 {
        assert!(
            (d.goal[k] - demos.goal[k]).abs() < 1e-5,
            "goal derived: {:?}",
            d.goal
        );
        assert!((d.start_q[k] - demos.start_q[k]).abs() < 1e-5);
    }
    assert!((d.cost_expert - demos.cost_expert).abs() < 1e-4 * demos.cost_expert.abs().max(1.0));
    // The random controller's episodes of `learner expert` again, on the derived task.
    assert!(
        (d.cost_random - demos.cost_random).abs() < 1e-4 * demos.cost_random,
        "C_random derived {}, recorded {}",
        d.cost_random,
        demos.cost_random
    );
    let cfg = GaifoConfig {
        iterations: 1,
        ..GaifoConfig::default()
    };
    let logs = learner::run::train(&cfg, d, None, |_| {}).unwrap();
    assert_eq!(logs.len(), 1);
    assert!(logs[0].performance.is_finite() && logs[0].final_distance.is_finite());
    std::fs::remove_dir_all(&dir).ok();
}

/// `learner/tests/data/lerobot_pyarrow/`: a LeRobot v3.0 layout written by pyarrow 26.0.1
/// (`make_fixture.py` beside it) from the first two demonstrations of the default
/// `learner train` run's `expert/demos.npz` (float32 states, snappy, no `ur5_task`).
#[test]
fn the_pyarrow_made_fixture_loads_and_passes_the_arms_checks() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/lerobot_pyarrow");
    let d = learner::io::demos::load_checked(&dir, &SimConfig::default()).unwrap();
    assert_eq!((d.count, d.dt), (2, 0.1));
    assert!(d.cost_random.is_finite() && d.cost_expert.is_finite());
}

#[test]
fn learner_train_takes_a_lerobot_folder_as_demos() {
    let dir = scratch("train-lerobot");
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/lerobot_pyarrow");
    let out = dir.join("run");
    let (ok, err) = learner(&[
        "train",
        "--demos",
        fixture.to_str().unwrap(),
        "--iterations",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("final distance"), "{err}");
    let log = std::fs::read_to_string(out.join("gaifo_log.csv")).unwrap();
    assert_eq!(log.lines().count(), 2, "header and one iteration: {log}");
    std::fs::remove_dir_all(&dir).ok();
}

/// One command for the main job. Without --demos the default expert is
/// trained into OUT/expert and imitated; a folder holding another run is refused before the
/// expert trains.
#[test]
fn learner_train_without_demos_records_them_first_then_imitates() {
    let dir = scratch("main-job");
    let out = dir.join("run");
    let o = out.to_str().unwrap();
    let (ok, err) = learner(&["train", "--iterations", "1", "--out", o]);
    assert!(ok, "{err}");
    assert!(
        err.contains("no --demos: training the default expert"),
        "{err}"
    );
    assert!(
        err.contains("done: normalised performance") && err.contains("final distance"),
        "{err}"
    );
    for f in [
        "expert/demos.npz",
        "expert/expert_table.npz",
        "gaifo_log.csv",
        "iter_001_table.npz",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let m = learner::io::manifest::read(&out).unwrap().unwrap();
    assert!(
        m.demos.ends_with("expert/demos.npz") && m.demos_hash != "-",
        "{m:?}"
    );
    let t0 = std::time::Instant::now();
    let (ok, err) = learner(&["train", "--iterations", "1", "--out", o]);
    assert!(!ok && err.contains("--force"), "{err}");
    assert!(
        !err.contains("training the default expert"),
        "refused first: {err}"
    );
    assert!(t0.elapsed().as_secs_f64() < 5.0);
    std::fs::remove_dir_all(&dir).ok();
}

/// Recorded episodes (`learner serve`'s files) export with their executed actions and task.
#[test]
fn recorded_episodes_export_with_their_actions() {
    use imitation::rollout::Episode;
    use learner::io::episode::{save_episode, EpisodeOrigin};
    let dir = scratch("episodes");
    let eps = dir.join("episodes");
    let task = ur5_shared::config::TaskConfig {
        horizon: 4,
        ..Default::default()
    };
    let mut states = Vec::new();
    for k in 0..3u64 {
        let ep = Episode {
            layout: ur5_shared::StateLayout::REACH3,
            x: (0..4 * DX)
                .map(|i| (i as f64 + 100.0 * k as f64) * 0.01)
                .collect(),
            u: (0..4 * 3).map(|i| i as f64 - k as f64).collect(),
            u_policy: vec![0.0; 12],
            eps: Vec::new(),
            noisy: k > 0,
        };
        states.extend_from_slice(&ep.x);
        let origin = EpisodeOrigin {
            table_version: 1,
            table_epoch: 0,
            episode: k,
            seed: 7,
        };
        save_episode(&eps.join(format!("{k:06}.npz")), &ep, &origin, &task).unwrap();
    }
    let traj = foreign::from_episodes(&eps).unwrap();
    assert_eq!((traj.count, traj.horizon), (3, 4));
    assert_eq!(
        traj.actions.as_ref().unwrap()[12..15],
        [0.0, 1.0, 2.0].map(|v| v - 1.0)
    );
    let out = dir.join("lerobot");
    lerobot::export(&traj, &out).unwrap();
    let back = lerobot::import(&out).unwrap();
    assert_eq!(back.states, states);
    let m = back.task.unwrap();
    assert_eq!((m.goal, m.start_q, m.seed), (task.goal, task.start_q, 7));
    assert_eq!(m.cost_random, None, "episodes do not know C_random");
    std::fs::remove_dir_all(&dir).ok();
}

/// Imported demonstrations get the checks of our own (docs/reliability.md): any integer type of
/// `episode_index`, non-finite values named with the file, demonstration, step and state
/// name, an `fps` that the joint velocities contradict, `cost_random` not above
/// `cost_expert`, and a CSV episode label used twice.
#[test]
fn imported_demonstrations_are_checked_like_our_own() {
    let dir = scratch("checked");
    let demos = recorded_demos();
    let sim = SimConfig::default();
    let info = |fps: f64| {
        serde_json::json!({
            "codebase_version": "v3.0", "robot_type": null, "fps": fps,
            "features": {"observation.state": {"dtype": "float32", "shape": [12], "names": null}}
        })
        .to_string()
    };
    let foreign = |tag: &str, states: &[f64], index: Index, fps: f64| {
        let d = dir.join(tag);
        write_foreign_indexed(&d, states, demos.horizon, DX, index);
        std::fs::create_dir_all(d.join("meta")).unwrap();
        std::fs::write(d.join("meta/info.json"), info(fps)).unwrap();
        d
    };
    for (tag, index) in [("u64", Index::U64), ("i8", Index::I8)] {
        let d = foreign(tag, &demos.states, index, 10.0);
        let got = learner::io::demos::load_checked(&d, &sim)
            .unwrap_or_else(|e| panic!("{index:?}: {e:#}"));
        assert_eq!(got.count, demos.count, "{index:?}");
    }
    // Data at 10 Hz said to be at 1 kHz or 20 Hz.
    for fps in [1000.0, 20.0] {
        let d = foreign(&format!("fps{fps}"), &demos.states, Index::I64, fps);
        let e = learner::error::line(&learner::io::demos::load_checked(&d, &sim).unwrap_err());
        assert!(
            e.contains("disagrees with the joint velocities"),
            "{fps}: {e}"
        );
    }
    // NaN and inf in an end-effector velocity (demonstration 1, step 3).
    let ee_vel_x = STATE_NAMES.iter().position(|n| *n == "ee_vel_x").unwrap();
    for bad in [f64::NAN, f64::INFINITY] {
        let mut states = demos.states.clone();
        states[(demos.horizon + 3) * DX + ee_vel_x] = bad;
        let d = foreign("nan", &states, Index::I64, 10.0);
        let e = learner::error::line(&learner::io::demos::load_checked(&d, &sim).unwrap_err());
        let want = format!(
            "states[1, 3]: ee_vel_x = {}: every state value must be finite",
            bad as f32 as f64
        );
        assert!(e.contains(&want), "want {want:?}, got {e}");
        assert!(e.contains(d.to_str().unwrap()), "names the file: {e}");
    }
    // cost_random below cost_expert (our own file layout).
    let npz = dir.join("d.npz");
    let swapped = Demos {
        cost_random: demos.cost_expert,
        cost_expert: demos.cost_random,
        ..demos.clone()
    };
    learner::io::demos::save(&swapped, &npz).unwrap();
    let e = learner::error::line(&learner::io::demos::load_checked(&npz, &sim).unwrap_err());
    assert!(e.contains("the expert's below the random policy's"), "{e}");

    // A CSV whose first episode's label comes back after the second.
    learner::io::demos::save(&demos, &npz).unwrap();
    let csv = dir.join("d.csv");
    let (ok, err) = learner(&[
        "dataset",
        "export",
        "--format",
        "csv",
        npz.to_str().unwrap(),
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let first: Vec<&str> = text.lines().skip(1).take(demos.horizon).collect();
    let again = format!("{text}{}\n", first.join("\n"));
    std::fs::write(&csv, again).unwrap();
    let e = learner::error::line(&learner::io::demos::load_checked(&csv, &sim).unwrap_err());
    let want = format!(
        "row {}: episode 0 again, after other episodes",
        2 * demos.horizon + 2
    );
    assert!(e.contains(&want), "want {want:?}, got {e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A LeRobot dataset's `ur5_task.cost_random` or `cost_expert` edited is refused naming the
/// field, the value and the one the data give; the exported values load unchanged, and a
/// dataset without them has them recomputed.
#[test]
fn a_datasets_edited_task_costs_are_refused() {
    let dir = scratch("costs");
    let demos = recorded_demos();
    let sim = SimConfig::default();
    let traj = foreign::from_demos(&demos);
    let export = |tag: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let d = dir.join(tag);
        lerobot::export(&traj, &d).unwrap();
        let info = d.join("meta/info.json");
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&info).unwrap()).unwrap();
        edit(&mut v["ur5_task"]);
        std::fs::write(&info, v.to_string()).unwrap();
        d
    };
    let same = export("same", &|_| {});
    let got = learner::io::demos::load_checked(&same, &sim).unwrap();
    assert_eq!(
        (got.cost_random, got.cost_expert),
        (demos.cost_random, demos.cost_expert)
    );
    let gone = export("gone", &|t| {
        t["cost_random"] = serde_json::Value::Null;
        t["cost_expert"] = serde_json::Value::Null;
    });
    let got = learner::io::demos::load_checked(&gone, &sim).unwrap();
    // Recomputed: the expert's states' mean cost, the default settings' random cost (those of
    // the demonstrations here).
    assert!((got.cost_expert - demos.cost_expert).abs() < 1e-9 * demos.cost_expert);
    assert_eq!(got.cost_random, demos.cost_random);
    for (field, value) in [
        ("cost_random", 1000.0),
        ("cost_expert", 0.5 * demos.cost_expert),
    ] {
        let d = export(field, &|t| t[field] = serde_json::json!(value));
        let e = learner::error::line(&learner::io::demos::load_checked(&d, &sim).unwrap_err());
        assert!(
            e.contains(&format!("ur5_task.{field} = {value} but ")) && e.contains("recomputed"),
            "{field}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Exports never mix or overwrite: a LeRobot export into a folder holding files, a CSV export
/// onto its input and an MCAP export onto a file of its run are refused, the files untouched.
#[test]
fn exports_never_mix_with_older_files_or_overwrite_their_input() {
    let dir = scratch("exports");
    let npz = dir.join("d.npz");
    common::save_short_demos(&npz, 0);
    let p = |x: &Path| x.to_str().unwrap().to_owned();
    let export = |fmt: &str, input: &Path, out: &Path| {
        learner(&["dataset", "export", "--format", fmt, &p(input), &p(out)])
    };
    let lr = dir.join("lr");
    let (ok, err) = export("lerobot", &npz, &lr);
    assert!(ok, "{err}");
    let info = std::fs::read(lr.join("meta/info.json")).unwrap();
    let (ok, err) = export("lerobot", &npz, &lr);
    assert!(!ok);
    assert!(err.contains("already holds files"), "{err}");
    assert_eq!(std::fs::read(lr.join("meta/info.json")).unwrap(), info);

    let csv = dir.join("d.csv");
    let (ok, err) = export("csv", &npz, &csv);
    assert!(ok, "{err}");
    let text = std::fs::read(&csv).unwrap();
    let (ok, err) = export("csv", &csv, &csv);
    assert!(!ok);
    assert!(err.contains("would overwrite its input"), "{err}");
    assert_eq!(std::fs::read(&csv).unwrap(), text);

    let run = dir.join("run");
    let (ok, err) = learner(&[
        "train",
        "--demos",
        &p(&npz),
        "--iterations",
        "1",
        "--record-episodes",
        "--out",
        &p(&run),
    ]);
    assert!(ok, "{err}");
    let manifest = std::fs::read(run.join("run.json")).unwrap();
    let (ok, err) = export("mcap", &run, &run.join("run.json"));
    assert!(!ok);
    assert!(err.contains("would overwrite its input"), "{err}");
    assert_eq!(std::fs::read(run.join("run.json")).unwrap(), manifest);
    let (ok, err) = export("mcap", &run, &dir.join("run.mcap"));
    assert!(ok, "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A UR5e recording exported to LeRobot names its model (`robot_type`, `ur_model`):
/// `dataset check` checks it on the UR5e, the UR5 refuses it naming both, `train --demos` with
/// a UR5e config trains on it; without the key a dataset is of the configured arm.
#[test]
fn a_ur5e_recording_exported_to_lerobot_checks_and_trains_as_a_ur5e() {
    let dir = scratch("ur5e");
    let m = ur5_shared::UrModel::Ur5e;
    let cfg = ExpertConfig {
        task: TaskConfig {
            horizon: 10,
            ..TaskConfig::for_model(m)
        },
        sim: SimConfig::for_model(m),
        iterations: 3,
        demos: 2,
        ..ExpertConfig::default()
    };
    let run = learner::run::expert(&cfg, |_| {}).unwrap();
    let demos = learner::run::demos(&cfg, &run).unwrap();
    assert_eq!(demos.model, m);
    let npz = dir.join("demos.npz");
    learner::io::demos::save(&demos, &npz).unwrap();
    let lr = dir.join("lr");
    fn s(p: &Path) -> String {
        p.to_str().unwrap().to_owned()
    }
    let (ok, err) = learner(&["dataset", "export", &s(&npz), &s(&lr)]);
    assert!(ok, "{err}");
    let info_path = lr.join("meta/info.json");
    let mut info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&info_path).unwrap()).unwrap();
    assert_eq!(
        (&info["robot_type"], &info["ur_model"]),
        (&"ur5e".into(), &"ur5e".into())
    );
    assert_eq!(lerobot::import(&lr).unwrap().model, Some(m));

    let (ok, out, err) = learner_output(&["dataset", "check", &s(&lr), "--json"]);
    assert!(ok, "{err}");
    let summary: serde_json::Value = serde_json::from_str(out.trim()).expect(&out);
    assert_eq!(
        (
            &summary["model"],
            &summary["count"],
            &summary["model_recorded"]
        ),
        (&"ur5e".into(), &2.into(), &true.into())
    );
    // A CSV names no model: what it is checked against is said to be assumed.
    let csv = dir.join("d.csv");
    let (ok, err) = learner(&["dataset", "export", "--format", "csv", &s(&npz), &s(&csv)]);
    assert!(ok, "{err}");
    let (ok, err) = learner(&["dataset", "check", &s(&csv)]);
    assert!(
        !ok || (err.contains("consistent with the ur5, assumed: the file names no arm model")),
        "{err}"
    );
    let e = learner::error::line(
        &learner::io::demos::load_checked(&lr, &SimConfig::default()).unwrap_err(),
    );
    assert!(
        e.contains("made on a ur5e") && e.contains("arm is a ur5:"),
        "{e}"
    );

    let train_cfg = dir.join("ur5e.toml");
    std::fs::write(&train_cfg, "seed = 1\n[sim]\nmodel = \"ur5e\"\n").unwrap();
    let (ok, err) = learner(&[
        "train",
        "--demos",
        &s(&lr),
        "--config",
        &s(&train_cfg),
        "--iterations",
        "1",
        "--out",
        &s(&dir.join("run")),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("final distance"), "{err}");

    // Without the key (an older export, a dataset made elsewhere): the configured arm's.
    info.as_object_mut().unwrap().remove("ur_model");
    std::fs::write(&info_path, info.to_string()).unwrap();
    assert_eq!(learner::io::demos::model_of(&lr).unwrap(), None);
    let d = learner::io::demos::load_checked(&lr, &SimConfig::for_model(m)).unwrap();
    assert_eq!(d.model, m);
    std::fs::remove_dir_all(&dir).ok();
}
