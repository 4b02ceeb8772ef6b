//! The run directory has one owner (docs/design.md §4.4): the
//! reproductions of the hostile-user report, through the `learner` binary.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("run-dir-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

use common::save_short_demos as demos;

/// `learner train` with `args`: (success, stderr).
fn train(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_learner"))
        .arg("train")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn rows(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("gaifo_log.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(String::from)
        .collect()
}

#[test]
fn a_run_directory_is_never_mixed_with_another_run() {
    let dir = scratch("mix");
    let (d, other) = (dir.join("d.npz"), dir.join("other.npz"));
    demos(&d, 0);
    demos(&other, 1);
    let r = dir.join("r");
    let (ds, rs, os) = (
        d.display().to_string(),
        r.display().to_string(),
        other.display().to_string(),
    );
    let (ok, err) = train(&["--demos", &ds, "--iterations", "3", "--out", &rs]);
    assert!(ok, "{err}");
    assert_eq!(rows(&r).len(), 3);

    // 1. Another run into the same folder is refused and changes nothing.
    let before = std::fs::read(r.join("gaifo_log.csv")).unwrap();
    let (ok, err) = train(&[
        "--demos",
        &ds,
        "--iterations",
        "2",
        "--seed",
        "5",
        "--out",
        &rs,
    ]);
    assert!(
        !ok && err.contains("already holds") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read(r.join("gaifo_log.csv")).unwrap(), before);

    // 10. Resuming with other demonstrations or another seed is refused.
    let (ok, err) = train(&["--demos", &os, "--resume", &rs, "--iterations", "4"]);
    assert!(!ok && err.contains("demonstrations"), "{err}");
    let (ok, err) = train(&[
        "--demos",
        &ds,
        "--resume",
        &rs,
        "--iterations",
        "4",
        "--seed",
        "5",
    ]);
    assert!(!ok && err.contains("seed 0 there, 5 now"), "{err}");

    // The same run resumes and extends its own log.
    let (ok, err) = train(&["--demos", &ds, "--resume", &rs, "--iterations", "4"]);
    assert!(ok, "{err}");
    let r4 = rows(&r);
    assert_eq!(r4.len(), 4);
    assert!(
        r4.iter()
            .enumerate()
            .all(|(i, l)| l.starts_with(&format!("{i},0,"))),
        "{r4:?}"
    );

    assert!(r.join("iter_003_table.npz").exists());
    // --force starts over: no file of the old run is left.
    let (ok, err) = train(&[
        "--demos",
        &ds,
        "--iterations",
        "2",
        "--seed",
        "5",
        "--out",
        &rs,
        "--force",
    ]);
    assert!(ok, "{err}");
    let r2 = rows(&r);
    assert_eq!(r2.len(), 2);
    assert!(
        r2.iter().all(|l| l.split(',').nth(1) == Some("5")),
        "{r2:?}"
    );
    for old in [
        "iter_003_table.npz",
        "iter_004_table.npz",
        "iter_003_critic.json",
    ] {
        assert!(!r.join(old).exists(), "{old} of the old run is left");
    }

    // 14. A resume without the per-iteration log is refused, not started on a new CSV.
    std::fs::remove_file(r.join("gaifo_log.csv")).unwrap();
    let (ok, err) = train(&[
        "--demos",
        &ds,
        "--resume",
        &rs,
        "--iterations",
        "4",
        "--seed",
        "5",
    ]);
    assert!(!ok && err.contains("no gaifo_log.csv"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// An `--out` that cannot be created is named in the error, for every command
/// that writes one (here the expert and an experiment, whose folders are created at different
/// depths).
#[test]
fn an_out_folder_that_cannot_be_made_is_named() {
    let dir = scratch("out");
    let file = dir.join("a-file");
    std::fs::write(&file, b"not a folder").unwrap();
    let bad = file.join("run");
    let bad_s = bad.display().to_string();
    for args in [
        vec!["expert", "--iterations", "1", "--out", &bad_s],
        vec![
            "experiment",
            "stability",
            "--iterations",
            "1",
            "--seeds",
            "1",
            "--out",
            &bad_s,
        ],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_learner"))
            .args(&args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}: {err}");
        assert!(
            err.contains(&format!("cannot create the folder {bad_s}")),
            "{args:?}: {err}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
