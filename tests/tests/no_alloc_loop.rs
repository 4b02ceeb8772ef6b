//! The loop phase does not touch the heap: ≥ 1,000 ticks of [`Controller::run`] over real
//! iceoryx2 ports, across episode boundaries and a table swap from one controller kind to the
//! other (gain table → policy table and policy table → gain table; docs/design.md §3.11), under
//! a counting global allocator. Its own test binary, so the allocator disturbs no other test; counting is armed
//! per thread, only on the controller's thread (the arm and learner stand-ins run on others).
//!
//! The order of events is fixed by the test, not by thread timing: version 1 is in the
//! controller's queue before the loop starts, and version 2 is published while the lockstep
//! controller waits for the arm to answer the reset of episode 3 (the arm stand-in holds that
//! answer), so it is taken at the boundary before episode 4 on any machine.
//!
//! Each arm backend (iceoryx2, `ur`, `ros2`) runs the reaching task (three joints, a point) and
//! the whole arm with a pose goal (six joints, three tool points: dX = 30, dU = 6).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use rt_controller::config::{LiveViewConfig, Safety};
use rt_controller::testkit::{
    constant_goal_table_for, pose_task, random_policy_table_for, run_kinematic_arm_for,
};
use rt_controller::{Controller, ControllerConfig, ExitReason};
use ur5_shared::config::TaskConfig;
use ur5_shared::services::{self, unique_prefix, ServiceNames};
use ur5_shared::{ArmCommand, CommandKind, GainTable, PolicyTable, StateLayout, StepSample};

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
    static FREES: Cell<u64> = const { Cell::new(0) };
}

