//! `hil-sim ur-sim`'s dashboard server: the replies of a real controller (e-Series and CB3),
//! the refusals, and the state they read and change (power, brakes, program, protective stop),
//! seen over RTDE as well. Lockstep; where arm time matters the test reads it from ur-sim, so
//! nothing depends on how fast the machine is.

use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Instant;

use hil_sim::ur_sim::{self, Series, UrSimConfig, UrSimHandle};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::UrModel;
use ur_protocol::state::runtime_state;
use ur_protocol::{RobotMode, SafetyMode};

use super::ur_sim::{run_program, servoj, Client, DEADLINE};

fn start(cfg: UrSimConfig, model: UrModel) -> UrSimHandle {
    let cfg = UrSimConfig {
        rtde_port: 0,
        secondary_port: 0,
        dashboard_port: Some(0),
        lockstep: true,
        ..cfg
    };
    ur_sim::spawn(
        &TaskConfig::for_model(model),
        &SimConfig::for_model(model),
        &cfg,
    )
    .expect("ur-sim starts")
}

/// A dashboard client: one line out, one line back.
struct Dash {
    r: BufReader<TcpStream>,
    w: TcpStream,
}

impl Dash {
    fn connect(addr: SocketAddr) -> Self {
        let s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(DEADLINE)).unwrap();
        let w = s.try_clone().unwrap();
        let mut d = Self {
            r: BufReader::new(s),
            w,
        };
        assert_eq!(d.line(), "Connected: Universal Robots Dashboard Server");
        d
    }

    fn line(&mut self) -> String {
        let mut l = String::new();
        self.r.read_line(&mut l).unwrap();
        assert!(l.ends_with('\n'), "one reply per line: {l:?}");
        l.trim_end().to_string()
    }

    fn ask(&mut self, cmd: &str) -> String {
        writeln!(self.w, "{cmd}").unwrap();
        self.line()
    }
}

fn dash(sim: &UrSimHandle) -> Dash {
    Dash::connect(sim.dashboard_addr.expect("a dashboard server"))
}

/// The robot mode a new RTDE client sees in its first package.
fn rtde_robot_mode(sim: &UrSimHandle) -> i32 {
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    c.state(&recipe).unwrap().robot_mode
}

#[test]
fn dashboard_replies_as_an_e_series_controller() {
    let sim = start(UrSimConfig::default(), UrModel::Ur5e);
    let mut d = dash(&sim);
    // An e-Series UR5e answers "UR5"; its PolyScope version (5.x) tells it from a CB3 UR5.
    assert_eq!(d.ask("get robot model"), "UR5");
    let serial = d.ask("get serial number");
    assert!(
        serial.starts_with("20") && serial.chars().all(|c| c.is_ascii_digit()),
        "{serial}"
    );
    assert!(
        d.ask("PolyscopeVersion").starts_with("URSoftware 5.12.0"),
        "e-Series"
    );
    assert_eq!(d.ask("robotmode"), "Robotmode: RUNNING");
    assert_eq!(d.ask("safetystatus"), "Safetystatus: NORMAL");
    assert_eq!(d.ask("safetymode"), "Safetymode: NORMAL");
    assert_eq!(d.ask("is in remote control"), "true");
    assert_eq!(d.ask("programState"), "STOPPED <unnamed>");
    assert_eq!(d.ask("running"), "Program running: false");
    assert_eq!(d.ask("close safety popup"), "closing safety popup");
    // Refusals: nothing to stop, nothing loaded to play, no such file, an unknown command.
    assert_eq!(d.ask("stop"), "Failed to execute: stop");
    assert_eq!(d.ask("play"), "Failed to execute: play");
    assert_eq!(
        d.ask("load /programs/x.urp"),
        "File not found: /programs/x.urp"
    );
    assert_eq!(d.ask("get loaded program"), "No program loaded");
    assert_eq!(d.ask("fly away"), "could not understand: 'fly away'");
    // Not protective-stopped: unlocking changes nothing.
    assert_eq!(d.ask("unlock protective stop"), "Protective stop releasing");
    assert_eq!(d.ask("quit"), "Disconnected");
    let mut rest = String::new();
    assert_eq!(d.r.read_line(&mut rest).unwrap(), 0, "closed after quit");
    let sum = sim.stop();
    assert_eq!(sum.programs, 0);
}

