//! `learner record` against what goes wrong (docs/reliability.md, the recorder's classes): the
//! robot going away after some demonstrations, an output it cannot or must not write, a robot
//! whose stream cannot be trusted, another arm model than it records for. Outcomes are asserted,
//! not timing: the recordings run in compressed real time, and waits are bounded only to catch a
//! hang.

use std::path::Path;
use std::time::{Duration, Instant};

use hil_sim::ur_sim::{self, Faults, UrSimConfig, UrSimHandle};
use integration_tests::{scratch, Proc};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::UrModel;

use crate::teach::generate_reaches;

const LONG: Duration = Duration::from_secs(120);

/// A UR5e ur-sim at 10 times real time with a dashboard server, playing `dir/reaches.csv` if
/// `playback`, with `faults`.
fn ur5e_sim(dir: &Path, playback: bool, faults: Faults) -> UrSimHandle {
    let m = UrModel::Ur5e;
    ur_sim::spawn(
        &TaskConfig::for_model(m),
        &SimConfig::for_model(m),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            dashboard_port: Some(0),
            time_compression: 10.0,
            playback: playback.then(|| dir.join("reaches.csv")),
            faults,
            ..UrSimConfig::default()
        },
    )
    .expect("ur-sim")
}

/// `learner record` on `sim` for a UR5e (T = 50, from a config file unless `extra` gives
/// `--model`) into `dir/out`, with `extra` arguments (`--rtde-port DASHBOARD`: the dashboard's
/// port).
fn record(sim: &UrSimHandle, dir: &Path, label: &str, extra: &[&str]) -> Proc {
    let port = sim.rtde_addr.port().to_string();
    let dashboard = sim.dashboard_addr.expect("dashboard").port().to_string();
    let cfg = dir.join("record.toml");
    std::fs::write(&cfg, "[task]\nhorizon = 50\n[sim]\nmodel = \"ur5e\"\n").unwrap();
    let cfg = cfg.display().to_string();
    let mut args = vec![
        "record",
        "--ur",
        "127.0.0.1",
        "--dashboard-port",
        &dashboard,
        "--json",
    ];
    if !extra.contains(&"--rtde-port") {
        args.extend(["--rtde-port", port.as_str()]);
    }
    // --model and the config's [sim] model must agree: no config with --model.
    if !extra.contains(&"--model") {
        args.extend(["--config", cfg.as_str()]);
    }
    args.extend(extra.iter().map(|a| {
        if *a == "DASHBOARD" {
            dashboard.as_str()
        } else {
            a
        }
    }));
    Proc::spawn("learner", label, &args, dir)
}

/// Exit code and stderr.
fn finish(mut p: Proc) -> (Option<i32>, String) {
    let (code, _) = p.wait(LONG);
    (code, p.log())
}

