//! A process killed while it creates a service leaves nothing that hangs a later process.
//!
//! iceoryx2 creates a service's dynamic config as a shared memory segment of size zero and sizes
//! it a moment later. A process killed in between (a controller killed by SIGKILL during its
//! setup) leaves the segment at size zero; the dead-node cleanup that every later process runs
//! when it creates or drops a node opened it and, unpatched, retried for ever: every controller,
//! arm and learner started afterwards on the machine hung (vendor/iceoryx2-cal/PATCHED.md).
//! Here the half-created state is made on purpose: a helper process opens a service, the test
//! gives the service's dynamic segment size zero and no read permission (as iceoryx2's creator
//! does before it initialises the segment), and kills the helper; a controller started next must
//! give its usual setup error within a bound that only catches a hang.

use std::io::BufRead;
use std::os::unix::fs::PermissionsExt;
use std::time::Duration;

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use integration_tests::{scratch, unique_prefix, Proc};
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::status::PeerStatus;

/// Only catches a hang: the controller below gives up after 0.2 s.
const BOUND: Duration = Duration::from_secs(60);

/// The shared memory file of the dynamic config of the service with hash `hash`.
fn dynamic_segment(hash: &str) -> Option<std::path::PathBuf> {
    std::fs::read_dir("/dev/shm").ok()?.flatten().find_map(|e| {
        let name = e.file_name().into_string().ok()?;
        (name.starts_with("iox2_") && name.ends_with(&format!("_{hash}.dynamic"))).then(|| e.path())
    })
}

/// Run by the test below in a process of its own: opens one service on `IT_HELPER_PREFIX`,
/// prints its hash on stdout and idles until killed. Does nothing when run normally.
#[test]
#[ignore = "helper process for a_process_killed_while_creating_a_service_hangs_no_later_process"]
fn service_creator_helper_process() {
    let Ok(prefix) = std::env::var("IT_HELPER_PREFIX") else {
        return;
    };
    set_log_level_from_env_or(LogLevel::Error);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let names = ServiceNames::new(&prefix);
    let svc = services::STATUS_QOS
        .open_or_create_retrying::<PeerStatus>(&node, &names.controller_status)
        .unwrap();
    println!("hash {}", svc.service_hash().as_str());
    loop {
        std::thread::sleep(Duration::from_secs(1));
    }
}

#[test]
fn a_process_killed_while_creating_a_service_hangs_no_later_process() {
    let dir = scratch("killed-setup");
    let mut helper = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--ignored",
            "--exact",
            "killed_setup::service_creator_helper_process",
            "--nocapture",
        ])
        .env("IT_HELPER_PREFIX", unique_prefix("killed-setup"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let hash = std::io::BufReader::new(helper.stdout.take().unwrap())
        .lines()
        .map_while(Result::ok)
        .find_map(|l| l.strip_prefix("hash ").map(str::to_owned))
        .expect("the helper prints its service's hash");
    let segment = dynamic_segment(&hash).expect("the helper's service has a dynamic segment");
    // The state iceoryx2's creator leaves when it dies between creating and sizing the segment.
    std::fs::OpenOptions::new()
        .write(true)
        .open(&segment)
        .unwrap()
        .set_len(0)
        .unwrap();
    std::fs::set_permissions(&segment, std::fs::Permissions::from_mode(0o200)).unwrap();
    helper.kill().unwrap();
    helper.wait().unwrap();

    let cfg = dir.join("noarm.toml");
    std::fs::write(&cfg, "setup_timeout_s = 0.2\n").unwrap();
    let prefix = unique_prefix("killed-setup-next");
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &[
            "run",
            "--config",
            cfg.to_str().unwrap(),
            "--prefix",
            &prefix,
        ],
        &dir,
    );
    let (code, _) = ctl.wait(BOUND);
    assert_eq!(code, Some(2), "{}", ctl.log());
    assert!(ctl.log().contains("no arm state"), "{}", ctl.log());
    // The empty segment itself stays in /dev/shm (0 bytes; its service's static config is
    // removed, so nothing opens it again): remove it here.
    let _ = std::fs::remove_file(&segment);
}