/// The newer models answer with their own names (URSim's on PolyScope 5: "UR7" and "UR12" for
/// the UR7e and UR12e, URCL's start_ursim.sh) and a controller version that runs them, the same
/// over the dashboard and RTDE.
#[test]
fn dashboard_and_rtde_name_the_newer_models_and_a_version_that_runs_them() {
    for (model, name, minor) in [
        (UrModel::Ur7e, "UR7", 22),
        (UrModel::Ur12e, "UR12", 22),
        (UrModel::Ur15, "UR15", 22),
        (UrModel::Ur18, "UR18", 23),
        (UrModel::Ur20, "UR20", 14),
        (UrModel::Ur30, "UR30", 15),
    ] {
        let sim = start(UrSimConfig::default(), model);
        let mut d = dash(&sim);
        assert_eq!(d.ask("get robot model"), name, "{model}");
        let want = format!("5.{minor}.0.0");
        assert_eq!(
            d.ask("PolyscopeVersion"),
            format!("URSoftware {want} (hil-sim ur-sim)"),
            "{model}"
        );
        assert_eq!(d.ask("version"), want, "{model}");
        let mut c = ur_protocol::client::Client::connect(sim.rtde_addr, DEADLINE).unwrap();
        let v = c.controller_version().unwrap();
        assert_eq!((v.major, v.minor), (5, minor), "{model}");
        drop(c);
        sim.stop();
    }
}

#[test]
fn dashboard_replies_as_a_cb3_controller() {
    let sim = start(
        UrSimConfig {
            series: Series::Cb3,
            ..UrSimConfig::default()
        },
        UrModel::Ur10,
    );
    let mut d = dash(&sim);
    assert_eq!(d.ask("get robot model"), "UR10");
    assert!(d.ask("PolyscopeVersion").starts_with("URSoftware 3.15.8"));
    assert_eq!(d.ask("safetymode"), "Safetymode: NORMAL");
    // Newer than 3.15: a CB3 does not know them.
    assert_eq!(
        d.ask("safetystatus"),
        "could not understand: 'safetystatus'"
    );
    assert_eq!(
        d.ask("is in remote control"),
        "could not understand: 'is in remote control'"
    );
    sim.stop();
}

#[test]
fn dashboard_power_and_brakes_change_the_robot_mode_and_gate_the_program() {
    let sim = start(
        UrSimConfig {
            start_powered_off: true,
            ..UrSimConfig::default()
        },
        UrModel::Ur5,
    );
    let mut d = dash(&sim);
    assert_eq!(d.ask("robotmode"), "Robotmode: POWER_OFF");
    assert_eq!(rtde_robot_mode(&sim), RobotMode::PowerOff.code());
    // Unpowered or with the brakes on, a program is refused.
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    c.state(&recipe).unwrap();
    send_program_refused(&sim, &mut c, "robot mode is POWER_OFF");
    assert_eq!(d.ask("power on"), "Powering on");
    assert_eq!(d.ask("robotmode"), "Robotmode: IDLE");
    assert_eq!(rtde_robot_mode(&sim), RobotMode::Idle.code());
    send_program_refused(&sim, &mut c, "robot mode is IDLE");
    assert_eq!(d.ask("brake release"), "Brake releasing");
    assert_eq!(d.ask("robotmode"), "Robotmode: RUNNING");
    assert_eq!(rtde_robot_mode(&sim), RobotMode::Running.code());
    // A brake release while powered off powers the arm on first, as a real controller does:
    // the reply is what it does.
    assert_eq!(d.ask("power off"), "Powering off");
    assert_eq!(d.ask("robotmode"), "Robotmode: POWER_OFF");
    assert_eq!(d.ask("brake release"), "Brake releasing");
    assert_eq!(d.ask("robotmode"), "Robotmode: RUNNING");
    assert_eq!(rtde_robot_mode(&sim), RobotMode::Running.code());
    // Now the program runs; `stop` ends it at once (the arm decelerates as with stopj), `power
    // off` ends it.
    let mut rev = run_program(&sim);
    let start_q = TaskConfig::default().start_arm_joints();
    servoj(&mut rev, start_q, 5_000);
    let s = c.state(&recipe).unwrap();
    assert_eq!(s.runtime_state, runtime_state::PLAYING);
    assert_eq!(d.ask("programState"), "PLAYING <unnamed>");
    assert_eq!(d.ask("running"), "Program running: true");
    assert_eq!(d.ask("stop"), "Stopped");
    assert_eq!(d.ask("programState"), "STOPPED <unnamed>");
    assert_eq!(d.ask("running"), "Program running: false");
    assert_eq!(d.ask("stop"), "Failed to execute: stop");
    // The program's next read ends it (the arm steps a cycle): RTDE says STOPPED.
    servoj(&mut rev, start_q, 5_000);
    let t0 = Instant::now();
    while c.state(&recipe).unwrap().runtime_state != runtime_state::STOPPED {
        assert!(t0.elapsed() < DEADLINE, "the program did not stop");
    }
    assert_eq!(d.ask("running"), "Program running: false");
    // `load` names the last program sent; `play` runs it again.
    assert_eq!(
        d.ask("load /programs/external_control.urp"),
        "Loading program: /programs/external_control.urp"
    );
    assert_eq!(
        d.ask("get loaded program"),
        "Loaded program: /programs/external_control.urp"
    );
    let listener_gone = d.ask("play");
    // The program connects back to the listener of the first run, which is gone: it starts
    // and ends at once, as on a robot whose PC is not listening.
    assert_eq!(listener_gone, "Starting program");
    assert_eq!(d.ask("power off"), "Powering off");
    assert_eq!(d.ask("robotmode"), "Robotmode: POWER_OFF");
    assert_eq!(rtde_robot_mode(&sim), RobotMode::PowerOff.code());
    assert_eq!(d.ask("play"), "Failed to execute: play");
    assert_eq!(d.ask("running"), "Program running: false");
    let sum = sim.stop();
    assert_eq!(sum.programs, 2, "{sum:?}");
    assert_eq!(sum.refused_scripts, 2, "{sum:?}");
}

