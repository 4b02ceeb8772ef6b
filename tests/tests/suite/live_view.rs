//! rt-controller's live view (`[live_view]`, docs/design.md §3.13) with the iceoryx2 arm
//! (`hil-sim serve`, real time ×10), read back over DDS by our own ur5-ros2 readers: the goal is
//! the configured one, every end-effector point is one of the learner's samples' (the states
//! the controller acted on), episode and table version advance (version 2 is published once the
//! view has shown episode 2), the joint states name the six UR joints.
//!
//! A ROS domain of its own and topics under a namespace of this process, so neither parallel
//! tests nor a second run of the suite see each other's data. The test waits on what it reads
//! (generous bounds only catch a hang) and asserts on values, never on timing or counts that
//! depend on it.

use std::time::{Duration, Instant};

use integration_tests::{
    cleanup_dead_nodes, reaching_table, scratch, spawn_sim_and_controller, unique_prefix,
    write_config, TestLearner,
};
use rt_controller::config::UR_JOINTS;
use ur5_ros2::{JointState, Message, Network, Node, PointStamped, Reader, TopicQos, UInt64};
use ur5_shared::layout::EE_MINUS_GOAL;

/// ur5_ros2's own tests use 201 and 202, the ros2 backend's 120–125.
const DOMAIN: u16 = 126;
const T: usize = 10;
const LONG: Duration = Duration::from_secs(120);
/// A goal other than the task's default, so that the view cannot show the default by chance.
const GOAL: [f64; 3] = [-0.40, -0.20, 0.30];
const Q_GOAL: [f64; 3] = [0.3, -1.6, 2.0];

#[test]
fn live_view_shows_goal_end_effector_episode_and_table_version() {
    let ns = format!("/lv{}", std::process::id());
    let tag = "it-live-view";
    let prefix = unique_prefix(tag);
    let dir = scratch(tag);
    // The readers exist before the controller, so they are matched early; what is published
    // before matching is lost (volatile), which the waits below allow.
    let node = Node::new(DOMAIN, Network::Loopback).expect("DDS node");
    fn reader<M: Message + 'static>(node: &Node, topic: String) -> Reader<M> {
        node.reader(&topic, TopicQos::reliable(100)).unwrap()
    }
    let mut goal_r = reader::<PointStamped>(&node, format!("{ns}/goal"));
    let mut ee_r = reader::<PointStamped>(&node, format!("{ns}/end_effector"));
    let mut episode_r = reader::<UInt64>(&node, format!("{ns}/episode"));
    let mut version_r = reader::<UInt64>(&node, format!("{ns}/table_version"));
    let mut js_r = reader::<JointState>(&node, format!("{ns}/joint_states"));

    let sim_cfg = write_config(
        &dir,
        "sim.toml",
        &format!("[task]\ndt = 0.1\nhorizon = {T}\n[serve]\nmode = \"real_time\"\ntime_compression = 10.0\nstate_period_s = 0.1\n"),
    );
    let ctl_cfg = write_config(
        &dir,
        "controller.toml",
        &format!(
            "mode = \"real_time\"\npacing = \"arm\"\ntime_compression = 10.0\n\
             [task]\ndt = 0.1\nhorizon = {T}\ngoal = [{}, {}, {}]\n\
             [live_view]\nenabled = true\ndomain_id = {DOMAIN}\nnamespace = \"{ns}\"\n\
             rate_hz = 1000.0\njoint_states = true\njoint_states_topic = \"{ns}/joint_states\"\n",
            GOAL[0], GOAL[1], GOAL[2]
        ),
    );
    let mut learner = TestLearner::learner_only(&prefix);
    learner.publish(&reaching_table(1, T, Q_GOAL, 0.02));
    let (_sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);

    let (mut goals, mut ees, mut episodes, mut versions, mut joint_states) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut v2_published = false;
    let mut v2_seen_at = None;
    let t0 = Instant::now();
    loop {
        learner.poll();
        while let Some(m) = goal_r.take() {
            goals.push(m);
        }
        while let Some(m) = ee_r.take() {
            ees.push(m);
        }
        while let Some(m) = episode_r.take() {
            episodes.push(m.data);
        }
        while let Some(m) = version_r.take() {
            versions.push(m.data);
        }
        while let Some(m) = js_r.take() {
            joint_states.push(m);
        }
        let last_episode = episodes.last().copied().unwrap_or(0);
        if !v2_published && last_episode >= 2 {
            learner.publish(&reaching_table(2, T, Q_GOAL, 0.02));
            v2_published = true;
        }
        // Version 2 shown, then two more episodes.
        if v2_seen_at.is_none() && versions.contains(&2) {
            v2_seen_at = Some(last_episode);
        }
        if v2_seen_at.is_some_and(|e| last_episode >= e + 2) && !ees.is_empty() && !goals.is_empty()
        {
            break;
        }
        assert!(
            ctl.running() && t0.elapsed() < LONG,
            "the view showed episodes {:?}, versions {:?}, {} end-effector points; controller log:\n{}",
            episodes.last(),
            versions.last(),
            ees.len(),
            ctl.log()
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let (j, _) = ctl.terminate_ok(LONG);
    learner.poll();

    // The goal: the configured one, in ur_description's base frame.
    for g in &goals {
        assert_eq!(g.header.frame_id, "base");
        assert_eq!([g.point.x, g.point.y, g.point.z], GOAL);
    }
    // Every end-effector point is that of a state the controller acted on: a sample's
    // (s holds ee − goal; 1e-12 m for the subtraction's rounding).
    let sample_ee: Vec<[f64; 3]> = learner
        .received
        .iter()
        .map(|s| core::array::from_fn(|k| s.s[EE_MINUS_GOAL.start + k] + GOAL[k]))
        .collect();
    for p in &ees {
        assert_eq!(p.header.frame_id, "base");
        let e = [p.point.x, p.point.y, p.point.z];
        assert!(
            sample_ee
                .iter()
                .any(|s| (0..3).all(|k| (s[k] - e[k]).abs() < 1e-12)),
            "{e:?} is no sample's end-effector point ({} samples)",
            sample_ee.len()
        );
    }
    // Episode and table version never go back, and advance.
    assert!(episodes.windows(2).all(|w| w[0] <= w[1]), "{episodes:?}");
    assert!(versions.windows(2).all(|w| w[0] <= w[1]), "{versions:?}");
    assert!(
        versions.contains(&1) && versions.contains(&2),
        "{versions:?}"
    );
    assert!(episodes.last() > episodes.first(), "{episodes:?}");
    // The joint states: six named joints, the wrist at arm.ur.wrist_q's default.
    assert!(!joint_states.is_empty());
    let wrist = ur5_shared::config::SimConfig::default().wrist_q;
    for m in &joint_states {
        assert_eq!(m.name, UR_JOINTS.map(String::from).to_vec());
        assert_eq!(m.position.len(), 6);
        assert_eq!(m.position[3..], wrist[..]);
    }
    assert!(
        j["live_view"]["published"].as_u64().unwrap() > 0 && j["live_view"]["publish_errors"] == 0,
        "{j}"
    );
    std::fs::remove_dir_all(&dir).ok();
    cleanup_dead_nodes();
}
