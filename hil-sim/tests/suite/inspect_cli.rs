//! `hil-sim inspect` refuses inputs outside the arm's limits instead of printing `null`
//!.

use std::process::Command;

fn inspect(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .arg("inspect")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn inspect_answers_in_range_and_refuses_out_of_range() {
    let (ok, stdout, err) = inspect(&["--q", "0,-1.5,1.5"]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(
        j["qdd"].as_array().unwrap().iter().all(|v| v.is_f64()),
        "{j}"
    );
    for (args, what) in [
        (
            ["--q", "0,-1.5,4.0"],
            "--q: joint `elbow_joint` at 4.0 rad is outside its limits",
        ),
        (["--q", "0,NaN,1.5"], "values must be finite"),
        (
            ["--tau", "1e300,0,0"],
            "--tau: joint `shoulder_pan_joint` at 1e300 N·m",
        ),
    ] {
        let mut a = args.to_vec();
        if a[0] != "--q" {
            a.extend_from_slice(&["--q", "0,-1.5,1.5"]);
        }
        let (ok, _, err) = inspect(&a);
        assert!(!ok && err.contains(what), "{args:?}: {err}");
    }
}

/// `hil-sim inspect --model M` prints M's flange (the shared kinematics of M, within f32
/// rounding), and `--model` against a config naming another model is refused naming both.
#[test]
fn inspect_prints_the_flange_of_the_model_asked_for() {
    use ur5_shared::kinematics::UrKinematics;
    use ur5_shared::UrModel;
    let q = [0.3, -1.2, 1.4];
    for model in [UrModel::Ur5, UrModel::Ur5e, UrModel::Ur10e, UrModel::Ur20] {
        let (ok, stdout, err) = inspect(&["--model", model.name(), "--q=0.3,-1.2,1.4"]);
        assert!(ok, "{model}: {err}");
        let j: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(j["model"], model.name());
        assert!(j["urdf"]
            .as_str()
            .unwrap()
            .ends_with(&format!("{}.urdf", model.name())));
        let want = UrKinematics::new(model, [0.0; 3])
            .ee_point(&UrKinematics::six(&q, &model.default_wrist_q()));
        let got: Vec<f64> = j["ee_pos"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let err = (0..3)
            .map(|k| (got[k] - want[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err < 2e-6, "{model}: ee_pos {got:?}, kinematics {want:?}");
    }
    let dir = std::env::temp_dir().join(format!("hil-sim-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("arm.toml");
    std::fs::write(&cfg, "[sim]\nmodel = \"ur10e\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .args([
            "--model",
            "ur5e",
            "demo",
            "--goals",
            "0,-1.5,1.5",
            "--config",
        ])
        .arg(&cfg)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--model ur5e") && err.contains("ur10e"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `hil-sim playback-gen` writes a new file and never replaces one: an existing CSV or a FIFO
/// is refused, untouched, before anything is generated; so are settings that would allocate
/// without bound and a start pose outside the limits, naming the setting.
#[cfg(unix)]
#[test]
fn playback_gen_never_replaces_a_file_and_bounds_its_output() {
    let dir = std::env::temp_dir().join(format!("hil-sim-playback-gen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let gen = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_hil-sim"))
            .arg("playback-gen")
            .args(args)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let csv = dir.join("reaches.csv");
    let csv_s = csv.to_str().unwrap();
    let (code, err) = gen(&["--motions", "1", "--out", csv_s]);
    assert_eq!(code, Some(0), "{err}");
    let first = std::fs::read(&csv).unwrap();
    let (code, err) = gen(&["--motions", "1", "--seed", "2", "--out", csv_s]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("exists") && err.contains("never replaces"),
        "{err}"
    );
    assert_eq!(std::fs::read(&csv).unwrap(), first);
    let fifo = dir.join("fifo");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let (code, err) = gen(&["--motions", "1", "--out", fifo.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{err}");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    let big = dir.join("big.csv");
    let (code, err) = gen(&[
        "--motions",
        "200000",
        "--rate",
        "1000",
        "--out",
        big.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("fewer motions or a lower rate"), "{err}");
    assert!(!big.exists());
    let cfg = dir.join("far.toml");
    std::fs::write(&cfg, "[task]\nstart_q = [0.0, -1.5, 4.0]\n").unwrap();
    let (code, err) = gen(&[
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        big.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("joint 2 (task.start_q) at 4 rad") && !err.contains("line"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
