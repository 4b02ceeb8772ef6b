//! rt-controller's `ur` arm against `hil-sim ur-sim`, free ports on 127.0.0.1:
//! the setup (handshake, recipe, mode check, the program's connection back) in-process, then
//! the loop: the `rt-controller` and `learner` binaries against an in-process ur-sim, learning
//! with the same outcome as over iceoryx2, the fault injections, a protective stop (ending the
//! run, or recovered over the dashboard), a dead ur-sim and a frozen controller; the dashboard's
//! model check and bring-up. Waits are bounded only to catch a hang; nothing asserts on timing.
//!
//! ur-sim's library default pairs the UR5 model with an e-Series controller, a combination no
//! robot has: the tests that use it do not check the model (`check_model = false`).

use std::path::Path;
use std::time::{Duration, Instant};

use hil_sim::ur_sim::{self, Faults, Series, UrSimConfig, UrSimHandle};
use integration_tests::{
    cleanup_dead_nodes, json_summary, learn_over_ipc, reaching_table, run_controller_polling,
    scratch, unique_prefix, write_config, Proc, TestLearner,
};
use rt_controller::arm::ur::setup::KEPT_TEXTS;
use rt_controller::arm::ur::UrRtde;
use rt_controller::arm::ur::{UrSession, UrSetupError};
use rt_controller::config::{UrConfig, UrSeries};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::UrModel;
use ur_protocol::client::ClientError;
use ur_protocol::rtde::Protocol;

const TIMEOUT: Duration = Duration::from_secs(20);

/// A lockstep ur-sim on free ports with `cfg`'s other settings.
fn sim(cfg: UrSimConfig) -> UrSimHandle {
    sim_clocked(cfg, true)
}

/// A ur-sim on free ports, in lockstep or in real time, with `cfg`'s other settings.
fn sim_clocked(cfg: UrSimConfig, lockstep: bool) -> UrSimHandle {
    let cfg = UrSimConfig {
        rtde_port: 0,
        secondary_port: 0,
        dashboard_port: Some(0),
        lockstep,
        ..cfg
    };
    ur_sim::spawn(&TaskConfig::default(), &SimConfig::default(), &cfg).expect("ur-sim starts")
}

fn ur_cfg(sim: &UrSimHandle, series: UrSeries) -> UrConfig {
    UrConfig {
        host: "127.0.0.1".into(),
        rtde_port: sim.rtde_addr.port(),
        secondary_port: sim.secondary_addr.port(),
        // A free port: the OS picks it and the rendered program names it.
        reverse_port: 0,
        dashboard_port: sim.dashboard_addr.unwrap().port(),
        check_model: false,
        series,
        ..UrConfig::default()
    }
}

#[test]
fn ur_backend_setup_negotiates_starts_and_the_program_connects_back() {
    let s = sim(UrSimConfig::default());
    let u = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT).expect("setup");
    assert_eq!(u.protocol, Protocol::V2);
    assert!(u.version.is_e_series());
    assert_eq!(u.cycle_s, 0.002);
    let start_q = TaskConfig::default().start_q;
    for j in 0..3 {
        assert!((u.state.actual_q[j] - start_q[j]).abs() < 1e-5);
    }
    drop(u);
    s.stop();
}

