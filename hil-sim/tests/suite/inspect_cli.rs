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
