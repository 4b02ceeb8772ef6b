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
