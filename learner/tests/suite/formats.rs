//! The file formats at six joints and a pose (dX = 30, dU = 6): demonstrations as CSV and
//! LeRobot datasets, a UR arm's LeRobot recording of six joint positions, episodes and the
//! MCAP export each round-trip with their dimensions; a file of another task's dimensions than
//! the run's is refused, naming both, in every format; `--goal-pose` on the command line.

use crate::common;

use std::path::{Path, PathBuf};

use super::six_joints::{pose_demos, pose_task, sim, POSE};
use common::{learner, learner_output};
use imitation::rollout::Episode;
use learner::io::episode::{load_episode, save_episode, EpisodeOrigin};
use learner::io::foreign;
use learner::io::lerobot;
use learner::io::run_mcap::{write_run_mcap, RunMcap};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::{StateLayout, UrModel};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("formats-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A synthetic episode of `layout`: every number different.
fn episode(layout: StateLayout, t: usize) -> Episode {
    Episode {
        layout,
        x: (0..t * layout.dx()).map(|i| i as f64 * 1e-3).collect(),
        u: (0..t * layout.du()).map(|i| -(i as f64) * 1e-2).collect(),
        u_policy: (0..t * layout.du()).map(|i| i as f64 * 1e-2).collect(),
        eps: Vec::new(),
        noisy: true,
    }
}

fn origin(episode: u64) -> EpisodeOrigin {
    EpisodeOrigin {
        table_version: 1,
        table_epoch: 0,
        episode,
        seed: 3,
    }
}

/// Asserts that `e` names the dimensions of both sides: the pose task's and the point task's.
fn names_both(e: &str) {
    assert!(
        e.contains("dX = 30, dU = 6") && e.contains("dX = 12, dU = 3"),
        "{e}"
    );
}

#[test]
fn pose_demonstrations_round_trip_through_csv_and_lerobot_with_their_layout() {
    let dir = tmp("roundtrip");
    let demos = pose_demos(10);
    let traj = foreign::from_demos(&demos);
    assert_eq!(traj.layout, StateLayout::POSE6);
    lerobot::export(&traj, &dir.join("lerobot")).unwrap();
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("lerobot/meta/info.json")).unwrap())
            .unwrap();
    let state = &info["features"]["observation.state"];
    assert_eq!(state["shape"], serde_json::json!([30]));
    assert_eq!(
        state["names"],
        serde_json::json!(StateLayout::POSE6.state_names())
    );
    assert_eq!(info["features"]["action"]["shape"], serde_json::json!([6]));
    assert_eq!(info["ur5_task"]["goal_pose"], serde_json::json!(POSE));
    let back = lerobot::import(&dir.join("lerobot")).unwrap();
    // The states bit for bit, the task with its goal pose (the reader takes no actions).
    let back = lerobot::Trajectories {
        actions: traj.actions.clone(),
        ..back
    };
    assert_eq!(back, traj);

    // CSV: the header names the 30 states; read back, the layout and states are the same.
    let csv = dir.join("d.csv");
    foreign::write_csv(&traj, &csv).unwrap();
    let header = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    assert!(header.ends_with("point2_vel_z") && header.contains(",q_wrist_3,"));
    let c = foreign::read_csv(&csv).unwrap();
    assert_eq!(c.layout, StateLayout::POSE6);
    assert_eq!(c.states, demos.states);
    // A CSV notes no task: the goal pose is derived from the first frame's three tool points.
    let d = learner::io::demos::load_checked(&csv, &sim()).unwrap();
    assert_eq!(d.layout(), StateLayout::POSE6);
    let derived = d.goal_pose.unwrap();
    for k in 0..6 {
        assert!((derived[k] - POSE[k]).abs() < 1e-4, "{derived:?}");
    }
    // The first frame's angles, as the arm (single precision) measured them.
    for (a, b) in d.start_q.iter().zip(demos.start_q.iter()) {
        assert!((a - b).abs() < 1e-6, "{:?}", d.start_q);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Each format refuses a file made for another task's dimensions than the run's, naming both.
#[test]
fn a_file_of_another_tasks_dimensions_is_refused_naming_both_in_every_format() {
    let dir = tmp("refused");
    // Demonstrations `.npz`: against the run's layout (`learner train --goal-pose` below).
    let pose = pose_demos(10);
    let npz = dir.join("pose.npz");
    learner::io::demos::save(&pose, &npz).unwrap();
    let e = learner::io::demos::check_run_layout(&pose, &StateLayout::REACH3, &npz).unwrap_err();
    let e = learner::error::line(&e);
    names_both(&e);
    assert!(e.contains("pose.npz"), "{e}");

    // LeRobot: a noted pose task over states of the point task's width.
    let three = common::short_expert(10, 3);
    let run = learner::run::expert(&three, |_| {}).unwrap();
    let reach = learner::run::demos(&three, &run).unwrap();
    let mut traj = foreign::from_demos(&reach);
    traj.task.as_mut().unwrap().goal_pose = Some(POSE);
    lerobot::export(&traj, &dir.join("mixed")).unwrap();
    let e = lerobot::import(&dir.join("mixed")).unwrap_err().to_string();
    assert!(
        e.contains("ur5_task") && e.contains("a goal pose") && e.contains("dX = 12"),
        "{e}"
    );

    // CSV: state columns of no task.
    let csv = dir.join("eleven.csv");
    let mut text = String::from("episode,time_s");
    for n in &StateLayout::REACH3.state_names()[..11] {
        text += &format!(",{n}");
    }
    std::fs::write(&csv, text + "\n").unwrap();
    let e = learner::error::line(&foreign::read_csv(&csv).unwrap_err());
    assert!(
        e.contains("11 state columns") && e.contains("dX = 12"),
        "{e}"
    );

    // Episodes: one file of the pose task among the point task's.
    let eps = dir.join("episodes");
    std::fs::create_dir_all(&eps).unwrap();
    let point = TaskConfig {
        horizon: 4,
        ..TaskConfig::default()
    };
    save_episode(
        &eps.join("000001.npz"),
        &episode(StateLayout::REACH3, 4),
        &origin(0),
        &point,
    )
    .unwrap();
    save_episode(
        &eps.join("000002.npz"),
        &episode(StateLayout::POSE6, 4),
        &origin(1),
        &pose_task(4),
    )
    .unwrap();
    let e = learner::error::line(&foreign::from_episodes(&eps).unwrap_err());
    names_both(&e);
    assert!(e.contains("000002.npz"), "{e}");

    // MCAP: a file of the point task's run refuses an episode of the pose task.
    let mut m = RunMcap::create(&dir.join("run.mcap"), StateLayout::REACH3).unwrap();
    let e = m
        .episode(
            &eps.join("000002.npz"),
            &episode(StateLayout::POSE6, 4),
            &origin(1),
            &pose_task(4),
        )
        .unwrap_err();
    names_both(&learner::error::line(&e));

    // The command line: demonstrations of the point task for a run of a pose goal, in each
    // format `--demos` takes.
    let reach_npz = dir.join("reach.npz");
    learner::io::demos::save(&reach, &reach_npz).unwrap();
    let reach_csv = dir.join("reach.csv");
    foreign::write_csv(&foreign::from_demos(&reach), &reach_csv).unwrap();
    let reach_lerobot = dir.join("reach_lerobot");
    lerobot::export(&foreign::from_demos(&reach), &reach_lerobot).unwrap();
    // A pose the UR5 reaches: its tool's at q = (0.293, −1.379, 2.092, −1.9, 1.3, 0.4) rad.
    let kin =
        ur5_shared::kinematics::UrKinematics::new(UrModel::Ur5, SimConfig::default().ee_offset);
    let reachable =
        ur5_shared::pose::ur_pose(&kin.tool_pose(&[0.293, -1.379, 2.092, -1.9, 1.3, 0.4]));
    let goal = reachable.map(|v| v.to_string()).join(",");
    let goal = goal.as_str();
    for demos in [&reach_npz, &reach_csv, &reach_lerobot] {
        let (ok, err) = learner(&[
            "train",
            "--goal-pose",
            goal,
            "--demos",
            demos.to_str().unwrap(),
            "--out",
            dir.join("run").to_str().unwrap(),
        ]);
        assert!(!ok, "{demos:?}");
        names_both(&err);
        assert!(
            err.contains(demos.file_name().unwrap().to_str().unwrap()),
            "{err}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn pose_episodes_and_their_mcap_export_carry_six_joints_and_three_points() {
    let dir = tmp("mcap");
    let task = pose_task(5);
    let eps = dir.join("run/episodes");
    std::fs::create_dir_all(&eps).unwrap();
    for k in 0..2 {
        let path = eps.join(format!("00000{}_e{k:06}_v0001.npz", k + 1));
        let ep = episode(StateLayout::POSE6, 5);
        save_episode(&path, &ep, &origin(k), &task).unwrap();
        let (back, o) = load_episode(&path).unwrap();
        assert_eq!((back, o), (ep, origin(k)));
        assert_eq!(
            learner::io::episode::load_episode_task(&path).unwrap(),
            task
        );
    }
    let file = dir.join("run.mcap");
    let c = write_run_mcap(&dir.join("run"), &file).unwrap();
    assert_eq!((c.episodes, c.messages["/state"]), (2, 10));
    let bytes = std::fs::read(&file).unwrap();
    let mut seen = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        let len = |k: &str| v[k].as_array().map_or(0, |a| a.len());
        match m.channel.topic.as_str() {
            "/joint_states" => {
                assert_eq!((len("name"), len("position"), len("velocity")), (6, 6, 6));
                assert_eq!(v["name"][5], "wrist_3_joint");
            }
            "/state" => {
                assert_eq!((len("q"), len("qd")), (6, 6));
                let t = v["t"].as_u64().unwrap() as usize;
                let s = &episode(StateLayout::POSE6, 5).x[t * 30..(t + 1) * 30];
                assert_eq!(v["point2_vel"], serde_json::json!(&s[27..30]));
                assert_eq!(v["point1_minus_target"], serde_json::json!(&s[15..18]));
                assert!(v.get("ee_minus_goal").is_none());
            }
            "/action" => assert_eq!((len("executed"), len("policy")), (6, 6)),
            "/episode" => {
                assert!(v["final_orientation_error_deg"]
                    .as_f64()
                    .unwrap()
                    .is_finite());
                seen += 1;
            }
            _ => {}
        }
        let schema = m.channel.schema.as_ref().unwrap();
        let s: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        if m.channel.topic == "/state" {
            assert_eq!(s["properties"]["q"]["maxItems"], 6);
            assert!(s["properties"]["point2_vel"].is_object());
        }
    }
    assert_eq!(seen, 2);
    std::fs::remove_dir_all(&dir).ok();
}

/// Writes a LeRobot dataset as a UR arm's recording elsewhere stores it: `observation.state`
/// the six joint positions (float32), `fps` 10, no task and no model noted.
fn write_joint_positions(dir: &Path, positions: &[f64], horizon: usize) {
    let rec = lerobot::JointRecording {
        positions: positions.to_vec(),
        count: positions.len() / 6 / horizon,
        horizon,
        dt: 0.1,
        model: None,
    };
    // Our exporter's layout with a 6-wide state: the frames as another tool writes them.
    let traj = lerobot::Trajectories {
        layout: StateLayout::REACH3,
        states: vec![0.0; rec.count * horizon * 12],
        actions: None,
        count: rec.count,
        horizon,
        dt: 0.1,
        task: None,
        model: None,
    };
    lerobot::export(&traj, dir).unwrap();
    // Replace the state column by the joint positions.
    let info_path = dir.join("meta/info.json");
    let mut info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&info_path).unwrap()).unwrap();
    info["features"]["observation.state"] = serde_json::json!({"dtype": "float32",
        "shape": [6], "names": ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]});
    info["robot_type"] = serde_json::json!("ur5e");
    std::fs::write(&info_path, info.to_string()).unwrap();
    crate::dataset::write_foreign_width(dir, positions, horizon, 6);
}