#[test]
fn ur_backend_setup_falls_back_to_v1_and_names_a_series_mismatch() {
    let s = sim(UrSimConfig {
        faults: Faults {
            refuse_v2: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let u = UrSession::connect(&ur_cfg(&s, UrSeries::E), TIMEOUT).expect("setup over v1");
    assert_eq!(u.protocol, Protocol::V1);
    drop(u);
    s.stop();

    let s = sim(UrSimConfig::default());
    let e = UrSession::connect(&ur_cfg(&s, UrSeries::Cb3), TIMEOUT)
        .err()
        .expect("a CB3 configured against an e-Series");
    assert!(matches!(e, UrSetupError::SeriesMismatch { .. }), "{e}");
    assert!(e.to_string().contains("arm.ur.series"), "{e}");
    s.stop();
}

#[test]
fn ur_backend_setup_reports_a_refused_start_and_a_missing_robot() {
    let s = sim(UrSimConfig {
        faults: Faults {
            refuse_start: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let e = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT)
        .err()
        .expect("START refused");
    assert!(
        matches!(e, UrSetupError::Rtde(ClientError::StartRefused)),
        "{e}"
    );
    let cfg = ur_cfg(&s, UrSeries::Auto);
    s.stop();
    let e = UrSession::connect(&cfg, TIMEOUT)
        .err()
        .expect("nothing listens any more");
    assert!(e.to_string().contains("arm.ur.host"), "{e}");
}

#[test]
fn ur_backend_setup_skips_text_messages_and_reports_refused_versions() {
    let s = sim(UrSimConfig {
        faults: Faults {
            text_before_reply: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let u = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT).expect("setup");
    assert!(!u.texts.is_empty(), "the texts before each answer are kept");
    drop(u);
    s.stop();

    let s = sim(UrSimConfig {
        faults: Faults {
            refuse_versions: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let e = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT)
        .err()
        .expect("every version refused");
    assert!(
        matches!(e, UrSetupError::Rtde(ClientError::NoProtocol)),
        "{e}"
    );
    s.stop();
}

#[test]
fn ur_backend_setup_timeout_is_a_deadline_over_a_robot_that_only_talks() {
    // The robot answers every request with a text message and keeps sending them: a timeout
    // per read never fires (the setup hung, keeping every text). A deadline over the setup does.
    let s = sim(UrSimConfig {
        faults: Faults {
            text_only: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let cfg = ur_cfg(&s, UrSeries::Auto);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(UrSession::connect(&cfg, Duration::from_secs(2)).err());
    });
    // Bounds a hang only.
    let e = rx
        .recv_timeout(LONG)
        .expect("the setup returns")
        .expect("no setup against a robot that only talks");
    let UrSetupError::Deadline {
        texts_total,
        texts,
        during,
        ..
    } = &e
    else {
        panic!("expected the setup deadline, got: {e}")
    };
    assert_eq!(*during, "protocol negotiation", "{e}");
    // At least 8 texts per 50 ms for 2 s: more than are kept.
    assert!(*texts_total > KEPT_TEXTS as u64, "{e}");
    assert_eq!(texts.len(), KEPT_TEXTS, "the newest texts only: {e}");
    assert!(texts[0].starts_with("hil-sim fault injection"), "{e}");
    let m = e.to_string();
    assert!(
        m.contains("setup_timeout_s = 2 s") && m.contains("text messages"),
        "{m}"
    );
    s.stop();
}

#[test]
fn ur_backend_setup_names_swapped_ports() {
    let s = sim(UrSimConfig::default());
    let swapped = UrConfig {
        rtde_port: s.secondary_addr.port(),
        secondary_port: s.rtde_addr.port(),
        ..ur_cfg(&s, UrSeries::Auto)
    };
    let e = UrSession::connect(&swapped, Duration::from_secs(1))
        .err()
        .expect("no RTDE on the secondary port");
    assert!(matches!(e, UrSetupError::PortsSwapped { .. }), "{e}");
    let m = e.to_string();
    let (r, sec) = (s.rtde_addr.port(), s.secondary_addr.port());
    assert!(
        m.contains("swapped")
            && m.contains(&format!("set rtde_port = {r} and secondary_port = {sec}")),
        "{m}"
    );
    // Nothing RTDE on either: both ports named, and what to check.
    let neither = UrConfig {
        rtde_port: sec,
        secondary_port: sec,
        ..ur_cfg(&s, UrSeries::Auto)
    };
    let e = UrSession::connect(&neither, Duration::from_secs(1))
        .err()
        .expect("no RTDE at all");
    assert!(matches!(e, UrSetupError::NotRtde { .. }), "{e}");
    let m = e.to_string();
    assert!(
        m.contains("arm.ur.rtde_port") && m.contains("secondary_port") && m.contains("no answer"),
        "{m}"
    );
    s.stop();
}

// ------------------------------------------------------------------------------ the loop

const LONG: Duration = Duration::from_secs(120);

/// The program's receive timeout in these tests (ms): long enough that a test process
/// descheduled on a loaded machine does not trip the watchdog (20 ms did, one run in seven).
const WATCHDOG_MS: u32 = 200;

/// The reaching tables' goal (rad).
const GOAL: [f64; 3] = [0.3, -1.7, 2.0];

/// The RTDE, secondary and dashboard ports of a ur-sim.
#[derive(Clone, Copy)]
struct Ports(u16, u16, u16);

impl From<&UrSimHandle> for Ports {
    fn from(s: &UrSimHandle) -> Self {
        Ports(
            s.rtde_addr.port(),
            s.secondary_addr.port(),
            s.dashboard_addr.unwrap().port(),
        )
    }
}

/// `[arm]` of a controller config for a ur-sim (the reverse port: any free one; the model not
/// checked).
fn arm_toml(p: Ports, receive_timeout_ms: u32) -> String {
    format!(
        "[arm]\nbackend = \"ur\"\n[arm.ur]\nhost = \"127.0.0.1\"\nrtde_port = {}\nsecondary_port = {}\ndashboard_port = {}\ncheck_model = false\nreverse_port = 0\nreceive_timeout_ms = {receive_timeout_ms}\n",
        p.0, p.1, p.2
    )
}

fn learner_toml(dir: &Path) -> String {
    write_config(
        dir,
        "learner.toml",
        "samples = 5\nseed = 7\niterations = 3\nrandom_episodes = 1\n[task]\nhorizon = 30\n\
         [serve]\nwait_report_s = 1.0\nidle_sleep_us = 200\n",
    )
}

/// The expert learning over IPC (3 iterations, lockstep): the learner's summary and the
/// controller's. With `pause` (the ur-sim the controller drives), the learner is stopped
/// (SIGSTOP) once its second table is written, until the arm has sent no package for 1.5 s:
/// the controller ran that table's cycle and then idled for three keepalive intervals of a
/// 1000 ms receive timeout.
fn learn(
    dir: &Path,
    prefix: &str,
    ctl_cfg: &str,
    label: &str,
    pause: Option<&UrSimHandle>,
) -> (serde_json::Value, serde_json::Value) {
    learn_over_ipc(
        dir,
        prefix,
        &learner_toml(dir),
        ctl_cfg,
        label,
        LONG,
        |learner, out| {
            let Some(arm) = pause else { return };
            let second = out.join("tables").join("v0002.npz");
            let t0 = Instant::now();
            while !second.exists() {
                assert!(
                    t0.elapsed() < LONG,
                    "no second table within {LONG:?}:\n{}",
                    learner.log()
                );
                std::thread::sleep(Duration::from_millis(5));
            }
            learner.signal(libc::SIGSTOP);
            let (mut packages, mut since) = (arm.summary().packages, Instant::now());
            while since.elapsed() < Duration::from_millis(1500) {
                assert!(t0.elapsed() < LONG, "the arm never went quiet");
                std::thread::sleep(Duration::from_millis(20));
                let now = arm.summary().packages;
                if now != packages {
                    (packages, since) = (now, Instant::now());
                }
            }
            learner.signal(libc::SIGCONT);
        },
    )
}

#[test]
fn ur_learning_has_the_outcome_of_the_iceoryx2_run_in_lockstep() {
    let dir = scratch("ur-learn");
    // One cycle per table: no episode of an old table moves the arm while the learner works
    // (docs/ur.md, "Lockstep over RTDE").
    let common = "seed = 7\nnoisy_episodes = 5\neval_episodes = 1\ncycles_per_table = 1\nmode = \"lockstep\"\n[task]\nhorizon = 30\n";
    // Over iceoryx2 with hil-sim serve.
    let prefix = unique_prefix("ur-learn-i");
    let sim_cfg = write_config(&dir, "sim.toml", "[task]\nhorizon = 30\n");
    let serve = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &sim_cfg, "--prefix", &prefix],
        &dir,
    );
    let (ice, _) = learn(
        &dir,
        &prefix,
        &write_config(&dir, "ctl-ice.toml", common),
        "iceoryx2",
        None,
    );
    serve.signal(libc::SIGTERM);
    // Over RTDE and the reverse interface with ur-sim (lockstep). The program's watchdog is
    // long so that a descheduled test machine cannot end the program mid-run.
    // Twice: the second time the learner is paused, so the controller idles (IDLE keepalives)
    // for longer than the learner's updates take; the run must not change by a bit.
    let mut runs = Vec::new();
    for (label, pause) in [("ur", false), ("ur-paused", true)] {
        let s = sim(UrSimConfig::default());
        let prefix = unique_prefix("ur-learn-u");
        let (ur, c) = learn(
            &dir,
            &prefix,
            &write_config(
                &dir,
                &format!("ctl-{label}.toml"),
                &format!("{common}{}", arm_toml(Ports::from(&s), 1000)),
            ),
            label,
            pause.then_some(&s),
        );
        let summary = s.stop();
        assert_eq!(summary.protective_stops, 0, "{summary:?}");
        assert_eq!(summary.programs, 1, "{summary:?}");
        assert_eq!(ur["counts"]["old_version"], 0, "one cycle per table: {ur}");
        if pause {
            assert!(
                c["arm"]["keepalives"].as_u64().unwrap() >= 1,
                "the pause made the controller idle: {c}"
            );
        }
        runs.push(ur);
    }
    let (ur, paused) = (&runs[0], &runs[1]);
    for key in ["eval_costs", "log"] {
        let strip = |v: &serde_json::Value| {
            let mut v = v[key].clone();
            for row in v.as_array_mut().unwrap() {
                if let Some(o) = row.as_object_mut() {
                    o.remove("seconds");
                }
            }
            v
        };
        assert_eq!(
            strip(ur),
            strip(paused),
            "{key}: a paused learner changed the run"
        );
    }
    // The same learning, up to the differences of the two arms: ur-sim's reset is a motion
    // that ends within 2 mrad of the start pose (hil-sim serve places the arm there), and
    // servoj targets travel rounded to 1 µrad.
    for i in 0..3 {
        let (a, b) = (
            ice["eval_costs"][i].as_f64().unwrap(),
            ur["eval_costs"][i].as_f64().unwrap(),
        );
        let (da, db) = (
            ice["log"][i]["final_distance_m"].as_f64().unwrap(),
            ur["log"][i]["final_distance_m"].as_f64().unwrap(),
        );
        eprintln!("iteration {i}: cost {a:.5} (iceoryx2) vs {b:.5} (ur); final distance {da:.5} vs {db:.5} m");
        assert!((a - b).abs() <= 0.01 * a, "iteration {i}: cost {a} vs {b}");
        assert!(
            (da - db).abs() <= 1e-3,
            "iteration {i}: distance {da} vs {db}"
        );
    }
    assert!(
        ur["eval_costs"][2].as_f64().unwrap() < ur["eval_costs"][0].as_f64().unwrap(),
        "it learned: {ur}"
    );
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}

/// A controller on the ur-sim `s` with a learner stand-in publishing a reaching table; returns
/// (exit code, stdout, log).
fn run_against_raw(
    ports: Ports,
    tag: &str,
    extra: &str,
    ur_extra: &str,
    receive_timeout_ms: u32,
    episodes: u64,
    q_goal: [f64; 3],
) -> (Option<i32>, String, String) {
    let dir = scratch(tag);
    let prefix = unique_prefix(tag);
    let cfg = write_config(
        &dir,
        "ctl.toml",
        &format!(
            "seed = 3\nnoisy_episodes = 1\neval_episodes = 1\nmode = \"lockstep\"\n{extra}\n[task]\nhorizon = 10\n[safety]\nstale_state_timeout_s = 2.0\n{}{ur_extra}",
            arm_toml(ports, receive_timeout_ms)
        ),
    );
    let learner = TestLearner::learner_only(&prefix);
    learner.publish(&reaching_table(1, 10, q_goal, 0.01));
    let (code, out, log) = run_controller_polling(&cfg, &prefix, episodes, &dir, LONG, || {
        learner.poll_gains_only()
    });
    std::fs::remove_dir_all(&dir).ok();
    (code, out, log)
}

/// [`run_against_raw`] with its `--json` summary.
fn run_against(
    ports: Ports,
    tag: &str,
    extra: &str,
    receive_timeout_ms: u32,
    episodes: u64,
    q_goal: [f64; 3],
) -> (Option<i32>, serde_json::Value, String) {
    run_against_with(ports, tag, extra, "", receive_timeout_ms, episodes, q_goal)
}

/// [`run_against`] with `ur_extra` lines appended to `[arm.ur]`.
fn run_against_with(
    ports: Ports,
    tag: &str,
    extra: &str,
    ur_extra: &str,
    receive_timeout_ms: u32,
    episodes: u64,
    q_goal: [f64; 3],
) -> (Option<i32>, serde_json::Value, String) {
    let (code, out, log) = run_against_raw(
        ports,
        tag,
        extra,
        ur_extra,
        receive_timeout_ms,
        episodes,
        q_goal,
    );
    (code, json_summary(&out, &log), log)
}

#[test]
fn ur_fault_injections_give_clear_reports_and_no_crash() {
    let faults = [
        (
            "merged and split packages",
            Faults {
                merge_split: true,
                ..Faults::default()
            },
        ),
        (
            "late packages",
            Faults {
                delay_every: 97,
                // Longer than a keepalive (half the watchdog), shorter than the watchdog.
                delay_ms: 150,
                ..Faults::default()
            },
        ),
        (
            "dropped packages",
            Faults {
                drop_every: 101,
                ..Faults::default()
            },
        ),
    ];
    for (what, f) in faults {
        let s = sim(UrSimConfig {
            faults: f,
            ..UrSimConfig::default()
        });
        let (code, j, log) = run_against(Ports::from(&s), "ur-fault", "", WATCHDOG_MS, 2, GOAL);
        let summary = s.stop();
        assert_eq!(code, Some(0), "{what}: {j}\n{log}");
        assert_eq!(j["episodes_completed"], 2, "{what}: {j}");
        assert_eq!(j["arm"]["decode_errors"], 0, "{what}: {j}");
        assert_eq!(summary.protective_stops, 0, "{what}: {summary:?}");
        if what != "merged and split packages" {
            // A package that does not come is replaced by a command written after half the
            // program's receive timeout: the program never times out.
            assert!(j["arm"]["keepalives"].as_u64().unwrap() >= 1, "{what}: {j}");
            assert_eq!(summary.receive_timeouts, 0, "{what}: {summary:?}");
        }
    }
    // The robot closes RTDE: the controller ends at once with exit 3 and says why.
    let s = sim(UrSimConfig {
        faults: Faults {
            disconnect_after: 300,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let (code, j, log) = run_against(Ports::from(&s), "ur-fault-d", "", WATCHDOG_MS, 50, GOAL);
    s.stop();
    assert_eq!(code, Some(3), "{j}\n{log}");
    assert_eq!(j["exit_reason"], "arm_lost", "{j}");
    assert_eq!(j["arm_lost"], "the robot closed the RTDE connection", "{j}");
    assert!(
        log.contains("the robot closed the RTDE connection"),
        "{log}"
    );
    cleanup_dead_nodes();
}

/// A second RTDE client on the ur-sim at `rtde_port` that watches the arm
/// ([`UrRtde::next_state`]).
fn observer(rtde_port: u16) -> UrRtde {
    UrRtde::connect(
        &UrConfig {
            host: "127.0.0.1".into(),
            rtde_port,
            ..UrConfig::default()
        },
        TIMEOUT,
    )
    .expect("observer")
}

#[test]
fn ur_a_stopped_ur_sim_gives_the_controller_a_clear_exit() {
    let s = sim(UrSimConfig::default());
    let (addr, ports) = (s.rtde_addr, Ports::from(&s));
    let stopper = std::thread::spawn(move || {
        // Let the controller run an episode or so, then take the robot away.
        let mut obs = observer(addr.port());
        while obs.next_state().expect("observer reads").timestamp < 1.0 {}
        s.stop()
    });
    let (code, j, log) = run_against(ports, "ur-dead", "", WATCHDOG_MS, 50, GOAL);
    let summary = stopper.join().unwrap();
    assert_eq!(summary.programs, 1, "{summary:?}");
    assert_eq!(code, Some(3), "{j}\n{log}");
    assert_eq!(j["exit_reason"], "arm_lost", "{j}");
    assert!(j["arm_lost"].as_str().unwrap().contains("closed"), "{j}");
    cleanup_dead_nodes();
}

/// The dashboard's `stop` in the middle of a run: the program ends (`programState` STOPPED at
/// once, as a real controller says) and the controller ends the run as an arm that stopped
/// itself, its program ended (exit 5), not as a lost one (exit 3).
#[test]
fn ur_a_dashboard_stop_ends_the_run_as_its_program_ended() {
    let s = sim(UrSimConfig::default());
    let (addr, ports) = (s.rtde_addr, Ports::from(&s));
    let dash = s.dashboard_addr.unwrap();
    let stopper = std::thread::spawn(move || {
        // Once the controller runs its first episode (arm time after the first reset), stop
        // the program as a person at the dashboard would.
        let mut obs = observer(addr.port());
        while obs.next_state().expect("observer reads").timestamp < 1.2 {}
        let mut d = ur_protocol::dashboard::Dashboard::connect(dash, TIMEOUT).unwrap();
        let stopped = d.ask("stop").unwrap();
        let state = d.ask("programState").unwrap();
        (stopped, state, s)
    });
    let (code, j, log) = run_against(ports, "ur-dash-stop", "", WATCHDOG_MS, 50, GOAL);
    let (stopped, state, s) = stopper.join().unwrap();
    let summary = s.stop();
    assert_eq!(stopped, "Stopped");
    assert_eq!(state, "STOPPED <unnamed>");
    assert_eq!(summary.programs, 1, "{summary:?}");
    assert_eq!(code, Some(5), "exit 5 = the arm stopped itself: {j}\n{log}");
    assert_eq!(j["exit_reason"], "arm_stopped", "{j}");
    let why = j["arm"]["robot_stop"].as_str().unwrap();
    assert!(why.contains("program not running"), "{why}");
    cleanup_dead_nodes();
}

#[test]
fn ur_a_protective_stop_ends_the_run_with_its_own_exit_code() {
    // The robot stops itself mid-run (as on a detected collision; the controller's own limits
    // may never be looser than the arm's, so it cannot drive the arm past them). In lockstep the
    // first reset of this task takes about 496 arm cycles and episode 0's 10 ticks follow, so
    // cycle 503 falls in that episode (a stop during a reset ends the run as ArmLost).
    let s = sim(UrSimConfig {
        faults: Faults {
            protective_stop_after: 503,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let (code, j, log) = run_against(
        Ports::from(&s),
        "ur-pstop",
        "",
        WATCHDOG_MS,
        5,
        [0.3, -1.7, 1.6],
    );
    let summary = s.stop();
    assert_eq!(summary.protective_stops, 1, "{summary:?}");
    assert_eq!(code, Some(5), "exit 5 = the arm stopped itself: {j}\n{log}");
    assert_eq!(j["exit_reason"], "arm_stopped", "{j}");
    assert_eq!(j["fault_at_exit"], "arm_fault", "{j}");
    let why = j["arm"]["robot_stop"].as_str().unwrap();
    assert!(why.contains("PROTECTIVE_STOP"), "{why}");
    cleanup_dead_nodes();
}

#[test]
fn ur_a_protective_stop_is_unlocked_and_the_run_goes_on_when_the_config_allows() {
    // As above, with recover_protective_stop: the controller waits until the robot's clock is
    // 5 s past the stop (ur-sim's clock runs while the arm stands in the stop, here 10x
    // faster than wall time), unlocks it on the dashboard, sends the program again and runs
    // the remaining episodes; the stopped one counts as aborted.
    let s = sim(UrSimConfig {
        time_compression: 10.0,
        faults: Faults {
            protective_stop_after: 503,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let (code, j, log) = run_against_with(
        Ports::from(&s),
        "ur-pstop-r",
        "",
        "recover_protective_stop = true\n",
        WATCHDOG_MS,
        5,
        [0.3, -1.7, 1.6],
    );
    let summary = s.stop();
    assert_eq!(summary.protective_stops, 1, "{summary:?}");
    assert_eq!(summary.programs, 2, "{summary:?}");
    assert_eq!(code, Some(0), "{j}\n{log}");
    assert_eq!(j["exit_reason"], "episodes_done", "{j}");
    assert_eq!(j["episodes_aborted"], 1, "{j}");
    assert_eq!(j["episodes_completed"], 4, "{j}");
    assert_eq!(j["arm"]["protective_stops_recovered"], 1, "{j}");
    assert!(log.contains("protective stop unlocked"), "{log}");
    cleanup_dead_nodes();
}

#[test]
fn ur_backend_checks_the_robots_model_over_the_dashboard() {
    // A CB3 UR5 (ur-sim's UR5 on a CB3 controller): the UR5 config is accepted.
    let cb3 = UrSimConfig {
        series: Series::Cb3,
        ..UrSimConfig::default()
    };
    let s = sim(cb3.clone());
    let ok = UrConfig {
        check_model: true,
        ..ur_cfg(&s, UrSeries::Auto)
    };
    drop(UrSession::connect(&ok, TIMEOUT).expect("a UR5 config on a UR5"));
    // A UR10 config on it is refused, naming both models.
    let e = UrSession::connect(
        &UrConfig {
            model: UrModel::Ur10,
            ..ok.clone()
        },
        TIMEOUT,
    )
    .err()
    .expect("a UR10 config on a UR5");
    assert!(matches!(e, UrSetupError::ModelMismatch { .. }), "{e}");
    let m = e.to_string();
    assert!(
        m.contains("\"ur10\"") && m.contains("UR5") && m.contains("a ur5;"),
        "{m}"
    );
    s.stop();
    // The same "UR5" on an e-Series controller is a UR5e: the UR5 config is refused.
    let s = sim(UrSimConfig::default());
    let e = UrSession::connect(
        &UrConfig {
            check_model: true,
            ..ur_cfg(&s, UrSeries::Auto)
        },
        TIMEOUT,
    )
    .err()
    .expect("a UR5 config on a UR5e");
    let m = e.to_string();
    assert!(m.contains("a ur5e") && m.contains("URSoftware 5."), "{m}");
    // No dashboard server: said so, with the way to skip the check.
    let s2 = ur_sim::spawn(
        &TaskConfig::default(),
        &SimConfig::default(),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            dashboard_port: None,
            lockstep: true,
            ..cb3
        },
    )
    .unwrap();
    let free = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let closed_port = free.local_addr().unwrap().port();
    drop(free);
    let e = UrSession::connect(
        &UrConfig {
            check_model: true,
            dashboard_port: closed_port,
            ..ur_cfg(&s, UrSeries::Auto)
        },
        TIMEOUT,
    )
    .err()
    .expect("no dashboard");
    assert!(matches!(e, UrSetupError::Dashboard { .. }), "{e}");
    assert!(e.to_string().contains("check_model = false"), "{e}");
    s.stop();
    s2.stop();
}

/// Every model on its own controller (ur-sim with the model's URDF and generation): its
/// dashboard answers name it to the `ur` backend, whose model check and RTDE setup accept it;
/// the UR7e, which answers "UR7", is not taken for the UR5e it shares its kinematics with.
#[test]
fn ur_backend_accepts_every_model_on_its_own_controller() {
    for model in UrModel::ALL {
        let series = if model.is_e_series() {
            Series::E
        } else {
            Series::Cb3
        };
        let cfg = UrSimConfig {
            series,
            rtde_port: 0,
            secondary_port: 0,
            dashboard_port: Some(0),
            lockstep: true,
            ..UrSimConfig::default()
        };
        let s = ur_sim::spawn(
            &TaskConfig::for_model(model),
            &SimConfig::for_model(model),
            &cfg,
        )
        .expect("ur-sim starts");
        let ok = UrConfig {
            model,
            check_model: true,
            ..ur_cfg(&s, UrSeries::Auto)
        };
        let u = UrSession::connect(&ok, TIMEOUT).unwrap_or_else(|e| panic!("{model}: {e}"));
        assert_eq!(u.cycle_s, series.cycle_s(), "{model}");
        drop(u);
        if model == UrModel::Ur7e {
            let e = UrSession::connect(
                &UrConfig {
                    model: UrModel::Ur5e,
                    ..ok
                },
                TIMEOUT,
            )
            .err()
            .expect("a UR5e config on a UR7e");
            assert!(matches!(e, UrSetupError::ModelMismatch { .. }), "{e}");
            assert!(e.to_string().contains("a ur7e"), "{e}");
        }
        s.stop();
    }
}

#[test]
fn ur_backend_brings_up_a_powered_off_arm_when_asked() {
    let s = sim(UrSimConfig {
        series: Series::Cb3,
        start_powered_off: true,
        ..UrSimConfig::default()
    });
    let cfg = UrConfig {
        check_model: true,
        ..ur_cfg(&s, UrSeries::Auto)
    };
    // Without bring-up: refused, with what to do.
    let e = UrSession::connect(&cfg, TIMEOUT)
        .err()
        .expect("a powered-off arm");
    assert!(
        matches!(e, UrSetupError::Rtde(ClientError::NotRunning { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("POWER_OFF"), "{e}");
    // With it: power on, brake release, RUNNING, the program connects back.
    let u = UrSession::connect(
        &UrConfig {
            bring_up: true,
            ..cfg.clone()
        },
        TIMEOUT,
    )
    .expect("bring-up");
    assert_eq!(u.state.robot_mode, ur_protocol::RobotMode::Running.code());
    assert_eq!(u.cycle_s, 0.008);
    drop(u);
    let summary = s.stop();
    assert_eq!(summary.programs, 1, "{summary:?}");
}

#[test]
fn ur_a_robot_stream_that_cannot_be_trusted_ends_the_run_naming_why() {
    // From the 100th package (in the first reset): a frozen clock (it ticked 0 times and never
    // said why), a clock going backwards, a NaN joint angle (reported as a network problem), a
    // joint angle of 100 rad (servoj targets toward it were streamed). Each ends the run as arm
    // lost (exit 3), nothing written after it (no protective stop: no target reached the arm).
    let cases: [(&str, Faults, &str); 4] = [
        (
            "frozen clock",
            Faults {
                frozen_clock_after: 100,
                ..Faults::default()
            },
            "is frozen",
        ),
        (
            "backwards clock",
            Faults {
                backwards_clock_after: 100,
                ..Faults::default()
            },
            "went backwards",
        ),
        (
            "NaN q",
            Faults {
                nan_q_after: 100,
                ..Faults::default()
            },
            "non-finite joint state: joint 0 actual_q = NaN",
        ),
        (
            "q outside the limits",
            Faults {
                q_out_of_limits_after: 100,
                ..Faults::default()
            },
            "joint 0 at 100 rad, outside [limits]",
        ),
    ];
    for (what, faults, says) in cases {
        let s = sim(UrSimConfig {
            faults,
            ..UrSimConfig::default()
        });
        let (code, j, log) = run_against(Ports::from(&s), "ur-stream", "", WATCHDOG_MS, 2, GOAL);
        let summary = s.stop();
        assert_eq!(code, Some(3), "{what}: {j}\n{log}");
        assert_eq!(j["exit_reason"], "arm_lost", "{what}: {j}");
        let fault = j["arm"]["stream_fault"].as_str().unwrap_or_default();
        assert!(fault.contains(says), "{what}: {fault}\n{j}");
        assert!(
            j["arm_lost"]
                .as_str()
                .unwrap()
                .contains("see arm.stream_fault"),
            "{what}: {j}"
        );
        assert!(!j["arm_lost"].as_str().unwrap().contains("network problem"));
        assert_eq!(summary.protective_stops, 0, "{what}: {summary:?}");
    }
    // Outside the limits from the first package: refused in setup (exit 2), naming it.
    let s = sim(UrSimConfig {
        faults: Faults {
            q_out_of_limits_after: 1,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let (code, _, log) =
        run_against_raw(Ports::from(&s), "ur-stream-0", "", "", WATCHDOG_MS, 2, GOAL);
    let summary = s.stop();
    assert_eq!(code, Some(2), "{log}");
    assert!(
        log.contains("joint 0 at 100 rad, outside [limits]"),
        "{log}"
    );
    assert_eq!(summary.programs, 0, "no program started: {summary:?}");
    cleanup_dead_nodes();
}

#[test]
fn ur_a_protective_stop_during_a_reset_ends_the_run_as_arm_stopped() {
    // Cycle 100 falls in the first reset (about 496 cycles): the reset's acknowledgement never
    // comes, and the run ended as arm lost (exit 3) when the program closed its connection.
    let s = sim(UrSimConfig {
        faults: Faults {
            protective_stop_after: 100,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let (code, j, log) = run_against(Ports::from(&s), "ur-pstop-reset", "", WATCHDOG_MS, 5, GOAL);
    let summary = s.stop();
    assert_eq!(summary.protective_stops, 1, "{summary:?}");
    assert_eq!(code, Some(5), "{j}\n{log}");
    assert_eq!(j["exit_reason"], "arm_stopped", "{j}");
    assert_eq!(j["episodes_completed"], 0, "{j}");
    let why = j["arm"]["robot_stop"].as_str().unwrap();
    assert!(why.contains("PROTECTIVE_STOP"), "{why}");
    cleanup_dead_nodes();
}

#[test]
fn ur_a_frozen_controller_is_stopped_by_the_programs_watchdog() {
    // Real time: the arm moves toward the table's goal; the controller is frozen (SIGSTOP:
    // its sockets stay open, nothing more is written) and the program's receive timeout stops
    // the arm. A CB3 (125 Hz, 16 kB/s of packages): the frozen controller's socket buffers hold
    // seconds of its stream, so ur-sim does not drop it as a client that does not read (at
    // 500 Hz they filled in about a second under load; the robot closing RTDE is then exit 3).
    // In lockstep nothing would advance the arm once the controller stops commanding it, so
    // the stop and its packages would depend on thread timing: real time.
    let s = sim_clocked(
        UrSimConfig {
            series: Series::Cb3,
            ..UrSimConfig::default()
        },
        false,
    );
    let dir = scratch("ur-freeze");
    let prefix = unique_prefix("ur-freeze");
    let cfg = write_config(
        &dir,
        "ctl.toml",
        &format!(
            "seed = 3\nnoisy_episodes = 1\neval_episodes = 1\nmode = \"real_time\"\npacing = \"arm\"\n[task]\nhorizon = 40\n{}",
            arm_toml(Ports::from(&s), WATCHDOG_MS)
        ),
    );
    let mut learner = TestLearner::learner_only(&prefix);
    learner.publish(&reaching_table(1, 40, [0.6, -1.5, 1.6], 0.01));
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &["run", "--config", &cfg, "--prefix", &prefix, "--json"],
        &dir,
    );
    learner.poll_until(&mut ctl, LONG, "ticks of episode 0", |l| {
        l.received.iter().any(|x| x.episode == 0 && x.t >= 3)
    });
    let mut obs = observer(s.rtde_addr.port());
    let moving = obs.next_state().unwrap().actual_qd[..3]
        .iter()
        .any(|v| v.abs() > 0.05);
    assert!(moving, "the arm moves before the freeze");
    ctl.signal(libc::SIGSTOP);
    let t0 = Instant::now();
    let stopped = loop {
        let r = *obs.next_state().unwrap();
        let at_rest = r.actual_qd.iter().all(|v| v.abs() < 1e-3);
        if r.runtime_state == ur_protocol::state::runtime_state::STOPPED && at_rest {
            break true;
        }
        if t0.elapsed() > LONG {
            break false;
        }
    };
    // Thawed, the controller finds the program ended: the arm stopped itself (exit 5, as the
    // exit-code table says; it exited 3, arm lost, on the closed reverse connection).
    ctl.signal(libc::SIGCONT);
    let (code, out) = ctl.wait(LONG);
    let log = ctl.log();
    let summary = s.stop();
    assert!(stopped, "the program did not stop the arm: {summary:?}");
    assert_eq!(summary.receive_timeouts, 1, "{summary:?}");
    let j = json_summary(&out, &log);
    assert_eq!(code, Some(5), "{j}\n{log}");
    assert_eq!(j["exit_reason"], "arm_stopped", "{j}");
    let why = j["arm"]["robot_stop"].as_str().unwrap();
    assert!(why.contains("program not running"), "{why}");
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}