/// Sends the program; ur-sim refuses it with a text message containing `why`.
fn send_program_refused(sim: &UrSimHandle, c: &mut Client, why: &str) {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let p = ur_protocol::script::ScriptParams::new(
        "127.0.0.1".parse().unwrap(),
        listener.local_addr().unwrap().port(),
        Series::E.cycle_s(),
    );
    let mut sec = TcpStream::connect(sim.secondary_addr).unwrap();
    sec.write_all(ur_protocol::script::render(super::ur_sim::PROGRAM, &p).as_bytes())
        .unwrap();
    drop(sec);
    let t = c.next_text().expect("a text message");
    assert!(t.contains("program not started") && t.contains(why), "{t}");
}

/// A protective stop raised by a servoj target outside the limits; returns the RTDE client and
/// the stop's arm cycle.
fn protective_stop(sim: &UrSimHandle) -> (Client, ur_protocol::OutputRecipe, TcpStream, u64) {
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    c.state(&recipe).unwrap();
    let mut rev = run_program(sim);
    servoj(&mut rev, [0.0, -2.0, 100.0], 5_000);
    let s = c.state(&recipe).unwrap();
    assert_eq!(s.safety_mode, SafetyMode::ProtectiveStop.code());
    let stop_cycle = (s.timestamp / Series::E.cycle_s()).round() as u64;
    (c, recipe, rev, stop_cycle)
}

#[test]
fn dashboard_refuses_to_unlock_a_protective_stop_within_5_s() {
    // The arm's clock frozen in the stop: no arm time passes, every unlock is refused.
    let sim = start(
        UrSimConfig {
            stopped_clock: false,
            ..UrSimConfig::default()
        },
        UrModel::Ur5,
    );
    let (_c, _recipe, _rev, _) = protective_stop(&sim);
    let mut d = dash(&sim);
    for _ in 0..3 {
        assert_eq!(
            d.ask("unlock protective stop"),
            ur_sim::dashboard::UNLOCK_TOO_EARLY
        );
    }
    assert_eq!(d.ask("safetystatus"), "Safetystatus: PROTECTIVE_STOP");
    // A program is refused in the stop.
    assert_eq!(
        d.ask("load external_control.urp"),
        "Loading program: external_control.urp"
    );
    assert_eq!(d.ask("play"), "Failed to execute: play");
    sim.stop();
}

