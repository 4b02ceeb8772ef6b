//! The binary's interface: help with units, the full default config, clear errors.

use std::io::Read;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use rt_controller::ControllerConfig;

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rt-controller"));
    c.env("IOX2_LOG_LEVEL", "Error");
    c
}

/// A run of the binary that ends in time: [`Command::output`], but the child is killed and the
/// test fails, with what the child printed, if it has not exited after `BOUND` (a hang).
trait OutputWithin {
    fn output_within(&mut self) -> std::io::Result<Output>;
}

/// Only catches a hang: every run below ends in well under a second.
const BOUND: Duration = Duration::from_secs(60);

impl OutputWithin for Command {
    fn output_within(&mut self) -> std::io::Result<Output> {
        let mut child = self.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn()?;
        let drain = |mut r: Box<dyn Read + Send>| {
            std::thread::spawn(move || {
                let mut buf = Vec::new();
                let _ = r.read_to_end(&mut buf);
                buf
            })
        };
        let out = drain(Box::new(child.stdout.take().expect("piped")));
        let err = drain(Box::new(child.stderr.take().expect("piped")));
        let t0 = Instant::now();
        let status = loop {
            if let Some(status) = child.try_wait()? {
                break status;
            }
            if t0.elapsed() > BOUND {
                let _ = child.kill();
                let _ = child.wait();
                let err = String::from_utf8_lossy(&err.join().unwrap_or_default()).into_owned();
                panic!("{self:?} still running after {BOUND:?}; killed; its stderr:\n{err}");
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        Ok(Output {
            status,
            stdout: out.join().unwrap_or_default(),
            stderr: err.join().unwrap_or_default(),
        })
    }
}

fn scratch_file(name: &str, text: &str) -> std::path::PathBuf {
    let p = std::env::temp_dir().join(format!("rt-controller-cli-{}-{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn help_explains_units() {
    let out = bin().args(["run", "--help"]).output_within().unwrap();
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
    let out = bin().arg("print-config").output_within().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let back: ControllerConfig = toml::from_str(&text).unwrap();
    let d = ControllerConfig::default();
    assert_eq!(
        back,
        ControllerConfig {
            limits: Some(d.limits()),
            ..d
        }
    );
    for key in [
        "[task]",
        "[limits]",
        "[safety]",
        "[bounds]",
        "[rt]",
        "[polling]",
        "stale_state_timeout_s",
        "noisy_episodes",
        "[arm.ros2]",
        "[live_view]",
        "[live_view.qos]",
        // [arm.ur]'s keys a configuration carries only when set.
        "model = \"ur5\"",
        "dashboard_port = 29999",
        "check_model = true",
        "bring_up = false",
        "recover_protective_stop = false",
        "servoj_lookahead_time_s",
        "servoj_gain",
    ] {
        assert!(text.contains(key), "missing {key}:\n{text}");
    }
}

#[test]
fn bad_configs_fail_with_the_key_named() {
    let typo = scratch_file("typo.toml", "[safety]\nstale_timeout = 1.0\n");
    let out = bin()
        .args(["run", "--config", typo.to_str().unwrap()])
        .output_within()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("stale_timeout"), "{err}");

    let rate = scratch_file("rate.toml", "[task]\ndt = 1.0\n");
    let out = bin()
        .args(["run", "--config", rate.to_str().unwrap()])
        .output_within()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("task.dt") && err.contains("10 Hz"), "{err}");

    // A NaN bound would reject every table; refused before the run.
    let nan = scratch_file("nan.toml", "[bounds]\nmax_abs_k_mat = nan\n");
    let out = bin()
        .args(["run", "--config", nan.to_str().unwrap()])
        .output_within()
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
        .output_within()
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
    // The first has made all its ports once its command publisher (the last) is there; it is
    // killed below only then: a process killed while iceoryx2 creates a port leaves a dead node
    // that no later cleanup can remove (docs/reliability.md).
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let cmd = ur5_shared::services::ARM_COMMAND_QOS
        .open_or_create_retrying::<ur5_shared::ArmCommand>(
            &node,
            &ur5_shared::services::ServiceNames::new(&prefix).arm_command,
        )
        .unwrap();
    while cmd.dynamic_config().number_of_publishers() == 0 {
        assert!(
            t0.elapsed().as_secs() < 15,
            "the first controller never made its ports"
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let out = bin()
        .args(["run", "--prefix", &prefix])
        .output_within()
        .unwrap();
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
