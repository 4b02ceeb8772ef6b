//! `hil-sim ur-sim` against a minimal RTDE client built on `ur-protocol`:
//! handshake, recipes, START, servoj over the reverse interface in lockstep, the program's
//! receive-timeout stop, a protective stop, refused scripts, and every fault injection.
//!
//! Deterministic by construction: motion tests run in lockstep (one package per command) and
//! assert on event order and on sim values, never on wall-clock timing; waits have generous
//! deadlines that only bound a hang.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use hil_sim::ur_sim::{self, Faults, Series, UrSimConfig, UrSimHandle};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur_protocol::client::{self, ClientError, OwnedFrame};
use ur_protocol::recipe::{OutputRecipe, RecipeError};
use ur_protocol::rtde::{Protocol, TextMessage};
use ur_protocol::script::{self, ScriptParams};
use ur_protocol::state::runtime_state;
use ur_protocol::{
    ClientMessage, ControlMode, ReverseCommand, RobotMessage, RobotState, SafetyMode,
};

pub(super) const PROGRAM: &str =
    include_str!("../../../rt-controller/urscript/external_control.script");
const NAMES: &str =
    "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state,speed_scaling,";
/// Bounds a hang, never a measurement.
pub(super) const DEADLINE: Duration = Duration::from_secs(20);

fn start(lockstep: bool, faults: Faults) -> UrSimHandle {
    let cfg = UrSimConfig {
        rtde_port: 0,
        secondary_port: 0,
        lockstep,
        faults,
        ..UrSimConfig::default()
    };
    ur_sim::spawn(&TaskConfig::default(), &SimConfig::default(), &cfg).expect("ur-sim starts")
}

/// The shared RTDE client ([`ur_protocol::client`]) with the tests' conveniences: each step
/// bounded by [`DEADLINE`], a failure that is not under test a panic.
pub(super) struct Client(client::Client);

impl std::ops::Deref for Client {
    type Target = client::Client;
    fn deref(&self) -> &client::Client {
        &self.0
    }
}

impl std::ops::DerefMut for Client {
    fn deref_mut(&mut self) -> &mut client::Client {
        &mut self.0
    }
}

/// A frame decoded (the server's frames are well formed).
trait Msg {
    fn msg(&self, p: Protocol) -> RobotMessage<'_>;
}

impl Msg for OwnedFrame {
    fn msg(&self, p: Protocol) -> RobotMessage<'_> {
        self.decode(p, "test").expect("well-formed package")
    }
}

/// A clear message for a failed read.
fn why(e: ClientError) -> String {
    match e {
        ClientError::Closed(_) => "connection closed by the controller".into(),
        e => e.to_string(),
    }
}

impl Client {
    fn connect(addr: SocketAddr) -> Self {
        Self(client::Client::connect(addr, DEADLINE).unwrap())
    }

    fn send(&mut self, m: ClientMessage<'_>) {
        self.0.send(m, "test").unwrap();
    }

    /// The next frame of any type; `Err` with a clear message on a closed connection.
    fn next_any(&mut self) -> Result<OwnedFrame, String> {
        self.0.restart_deadline(DEADLINE);
        self.0.next_frame("test").map_err(why)
    }

    /// The next frame that is not a text message; text messages are kept in `texts`.
    fn next(&mut self) -> Result<OwnedFrame, String> {
        self.0.restart_deadline(DEADLINE);
        self.0.next("test").map_err(why)
    }

    /// Reads frames until a text message (v2) and returns it.
    pub(super) fn next_text(&mut self) -> Result<String, String> {
        loop {
            let f = self.next_any()?;
            if let RobotMessage::TextMessage(TextMessage::V2 { message, .. }) = f.msg(self.protocol)
            {
                return Ok(message.to_owned());
            }
        }
    }

    fn negotiate(&mut self, version: u16) -> bool {
        self.0.restart_deadline(DEADLINE);
        self.0.request_protocol(version).unwrap()
    }

