//! `hil-sim serve` as an arm driver, driven by this test over iceoryx2: resets, one state per
//! command in lockstep, zero-order hold and stale-command hold in real time, and rejected
//! commands reported in `faults`. Behaviour only, no latency assertions.

use std::time::{Duration, Instant};

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use integration_tests::{json_summary, scratch, unique_prefix, write_config, Proc};
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{ArmCommand, ArmFaults, ArmState, ArmStatus};

const LONG: Duration = Duration::from_secs(30);

type CmdService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, ArmCommand, ()>;

struct Driver {
    cmd: Publisher<ipc::Service, ArmCommand, ()>,
    cmd_service: CmdService,
    state: Subscriber<ipc::Service, ArmState, ()>,
    seq: u64,
    _node: Node<ipc::Service>,
}

impl Driver {
    fn new(prefix: &str) -> Self {
        set_log_level_from_env_or(LogLevel::Error);
        let names = ServiceNames::new(prefix);
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .unwrap();
        let c = services::ARM_COMMAND_QOS
            .open_or_create_retrying::<ArmCommand>(&node, &names.arm_command)
            .unwrap();
        let s = services::ARM_STATE_QOS
            .open_or_create_retrying::<ArmState>(&node, &names.arm_state)
            .unwrap();
        Self {
            cmd: c.publisher_builder().create().unwrap(),
            cmd_service: c,
            state: s.subscriber_builder().create().unwrap(),
            seq: 0,
            _node: node,
        }
    }

    /// Waits until the arm's command subscriber is registered, so no command is lost.
    fn wait_for_arm_subscriber(&self) {
        let t0 = Instant::now();
        while self.cmd_service.dynamic_config().number_of_subscribers() == 0 {
            assert!(
                t0.elapsed() < LONG,
                "the arm never subscribed to arm/command"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The next state satisfying `ok`.
    fn wait_state(&self, sim: &mut Proc, what: &str, ok: impl Fn(&ArmState) -> bool) -> ArmState {
        let t0 = Instant::now();
        loop {
            if let Some(s) = self.state.receive().unwrap() {
                if ok(&s) {
                    return *s;
                }
            }
            assert!(
                sim.running() && t0.elapsed() < LONG,
                "no state with {what}; sim log:\n{}",
                sim.log()
            );
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Sends `make(seq)` once the arm's subscriber is connected and returns the state that
    /// acknowledges it.
    fn command(&mut self, sim: &mut Proc, make: impl Fn(u64) -> ArmCommand) -> ArmState {
        self.seq += 1;
        let seq = self.seq;
        self.cmd.send_copy(make(seq)).unwrap();
        self.wait_state(sim, &format!("last_command_seq {seq}"), |s| {
            s.last_command_seq == seq
        })
    }
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn lockstep_serve_answers_each_command_once_and_reports_bad_ones() {
    let prefix = unique_prefix("serve-lockstep");
    let dir = scratch("serve-lockstep");
    let mut sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--prefix", &prefix, "--json"],
        &dir,
    );
    let mut d = Driver::new(&prefix);
    let first = d.wait_state(&mut sim, "the initial state", |_| true);
    assert!(
        close(first.q(), &[0.0, -2.0, 2.4], 1e-5),
        "starts at task.start_q: {:?}",
        first.q
    );
    assert_eq!(first.last_command_seq, 0);
    assert!(first.status.contains(ArmStatus::READY) && first.status.contains(ArmStatus::HOLDING));
    d.wait_for_arm_subscriber();

    let pose = [0.2, -1.5, 2.0];
    let s = d.command(&mut sim, |seq| ArmCommand::reset(seq, 0, 7, pose));
    assert!(
        close(s.q(), &pose, 1e-5) && close(s.qd(), &[0.0; 3], 1e-9),
        "reset: {s:?}"
    );
    assert_eq!(s.episode, 7);
    assert!(!s.faults.any());
    let seq_before = s.seq;

    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 7, [0.3, -1.5, 2.0])
    });
    assert_eq!(s.seq, seq_before + 1, "exactly one state per command");
    assert!(
        s.q[0] > 0.2 + 1e-3 && s.q[0] < 0.3 + 1e-2,
        "moved towards the goal: {:?}",
        s.q
    );
    assert!(!s.status.contains(ArmStatus::HOLDING));

    let s = d.command(&mut sim, |seq| ArmCommand::torques(seq, 0, 7, [1.0; 3]));
    assert!(
        s.faults.contains(ArmFaults::UNKNOWN_COMMAND),
        "torques in goal-angle mode: {s:?}"
    );
    assert!(s.status.contains(ArmStatus::HOLDING));
    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 7, [0.3, -1.5, 2.0])
    });
    assert!(
        !s.faults.any(),
        "a fault is reported with the state of its command only"
    );
    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 7, [f64::NAN, -1.5, 2.0])
    });
    assert!(s.faults.contains(ArmFaults::NON_FINITE_COMMAND));
    // A command for six joints to an arm with three active: refused, held, named.
    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 7, [0.3, -1.5, 2.0, 0.0, 0.0, 0.0])
    });
    assert!(s.faults.contains(ArmFaults::WRONG_JOINTS), "{s:?}");
    assert!(s.status.contains(ArmStatus::HOLDING));
    assert_eq!(s.joints, 3);
    let s = d.command(&mut sim, |seq| ArmCommand {
        kind: 9,
        ..ArmCommand::hold(seq, 0, 7)
    });
    assert!(s.faults.contains(ArmFaults::UNKNOWN_COMMAND));
    let before = s.q().to_vec();
    let s = d.command(&mut sim, |seq| ArmCommand::hold(seq, 0, 7));
    assert!(s.status.contains(ArmStatus::HOLDING));
    assert!(
        close(s.q(), &before, 0.02),
        "holds its pose: {:?} → {:?}",
        before,
        s.q
    );
    let s = d.command(&mut sim, |seq| {
        ArmCommand::reset(seq, 0, 8, [0.0, -1.5, 4.0])
    });
    assert!(
        s.faults.contains(ArmFaults::UNKNOWN_COMMAND),
        "a reset outside the joint limits is refused"
    );

    sim.signal(libc::SIGTERM);
    let (code, out) = sim.wait(LONG);
    assert_eq!(code, Some(0), "log:\n{}", sim.log());
    let j = json_summary(&out, &sim.log());
    assert_eq!(j["commands"], 9);
    assert_eq!(j["resets"], 2);
    assert_eq!(j["holds"], 1);
    assert_eq!(j["rejected_commands"], 5);
    assert_eq!(j["states"], 10, "the initial state plus one per command");
}

