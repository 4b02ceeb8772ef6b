//! ur-sim's servoj tracking (`--servoj tracking`): the program's `lookahead_time` and `gain`
//! change how the arm follows a step in its target; `ideal` ignores them. Lockstep: one
//! package per command, so each run is the same sequence of arm cycles.

use hil_sim::ur_sim::plant::ServojModel;
use hil_sim::ur_sim::{self, UrSimConfig};
use ur5_shared::config::{SimConfig, TaskConfig};

use super::ur_sim::{run_program_with, servoj, Client};

/// The shoulder's travel (rad) toward a 0.2 rad step after 0.05, 0.1, 0.2 and 1 s.
fn step_response(model: ServojModel, lookahead_time_s: f64, gain: f64) -> [f64; 4] {
    let sim = ur_sim::spawn(
        &TaskConfig::default(),
        &SimConfig::default(),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            lockstep: true,
            servoj: model,
            ..UrSimConfig::default()
        },
    )
    .unwrap();
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    let q0 = c.state(&recipe).unwrap().actual_q[0];
    let start_q = TaskConfig::default().start_q;
    let target = [start_q[0] + 0.2, start_q[1], start_q[2]];
    let mut rev = run_program_with(&sim, |p| {
        p.lookahead_time_s = lookahead_time_s;
        p.gain = gain;
    });
    let mut out = [0.0; 4];
    let marks = [25, 50, 100, 500];
    for n in 1..=500 {
        servoj(&mut rev, target, 5_000);
        let s = c.state(&recipe).unwrap();
        if let Some(k) = marks.iter().position(|&m| m == n) {
            out[k] = s.actual_q[0] - q0;
        }
    }
    drop(rev);
    sim.stop();
    out
}

#[test]
fn servoj_lookahead_and_gain_shape_the_tracking_and_ideal_ignores_them() {
    let ideal = step_response(ServojModel::Ideal, 0.2, 100.0);
    assert_eq!(
        ideal,
        step_response(ServojModel::Ideal, 0.03, 2000.0),
        "ideal: the settings change nothing"
    );
    let fast = step_response(ServojModel::Tracking, 0.03, 2000.0);
    let smooth = step_response(ServojModel::Tracking, 0.2, 2000.0);
    let soft = step_response(ServojModel::Tracking, 0.03, 100.0);
    eprintln!("travel after 0.05/0.1/0.2/1 s (rad): ideal {ideal:?}, lookahead 0.03 gain 2000 {fast:?}, lookahead 0.2 {smooth:?}, gain 100 {soft:?}");
    for k in 0..3 {
        // A longer lookahead lags more, a lower gain lags more, and either lags the ideal servo.
        assert!(ideal[k] > fast[k], "{k}: {ideal:?} vs {fast:?}");
        assert!(fast[k] > smooth[k], "{k}: {fast:?} vs {smooth:?}");
        assert!(fast[k] > soft[k], "{k}: {fast:?} vs {soft:?}");
    }
    // All of them arrive.
    for r in [ideal, fast, smooth, soft] {
        assert!((r[3] - 0.2).abs() < 0.01, "{r:?}");
    }
}
