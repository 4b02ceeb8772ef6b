//! Three processes over iceoryx2: `hil-sim serve`, `rt-controller run`, and this test acting as
//! the learner (publishing tables, receiving samples). See `tests/src/lib.rs` for how the
//! binaries are found and built. Assertions are on behaviour only, never on latency.

use std::time::Duration;

use integration_tests::{
    cleanup_dead_nodes, json_summary, reaching_table, scratch, spawn_sim_and_controller,
    unique_prefix, write_config, Proc, TestLearner,
};
use ur5_shared::{controller_action, CommandKind, StepSample, DX, NO_NOISE};

/// Episode length (ticks) and control period (s) of these tests: short episodes, fast physics.
const T: usize = 30;
const DT: f64 = 0.05;
/// Goal angles of the test tables (rad); the arm starts at the task default [0, −2, 2.4].
const Q_GOAL: [f64; 3] = [0.3, -1.6, 2.0];
const LONG: Duration = Duration::from_secs(60);

fn sim_config(dir: &std::path::Path, extra: &str) -> String {
    write_config(
        dir,
        "sim.toml",
        &format!("[task]\ndt = {DT}\nhorizon = {T}\n{extra}"),
    )
}

fn controller_config(dir: &std::path::Path, extra_top: &str, extra_safety: &str) -> String {
    let stale = if extra_safety.contains("stale_state_timeout_s") {
        ""
    } else {
        "stale_state_timeout_s = 0.5"
    };
    write_config(
        dir,
        "controller.toml",
        &format!(
            "seed = 7\nnoisy_episodes = 2\neval_episodes = 1\n{extra_top}\n[task]\ndt = {DT}\nhorizon = {T}\n[safety]\n{stale}\n{extra_safety}\n"
        ),
    )
}

struct Rig {
    prefix: String,
    dir: std::path::PathBuf,
    sim: Proc,
    ctl: Proc,
}

/// Starts the sim and the controller (`run_args` appended) on a fresh prefix.
fn start(tag: &str, sim_extra: &str, ctl_top: &str, ctl_safety: &str, run_args: &[&str]) -> Rig {
    let prefix = unique_prefix(tag);
    let dir = scratch(tag);
    let sim_cfg = sim_config(&dir, sim_extra);
    let ctl_cfg = controller_config(&dir, ctl_top, ctl_safety);
    let sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &sim_cfg, "--prefix", &prefix, "--json"],
        &dir,
    );
    let mut args = vec!["run", "--config", &ctl_cfg, "--prefix", &prefix, "--json"];
    args.extend_from_slice(run_args);
    let ctl = Proc::spawn("rt-controller", "controller", &args, &dir);
    Rig {
        prefix,
        dir,
        sim,
        ctl,
    }
}

/// Samples of one episode, in arrival order.
fn episode(samples: &[StepSample], e: u64) -> Vec<StepSample> {
    samples.iter().filter(|s| s.episode == e).copied().collect()
}

/// Every episode in `samples` is complete (t = 0..T−1 in order) and uses one table version,
/// except possibly the last one (`allow_partial_last`, e.g. cut by SIGTERM); arrival order is
/// (episode, t) order; versions never decrease.
fn check_stream(samples: &[StepSample], allow_partial_last: bool) {
    assert!(!samples.is_empty());
    for w in samples.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let next =
            (b.episode == a.episode && b.t == a.t + 1) || (b.episode > a.episode && b.t == 0);
        assert!(
            next,
            "out of order or lost: {:?} then {:?}",
            (a.episode, a.t),
            (b.episode, b.t)
        );
        assert!(b.table_version >= a.table_version, "version went back");
        if b.episode == a.episode {
            assert_eq!(
                b.table_version, a.table_version,
                "version changed inside episode {}",
                a.episode
            );
        }
        assert!(
            b.state_seq > a.state_seq,
            "state sequence numbers must increase"
        );
    }
    let last = samples.last().unwrap().episode;
    let first = samples[0].episode;
    assert_eq!(samples[0].t, 0);
    for e in first..=last {
        let ep = episode(samples, e);
        if e == last && allow_partial_last {
            continue;
        }
        assert_eq!(ep.len(), T, "episode {e} has {} samples", ep.len());
    }
}