fn note(counter: &'static std::thread::LocalKey<Cell<u64>>) {
    // try_with: the allocator may run while thread-locals are torn down.
    let _ = ARMED.try_with(|armed| {
        if armed.get() {
            let _ = counter.try_with(|c| c.set(c.get() + 1));
        }
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(&ALLOCS);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(&ALLOCS);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(&ALLOCS);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note(&FREES);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const T: usize = 100;
const EPISODES: u64 = 12;
/// The first episode that runs on table version 2: the arm answers the reset of the episode
/// before it only once version 2 is published, so the controller takes it at this boundary.
const V2_FROM_EPISODE: u64 = 4;

/// A controller kind the learner stand-in publishes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Gains,
    Policy,
}

/// The goal angles of table `version` for `layout`'s joints (rad).
fn goal_angles(layout: &StateLayout, version: u64) -> Vec<f64> {
    let q = if version == 1 {
        [0.2, -1.8, 2.2, -1.6, -1.5, 0.1]
    } else {
        [-0.2, -1.7, 2.0, -1.5, -1.6, -0.1]
    };
    q[..layout.du()].to_vec()
}

/// The stand-in's table of `kind` and `version` for `layout`: a constant goal with noise, or a
/// random dX-64-64-1 policy (σ = 0.01 rad).
fn send(
    layout: &StateLayout,
    kind: Kind,
    version: u64,
    gains: &iceoryx2::port::publisher::Publisher<ipc::Service, GainTable, ()>,
    policy: &iceoryx2::port::publisher::Publisher<ipc::Service, PolicyTable, ()>,
) {
    match kind {
        Kind::Gains => {
            let q = goal_angles(layout, version);
            let t = constant_goal_table_for(layout, version, T, &q, 0.01);
            gains.send_copy(*t).unwrap();
        }
        Kind::Policy => {
            publish_policy(
                policy,
                &random_policy_table_for(layout, version, &[64, 64], 0.05, 0.01, version),
            );
        }
    }
}

/// Sends `table` through a loaned sample (no 384 KB value on the stack).
fn publish_policy(
    publisher: &iceoryx2::port::publisher::Publisher<ipc::Service, PolicyTable, ()>,
    table: &PolicyTable,
) {
    let mut slot = publisher.loan_uninit().unwrap();
    PolicyTable::init_zeroed(slot.payload_mut()).copy_from(table);
    // SAFETY: init_zeroed initialised the payload.
    unsafe { slot.assume_init() }.send().unwrap();
}

/// The learner stand-in. Version 1 goes out once the controller's `controller/gains`
/// subscriber exists, so it sits in the controller's queue before its first boundary (a send
/// delivers to every connected subscriber at once); `v1_sent` reports that. Version 2 goes out
/// when the arm asks on `publish_v2`, after draining the samples so far; `v2_sent` confirms.
/// Returns (episode, table version) of every sample received, in order.
fn learner(
    layout: StateLayout,
    prefix: String,
    kinds: [Kind; 2],
    stop: Arc<AtomicBool>,
    v1_sent: mpsc::Sender<()>,
    publish_v2: mpsc::Receiver<()>,
    v2_sent: mpsc::Sender<()>,
) -> Vec<(u64, u64)> {
    let names = ServiceNames::new(&prefix);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let gains = services::CONTROLLER_GAINS_QOS
        .open_or_create_retrying::<GainTable>(&node, &names.controller_gains)
        .unwrap();
    let policy = services::CONTROLLER_POLICY_QOS
        .open_or_create_retrying::<PolicyTable>(&node, &names.controller_policy)
        .unwrap();
    let samples = services::LEARNER_SAMPLES_QOS
        .open_or_create_retrying::<StepSample>(&node, &names.learner_samples)
        .unwrap();
    // Both publishers before the subscriber: the controller's setup waits for a sample
    // subscriber, and every connection must exist before its loop (D20).
    let publisher = gains.publisher_builder().create().unwrap();
    let policy_pub = policy.publisher_builder().create().unwrap();
    let subscriber = samples.subscriber_builder().create().unwrap();
    let mut received = Vec::new();
    let drain = |received: &mut Vec<(u64, u64)>| {
        while let Some(s) = subscriber.receive().unwrap() {
            received.push((s.episode, s.table_version));
        }
    };

    while gains.dynamic_config().number_of_subscribers() == 0
        || policy.dynamic_config().number_of_subscribers() == 0
    {
        if stop.load(Ordering::Relaxed) {
            return received;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    send(&layout, kinds[0], 1, &publisher, &policy_pub);
    v1_sent.send(()).unwrap();

    while !stop.load(Ordering::Relaxed) {
        let _ = publisher.update_connections();
        let _ = policy_pub.update_connections();
        drain(&mut received);
        match publish_v2.recv_timeout(Duration::from_millis(1)) {
            Ok(()) => {
                drain(&mut received);
                send(&layout, kinds[1], 2, &publisher, &policy_pub);
                v2_sent.send(()).unwrap();
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                std::thread::sleep(Duration::from_millis(1))
            }
        }
    }
    // Every sample was sent before the controller returned, i.e. before `stop`.
    drain(&mut received);
    received
}

#[test]
fn counter_sees_allocations() {
    ARMED.with(|a| a.set(true));
    let v = vec![1u8; 32];
    drop(v);
    ARMED.with(|a| a.set(false));
    assert!(
        ALLOCS.with(|c| c.get()) >= 1 && FREES.with(|c| c.get()) >= 1,
        "the counting allocator is not active"
    );
}

#[test]
fn the_loop_does_not_allocate_across_a_swap_from_gains_to_a_policy() {
    no_allocation_across_a_swap(TaskConfig::default(), [Kind::Gains, Kind::Policy], false);
}

#[test]
fn the_loop_does_not_allocate_across_a_swap_from_a_policy_to_gains() {
    no_allocation_across_a_swap(TaskConfig::default(), [Kind::Policy, Kind::Gains], false);
}

/// Six joints and a pose goal, both controller kinds.
#[test]
fn the_loop_does_not_allocate_at_six_joints_and_a_pose() {
    no_allocation_across_a_swap(pose_task(T), [Kind::Gains, Kind::Policy], false);
    no_allocation_across_a_swap(pose_task(T), [Kind::Policy, Kind::Gains], false);
}

/// The same with the live view on (`[live_view]`: an entry at every tick and every fresh state
/// between episodes, joint states too, on ROS domain 127); its DDS thread is not counted.
#[test]
fn the_loop_with_the_live_view_does_not_allocate() {
    no_allocation_across_a_swap(TaskConfig::default(), [Kind::Gains, Kind::Policy], true);
}

/// On `task`: version 1 of kind `kinds[0]`, version 2 of kind `kinds[1]`; `live_view`: with
/// the live view.
fn no_allocation_across_a_swap(task: TaskConfig, kinds: [Kind; 2], live_view: bool) {
    let layout = task.layout();
    let prefix = unique_prefix("no-alloc-loop");
    let stop = Arc::new(AtomicBool::new(false));
    let (v1_sent_tx, v1_sent) = mpsc::channel();
    let (publish_v2_tx, publish_v2) = mpsc::channel();
    let (v2_sent_tx, v2_sent) = mpsc::channel();
    let arm = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || {
            // Holds the answer to the reset of episode V2_FROM_EPISODE − 1 until version 2 is
            // published: the controller has taken its table for that episode and waits, so
            // version 2 is in its queue before the next boundary, however the threads are
            // scheduled.
            let mut asked = false;
            let before_answer = |cmd: &ArmCommand| {
                if !asked
                    && cmd.kind() == Ok(CommandKind::Reset)
                    && cmd.episode == V2_FROM_EPISODE - 1
                {
                    asked = true;
                    publish_v2_tx.send(()).unwrap();
                    v2_sent.recv().unwrap();
                }
            };
            run_kinematic_arm_for(
                &layout,
                &prefix,
                0.1,
                std::f64::consts::PI,
                &stop,
                before_answer,
            )
            .unwrap()
            .commands
        })
    };
    let learner = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || {
            learner(
                layout, prefix, kinds, stop, v1_sent_tx, publish_v2, v2_sent_tx,
            )
        })
    };

    // Setup phase: may allocate.
    let cfg = ControllerConfig {
        prefix,
        episodes: EPISODES,
        task,
        wait_for_learner: true,
        // The per-episode report goes through the loop too.
        episode_report: true,
        safety: Safety {
            // The arm holds one answer while version 2 is published (microseconds unless a
            // thread is descheduled); only a hang should count as a stale arm here, and a
            // stand-in that died ends the run (a failure, not a test that never returns).
            stale_state_timeout_s: 30.0,
            give_up_after_s: 60.0,
            ..Safety::default()
        },
        live_view: LiveViewConfig {
            enabled: live_view,
            // This test's own domain; topics of this process.
            domain_id: 127,
            namespace: format!("/na{}", std::process::id()),
            rate_hz: 1000.0,
            joint_states: true,
            joint_states_topic: format!("/na{}/joint_states", std::process::id()),
            ..LiveViewConfig::default()
        },
        ..ControllerConfig::default()
    };
    let mut controller = Controller::setup(cfg).expect("setup");
    v1_sent
        .recv()
        .expect("the learner stand-in did not publish version 1");
    let never = AtomicBool::new(false);

    // Loop phase: counted.
    ALLOCS.with(|c| c.set(0));
    FREES.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let t0 = Instant::now();
    let reason = controller.run(&never);
    let wall = t0.elapsed();
    ARMED.with(|a| a.set(false));
    let (allocs, frees) = (ALLOCS.with(|c| c.get()), FREES.with(|c| c.get()));

    stop.store(true, Ordering::Relaxed);
    let commands = arm.join().unwrap();
    let received = learner.join().unwrap();
    let s = controller.stats();
    assert_eq!(reason, ExitReason::EpisodesDone);
    assert_eq!(s.episodes_completed, EPISODES);
    assert!(s.ticks >= 1000, "only {} ticks", s.ticks);
    assert_eq!(
        s.swaps, 2,
        "version 1 at the first boundary, version 2 later"
    );
    assert_eq!(
        s.faults.stale_state + s.faults.arm_fault + s.faults.non_finite_action + s.faults.no_table,
        0
    );
    assert!(commands >= s.ticks);
    // Swaps at boundaries only: every episode ran on one version, version 1 from the first
    // boundary, version 2 from the one it was published before. The 1,200 samples fit in the
    // learner's queue (8 × MAX_HORIZON) in two parts (before and after the drain at the
    // request for version 2), so none is dropped.
    assert_eq!(received.len() as u64, s.ticks);
    for (episode, version) in &received {
        let expected = if *episode < V2_FROM_EPISODE { 1 } else { 2 };
        assert_eq!(
            *version, expected,
            "episode {episode} ran on version {version}"
        );
    }
    let live = controller.summary(reason).live_view;
    if live_view {
        // The first offer is always kept; how many more depends on the loop's speed (lockstep
        // may tick faster than the 1 kHz rate limit).
        let live = live.expect("the live view ran");
        assert!(live.entries >= 1, "{live:?}");
    } else {
        assert_eq!(live, None);
    }
    assert_eq!(
        (allocs, frees),
        (0, 0),
        "the loop allocated {allocs} and freed {frees} times over {} ticks ({wall:?}){}",
        s.ticks,
        if live_view { ", live view on" } else { "" }
    );
}