    fn setup(&mut self, names: &str) -> Result<OutputRecipe, RecipeError> {
        self.0.restart_deadline(DEADLINE);
        match self.0.setup_outputs(names, 500.0) {
            Ok(r) => Ok(r),
            Err(ClientError::Recipe(e)) => Err(e),
            Err(e) => panic!("SETUP_OUTPUTS: {e}"),
        }
    }

    fn start(&mut self) -> bool {
        self.0.restart_deadline(DEADLINE);
        match self.0.start() {
            Ok(()) => true,
            Err(ClientError::StartRefused) => false,
            Err(e) => panic!("START: {e}"),
        }
    }

    /// Handshake v2, the driver's recipe, START.
    pub(super) fn ready(addr: SocketAddr) -> (Self, OutputRecipe) {
        let mut c = Self::connect(addr);
        assert!(c.negotiate(2));
        let r = c.setup(NAMES).expect("usable recipe");
        assert!(c.start());
        (c, r)
    }

    pub(super) fn state(&mut self, recipe: &OutputRecipe) -> Result<RobotState, String> {
        self.0.restart_deadline(DEADLINE);
        self.0.state(recipe).map_err(why)
    }
}

/// Sends the project's program with a reverse listener; returns the accepted reverse socket.
pub(super) fn run_program(sim: &UrSimHandle) -> TcpStream {
    run_program_with(sim, |_| {})
}

/// [`run_program`] with the parameters changed by `edit` (servoj's lookahead and gain).
pub(super) fn run_program_with(sim: &UrSimHandle, edit: impl Fn(&mut ScriptParams)) -> TcpStream {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let mut params = ScriptParams::new(
        "127.0.0.1".parse().unwrap(),
        listener.local_addr().unwrap().port(),
        Series::E.cycle_s(),
    );
    edit(&mut params);
    let mut sec = TcpStream::connect(sim.secondary_addr).unwrap();
    sec.write_all(script::render(PROGRAM, &params).as_bytes())
        .unwrap();
    drop(sec);
    listener.set_nonblocking(true).unwrap();
    let t0 = Instant::now();
    loop {
        match listener.accept() {
            Ok((s, _)) => {
                s.set_nonblocking(false).unwrap();
                s.set_nodelay(true).unwrap();
                return s;
            }
            Err(_) if t0.elapsed() < DEADLINE => std::thread::sleep(Duration::from_millis(2)),
            Err(e) => panic!("the program did not connect back: {e}"),
        }
    }
}

pub(super) fn servoj(rev: &mut TcpStream, q3: [f64; 3], timeout_ms: i32) {
    let w = SimConfig::default().wrist_q;
    let cmd = ReverseCommand {
        timeout_ms,
        q: [q3[0], q3[1], q3[2], w[0], w[1], w[2]],
        mode: ControlMode::Servoj,
    };
    rev.write_all(&cmd.encode().unwrap()).unwrap();
}

