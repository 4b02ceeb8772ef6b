//! `rt-controller bench` (needs the `testkit` feature): the real loop ([`Controller::run`], lockstep) against an in-process
//! kinematic arm and a learner stand-in that publishes a new table before every episode, over
//! real iceoryx2 ports, once with gain tables and once with policy tables (the MDGPS policy's
//! default shape, three heads 12-64-64-1; docs/design.md §3.11). Reports, from inside the loop: compute per tick (controller law + clamp
//! + command + sample publish), table swap (copy + flip) and validation; from the arm: the IPC
//! round trip state → command.

use core::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use serde::Serialize;
use ur5_shared::services::{self, unique_prefix, ServiceNames};
use ur5_shared::{GainTable, PolicyTable, StepSample};

use rt_controller::config::{ControllerConfig, Mode, Polling};
use rt_controller::stats::Percentiles;
use rt_controller::testkit::{
    constant_goal_table_for, random_policy_table_for, run_kinematic_arm_for,
};
use rt_controller::{Controller, ExitReason};
use ur5_shared::config::TaskConfig;
use ur5_shared::StateLayout;

/// Benchmark results (ns).
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Always "bench".
    pub command: &'static str,
    /// Episodes run.
    pub episodes: u64,
    /// Ticks run.
    pub ticks: u64,
    /// Per tick: law + clamp + command + sample publish.
    pub compute: Percentiles,
    /// Per accepted table: copy into the inactive half (+ index flip).
    pub swap: Percentiles,
    /// Per table: validation (dimensions, checksum, finiteness, Cholesky, bounds).
    pub validate: Percentiles,
    /// Per table: receive + copy + validate + flip.
    pub intake: Percentiles,
    /// State published → answering command received, at the arm.
    pub round_trip: Percentiles,
    /// Tables taken.
    pub swaps: u64,
    /// Why the loop ended.
    pub exit_reason: ExitReason,
    /// Controller spin before sleeping between polls (ns).
    pub spin_ns: u64,
}

/// Which controller kind the learner stand-in publishes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Gain tables (a constant goal with noise).
    Gains,
    /// Policy tables of hidden widths [`POLICY_HIDDEN`] (random weights).
    Policy,
}

/// Hidden widths of the benchmark's policy: the MDGPS default (docs/design.md §6.1).
pub const POLICY_HIDDEN: [usize; 2] = [64, 64];

/// Runs `episodes` episodes of `horizon` ticks of `task` (its layout: the reaching task or
/// `testkit::pose_task`). `spin_ns`: the controller's busy-poll budget per wait (longer measures the
/// IPC, shorter measures the sleep granularity too).
pub fn run(
    episodes: u64,
    horizon: usize,
    spin_ns: u64,
    kind: Kind,
    task: TaskConfig,
) -> anyhow::Result<BenchReport> {
    let prefix = unique_prefix("rt-bench");
    let stop = Arc::new(AtomicBool::new(false));
    let dt = 0.01;
    let layout = task.layout();

    let arm = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || {
            run_kinematic_arm_for(&layout, &prefix, dt, std::f64::consts::PI, &stop, |_| {})
        })
    };
    let learner = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || learner_stand_in(&prefix, &layout, horizon, kind, &stop))
    };

    let cfg = bench_config(prefix.clone(), episodes, horizon, spin_ns, dt, task);
    let mut controller = Controller::setup(cfg)?;
    let never = AtomicBool::new(false);
    let reason = controller.run(&never);
    stop.store(true, Ordering::Relaxed);
    let arm = arm
        .join()
        .map_err(|_| anyhow::anyhow!("arm thread panicked"))??;
    learner
        .join()
        .map_err(|_| anyhow::anyhow!("learner thread panicked"))??;
    let s = controller.stats();
    Ok(BenchReport {
        command: "bench",
        episodes: s.episodes_completed,
        ticks: s.ticks,
        compute: s.compute.summary(),
        swap: s.swap.summary(),
        validate: s.validate.summary(),
        intake: s.intake.summary(),
        round_trip: arm.round_trip.summary(),
        swaps: s.swaps,
        exit_reason: reason,
        spin_ns,
    })
}