#[test]
fn a_ur_recordings_joint_positions_import_as_the_whole_arm_and_a_pose() {
    let dir = tmp("ur-recording");
    let demos = pose_demos(10);
    let l = demos.layout();
    let positions: Vec<f64> = (0..demos.count)
        .flat_map(|d| (0..demos.horizon).map(move |t| (d, t)))
        .flat_map(|(d, t)| demos.state(d, t)[l.q()].to_vec())
        .collect();
    write_joint_positions(&dir, &positions, demos.horizon);
    assert_eq!(lerobot::state_width(&dir).unwrap(), 6);
    let d = learner::io::demos::load_checked(&dir, &sim()).unwrap();
    assert_eq!(d.layout(), StateLayout::POSE6);
    assert_eq!((d.count, d.horizon, d.dt), (2, 10, 0.1));
    // The goal pose: the mean of the last tool poses, so the episodes end near it.
    let kin = ur5_shared::kinematics::UrKinematics::new(UrModel::Ur5e, sim().ee_offset);
    let task = d.task().unwrap();
    for e in 0..d.count {
        let s = d.state(e, d.horizon - 1);
        let q: [f64; 6] = s[l.q()].try_into().unwrap();
        let mut pts = [[0.0; 3]; 3];
        ur5_shared::pose::tool_points(&kin.tool_pose(&q), task.tool_offsets(), &mut pts);
        for (i, target) in task.targets().iter().enumerate() {
            for k in 0..3 {
                // The state's point minus target is the forward kinematics minus the target.
                let fk = s[l.point(i)][k] + target[k];
                assert!((fk - pts[i][k]).abs() < 1e-6, "{fk} vs {:?}", pts[i]);
            }
        }
        assert!(d.goal_pose.is_some());
    }
    // Velocities: central differences of the (float32) positions.
    let (a, b) = (d.state(0, 2), d.state(0, 4));
    let qd = d.state(0, 3)[l.qd()][1];
    assert!((qd - (b[1] - a[1]) / 0.2).abs() < 1e-9, "{qd}");
    // Any other width is refused naming it.
    std::fs::remove_dir_all(&dir).unwrap();
    std::fs::create_dir_all(&dir).unwrap();
    write_joint_positions(&dir, &positions, demos.horizon);
    let info_path = dir.join("meta/info.json");
    let text = std::fs::read_to_string(&info_path).unwrap();
    std::fs::write(&info_path, text.replace("[6]", "[7]")).unwrap();
    let e = learner::error::line(&learner::io::demos::load_checked(&dir, &sim()).unwrap_err());
    assert!(e.contains("shape [7]") && e.contains("[30]"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn goal_pose_on_the_command_line_makes_a_pose_task_and_bad_input_is_named() {
    let dir = tmp("goal-pose");
    let out = dir.join("expert");
    let cfg = dir.join("expert.toml");
    std::fs::write(
        &cfg,
        "iterations = 1\nrandom_episodes = 2\ndemos = 2\n[task]\nhorizon = 10\n[sim]\nmodel = \"ur5e\"\n",
    )
    .unwrap();
    let pose = POSE.map(|v| v.to_string()).join(",");
    let (ok, stdout, err) = learner_output(&[
        "expert",
        "--goal-pose",
        &pose,
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(ok, "{err}");
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert!(
        line["runs"][0]["final_orientation_error_deg"].is_number(),
        "{line}"
    );
    let d = learner::io::demos::load(&out.join("demos.npz")).unwrap();
    assert_eq!(d.layout(), StateLayout::POSE6);
    assert_eq!(d.goal_pose, Some(POSE));
    assert_eq!(d.goal, [POSE[0], POSE[1], POSE[2]]);

    let bad = |goal: &str, config: Option<&Path>| {
        let mut args = vec![
            "expert",
            "--goal-pose",
            goal,
            "--out",
            out.to_str().unwrap(),
        ];
        if let Some(c) = config {
            args.extend(["--config", c.to_str().unwrap()]);
        }
        let (ok, err) = learner(&args);
        assert!(!ok, "{goal}");
        err
    };
    let e = bad("0.1,0.2,0.3", None);
    assert!(
        e.contains("expected 6 comma-separated numbers, got 3"),
        "{e}"
    );
    let e = bad("0.1,0.2,0.3,NaN,0,0", None);
    assert!(e.contains("finite"), "{e}");
    let e = bad("2.5,0,0.3,0,0,0", None);
    assert!(e.contains("out of the ur5's reach"), "{e}");
    // A config that says three joints: a pose needs the wrist.
    let three = dir.join("three.toml");
    std::fs::write(&three, "[task]\njoints = 3\n").unwrap();
    let e = bad(&pose, Some(&three));
    assert!(e.contains("task.joints = 6"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
