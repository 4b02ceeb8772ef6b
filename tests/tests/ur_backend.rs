//! rt-controller's `ur` arm setup against `hil-sim ur-sim` in-process (issue 13): the
//! handshake, the recipe, the mode check and the program's connection back, with free ports on
//! 127.0.0.1. Waits are bounded only to catch a hang; nothing asserts on timing.

use std::time::Duration;

use hil_sim::ur_sim::{self, Faults, UrSimConfig, UrSimHandle};
use rt_controller::arm::ur::{UrSession, UrSetupError};
use rt_controller::config::{UrConfig, UrSeries};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur_protocol::rtde::Protocol;

const TIMEOUT: Duration = Duration::from_secs(20);

fn sim(cfg: UrSimConfig) -> UrSimHandle {
    let cfg = UrSimConfig {
        rtde_port: 0,
        secondary_port: 0,
        lockstep: true,
        ..cfg
    };
    ur_sim::spawn(&TaskConfig::default(), &SimConfig::default(), &cfg).expect("ur-sim starts")
}

fn ur_cfg(sim: &UrSimHandle, series: UrSeries) -> UrConfig {
    UrConfig {
        host: "127.0.0.1".into(),
        rtde_port: sim.rtde_addr.port(),
        secondary_port: sim.secondary_addr.port(),
        // A free port: the OS picks it and the rendered program names it.
        reverse_port: 0,
        series,
        ..UrConfig::default()
    }
}

#[test]
fn ur_backend_setup_negotiates_starts_and_the_program_connects_back() {
    let s = sim(UrSimConfig::default());
    let u = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT).expect("setup");
    assert_eq!(u.protocol, Protocol::V2);
    assert!(u.version.is_e_series());
    assert_eq!(u.cycle_s, 0.002);
    let start_q = TaskConfig::default().start_q;
    for j in 0..3 {
        assert!((u.state.actual_q[j] - start_q[j]).abs() < 1e-5);
    }
    drop(u);
    s.stop();
}

#[test]
fn ur_backend_setup_falls_back_to_v1_and_names_a_series_mismatch() {
    let s = sim(UrSimConfig {
        faults: Faults {
            refuse_v2: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let u = UrSession::connect(&ur_cfg(&s, UrSeries::E), TIMEOUT).expect("setup over v1");
    assert_eq!(u.protocol, Protocol::V1);
    drop(u);
    s.stop();

    let s = sim(UrSimConfig::default());
    let e = UrSession::connect(&ur_cfg(&s, UrSeries::Cb3), TIMEOUT)
        .err()
        .expect("a CB3 configured against an e-Series");
    assert!(matches!(e, UrSetupError::SeriesMismatch { .. }), "{e}");
    assert!(e.to_string().contains("arm.ur.series"), "{e}");
    s.stop();
}

#[test]
fn ur_backend_setup_reports_a_refused_start_and_a_missing_robot() {
    let s = sim(UrSimConfig {
        faults: Faults {
            refuse_start: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let e = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT)
        .err()
        .expect("START refused");
    assert!(matches!(e, UrSetupError::StartRefused), "{e}");
    let cfg = ur_cfg(&s, UrSeries::Auto);
    s.stop();
    let e = UrSession::connect(&cfg, TIMEOUT)
        .err()
        .expect("nothing listens any more");
    assert!(e.to_string().contains("arm.ur.host"), "{e}");
}

#[test]
fn ur_backend_setup_skips_text_messages_and_reports_refused_versions() {
    let s = sim(UrSimConfig {
        faults: Faults {
            text_before_reply: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let u = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT).expect("setup");
    assert!(!u.texts.is_empty(), "the texts before each answer are kept");
    drop(u);
    s.stop();

    let s = sim(UrSimConfig {
        faults: Faults {
            refuse_versions: true,
            ..Faults::default()
        },
        ..UrSimConfig::default()
    });
    let e = UrSession::connect(&ur_cfg(&s, UrSeries::Auto), TIMEOUT)
        .err()
        .expect("every version refused");
    assert!(matches!(e, UrSetupError::NoProtocol), "{e}");
    s.stop();
}