/// The benchmark's controller: lockstep, `episodes` of `horizon` ticks of `dt`, no episode
/// report, waiting for the learner stand-in.
fn bench_config(
    prefix: String,
    episodes: u64,
    horizon: usize,
    spin_ns: u64,
    dt: f64,
    task: TaskConfig,
) -> ControllerConfig {
    ControllerConfig {
        prefix,
        mode: Mode::Lockstep,
        episodes,
        episode_report: false,
        wait_for_learner: true,
        task: TaskConfig {
            dt,
            horizon,
            ..task
        },
        polling: Polling {
            spin_ns,
            sleep_ns: 20_000,
        },
        ..ControllerConfig::default()
    }
}

/// [`ur5_shared::policy_action`] alone on a warm cache: `calls` calls in a row on one policy
/// table of hidden widths [`POLICY_HIDDEN`] and a moving state, each timed (ns). The loop's
/// tick adds the clamp, command and sample to this, and whatever the other threads between two
/// ticks have pushed out of the cache.
pub fn policy_action_alone(calls: usize) -> Percentiles {
    use ur5_shared::policy::{policy_action, PolicyScratch};
    let table = random_policy_table_for(&StateLayout::REACH3, 1, &POLICY_HIDDEN, 0.05, 0.01, 1);
    let mut scratch = PolicyScratch::default();
    let mut h = rt_controller::stats::Histogram::new();
    let (mut s, mut a) = ([0.1; ur5_shared::DX], [0.0; ur5_shared::DU]);
    for i in 0..calls {
        s[i % ur5_shared::DX] += 1e-3;
        let t0 = ur5_shared::clock::monotonic_ns();
        policy_action(&table, &s, &ur5_shared::NO_NOISE, &mut scratch, &mut a)
            .expect("the reaching task's policy and arrays");
        h.record(ur5_shared::clock::monotonic_ns() - t0);
        std::hint::black_box(&a);
    }
    h.summary()
}

/// [`ur5_shared::controller_action`] alone on a warm cache at `layout`'s dimensions: `calls`
/// calls on one seeded random gain table of T = 100 (t cycling) and a moving state, each timed
/// (ns). The loop's tick adds the state assembly, clamp, command and sample to this; it shows
/// what the six-joint pose task's larger K (6 × 30 against 3 × 12) costs the law.
pub fn controller_action_alone(layout: &ur5_shared::StateLayout, calls: usize) -> Percentiles {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let (dx, du) = (layout.dx(), layout.du());
    let mut table = ur5_shared::GainTable::new_boxed_for(layout);
    table.set_version(1);
    table.set_horizon(100).expect("T = 100");
    for t in 0..100 {
        let mut st = table.step_mut(t);
        st.k_mat
            .iter_mut()
            .chain(st.k_vec.iter_mut())
            .chain(st.s_hat.iter_mut())
            .for_each(|v| *v = rng.random_range(-1.0..1.0));
        for i in 0..du {
            st.set_l(i, i, 0.1);
        }
    }
    table.seal();
    let mut h = rt_controller::stats::Histogram::new();
    let mut s = [0.1; ur5_shared::MAX_DX];
    let mut a = [0.0; ur5_shared::MAX_DU];
    let eps = [0.5; ur5_shared::MAX_DU];
    for i in 0..calls {
        s[i % dx] += 1e-3;
        let t0 = ur5_shared::clock::monotonic_ns();
        ur5_shared::controller_action(&table, i % 100, &s[..dx], &eps[..du], &mut a[..du])
            .expect("the table's own dimensions");
        h.record(ur5_shared::clock::monotonic_ns() - t0);
        std::hint::black_box(&a);
    }
    h.summary()
}