/// The robot goes away (the connection drops) after 2 of the 5 demonstrations asked for: the
/// 2 finished ones are written, the exit is an error saying so, and no claim is left behind.
#[test]
fn the_recorder_keeps_what_was_taught_when_the_robot_goes() {
    let dir = scratch("rec-drop");
    generate_reaches(UrModel::Ur5e, 2, 3, &dir);
    let sim = ur5e_sim(&dir, true, Faults::default());
    let out = dir.join("out").display().to_string();
    let p = record(
        &sim,
        &dir,
        "record",
        &["--episodes", "5", "--out", &out, "--max-time-s", "100"],
    );
    let t0 = Instant::now();
    while !p.log().contains("demonstration 2/5") {
        assert!(t0.elapsed() < LONG, "no second demonstration:\n{}", p.log());
        std::thread::sleep(Duration::from_millis(50));
    }
    // The robot's controller goes away.
    sim.stop();
    let (code, log) = finish(p);
    assert_eq!(code, Some(1), "{log}");
    assert!(
        log.contains("stopped after 2 of 5 demonstrations")
            && log.contains("saved in")
            && log.contains("RTDE"),
        "{log}"
    );
    let demos = learner::io::demos::load(&dir.join("out/demos.npz")).unwrap();
    assert_eq!((demos.count, demos.model), (2, UrModel::Ur5e));
    assert!(!dir.join("out/.recording").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// Ctrl-C (SIGINT) after the first demonstration: the recording stops, and the finished
/// demonstrations (as many as it says) are written.
#[test]
fn the_recorder_keeps_what_was_taught_when_it_is_interrupted() {
    let dir = scratch("rec-int");
    generate_reaches(UrModel::Ur5e, 3, 4, &dir);
    let sim = ur5e_sim(&dir, true, Faults::default());
    let out = dir.join("out").display().to_string();
    let p = record(&sim, &dir, "record", &["--episodes", "5", "--out", &out]);
    let t0 = Instant::now();
    while !p.log().contains("demonstration 1/5") {
        assert!(t0.elapsed() < LONG, "no demonstration:\n{}", p.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    p.signal(libc::SIGINT);
    let (code, log) = finish(p);
    sim.stop();
    assert_eq!(code, Some(1), "{log}");
    let n = (1..=3)
        .find(|n| log.contains(&format!("stopped after {n} of 5 demonstrations")))
        .unwrap_or_else(|| panic!("{log}"));
    assert!(log.contains("interrupted (SIGINT or SIGTERM)"), "{log}");
    let demos = learner::io::demos::load(&dir.join("out/demos.npz")).unwrap();
    assert_eq!(demos.count, n, "{log}");
    assert!(!dir.join("out/.recording").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// The output is checked before anything is recorded: a path that cannot be a folder, a
/// LeRobot folder holding an older dataset's data file, a folder another recorder is writing
/// into (refused, naming it) or one a killed recorder left (named as such). None of them
/// connects to the robot (the port given answers nothing).
#[test]
fn the_recorder_checks_its_output_before_it_records() {
    let dir = scratch("rec-out");
    let d = |p: &str| dir.join(p).display().to_string();
    std::fs::write(dir.join("afile"), "x").unwrap();
    std::fs::create_dir_all(dir.join("old/data/chunk-000")).unwrap();
    std::fs::write(dir.join("old/data/chunk-000/file-000.parquet"), "x").unwrap();
    let busy = dir.join("busy");
    std::fs::create_dir_all(&busy).unwrap();
    let me = std::process::id();
    std::fs::write(
        busy.join(".recording"),
        format!("pid {me} since Unix time 1\n"),
    )
    .unwrap();
    let gone = dir.join("gone");
    std::fs::create_dir_all(&gone).unwrap();
    // Process ids are below 2^22 on Linux.
    std::fs::write(
        gone.join(".recording"),
        "pid 2147483000 since Unix time 1\n",
    )
    .unwrap();
    let cases: [(&[&str], &[&str]); 4] = [
        (
            &["--out", &d("afile/sub")],
            &["cannot create the folder", "afile/sub"],
        ),
        (
            &["--out", &d("old"), "--format", "lerobot"],
            &["already holds files", "new or empty folder"],
        ),
        (
            &["--out", &d("busy")],
            &[
                "being recorded into by another `learner record`",
                &format!("pid {me}"),
            ],
        ),
        (
            &["--out", &d("gone")],
            &["no longer runs", "delete the file"],
        ),
    ];
    for (args, want) in cases {
        let mut all = vec!["record", "--ur", "127.0.0.1", "--rtde-port", "1"];
        all.extend_from_slice(args);
        let mut p = Proc::spawn("learner", "record", &all, &dir);
        let (code, _) = p.wait(LONG);
        let log = p.log();
        assert_eq!(code, Some(1), "{args:?}: {log}");
        for w in want {
            assert!(log.contains(w), "{args:?}: want {w:?} in\n{log}");
        }
        assert!(
            !log.contains("RTDE"),
            "{args:?}: checked after connecting: {log}"
        );
    }
    // Nothing was touched.
    assert!(dir.join("busy/.recording").exists() && dir.join("gone/.recording").exists());
    assert_eq!(std::fs::read_dir(dir.join("old")).unwrap().count(), 1);
    std::fs::remove_dir_all(&dir).ok();
}

/// A robot whose clock stops (with no --max-time-s: it never ends otherwise), whose joint reads
/// NaN or 100 rad, an RTDE port that is the dashboard's, or a robot of another model than the
/// recording's: each ends the recording with an error naming it.
#[test]
fn the_recorder_names_a_robot_it_cannot_trust() {
    let dir = scratch("rec-faults");
    let cases: [(Faults, &[&str], &[&str]); 5] = [
        (
            Faults {
                frozen_clock_after: 200,
                ..Faults::default()
            },
            &[],
            &["the robot's clock is frozen", "packages in a row"],
        ),
        (
            Faults {
                nan_q_after: 200,
                ..Faults::default()
            },
            &[],
            &["non-finite joint state", "joint 0 actual_q = NaN"],
        ),
        (
            Faults {
                q_out_of_limits_after: 200,
                ..Faults::default()
            },
            &[],
            &["joint 0 at 100 rad", "outside the ur5e's limits"],
        ),
        (
            Faults::default(),
            &["--rtde-port", "DASHBOARD"],
            &[
                "answers, but not in RTDE: wrong --rtde-port?",
                "29999 is its dashboard",
            ],
        ),
        (
            Faults::default(),
            &["--model", "ur5"],
            &[
                "the robot says it is a UR5 on URSoftware 5",
                "that is a ur5e",
                "--model ur5e",
            ],
        ),
    ];
    for (i, (faults, extra, want)) in cases.into_iter().enumerate() {
        let sim = ur5e_sim(&dir, false, faults);
        let out = dir.join(format!("out{i}")).display().to_string();
        let mut args = vec!["--out", out.as_str()];
        args.extend_from_slice(extra);
        let p = record(&sim, &dir, "record", &args);
        let (code, log) = finish(p);
        sim.stop();
        assert_eq!(code, Some(1), "case {i}: {log}");
        for w in want {
            assert!(log.contains(w), "case {i}: want {w:?} in\n{log}");
        }
        assert!(
            !Path::new(&out).exists(),
            "case {i}: nothing recorded, nothing left"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
