//! Bounded time on any input: a control period outside the project's 10 Hz – 1 kHz
//! (`ur5_shared::config::RATE_RANGE_HZ`, the controller's bound too), wherever it comes from
//! (a LeRobot `fps`, a CSV time column, a demonstrations file, a policy file), and a
//! `--threads` beyond any machine are refused at once, naming the value, instead of
//! simulating for hours.

use crate::common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{learner, save_short_demos};

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bounded-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `learner ARGS` fails within 20 s with a message containing `want`.
fn refused_quickly(args: &[&str], want: &str) {
    let t0 = Instant::now();
    let (ok, err) = learner(args);
    let took = t0.elapsed();
    assert!(!ok, "{args:?} accepted:\n{err}");
    assert!(err.contains(want), "{args:?}: want {want:?}, got\n{err}");
    assert!(took < Duration::from_secs(20), "{args:?} took {took:?}");
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_control_period_outside_10_hz_to_1_khz_is_refused_at_once() {
    let dir = scratch("dt");
    let demos = dir.join("d.npz");
    save_short_demos(&demos, 0);
    let (lr, csv) = (dir.join("lr"), dir.join("d.csv"));
    for (fmt, out) in [("lerobot", &lr), ("csv", &csv)] {
        let (ok, err) = learner(&["dataset", "export", "--format", fmt, s(&demos), s(out)]);
        assert!(ok, "{err}");
        let (ok, err) = learner(&["dataset", "check", s(out)]);
        assert!(ok, "the export passes: {err}");
    }

    // LeRobot `fps` 1e-300 (dt 1e300 s) and 5000 (dt 0.2 ms).
    let info_path = lr.join("meta/info.json");
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&info_path).unwrap()).unwrap();
    for fps in [1e-300, 5000.0] {
        let mut i = info.clone();
        i["fps"] = fps.into();
        std::fs::write(&info_path, serde_json::to_vec(&i).unwrap()).unwrap();
        refused_quickly(
            &["dataset", "check", s(&lr)],
            "Hz; supported are 10 Hz to 1 kHz",
        );
    }

    // A CSV with its time column in ms (dt 100).
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let mut ms = format!("{}\n", lines.next().unwrap());
    for l in lines {
        let mut f: Vec<String> = l.split(',').map(str::to_owned).collect();
        f[1] = format!("{}", f[1].parse::<f64>().unwrap() * 1000.0);
        ms.push_str(&f.join(","));
        ms.push('\n');
    }
    let ms_csv = dir.join("ms.csv");
    std::fs::write(&ms_csv, ms).unwrap();
    refused_quickly(
        &["dataset", "check", s(&ms_csv)],
        "time step dt of the trajectories (1 / fps, or the step of the time column): 100 s is a \
         control rate of 0.01 Hz",
    );
    let out = dir.join("out");
    refused_quickly(
        &[
            "train",
            "--demos",
            s(&ms_csv),
            "--iterations",
            "1",
            "--out",
            s(&out),
        ],
        "0.01 Hz",
    );

    // Our own demonstrations file with dt = 100 s.
    let mut d = learner::io::demos::load(&demos).unwrap();
    d.dt = 100.0;
    let slow = dir.join("slow.npz");
    learner::io::demos::save(&d, &slow).unwrap();
    refused_quickly(&["dataset", "check", s(&slow)], "0.01 Hz");

    // The bound is one: 0.1 s and 1 ms pass, a hair beyond does not.
    use ur5_shared::config::check_dt;
    assert!(check_dt(0.1).is_ok() && check_dt(0.001).is_ok() && check_dt(1.0 / 30.0).is_ok());
    for dt in [0.1001, 0.000999, 0.0, -0.1, f64::NAN, f64::INFINITY, 1e300] {
        assert!(check_dt(dt).is_err(), "{dt}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn threads_and_time_compression_beyond_any_machine_are_refused() {
    let dir = scratch("threads");
    let out = dir.join("e");
    refused_quickly(
        &["expert", "--threads", "100000", "--out", s(&out)],
        "--threads 100000: must be 0 (one per core) to 1024",
    );
    use ur5_shared::config::check_time_compression;
    assert!(check_time_compression(1.0).is_ok() && check_time_compression(1000.0).is_ok());
    for c in [0.5, 1000.5, 1e308, f64::NAN, f64::INFINITY] {
        assert!(check_time_compression(c).is_err(), "{c}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