/// Publishes table version 1, then a new version whenever an episode starts (seen on
/// `learner/samples`), so that every boundary swaps.
fn learner_stand_in(
    prefix: &str,
    layout: &StateLayout,
    horizon: usize,
    kind: Kind,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    if kind == Kind::Policy {
        return policy_stand_in(prefix, layout, stop);
    }
    let names = ServiceNames::new(prefix);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?;
    let gains = services::CONTROLLER_GAINS_QOS
        .open_or_create::<GainTable>(&node, &names.controller_gains()?)?;
    let samples = services::LEARNER_SAMPLES_QOS
        .open_or_create::<StepSample>(&node, &names.learner_samples()?)?;
    let publisher = gains.publisher_builder().create()?;
    let subscriber = samples.subscriber_builder().create()?;
    let mut version = 1;
    let goal = |v: u64| [0.1 * (v % 5) as f64, -1.8, 2.2, -1.6, -1.5, 0.0];
    let table = |v: u64| constant_goal_table_for(layout, v, horizon, &goal(v)[..layout.du()], 0.01);
    publisher.send_copy(*table(version))?;
    let mut last_episode = 0;
    while !stop.load(Ordering::Relaxed) {
        let _ = publisher.update_connections();
        while let Some(s) = subscriber.receive()? {
            if s.episode > last_episode || (s.episode == 0 && s.t == 0 && version == 1) {
                last_episode = s.episode;
                version += 1;
                let mut slot = publisher.loan_uninit()?;
                table(version).copy_to_uninit(slot.payload_mut());
                // SAFETY: copy_to_uninit initialised the payload.
                unsafe { slot.assume_init() }.send()?;
            }
        }
        // Short sleeps: an episode of the kinematic arm lasts about a millisecond and most
        // boundaries should find a new table, but a spinning third thread on a 2-core machine
        // would distort the round trip being measured.
        std::thread::sleep(core::time::Duration::from_micros(100));
    }
    Ok(())
}

/// As [`learner_stand_in`] with policy tables (seeded random weights, σ = 0.01 rad) on
/// `controller/policy`; also subscribes to `controller/gains`' publisher count by opening it,
/// so the controller's learner check sees a table publisher.
fn policy_stand_in(prefix: &str, layout: &StateLayout, stop: &AtomicBool) -> anyhow::Result<()> {
    let names = ServiceNames::new(prefix);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?;
    let policy = services::CONTROLLER_POLICY_QOS
        .open_or_create::<PolicyTable>(&node, &names.controller_policy()?)?;
    let samples = services::LEARNER_SAMPLES_QOS
        .open_or_create::<StepSample>(&node, &names.learner_samples()?)?;
    let publisher = policy.publisher_builder().create()?;
    let subscriber = samples.subscriber_builder().create()?;
    let table = |v: u64| random_policy_table_for(layout, v, &POLICY_HIDDEN, 0.05, 0.01, v);
    let mut version = 1;
    {
        let first = table(version);
        let mut slot = publisher.loan_uninit()?;
        PolicyTable::init_zeroed(slot.payload_mut()).copy_from(&first);
        // SAFETY: init_zeroed initialised the payload.
        unsafe { slot.assume_init() }.send()?;
    }
    let mut last_episode = 0;
    while !stop.load(Ordering::Relaxed) {
        let _ = publisher.update_connections();
        while let Some(s) = subscriber.receive()? {
            if s.episode > last_episode || (s.episode == 0 && s.t == 0 && version == 1) {
                last_episode = s.episode;
                version += 1;
                let next = table(version);
                let mut slot = publisher.loan_uninit()?;
                let p = PolicyTable::init_zeroed(slot.payload_mut());
                p.copy_from(&next);
                // SAFETY: init_zeroed initialised the payload.
                unsafe { slot.assume_init() }.send()?;
            }
        }
        std::thread::sleep(core::time::Duration::from_micros(100));
    }
    Ok(())
}