#[test]
fn lockstep_episodes_arrive_complete_in_order_with_the_controller_law() {
    let prefix = unique_prefix("it-a");
    let mut learner = TestLearner::new(&prefix);
    let table = reaching_table(1, T, Q_GOAL, 0.02);
    learner.publish(&table);
    let dir = scratch("it-a");
    let sim_cfg = sim_config(&dir, "");
    let ctl_cfg = controller_config(&dir, "", "");
    let _sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &sim_cfg, "--prefix", &prefix],
        &dir,
    );
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &[
            "run",
            "--config",
            &ctl_cfg,
            "--prefix",
            &prefix,
            "--episodes",
            "4",
            "--json",
        ],
        &dir,
    );
    learner.poll_until(&mut ctl, LONG, "4 episodes of samples", |l| {
        l.received.len() >= 4 * T
    });
    let (code, out) = ctl.wait(LONG);
    let log = ctl.log();
    assert_eq!(code, Some(0), "controller log:\n{log}");
    let j = json_summary(&out, &log);
    assert_eq!(j["exit_reason"], "episodes_done");
    assert_eq!(j["episodes_completed"], 4);
    assert_eq!(j["episodes_aborted"], 0);
    assert_eq!(j["ticks"], 4 * T as u64);
    assert_eq!(j["swaps"], 1);
    assert_eq!(j["rejected_total"], 0);
    assert_eq!(j["faults"]["stale_state"], 0);
    assert_eq!(j["table_version"], 1);

    learner.poll();
    let samples = &learner.received;
    assert_eq!(samples.len(), 4 * T, "exactly 4 × T samples");
    check_stream(samples, false);
    assert_eq!(samples[0].episode, 0);
    for s in samples {
        assert_eq!(s.table_version, 1);
        // noisy_episodes = 2, eval_episodes = 1: episodes 0, 1 noisy, 2 noise-free, 3 noisy.
        assert_eq!(
            s.is_noisy(),
            s.episode != 2,
            "noise flag of episode {}",
            s.episode
        );
        assert!(s.s.iter().all(|v| v.is_finite()));
        // The clamp: at most π rad/s × dt from the current angles.
        for j in 0..3 {
            assert!((s.a_sent[j] - s.s[j]).abs() <= std::f64::consts::PI * DT + 1e-12);
        }
        assert!(s.command_stamp_ns >= s.state_stamp_ns);
    }
    // The noise-free episode executes exactly the shared controller law.
    for s in episode(samples, 2) {
        let mut a = [0.0; 3];
        controller_action(&table, s.t as usize, s.state(), &NO_NOISE, &mut a).unwrap();
        assert_eq!(a, s.action(), "t = {}", s.t);
    }
    // Noisy episodes do not.
    let differ = episode(samples, 0)
        .iter()
        .filter(|s| {
            let mut a = [0.0; 3];
            controller_action(&table, s.t as usize, s.state(), &NO_NOISE, &mut a).unwrap();
            a != s.action()
        })
        .count();
    assert_eq!(differ, T, "every noisy action differs from the mean");
    // Every episode starts from the reset pose and the arm reaches towards the goal angles.
    for e in 0..4 {
        let ep = episode(samples, e);
        let dist = |s: &StepSample| {
            (0..3)
                .map(|j| (s.s[j] - Q_GOAL[j]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        for j in 0..3 {
            assert!(
                (ep[0].s[j] - [0.0, -2.0, 2.4][j]).abs() < 1e-3,
                "episode {e} starts at {:?}",
                &ep[0].s[..3]
            );
        }
        assert!(
            dist(&ep[T - 1]) < 0.25 * dist(&ep[0]),
            "episode {e}: {} → {}",
            dist(&ep[0]),
            dist(&ep[T - 1])
        );
    }
    assert_eq!(DX, 12);
}

#[test]
fn new_table_versions_are_taken_only_at_episode_boundaries() {
    let mut rig = start("it-b", "", "", "", &[]);
    let mut learner = TestLearner::new(&rig.prefix);
    learner.publish(&reaching_table(1, T, Q_GOAL, 0.02));
    learner.poll_until(&mut rig.ctl, LONG, "samples of version 1", |l| {
        l.received.iter().any(|s| s.table_version == 1)
    });
    for v in 2..=4u64 {
        // Publish mid-episode: wait for a sample well inside an episode.
        learner.poll_until(&mut rig.ctl, LONG, "a mid-episode sample", |l| {
            let s = l.received.last().unwrap();
            s.table_version == v - 1 && (2..T as u32 - 3).contains(&s.t)
        });
        let seen = *learner.received.last().unwrap();
        let goal = [Q_GOAL[0] - 0.1 * v as f64, Q_GOAL[1], Q_GOAL[2]];
        learner.publish(&reaching_table(v, T, goal, 0.02));
        learner.poll_until(&mut rig.ctl, LONG, "samples of the new version", |l| {
            l.received.iter().any(|s| s.table_version == v)
        });
        let first = learner
            .received
            .iter()
            .find(|s| s.table_version == v)
            .unwrap();
        assert_eq!(first.t, 0, "version {v} first used at t = {}", first.t);
        assert!(
            first.episode > seen.episode,
            "version {v} used in episode {} while episode {} was running when it was published",
            first.episode,
            seen.episode
        );
    }
    // One more full episode of version 4, then stop.
    learner.poll_until(&mut rig.ctl, LONG, "a full episode of version 4", |l| {
        l.received.iter().filter(|s| s.table_version == 4).count() > T
    });
    rig.ctl.signal(libc::SIGTERM);
    let (code, out) = rig.ctl.wait(LONG);
    let log = rig.ctl.log();
    assert_eq!(code, Some(0), "log:\n{log}");
    let j = json_summary(&out, &log);
    assert_eq!(j["exit_reason"], "stopped");
    assert_eq!(j["swaps"], 4);
    assert_eq!(j["table_version"], 4);
    assert_eq!(j["rejected_total"], 0);
    learner.poll();
    check_stream(&learner.received, true);
    let versions: Vec<u64> = learner.received.iter().map(|s| s.table_version).collect();
    for v in 1..=4 {
        assert!(versions.contains(&v));
    }
    assert!(rig.sim.running(), "the sim keeps serving");
    let _ = &rig.dir;
}

#[test]
fn bad_tables_are_rejected_counted_and_never_used() {
    let mut rig = start("it-c", "", "", "", &[]);
    let mut learner = TestLearner::new(&rig.prefix);
    learner.publish(&reaching_table(1, T, Q_GOAL, 0.02));
    learner.poll_until(&mut rig.ctl, LONG, "samples of version 1", |l| {
        !l.received.is_empty()
    });

    let mut nan = reaching_table(2, T, Q_GOAL, 0.02);
    nan.step_mut(T / 2).set_k(1, 4, f64::NAN);
    nan.seal();
    let mut dims = reaching_table(3, T, Q_GOAL, 0.02);
    dims.dx = 13;
    dims.seal();
    let mut checksum = reaching_table(4, T, Q_GOAL, 0.02);
    checksum.step_mut(0).a_hat[0] += 0.5; // changed after sealing
    for bad in [nan, dims, checksum] {
        let e = learner.last_episode().unwrap();
        learner.publish(&bad);
        // Two boundaries later it has certainly been looked at.
        learner.poll_until(&mut rig.ctl, LONG, "two more episodes", |l| {
            l.last_episode().unwrap() >= e + 2
        });
    }
    learner.publish(&reaching_table(5, T, [0.0, -1.7, 2.1], 0.02));
    learner.poll_until(&mut rig.ctl, LONG, "samples of version 5", |l| {
        l.received.iter().any(|s| s.table_version == 5)
    });
    rig.ctl.signal(libc::SIGTERM);
    let (code, out) = rig.ctl.wait(LONG);
    let log = rig.ctl.log();
    assert_eq!(code, Some(0), "log:\n{log}");
    let j = json_summary(&out, &log);
    assert_eq!(j["rejected"]["non_finite"], 1, "{j}");
    assert_eq!(j["rejected"]["dimensions"], 1, "{j}");
    assert_eq!(j["rejected"]["checksum"], 1, "{j}");
    assert_eq!(j["rejected_total"], 3, "{j}");
    assert_eq!(j["swaps"], 2);
    assert_eq!(j["table_version"], 5);
    assert_eq!(j["faults"]["non_finite_action"], 0);
    assert_eq!(log.matches("rejected gain table").count(), 3, "log:\n{log}");
    learner.poll();
    check_stream(&learner.received, true);
    assert!(
        learner
            .received
            .iter()
            .all(|s| s.table_version == 1 || s.table_version == 5),
        "a rejected table was used"
    );
}

#[test]
fn killing_the_sim_makes_the_controller_hold_and_report() {
    let mut rig = start(
        "it-d",
        "",
        "",
        "give_up_after_s = 1.5\nstale_state_timeout_s = 0.3",
        &[],
    );
    let mut learner = TestLearner::new(&rig.prefix);
    learner.publish(&reaching_table(1, T, Q_GOAL, 0.02));
    learner.poll_until(&mut rig.ctl, LONG, "samples of episode 1", |l| {
        l.received.iter().any(|s| s.episode == 1 && s.t > 3)
    });
    rig.sim.signal(libc::SIGKILL);
    let (code, out) = rig.ctl.wait(LONG);
    let log = rig.ctl.log();
    assert_eq!(code, Some(3), "exit code 3 = arm lost; log:\n{log}");
    let j = json_summary(&out, &log);
    assert_eq!(j["exit_reason"], "arm_lost");
    assert!(j["faults"]["stale_state"].as_u64().unwrap() >= 1, "{j}");
    assert_eq!(j["fault_at_exit"], "stale_state");
    assert!(
        j["lost_peers"]["arm"].as_u64().unwrap() >= 1,
        "the monitor saw the dead sim: {j}"
    );
    assert!(log.contains("peer died: arm"), "log:\n{log}");
    assert!(
        log.contains("fault latched: stale arm state"),
        "log:\n{log}"
    );
    learner.poll();
    let last = *learner.received.last().unwrap();
    let after: Vec<_> = learner
        .seen_commands
        .iter()
        .filter(|c| c.stamp_ns > last.command_stamp_ns)
        .collect();
    assert!(!after.is_empty(), "no command after the last sample");
    for c in after {
        assert_eq!(c.kind(), Ok(CommandKind::GoalAngles), "{c:?}");
        assert_eq!(c.values(), &last.state()[..3], "hold at the last safe pose");
    }
    cleanup_dead_nodes();
}

#[test]
fn an_absent_learner_leaves_the_arm_holding_without_a_table() {
    let mut rig = start(
        "it-d2",
        "",
        "wait_for_learner = false",
        "no_table_timeout_s = 0.5",
        &[],
    );
    let (code, out) = rig.ctl.wait(LONG);
    let log = rig.ctl.log();
    assert_eq!(code, Some(4), "exit code 4 = no table; log:\n{log}");
    let j = json_summary(&out, &log);
    assert_eq!(j["exit_reason"], "no_table");
    assert_eq!(j["faults"]["no_table"], 1);
    assert_eq!(j["ticks"], 0);
    assert!(log.contains("no valid gain table"), "log:\n{log}");
    assert!(rig.sim.running());
}

/// A learner in its own process (this test binary re-executed): publishes version 1, opens a
/// samples subscriber it never reads, and idles until killed. Does nothing when run normally.
#[test]
#[ignore = "helper process for killing_the_learner_never_stalls_the_loop_and_is_reported"]
fn learner_helper_process() {
    let Ok(prefix) = std::env::var("IT_HELPER_PREFIX") else {
        return;
    };
    let learner = TestLearner::learner_only(&prefix);
    learner.publish(&reaching_table(1, T, Q_GOAL, 0.02));
    eprintln!("helper learner up");
    loop {
        // Keeps delivering the table to the controller, never reads the samples.
        learner.poll_gains_only();
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn killing_the_learner_never_stalls_the_loop_and_is_reported() {
    let mut rig = start("it-d3", "", "", "", &[]);
    let log_path = rig.dir.join("helper.log");
    let mut helper = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--ignored",
            "--exact",
            // The test's name in the suite binary: module, then function.
            "processes::learner_helper_process",
            "--nocapture",
        ])
        .env("IT_HELPER_PREFIX", &rig.prefix)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&log_path).unwrap())
        .spawn()
        .unwrap();
    let wait_log = |rig: &mut Rig, needle: &str| {
        let t0 = std::time::Instant::now();
        while !rig.ctl.log().contains(needle) {
            assert!(
                rig.ctl.running(),
                "controller exited; log:\n{}",
                rig.ctl.log()
            );
            assert!(
                t0.elapsed() < LONG,
                "no {needle:?} in the controller log:\n{}",
                rig.ctl.log()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    wait_log(&mut rig, "episode 2 done");
    helper.kill().unwrap();
    helper.wait().unwrap();
    wait_log(&mut rig, "peer died: learner");
    // 40 episodes × 30 samples = 1200: more than the dead learner's queue (1024) holds.
    wait_log(&mut rig, "episode 40 done");
    rig.ctl.signal(libc::SIGTERM);
    let (code, out) = rig.ctl.wait(LONG);
    let log = rig.ctl.log();
    assert_eq!(code, Some(0), "log:\n{log}");
    let j = json_summary(&out, &log);
    assert_eq!(j["exit_reason"], "stopped");
    assert!(j["episodes_completed"].as_u64().unwrap() >= 40, "{j}");
    assert_eq!(j["episodes_aborted"], 0, "every episode finished");
    assert_eq!(j["table_version"], 1, "the current table stays");
    assert!(j["lost_peers"]["learner"].as_u64().unwrap() >= 1, "{j}");
    assert_eq!(j["lost_peers"]["arm"], 0, "{j}");
    cleanup_dead_nodes();
}

#[test]
fn real_time_mode_runs_episodes_with_both_pacings() {
    for (pacing, state_period) in [("deadline", "0.01"), ("arm", "0.1")] {
        let tag = format!("it-e-{pacing}");
        let prefix = unique_prefix(&tag);
        let dir = scratch(&tag);
        let sim_cfg = write_config(&dir, "sim.toml", &format!("[task]\ndt = 0.1\nhorizon = 10\n[serve]\nmode = \"real_time\"\ntime_compression = 10.0\nstate_period_s = {state_period}\n"));
        let ctl_cfg = write_config(
            &dir,
            "controller.toml",
            &format!("mode = \"real_time\"\npacing = \"{pacing}\"\ntime_compression = 10.0\nepisodes = 2\n[task]\ndt = 0.1\nhorizon = 10\n"),
        );
        let mut learner = TestLearner::new(&prefix);
        learner.publish(&reaching_table(1, 10, Q_GOAL, 0.02));
        let (_sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);
        learner.poll_until(&mut ctl, LONG, "2 episodes", |l| l.received.len() >= 20);
        let (code, out) = ctl.wait(LONG);
        let log = ctl.log();
        assert_eq!(code, Some(0), "{pacing}: log:\n{log}");
        let j = json_summary(&out, &log);
        assert_eq!(j["episodes_completed"], 2, "{pacing}: {j}");
        assert_eq!(j["mode"], "real_time");
        learner.poll();
        assert_eq!(learner.received.len(), 20);
        for (i, s) in learner.received.iter().enumerate() {
            assert_eq!(
                (s.episode, s.t as usize),
                ((i / 10) as u64, i % 10),
                "{pacing}"
            );
        }
    }
}