#[test]
fn dashboard_unlocks_a_protective_stop_5_s_of_arm_time_after_it() {
    // Lockstep; the arm's clock runs while it stands in the stop (10x faster than wall time
    // here). Each unlock is judged against the arm time ur-sim reports just before and after it.
    let sim = start(
        UrSimConfig {
            time_compression: 10.0,
            ..UrSimConfig::default()
        },
        UrModel::Ur5,
    );
    let dt = Series::E.cycle_s();
    let (mut c, recipe, _rev, stop_cycle) = protective_stop(&sim);
    let mut d = dash(&sim);
    assert_eq!(d.ask("safetystatus"), "Safetystatus: PROTECTIVE_STOP");
    assert_eq!(d.ask("safetymode"), "Safetymode: PROTECTIVE_STOP");
    let (mut refused, t0) = (0, Instant::now());
    loop {
        assert!(t0.elapsed() < DEADLINE, "never unlocked");
        let before = sim.summary().cycles;
        let reply = d.ask("unlock protective stop");
        let after = sim.summary().cycles;
        let since = |c: u64| (c - stop_cycle) as f64 * dt;
        if reply == "Protective stop releasing" {
            assert!(
                since(after) >= 5.0,
                "unlocked {} s after the stop",
                since(after)
            );
            break;
        }
        assert_eq!(reply, ur_sim::dashboard::UNLOCK_TOO_EARLY);
        assert!(
            since(before) < 5.0,
            "refused {} s after the stop",
            since(before)
        );
        refused += 1;
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    eprintln!("{refused} unlocks refused before 5 s of arm time had passed");
    assert_eq!(d.ask("safetystatus"), "Safetystatus: NORMAL");
    // Unlocked, the program can run again.
    let mut rev = run_program(&sim);
    servoj(&mut rev, TaskConfig::default().start_arm_joints(), 5_000);
    let t0 = Instant::now();
    loop {
        assert!(t0.elapsed() < DEADLINE);
        let s = c.state(&recipe).unwrap();
        if s.runtime_state == runtime_state::PLAYING {
            assert_eq!(s.safety_mode, SafetyMode::Normal.code());
            break;
        }
    }
    let sum = sim.stop();
    assert_eq!((sum.protective_stops, sum.programs), (1, 2), "{sum:?}");
}

/// Freedrive needs a powered arm with its brakes released: a playback does not move an arm
/// that is powered off (it waits where the file is, at rest) and plays on once `power on` and
/// `brake release` have made it RUNNING. Real time at 10 times; the assertions are on arm time.
#[test]
fn a_playback_moves_the_arm_only_while_it_runs() {
    let dir = std::env::temp_dir().join(format!("ur-sim-playback-off-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("reach.csv");
    let w = "-1.5707963267948966,1.5707963267948966,0";
    // 1 s from q0 = 0 to 0.1 rad, a row every 0.1 s.
    let rows: String = (0..=10)
        .map(|k| format!("{},{},-2,2.4,{w}\n", k as f64 * 0.1, k as f64 * 0.01))
        .collect();
    std::fs::write(&csv, format!("t,q0,q1,q2,q3,q4,q5\n{rows}")).unwrap();
    let sim = ur_sim::spawn(
        &TaskConfig::default(),
        &SimConfig::default(),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            dashboard_port: Some(0),
            time_compression: 10.0,
            start_powered_off: true,
            playback: Some(csv),
            ..UrSimConfig::default()
        },
    )
    .expect("ur-sim starts");
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    let t0 = c.state(&recipe).unwrap().timestamp;
    // Powered off for 2 s of arm time: where the file starts, at rest.
    loop {
        let s = c.state(&recipe).unwrap();
        assert_eq!(s.robot_mode, RobotMode::PowerOff.code());
        assert_eq!(
            (s.actual_q[0], s.actual_qd[0]),
            (0.0, 0.0),
            "at {} s",
            s.timestamp
        );
        if s.timestamp > t0 + 2.0 {
            break;
        }
    }
    let mut d = dash(&sim);
    assert_eq!(d.ask("power on"), "Powering on");
    assert_eq!(d.ask("brake release"), "Brake releasing");
    // Running: the file plays (1 s), then the arm holds its last row.
    let deadline = Instant::now() + DEADLINE;
    let t1 = loop {
        let s = c.state(&recipe).unwrap();
        if s.robot_mode == RobotMode::Running.code() {
            break s.timestamp;
        }
        assert!(Instant::now() < deadline, "never RUNNING");
    };
    let last = loop {
        let s = c.state(&recipe).unwrap();
        if s.timestamp > t1 + 2.0 {
            break s;
        }
    };
    assert!(
        (last.actual_q[0] - 0.1).abs() < 1e-12,
        "{:?}",
        last.actual_q
    );
    sim.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// Two of ur-sim's servers on one port are refused, naming both options (was the OS's
/// "Address already in use" naming neither).
#[test]
fn two_servers_on_one_port_are_named() {
    let e = ur_sim::spawn(
        &TaskConfig::default(),
        &SimConfig::default(),
        &UrSimConfig {
            rtde_port: 30977,
            secondary_port: 30977,
            ..UrSimConfig::default()
        },
    )
    .err()
    .expect("refused")
    .to_string();
    assert!(
        e.contains(
            "rtde_port (--rtde-port) and secondary_port (--secondary-port) are both port 30977"
        ),
        "{e}"
    );
}