/// The `ros2` arm's round trip (docs/design.md §3.13): a driver stand-in publishes a joint state
/// (stamps one control period apart, so that each is a control-period state) over DDS on the
/// loopback, the real loop ([`Controller::run`], real time, arm pacing) answers through the
/// arm's DDS thread, and the stand-in times joint state published → command received, then
/// publishes the next one. Domain `domain` (ROS_DOMAIN_ID) and a fresh iceoryx2 prefix.
pub fn run_ros2(
    episodes: u64,
    horizon: usize,
    spin_ns: u64,
    domain: u16,
) -> anyhow::Result<Percentiles> {
    use rt_controller::config::{ArmConfig, ArmKind, Pacing, Ros2Config};
    let prefix = unique_prefix("rt-bench-ros2");
    let stop = Arc::new(AtomicBool::new(false));
    let dt = 0.01;
    let driver = {
        let stop = stop.clone();
        std::thread::spawn(move || driver_stand_in(domain, dt, &stop))
    };
    let learner = {
        let (prefix, stop) = (prefix.clone(), stop.clone());
        std::thread::spawn(move || {
            learner_stand_in(&prefix, &StateLayout::REACH3, horizon, Kind::Gains, &stop)
        })
    };
    let cfg = ControllerConfig {
        mode: Mode::RealTime,
        pacing: Pacing::Arm,
        arm: ArmConfig {
            backend: ArmKind::Ros2,
            ros2: Ros2Config {
                domain_id: domain,
                joint_state_rate_hz: 1.0 / dt,
                watch_status: false,
                ..Ros2Config::default()
            },
            ..ArmConfig::default()
        },
        ..bench_config(
            prefix,
            episodes,
            horizon,
            spin_ns,
            dt,
            TaskConfig::default(),
        )
    };
    let mut controller = rt_controller::Controller::setup_ros2(cfg)?;
    let never = AtomicBool::new(false);
    controller.run(&never);
    stop.store(true, Ordering::Relaxed);
    let round_trip = driver
        .join()
        .map_err(|_| anyhow::anyhow!("driver thread panicked"))??;
    learner
        .join()
        .map_err(|_| anyhow::anyhow!("learner thread panicked"))??;
    Ok(round_trip)
}

/// A kinematic UR arm behind the driver's topics: publishes a joint state, waits (epoll) for a
/// command, moves there, publishes the next; times each round trip (ns).
fn driver_stand_in(domain: u16, dt: f64, stop: &AtomicBool) -> anyhow::Result<Percentiles> {
    use rt_controller::stats::Histogram;
    use rustdds::mio1::{Events, Interest, Poll, Token};
    use ur5_ros2::{Float64MultiArray, Header, JointState, Network, Node, Time, TopicQos};
    use ur5_shared::clock::monotonic_ns;
    let cfg = rt_controller::config::Ros2Config::default();
    let node = Node::new(domain, Network::Loopback)?;
    let writer = node.writer::<JointState>(&cfg.joint_states_topic, cfg.joint_states_qos)?;
    let mut reader =
        node.reader::<Float64MultiArray>(&cfg.command_topic, TopicQos::reliable(10))?;
    let mut poll = Poll::new()?;
    poll.registry()
        .register(reader.source(), Token(0), Interest::READABLE)?;
    let mut events = Events::with_capacity(4);
    let start = ur5_shared::config::TaskConfig::default().start_q;
    let mut q = [
        start[0],
        start[1],
        start[2],
        -core::f64::consts::FRAC_PI_2,
        core::f64::consts::FRAC_PI_2,
        0.0,
    ];
    let mut msg = JointState {
        header: Header::default(),
        name: cfg.joints.to_vec(),
        position: q.to_vec(),
        velocity: vec![0.0; 6],
        effort: vec![],
    };
    let mut hist = Histogram::new();
    let mut stamp_ns = 1_000_000_000u64;
    while !stop.load(Ordering::Relaxed) {
        stamp_ns += (dt * 1e9) as u64;
        msg.header.stamp = Time::from_ns(stamp_ns);
        msg.position.copy_from_slice(&q);
        let sent = monotonic_ns();
        writer
            .write(msg.clone())
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        // The answer, or after 50 ms the next state (the controller may be waiting for a table).
        let deadline = sent + 50_000_000;
        let mut answered = false;
        while !answered && monotonic_ns() < deadline && !stop.load(Ordering::Relaxed) {
            while let Some(c) = reader.take() {
                if !answered {
                    hist.record(monotonic_ns() - sent);
                    answered = true;
                }
                if c.data.len() == 6 {
                    q.copy_from_slice(&c.data);
                }
            }
            if !answered {
                let _ = poll.poll(&mut events, Some(core::time::Duration::from_millis(5)));
            }
        }
    }
    Ok(hist.summary())
}
