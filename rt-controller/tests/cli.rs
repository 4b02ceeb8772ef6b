//! The binary's interface: help with units, the full default config, clear errors.

use std::process::Command;

use rt_controller::ControllerConfig;

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rt-controller"));
    c.env("IOX2_LOG_LEVEL", "Error");
    c
}

fn scratch_file(name: &str, text: &str) -> std::path::PathBuf {
    let p = std::env::temp_dir().join(format!("rt-controller-cli-{}-{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn help_explains_units() {
    let out = bin().args(["run", "--help"]).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(out.status.success());
    for needle in [
        "rad",
        "rad/s",
        "N·m",
        "time_compression",
        "--json",
        "print-config",
    ] {
        assert!(
            text.contains(needle),
            "`run --help` lacks {needle:?}:\n{text}"
        );
    }
}

#[test]
fn print_config_lists_every_option_and_parses_back() {
    let out = bin().arg("print-config").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let back: ControllerConfig = toml::from_str(&text).unwrap();
    assert_eq!(back, ControllerConfig::default());
    for key in [
        "[task]",
        "[limits]",
        "[safety]",
        "[bounds]",
        "[rt]",
        "[polling]",
        "stale_state_timeout_s",
        "noisy_episodes",
    ] {
        assert!(text.contains(key), "missing {key}:\n{text}");
    }
}

#[test]
fn bad_configs_fail_with_the_key_named() {
    let typo = scratch_file("typo.toml", "[safety]\nstale_timeout = 1.0\n");
    let out = bin()
        .args(["run", "--config", typo.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("stale_timeout"), "{err}");

    let rate = scratch_file("rate.toml", "[task]\ndt = 1.0\n");
    let out = bin()
        .args(["run", "--config", rate.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("task.dt") && err.contains("10 Hz"), "{err}");
}

#[test]
fn a_missing_arm_is_a_clear_setup_error() {
    let cfg = scratch_file("noarm.toml", "setup_timeout_s = 0.2\n");
    let prefix = ur5_shared::services::unique_prefix("cli-no-arm");
    let out = bin()
        .args([
            "run",
            "--config",
            cfg.to_str().unwrap(),
            "--prefix",
            &prefix,
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.contains("no arm state") && err.contains("hil-sim serve --prefix"),
        "{err}"
    );
}
