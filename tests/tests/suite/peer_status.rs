//! Learner and controller that cannot work together both stop, with the same message, instead
//! of one waiting for the other (docs/design.md §3.12): a horizon mismatch
//! found by the controller (it rejects the learner's table), and a seed mismatch found by the
//! learner (the controller's exploration noise is not its seed's).

use std::time::{Duration, Instant};

use integration_tests::{
    json_summary, scratch, spawn_sim_and_controller, unique_prefix, write_config, Proc,
};

/// Waits for both to exit (at most `limit` in all); returns (learner code, controller code,
/// controller stdout).
fn both_exit(
    learner: &mut Proc,
    ctl: &mut Proc,
    limit: Duration,
) -> (Option<i32>, Option<i32>, String) {
    let t0 = Instant::now();
    let (lcode, _) = learner.wait(limit);
    let left = limit.saturating_sub(t0.elapsed());
    let (ccode, cout) = ctl.wait(left.max(Duration::from_secs(1)));
    (lcode, ccode, cout)
}

#[test]
fn a_horizon_mismatch_stops_both_sides_with_the_same_message() {
    let dir = scratch("peer-horizon");
    let prefix = unique_prefix("peer-horizon");
    // The learner's task has T = 50; the controller and the arm run the default T = 100.
    let learner_cfg = write_config(&dir, "learner.toml", "samples = 2\n[task]\nhorizon = 50\n");
    let out = dir.join("out").display().to_string();
    let sim = Proc::spawn("hil-sim", "sim", &["serve", "--prefix", &prefix], &dir);
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &["run", "--prefix", &prefix, "--json"],
        &dir,
    );
    let mut learner = Proc::spawn(
        "learner",
        "learner",
        &[
            "serve",
            "--config",
            &learner_cfg,
            "--prefix",
            &prefix,
            "--out",
            &out,
        ],
        &dir,
    );
    let (lcode, ccode, cout) = both_exit(&mut learner, &mut ctl, Duration::from_secs(60));
    let (llog, clog) = (learner.log(), ctl.log());
    assert_eq!(ccode, Some(6), "controller:\n{clog}");
    assert!(
        lcode.is_some_and(|c| c != 0),
        "learner exit {lcode:?}:\n{llog}"
    );
    let summary = json_summary(&cout, &clog);
    assert_eq!(summary["exit_reason"], "task_mismatch", "{summary}");
    let msg = summary["stop_message"]
        .as_str()
        .expect("stop_message")
        .to_owned();
    assert!(
        msg.contains("horizon T = 50") && msg.contains("T = 100"),
        "{msg}"
    );
    assert!(
        llog.contains(&msg),
        "the learner's log lacks the controller's message {msg:?}:\n{llog}"
    );
    drop(sim); // killed on drop
}

#[test]
fn a_seed_mismatch_stops_both_sides_with_the_same_message() {
    let dir = scratch("peer-seed");
    let prefix = unique_prefix("peer-seed");
    let t = 30;
    let learner_cfg = write_config(
        &dir,
        "learner.toml",
        &format!("samples = 2\nseed = 7\n[task]\nhorizon = {t}\n[serve]\nwait_report_s = 1.0\n"),
    );
    let sim_cfg = write_config(&dir, "sim.toml", &format!("[task]\nhorizon = {t}\n"));
    let ctl_cfg = write_config(
        &dir,
        "controller.toml",
        &format!("seed = 8\nnoisy_episodes = 2\neval_episodes = 1\n[task]\nhorizon = {t}\n"),
    );
    let out = dir.join("out").display().to_string();
    let (sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);
    let mut learner = Proc::spawn(
        "learner",
        "learner",
        &[
            "serve",
            "--config",
            &learner_cfg,
            "--prefix",
            &prefix,
            "--out",
            &out,
        ],
        &dir,
    );
    let (lcode, ccode, cout) = both_exit(&mut learner, &mut ctl, Duration::from_secs(120));
    let (llog, clog) = (learner.log(), ctl.log());
    assert!(
        lcode.is_some_and(|c| c != 0),
        "learner exit {lcode:?}:\n{llog}"
    );
    assert_eq!(ccode, Some(6), "controller:\n{clog}");
    let summary = json_summary(&cout, &clog);
    assert_eq!(summary["exit_reason"], "learner_stopped", "{summary}");
    let msg = summary["stop_message"].as_str().expect("stop_message");
    assert!(
        msg.starts_with("the learner stopped: ") && msg.contains("seed 7"),
        "{msg}"
    );
    let reason = msg.trim_start_matches("the learner stopped: ");
    assert!(
        llog.contains(reason),
        "the learner's log lacks {reason:?}:\n{llog}"
    );
    drop(sim); // killed on drop
}