fn dist(q: &[f64; 6], t: [f64; 3]) -> f64 {
    (0..3).map(|j| (q[j] - t[j]).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn ur_lockstep_servoj_moves_the_arm_and_a_silent_controller_stops_it() {
    let sim = start(true, Faults::default());
    let mut c = Client::connect(sim.rtde_addr);
    assert!(c.negotiate(2), "v2 accepted");
    c.send(ClientMessage::GetUrcontrolVersion);
    let RobotMessage::UrcontrolVersion(v) = c.next().unwrap().msg(c.protocol) else {
        panic!("expected the controller version")
    };
    assert!(v.is_e_series() && v.max_frequency_hz() == 500.0, "{v}");
    // An unknown name: NOT_FOUND, an error naming it.
    let e = c.setup("timestamp,no_such_output").unwrap_err();
    assert!(e.to_string().contains("no_such_output"), "{e}");
    // The driver's recipe with ur_rtde's trailing comma.
    let recipe = c.setup(NAMES).expect("usable recipe");
    assert!(c.start());

    let s0 = c.state(&recipe).unwrap();
    let start_q = TaskConfig::default().start_arm_joints();
    assert!(dist(&s0.actual_q, start_q) < 1e-5, "{:?}", s0.actual_q);
    assert_eq!(s0.robot_mode, 7, "RUNNING");
    assert_eq!(s0.safety_mode, SafetyMode::Normal.code());
    assert_eq!(s0.runtime_state, runtime_state::STOPPED);

    let mut rev = run_program(&sim);
    let target = [start_q[0] + 0.3, start_q[1] + 0.2, start_q[2] - 0.2];
    let d0 = dist(&s0.actual_q, target);
    let mut last = s0;
    for i in 1..=500u32 {
        // A generous timeout while moving: the watchdog must not fire under load.
        servoj(&mut rev, target, 5_000);
        let s = c.state(&recipe).unwrap();
        // Lockstep: exactly one 2 ms arm cycle per command.
        assert_eq!(s.timestamp, f64::from(i) * 0.002, "package {i}");
        assert_eq!(s.runtime_state, runtime_state::PLAYING);
        last = s;
    }
    let d1 = dist(&last.actual_q, target);
    assert!(
        d1 < 0.05 * d0,
        "after 1 s the arm is near its target: {d1} of {d0} rad"
    );

    // The controller goes silent after a command with a 100 ms timeout: the program stops the
    // arm (stopj) and ends.
    let moving_to = [start_q[0] - 0.5, start_q[1] - 0.3, start_q[2] + 0.3];
    for _ in 0..50 {
        servoj(&mut rev, moving_to, 5_000);
        c.state(&recipe).unwrap();
    }
    servoj(&mut rev, moving_to, 100);
    last = c.state(&recipe).unwrap();
    let moving = last.actual_qd.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(
        moving > 0.1,
        "the arm is moving when the controller stops: {moving} rad/s"
    );
    let t_silent = last.timestamp;
    let t0 = Instant::now();
    while last.runtime_state != runtime_state::STOPPED {
        assert!(t0.elapsed() < DEADLINE, "the program did not stop");
        last = c.state(&recipe).unwrap();
    }
    // stopj(4.0) from v needs v / 4 s; the servo's exponential approach to the stopping point
    // takes longer (1.06 s from 3.09 rad/s, design §3.10): at rest within twice the ideal.
    let stop_s = last.timestamp - t_silent;
    eprintln!("stopj from {moving:.3} rad/s took {stop_s:.3} s of arm time");
    assert!(
        stop_s > 0.0 && stop_s < 2.0 * moving / 4.0,
        "stop took {stop_s} s"
    );
    let still = last.actual_qd.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(still < 1e-3, "held at rest: {still} rad/s");
    assert!(
        dist(&last.actual_q, moving_to) > 0.1,
        "stopped short of the target"
    );
    assert!(
        c.texts().iter().any(|t| t.contains("receive timeout")),
        "{:?}",
        c.texts()
    );
    // The reverse socket is closed by the ended program.
    let mut b = [0u8; 1];
    assert_eq!(rev.read(&mut b).unwrap_or(0), 0);
    let sum = sim.stop();
    assert_eq!(sum.receive_timeouts, 1);
    assert_eq!(sum.programs, 1);
    assert_eq!(sum.protective_stops, 0);
}

#[test]
fn ur_limit_violation_raises_a_protective_stop() {
    let sim = start(true, Faults::default());
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    c.state(&recipe).unwrap();
    let mut rev = run_program(&sim);
    servoj(&mut rev, [0.0, -2.0, 100.0], 5_000);
    let mut s = c.state(&recipe).unwrap();
    assert_eq!(s.safety_mode, SafetyMode::ProtectiveStop.code());
    let t0 = Instant::now();
    while s.runtime_state != runtime_state::STOPPED {
        assert!(t0.elapsed() < DEADLINE);
        s = c.state(&recipe).unwrap();
    }
    assert_eq!(s.safety_mode, 3);
    assert!(
        c.texts()
            .iter()
            .any(|t| t.contains("protective stop") && t.contains("elbow")),
        "{:?}",
        c.texts()
    );
    assert_eq!(sim.stop().protective_stops, 1);
}

#[test]
fn ur_other_scripts_are_refused_with_a_text_message() {
    let sim = start(true, Faults::default());
    let mut c = Client::connect(sim.rtde_addr);
    assert!(c.negotiate(2));
    let mut sec = TcpStream::connect(sim.secondary_addr).unwrap();
    sec.write_all(b"def prog():\n  movej([0,0,0,0,0,0])\nend\n")
        .unwrap();
    drop(sec);
    let f = c.next_any().unwrap();
    let RobotMessage::TextMessage(TextMessage::V2 { message, .. }) = f.msg(c.protocol) else {
        panic!("expected a text message")
    };
    assert!(message.contains("was not run"), "{message}");
    // The program template itself (placeholders not filled in) is refused too.
    let mut sec = TcpStream::connect(sim.secondary_addr).unwrap();
    sec.write_all(PROGRAM.as_bytes()).unwrap();
    drop(sec);
    let f = c.next_any().unwrap();
    let RobotMessage::TextMessage(TextMessage::V2 { message, .. }) = f.msg(c.protocol) else {
        panic!("expected a text message")
    };
    assert!(message.contains("placeholder"), "{message}");
    let sum = sim.stop();
    assert_eq!((sum.refused_scripts, sum.programs), (2, 0));
}

#[test]
fn ur_input_registers_taken_by_another_client_are_in_use() {
    let sim = start(true, Faults::default());
    let setup_inputs = |c: &mut Client, names: &str| {
        c.send(ClientMessage::SetupInputs { names });
        let f = c.next().unwrap();
        let RobotMessage::SetupInputs { recipe_id, types } = f.msg(c.protocol) else {
            panic!("expected a SETUP_INPUTS answer")
        };
        (recipe_id, types.to_owned())
    };
    let mut a = Client::connect(sim.rtde_addr);
    assert!(a.negotiate(2));
    let (id, types) = setup_inputs(&mut a, "input_int_register_24,input_double_register_24");
    assert!(id > 0);
    assert_eq!(types, "INT32,DOUBLE");
    let mut b = Client::connect(sim.rtde_addr);
    assert!(b.negotiate(2));
    let (_, types) = setup_inputs(&mut b, "input_int_register_24,input_int_register_25,bogus");
    assert_eq!(types, "IN_USE,INT32,NOT_FOUND");
    // Released when the first client leaves.
    drop(a);
    let t0 = Instant::now();
    loop {
        let (_, types) = setup_inputs(&mut b, "input_int_register_24");
        if types == "INT32" {
            break;
        }
        assert!(t0.elapsed() < DEADLINE, "register not released");
        std::thread::sleep(Duration::from_millis(10));
    }
    sim.stop();
}

#[test]
fn ur_fault_version_refusals() {
    let sim = start(
        true,
        Faults {
            refuse_v2: true,
            ..Faults::default()
        },
    );
    let mut c = Client::connect(sim.rtde_addr);
    assert!(!c.negotiate(2), "v2 refused");
    assert!(c.negotiate(1), "v1 fallback accepted");
    // v1: SETUP_OUTPUTS without frequency.
    let recipe = c.setup(NAMES).unwrap();
    assert!(c.start());
    assert!(c.state(&recipe).is_ok());
    sim.stop();

    let sim = start(
        true,
        Faults {
            refuse_versions: true,
            ..Faults::default()
        },
    );
    let mut c = Client::connect(sim.rtde_addr);
    assert!(!c.negotiate(2));
    assert!(!c.negotiate(1));
    sim.stop();
}

#[test]
fn ur_fault_text_before_reply_and_refused_start() {
    let sim = start(
        true,
        Faults {
            text_before_reply: true,
            refuse_start: true,
            ..Faults::default()
        },
    );
    let mut c = Client::connect(sim.rtde_addr);
    assert!(c.negotiate(2));
    c.setup(NAMES).unwrap();
    assert!(!c.start(), "START refused");
    assert_eq!(
        c.texts().len(),
        3,
        "one text before each answer: {:?}",
        c.texts()
    );
    sim.stop();
}

/// Real-time stream with a fault; returns the decoded states (or the error that ended them).
fn stream_with(faults: Faults, n: usize) -> (Vec<RobotState>, Option<String>) {
    let sim = start(false, faults);
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    let mut out = Vec::new();
    let mut err = None;
    for _ in 0..n {
        match c.state(&recipe) {
            Ok(s) => out.push(s),
            Err(e) => {
                err = Some(e);
                break;
            }
        }
    }
    sim.stop();
    (out, err)
}

fn cycles(states: &[RobotState]) -> Vec<i64> {
    states
        .iter()
        .map(|s| (s.timestamp / 0.002).round() as i64)
        .collect()
}

#[test]
fn ur_fault_merged_split_delayed_dropped_and_closed_streams_decode_cleanly() {
    // Merged (with a repeat of the previous package) and split packages: all decode, in order.
    let (s, err) = stream_with(
        Faults {
            merge_split: true,
            ..Faults::default()
        },
        30,
    );
    assert!(err.is_none(), "{err:?}");
    let c = cycles(&s);
    assert!(c.windows(2).all(|w| w[1] >= w[0]), "{c:?}");
    assert!(
        c.windows(2).any(|w| w[1] == w[0]),
        "a repeated package is seen: {c:?}"
    );

    // Every 2nd package dropped: cycles advance by at least 2 after the first.
    let (s, err) = stream_with(
        Faults {
            drop_every: 2,
            ..Faults::default()
        },
        10,
    );
    assert!(err.is_none(), "{err:?}");
    let c = cycles(&s);
    assert!(c[1..].windows(2).all(|w| w[1] - w[0] >= 2), "{c:?}");

    // Every 3rd package 30 ms late: still in order.
    let (s, err) = stream_with(
        Faults {
            delay_every: 3,
            delay_ms: 30,
            ..Faults::default()
        },
        10,
    );
    assert!(err.is_none(), "{err:?}");
    assert!(cycles(&s).windows(2).all(|w| w[1] > w[0]));

    // Connection closed after 5 packages: a clear error, no panic.
    let (s, err) = stream_with(
        Faults {
            disconnect_after: 5,
            ..Faults::default()
        },
        10,
    );
    assert_eq!(s.len(), 5);
    assert_eq!(err.as_deref(), Some("connection closed by the controller"));
}

#[test]
fn ur_binary_prints_its_ports_and_answers_rtde() {
    use std::io::BufRead;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .args([
            "ur-sim",
            "--rtde-port",
            "0",
            "--secondary-port",
            "0",
            "--dashboard-port",
            "0",
            "--lockstep",
            "--series",
            "cb3",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let v: serde_json::Value = serde_json::from_str(&line).expect(&line);
    let addr: SocketAddr = v["rtde"].as_str().unwrap().parse().unwrap();
    let mut c = Client::connect(addr);
    assert!(c.negotiate(2));
    c.send(ClientMessage::GetUrcontrolVersion);
    let RobotMessage::UrcontrolVersion(ver) = c.next().unwrap().msg(c.protocol) else {
        panic!()
    };
    assert_eq!((ver.major, ver.max_frequency_hz()), (3, 125.0));
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn ur_real_time_servoj_and_the_watchdog_stop() {
    // Real time x5: the arm's own clock, a command per package; only event order is asserted.
    let cfg = UrSimConfig {
        rtde_port: 0,
        secondary_port: 0,
        time_compression: 5.0,
        ..UrSimConfig::default()
    };
    let sim = ur_sim::spawn(&TaskConfig::default(), &SimConfig::default(), &cfg).unwrap();
    let (mut c, recipe) = Client::ready(sim.rtde_addr);
    let s0 = c.state(&recipe).unwrap();
    let start_q = TaskConfig::default().start_arm_joints();
    let target = [start_q[0] + 0.2, start_q[1], start_q[2]];
    let mut rev = run_program(&sim);
    let mut last = s0;
    let t0 = Instant::now();
    while dist(&last.actual_q, target) > 0.01 {
        assert!(
            t0.elapsed() < DEADLINE,
            "never reached the target: {:?}",
            last.actual_q
        );
        servoj(&mut rev, target, 5_000);
        last = c.state(&recipe).unwrap();
        assert_eq!(last.safety_mode, SafetyMode::Normal.code());
    }
    assert!(last.timestamp > s0.timestamp);
    // Silence after a 20 ms timeout (4 ms of wall time at x5): the program stops and ends.
    servoj(&mut rev, target, 20);
    while last.runtime_state != runtime_state::STOPPED {
        assert!(t0.elapsed() < DEADLINE, "the program did not stop");
        last = c.state(&recipe).unwrap();
    }
    let sum = sim.stop();
    assert_eq!((sum.receive_timeouts, sum.programs), (1, 1));
}

impl Client {
    /// SETUP_OUTPUTS with any names: (recipe id, types).
    fn setup_raw(&mut self, names: &str) -> (u8, String) {
        self.send(ClientMessage::SetupOutputs {
            frequency: Some(500.0),
            names,
        });
        let f = self.next().expect("an answer, not a closed connection");
        let RobotMessage::SetupOutputs { recipe_id, types } = f.msg(self.protocol) else {
            panic!("expected a SETUP_OUTPUTS answer, got {:?}", f.kind)
        };
        (recipe_id, types.to_owned())
    }

    /// SETUP_INPUTS with any names: (recipe id, types).
    fn setup_inputs_raw(&mut self, names: &str) -> (u8, String) {
        self.send(ClientMessage::SetupInputs { names });
        let f = self.next().expect("an answer, not a closed connection");
        let RobotMessage::SetupInputs { recipe_id, types } = f.msg(self.protocol) else {
            panic!("expected a SETUP_INPUTS answer, got {:?}", f.kind)
        };
        (recipe_id, types.to_owned())
    }
}

#[test]
fn ur_recipes_it_cannot_set_up_are_refused_and_the_server_serves_on() {
    let sim = start(true, Faults::default());
    let mut c = Client::connect(sim.rtde_addr);
    assert!(c.negotiate(2));
    // 65 known names (a panic of the connection thread before): recipe id 0, a text saying why.
    let many: Vec<String> = (0..65)
        .map(|i| format!("output_int_register_{}", i % 48))
        .collect();
    let (id, types) = c.setup_raw(&many.join(","));
    assert_eq!(id, 0, "{types}");
    assert_eq!(types.split(',').count(), 65, "one type per name: {types}");
    // 64 names that are all there, answered with recipe id 0: the client names the refusal.
    assert_eq!(
        OutputRecipe::from_answer(
            &many[..64].join(","),
            0,
            &types[..types.rfind(',').unwrap()]
        ),
        Err(RecipeError::Refused)
    );
    assert!(
        c.texts()
            .iter()
            .any(|t| t.contains("65 variables") && t.contains("at most 64")),
        "{:?}",
        c.texts()
    );
    // 64 is the most: accepted.
    let (id, _) = c.setup_raw(&many[..64].join(","));
    assert!(id > 0);
    // 5000 unknown names: their answer (50 kB) would not fit a client's buffer; refused with an
    // empty list.
    let huge = vec!["x"; 5000].join(",");
    assert_eq!(c.setup_raw(&huge), (0, String::new()));
    // Inputs: 65 names refused, and the registers stay free.
    let inputs: Vec<String> = (0..65)
        .map(|i| format!("input_double_register_{}", i % 48))
        .collect();
    let (id, _) = c.setup_inputs_raw(&inputs.join(","));
    assert_eq!(id, 0);
    // Empty recipes (nothing, or only ur_rtde's empty names): refused as a controller does.
    for empty in ["", ",", ",,"] {
        c.take_texts();
        assert_eq!(c.setup_raw(empty), (0, String::new()), "{empty:?}");
        assert!(
            c.texts().iter().any(|t| t.contains("names no variable")),
            "{empty:?}: {:?}",
            c.texts()
        );
        assert_eq!(c.setup_inputs_raw(empty).0, 0, "{empty:?}");
    }
    assert_eq!(
        c.setup("").unwrap_err(),
        RecipeError::Refused,
        "the client names the refusal"
    );
    // The client's own text messages (RTDE v2 TEXT_MESSAGE from a client) are accepted.
    let mut buf = [0u8; 256];
    let n = ClientMessage::TextMessage(TextMessage::V2 {
        message: "hello from the client",
        source: "test",
        level: 3,
    })
    .encode(&mut buf)
    .unwrap();
    c.socket().write_all(&buf[..n]).unwrap();
    let recipe = c.setup(NAMES).expect("the same connection still serves");
    let (id, types) = c.setup_inputs_raw("input_double_register_0");
    assert!(id > 0, "{types}");
    assert!(c.start());
    c.state(&recipe).expect("packages after all that");
    // Another client is served too.
    let (mut d, r) = Client::ready(sim.rtde_addr);
    d.state(&r).expect("a second client gets packages");
    sim.stop();
}

#[test]
fn ur_a_stopped_and_continued_ur_sim_keeps_its_rtde_clients() {
    use std::io::BufRead;
    // Real time: SIGSTOP/SIGCONT interrupts the connection thread's read (EINTR, even without
    // a signal handler, for a socket with a read timeout); the client must keep its stream.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .args(["ur-sim", "--rtde-port", "0", "--secondary-port", "0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let v: serde_json::Value = serde_json::from_str(&line).expect(&line);
    let addr: SocketAddr = v["rtde"].as_str().unwrap().parse().unwrap();
    let (mut c, recipe) = Client::ready(addr);
    let mut last = c.state(&recipe).unwrap().timestamp;
    let signal = |sig: &str| {
        let ok = std::process::Command::new("kill")
            .args([sig, &child.id().to_string()])
            .status()
            .unwrap()
            .success();
        assert!(ok, "kill {sig}");
    };
    for round in 0..3 {
        signal("-STOP");
        // A pause long enough for a few of the server's 50 ms read timeouts to be due.
        std::thread::sleep(Duration::from_millis(120));
        signal("-CONT");
        // The stream goes on: 50 more packages, the arm's clock advancing.
        for _ in 0..50 {
            let s = c
                .state(&recipe)
                .unwrap_or_else(|e| panic!("round {round}: the stream ended: {e}"));
            assert!(s.timestamp >= last, "round {round}");
            last = s.timestamp;
        }
    }
    // A new client is served as well.
    let (mut d, r) = Client::ready(addr);
    d.state(&r).expect("a new client after SIGCONT");
    child.kill().unwrap();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("Interrupted"), "{err}");
}

/// `ur-sim` with six active joints: servoj moves the wrist too, and RTDE reports all six
/// joints where the shared kinematics put them; a three-joint `ur-sim` keeps its wrist locked
/// under the same targets.
#[test]
fn ur_six_joint_servoj_moves_the_wrist() {
    for joints in [6, 3] {
        let cfg = UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            lockstep: true,
            joints,
            ..UrSimConfig::default()
        };
        let sim = ur_sim::spawn(&TaskConfig::default(), &SimConfig::default(), &cfg)
            .expect("ur-sim starts");
        let mut c = Client::connect(sim.rtde_addr);
        assert!(c.negotiate(2));
        let recipe = c.setup(NAMES).expect("usable recipe");
        assert!(c.start());
        let s0 = c.state(&recipe).unwrap();
        let w = SimConfig::default().wrist_q;
        let start_q = TaskConfig::default().start_arm_joints();
        let target = [
            start_q[0] + 0.2,
            start_q[1] + 0.1,
            start_q[2] - 0.1,
            w[0] + 0.4,
            w[1] - 0.3,
            w[2] + 0.5,
        ];
        let mut rev = run_program(&sim);
        let mut last = s0;
        for _ in 0..1000 {
            let cmd = ReverseCommand {
                timeout_ms: 5_000,
                q: target,
                mode: ControlMode::Servoj,
            };
            rev.write_all(&cmd.encode().unwrap()).unwrap();
            last = c.state(&recipe).unwrap();
        }
        let err: Vec<f64> = (0..6)
            .map(|j| (last.actual_q[j] - target[j]).abs())
            .collect();
        if joints == 6 {
            assert!(err.iter().all(|e| *e < 1e-3), "six joints: {err:?}");
        } else {
            assert!(err[..3].iter().all(|e| *e < 1e-3), "arm: {err:?}");
            for k in 0..3 {
                assert_eq!(last.actual_q[3 + k], w[k], "the locked wrist stays");
            }
        }
    }
}
