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

    // A NaN bound would reject every table; refused before the run.
    let nan = scratch_file("nan.toml", "[bounds]\nmax_abs_k_mat = nan\n");
    let out = bin()
        .args(["run", "--config", nan.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("max_abs_k_mat = NaN"), "{err}");
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

/// A second controller on a prefix exits at once naming the running one; the
/// first is undisturbed.
#[test]
fn a_second_controller_on_a_prefix_is_refused() {
    let prefix = ur5_shared::services::unique_prefix("two-ctl");
    // The first waits for an arm that never comes (up to 20 s), holding the prefix.
    let cfg = scratch_file("wait.toml", "setup_timeout_s = 20.0\n");
    let mut first = bin()
        .args([
            "run",
            "--prefix",
            &prefix,
            "--config",
            cfg.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lock = ur5_shared::services::RoleLock::path(&prefix, "controller");
    let pid = first.id().to_string();
    // The lock file names the first controller once it holds the role.
    let t0 = std::time::Instant::now();
    while std::fs::read_to_string(&lock).unwrap_or_default() != pid {
        assert!(
            t0.elapsed().as_secs() < 15,
            "the first controller never took the prefix"
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let out = bin().args(["run", "--prefix", &prefix]).output().unwrap();
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("another controller is running") && err.contains(&pid),
        "{err}"
    );
    assert!(
        first.try_wait().unwrap().is_none(),
        "the first controller was disturbed"
    );
    first.kill().unwrap();
    first.wait().unwrap();
}