/// `[serve] joints = 6`: states carry six joints, a six-joint reset and goal move the wrist,
/// and a three-joint command is refused naming the joint count.
#[test]
fn lockstep_serve_with_six_joints_moves_the_wrist() {
    let prefix = unique_prefix("serve-six");
    let dir = scratch("serve-six");
    let config = write_config(&dir, "six.toml", "[serve]\njoints = 6\n");
    let mut sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &config, "--prefix", &prefix],
        &dir,
    );
    let mut d = Driver::new(&prefix);
    let first = d.wait_state(&mut sim, "the initial state", |_| true);
    let w = [
        -std::f64::consts::FRAC_PI_2,
        std::f64::consts::FRAC_PI_2,
        0.0,
    ];
    assert_eq!(first.joints, 6);
    assert!(
        close(first.q(), &[0.0, -2.0, 2.4, w[0], w[1], w[2]], 1e-5),
        "starts at task.start_q, the wrist at sim.wrist_q: {:?}",
        first.q
    );
    d.wait_for_arm_subscriber();
    let pose = [0.2, -1.5, 2.0, -1.2, 1.3, 0.4];
    let s = d.command(&mut sim, |seq| ArmCommand::reset(seq, 0, 1, pose));
    assert!(close(s.q(), &pose, 1e-5) && !s.faults.any(), "reset: {s:?}");
    let goal = [0.2, -1.5, 2.0, -1.0, 1.1, 0.6];
    let mut s = s;
    for _ in 0..30 {
        s = d.command(&mut sim, |seq| ArmCommand::goal_angles(seq, 0, 1, goal));
    }
    assert!(close(s.q(), &goal, 1e-3), "reaches the goal: {:?}", s.q);
    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 1, [0.3, -1.5, 2.0])
    });
    assert!(s.faults.contains(ArmFaults::WRONG_JOINTS), "{s:?}");
    assert!(s.status.contains(ArmStatus::HOLDING) && s.joints == 6);
    sim.signal(libc::SIGTERM);
    let (code, _) = sim.wait(LONG);
    assert_eq!(code, Some(0), "log:\n{}", sim.log());
}

#[test]
fn real_time_serve_holds_the_last_command_and_reports_a_stale_one() {
    let prefix = unique_prefix("serve-rt");
    let dir = scratch("serve-rt");
    let cfg = write_config(
        &dir,
        "sim.toml",
        "[serve]\nmode = \"real_time\"\ntime_compression = 10.0\nstate_period_s = 0.01\ncommand_timeout_s = 0.3\n",
    );
    let mut sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &cfg, "--prefix", &prefix],
        &dir,
    );
    let mut d = Driver::new(&prefix);
    // States flow on the arm's own clock, without any command and without a stale fault.
    let a = d.wait_state(&mut sim, "a first state", |_| true);
    let b = d.wait_state(&mut sim, "a later state", |s| s.seq >= a.seq + 5);
    assert!(!b.faults.any() && b.last_command_seq == 0);
    d.wait_for_arm_subscriber();
    // One goal command: the arm keeps tracking it (zero-order hold) over many states.
    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 1, [0.3, -2.0, 2.4])
    });
    let later = d.wait_state(&mut sim, "the goal reached under the held command", |x| {
        x.seq > s.seq + 3 && x.q[0] > 0.25
    });
    assert!(!later.status.contains(ArmStatus::HOLDING));
    // No command for command_timeout_s: hold and report.
    let stale = d.wait_state(&mut sim, "a stale-command fault", |x| {
        x.faults.contains(ArmFaults::STALE_COMMAND)
    });
    assert!(stale.status.contains(ArmStatus::HOLDING));
    // A new command clears it.
    let s = d.command(&mut sim, |seq| {
        ArmCommand::goal_angles(seq, 0, 1, [0.0, -2.0, 2.4])
    });
    let next = d.wait_state(&mut sim, "a state after the new command", |x| x.seq > s.seq);
    assert!(!next.faults.contains(ArmFaults::STALE_COMMAND), "{next:?}");
}
