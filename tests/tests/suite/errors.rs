//! A failed command tells a user its cause in one line (`PROGRAM: error: cause: cause…`), with no
//! stack backtrace even when the user's shell sets `RUST_BACKTRACE=1`; `RUST_LIB_BACKTRACE=1`
//! asks for one.

use std::process::Command;

use integration_tests::{bin, scratch};

/// (exit code, the non-empty lines of stderr) of `program args` with `env` set.
fn failed(program: &str, args: &[&str], env: &[(&str, &str)]) -> (Option<i32>, Vec<String>) {
    let mut cmd = Command::new(bin(program));
    cmd.args(args).env_remove("RUST_LIB_BACKTRACE");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    let lines = String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_owned)
        .collect();
    (out.status.code(), lines)
}

#[test]
fn every_binary_prints_one_error_line_without_a_backtrace() {
    let dir = scratch("errors");
    let missing = dir.join("missing.toml");
    let missing = missing.to_str().unwrap();
    let out = dir.join("out");
    let cases: [(&str, Vec<&str>); 3] = [
        (
            "learner",
            vec!["train", "--demos", missing, "--out", out.to_str().unwrap()],
        ),
        ("hil-sim", vec!["demo", "--config", missing]),
        ("rt-controller", vec!["run", "--config", missing]),
    ];
    for (program, args) in &cases {
        let (code, lines) = failed(program, args, &[("RUST_BACKTRACE", "1")]);
        assert!(code.is_some_and(|c| c != 0), "{program}: exit {code:?}");
        assert_eq!(
            lines.len(),
            1,
            "{program}: one line expected, got {lines:#?}"
        );
        assert!(
            lines[0].starts_with(&format!("{program}: error: "))
                && lines[0].contains("missing.toml"),
            "{program}: {}",
            lines[0]
        );
    }
    // A cause whose own message spans lines (TOML's) is folded onto the line, and given once.
    let config = dir.join("unknown.toml");
    std::fs::write(&config, "[discriminator]\nbogus = 1\n").unwrap();
    let args = [
        "train",
        "--demos",
        "demos.npz",
        "--out",
        out.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ];
    let (_, lines) = failed("learner", &args, &[("RUST_BACKTRACE", "1")]);
    assert_eq!(lines.len(), 1, "one line expected, got {lines:#?}");
    assert_eq!(
        lines[0].matches("unknown field `bogus`").count(),
        1,
        "{}",
        lines[0]
    );
    // Asked for, the backtrace follows the line.
    let (_, lines) = failed("learner", &cases[0].1, &[("RUST_LIB_BACKTRACE", "1")]);
    assert!(lines.len() > 1, "no backtrace: {lines:#?}");
    let _ = std::fs::remove_dir_all(&dir);
}