/// What [`run_swapping`] saw: the two runs' exits, the allocations and frees counted on the
/// loop's thread, and every (episode, table version) sampled.
struct Swapped<A: rt_controller::ArmBackend> {
    first: ExitReason,
    second: ExitReason,
    allocs: u64,
    frees: u64,
    received: Vec<(u64, u64)>,
    controller: Controller<A>,
}

/// A controller from `make` (given the service prefix) run under the counting allocator across
/// boundaries and a table swap from a gain table to a policy table. The order is fixed by the
/// test: version 1 waits in the controller's queue before the loop; the learner stand-in
/// raises `pause` at the first sample (version 1 is then in use), the loop returns, the test
/// publishes version 2 (not counted) and runs the loop again, which takes version 2 at its
/// next boundary.
fn run_swapping<A: rt_controller::ArmBackend>(
    tag: &str,
    layout: &StateLayout,
    horizon: usize,
    make: impl FnOnce(&str) -> Controller<A>,
) -> Swapped<A> {
    let prefix = unique_prefix(tag);
    let names = ServiceNames::new(&prefix);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let gains = services::CONTROLLER_GAINS_QOS
        .open_or_create_retrying::<GainTable>(&node, &names.controller_gains)
        .unwrap();
    let publisher = gains.publisher_builder().create().unwrap();
    let policy = services::CONTROLLER_POLICY_QOS
        .open_or_create_retrying::<PolicyTable>(&node, &names.controller_policy)
        .unwrap();
    let policy_pub = policy.publisher_builder().create().unwrap();
    // The sample watcher (its own node: iceoryx2 ports stay on their thread); `pause` at the
    // first sample.
    let pause = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready) = mpsc::channel();
    let watcher = {
        let (pause, stop, prefix) = (pause.clone(), stop.clone(), prefix.clone());
        std::thread::spawn(move || {
            let node = NodeBuilder::new()
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<ipc::Service>()
                .unwrap();
            let samples = services::LEARNER_SAMPLES_QOS
                .open_or_create_retrying::<StepSample>(
                    &node,
                    &ServiceNames::new(&prefix).learner_samples,
                )
                .unwrap();
            let subscriber = samples
                .subscriber_builder()
                .buffer_size(services::LEARNER_SAMPLES_QOS.subscriber_buffer)
                .create()
                .unwrap();
            ready_tx.send(()).unwrap();
            let mut received = Vec::new();
            while !stop.load(Ordering::Relaxed) {
                while let Some(s) = subscriber.receive().unwrap() {
                    received.push((s.episode, s.table_version));
                    pause.store(true, Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            while let Some(s) = subscriber.receive().unwrap() {
                received.push((s.episode, s.table_version));
            }
            received
        })
    };
    ready.recv().unwrap();
    let mut controller = make(&prefix);
    while gains.dynamic_config().number_of_subscribers() == 0 {
        std::thread::sleep(Duration::from_millis(1));
    }
    let q = goal_angles(layout, 1);
    publisher
        .send_copy(*constant_goal_table_for(layout, 1, horizon, &q, 0.01))
        .unwrap();
    ALLOCS.with(|c| c.set(0));
    FREES.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let first = controller.run(&pause);
    ARMED.with(|a| a.set(false));
    // Version 2 is the other controller kind, a policy table.
    publish_policy(
        &policy_pub,
        &random_policy_table_for(layout, 2, &[64, 64], 0.05, 0.01, 2),
    );
    let never = AtomicBool::new(false);
    ARMED.with(|a| a.set(true));
    let second = controller.run(&never);
    ARMED.with(|a| a.set(false));
    let (allocs, frees) = (ALLOCS.with(|c| c.get()), FREES.with(|c| c.get()));
    stop.store(true, Ordering::Relaxed);
    let received = watcher.join().unwrap();
    Swapped {
        first,
        second,
        allocs,
        frees,
        received,
        controller,
    }
}

/// The `ur` arm's loop (RTDE packages in, servoj targets out) against `hil-sim ur-sim` in this
/// process (lockstep; its threads are not counted), across boundaries and a table swap from a
/// gain table to a policy table ([`run_swapping`]).
#[test]
fn the_ur_loop_does_not_allocate_across_boundaries_and_a_swap() {
    ur_loop(TaskConfig::default());
}

/// The same with six joints and a pose goal: the servoj targets move the wrist too.
#[test]
fn the_ur_loop_does_not_allocate_at_six_joints_and_a_pose() {
    ur_loop(pose_task(20));
}

fn ur_loop(task: TaskConfig) {
    use hil_sim::ur_sim::{self, UrSimConfig};
    use rt_controller::config::{ArmConfig, ArmKind, UrConfig};
    use ur5_shared::config::SimConfig;

    const T_UR: usize = 20;
    const EPISODES_UR: u64 = 5;
    let layout = task.layout();
    let sim = ur_sim::spawn(
        &task,
        &SimConfig::default(),
        &UrSimConfig {
            rtde_port: 0,
            secondary_port: 0,
            lockstep: true,
            ..UrSimConfig::default()
        },
    )
    .expect("ur-sim");
    let run = run_swapping("no-alloc-ur", &layout, T_UR, |prefix| {
        let cfg = ControllerConfig {
            prefix: prefix.to_owned(),
            episodes: EPISODES_UR,
            wait_for_learner: true,
            episode_report: true,
            task: TaskConfig {
                horizon: T_UR,
                ..task
            },
            safety: Safety {
                stale_state_timeout_s: 30.0,
                ..Safety::default()
            },
            arm: ArmConfig {
                backend: ArmKind::Ur,
                ur: UrConfig {
                    host: "127.0.0.1".into(),
                    rtde_port: sim.rtde_addr.port(),
                    secondary_port: sim.secondary_addr.port(),
                    reverse_port: 0,
                    // ur-sim's library default (a UR5 on an e-Series controller) has no dashboard.
                    check_model: false,
                    // Long: a descheduled test thread must not end the program.
                    receive_timeout_ms: 1000,
                    ..UrConfig::default()
                },
                ..ArmConfig::default()
            },
            ..ControllerConfig::default()
        };
        Controller::setup_ur(cfg).expect("setup")
    });
    let report = run.controller.arm().report();
    let s = run.controller.stats();
    sim.stop();
    assert_eq!(
        (run.first, run.second),
        (ExitReason::Stopped, ExitReason::EpisodesDone)
    );
    assert_eq!(
        s.swaps, 2,
        "version 1 (gains) first, version 2 (policy) after the pause"
    );
    assert!(s.ticks >= 80, "only {} ticks", s.ticks);
    assert!(report.packages >= 50 * s.ticks, "{report:?}");
    assert!(run.received.iter().any(|(_, v)| *v == 2));
    assert_eq!(
        (run.allocs, run.frees),
        (0, 0),
        "the ur loop allocated {} and freed {} times over {} ticks and {} packages",
        run.allocs,
        run.frees,
        s.ticks,
        report.packages
    );
}

/// The `ros2` arm's loop (joint states from its DDS thread through the lock-free queue in,
/// targets out through the other) against `hil-sim ros2-sim` in this process over DDS on the
/// loopback (real time x10; the DDS and sim threads are not counted), across boundaries and a
/// table swap ([`run_swapping`]).
#[test]
fn the_ros2_loop_does_not_allocate_across_boundaries_and_a_swap() {
    ros2_loop(TaskConfig::default(), 125);
}

/// The same with six joints and a pose goal: the commands move the wrist too.
#[test]
fn the_ros2_loop_does_not_allocate_at_six_joints_and_a_pose() {
    ros2_loop(pose_task(20), 131);
}

/// On ROS domain `domain` (the test's own).
fn ros2_loop(task: TaskConfig, domain: u16) {
    use hil_sim::ros2_sim::{self, Ros2SimConfig};
    use rt_controller::config::{ArmConfig, ArmKind, Mode, Pacing, Ros2Config};
    use ur5_shared::config::SimConfig;

    const T_R: usize = 20;
    const EPISODES_R: u64 = 5;
    let layout = task.layout();
    // Topics of this process only: a second run of this test at the same time uses the same
    // domain.
    let ns = format!("/na{}", std::process::id());
    let sim = ros2_sim::spawn(
        &task,
        &SimConfig::default(),
        &Ros2SimConfig {
            domain_id: domain,
            time_compression: 10.0,
            joint_states_topic: format!("{ns}/joint_states"),
            command_topic: format!("{ns}/forward_position_controller/commands"),
            robot_mode_topic: format!("{ns}/io_and_status_controller/robot_mode"),
            safety_mode_topic: format!("{ns}/io_and_status_controller/safety_mode"),
            ..Ros2SimConfig::default()
        },
    )
    .expect("ros2-sim");
    let run = run_swapping("no-alloc-ros2", &layout, T_R, |prefix| {
        let cfg = ControllerConfig {
            prefix: prefix.to_owned(),
            episodes: EPISODES_R,
            wait_for_learner: true,
            episode_report: true,
            mode: Mode::RealTime,
            pacing: Pacing::Arm,
            time_compression: 10.0,
            task: TaskConfig {
                horizon: T_R,
                ..task
            },
            safety: Safety {
                stale_state_timeout_s: 30.0,
                ..Safety::default()
            },
            arm: ArmConfig {
                backend: ArmKind::Ros2,
                ros2: Ros2Config {
                    domain_id: domain,
                    joint_states_topic: format!("{ns}/joint_states"),
                    command_topic: format!("{ns}/forward_position_controller/commands"),
                    robot_mode_topic: format!("{ns}/io_and_status_controller/robot_mode"),
                    safety_mode_topic: format!("{ns}/io_and_status_controller/safety_mode"),
                    ..Ros2Config::default()
                },
                ..ArmConfig::default()
            },
            ..ControllerConfig::default()
        };
        Controller::setup_ros2(cfg).expect("setup")
    });
    let report = run.controller.arm().report();
    let s = run.controller.stats();
    let summary = sim.stop();
    assert_eq!(
        (run.first, run.second),
        (ExitReason::Stopped, ExitReason::EpisodesDone)
    );
    assert_eq!(s.swaps, 2, "version 1 (gains) first, version 2 (policy)");
    assert!(s.ticks >= 80, "only {} ticks", s.ticks);
    // Several joint states per control period (all 50 at x1; at x10, 5000 a second, DDS
    // delivers fewer on this machine).
    assert!(report.samples >= 2 * s.ticks, "{report:?} {summary:?}");
    assert!(report.commands > 0, "{report:?}");
    assert!(run.received.iter().any(|(_, v)| *v == 2));
    assert_eq!(
        (run.allocs, run.frees),
        (0, 0),
        "the ros2 loop allocated {} and freed {} times over {} ticks and {} joint states",
        run.allocs,
        run.frees,
        s.ticks,
        report.samples
    );
}
