//! In-process stand-ins for the controller's peers, for the benchmark and the tests: a
//! kinematic arm (no physics: goal angles are reached at the velocity limit) that answers every
//! command with a state (lockstep), and table builders (gain and policy). They use the same services and QoS as
//! the real processes. Not for experiments: use `hil-sim serve` for an arm.

use core::sync::atomic::{AtomicBool, Ordering};

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ActionMode;
use ur5_shared::layout::{MAX_JOINTS, MAX_TOOL_POINTS};
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{
    ArmCommand, ArmState, ArmStatus, CommandKind, GainTable, PolicyTable, StateLayout, DU,
};

use crate::ports::SetupError;
use crate::stats::Histogram;

/// What the kinematic arm saw.
pub struct ArmReport {
    /// Commands applied.
    pub commands: u64,
    /// Reset commands among them.
    pub resets: u64,
    /// Hold commands among them.
    pub holds: u64,
    /// Time from publishing a state to receiving the command that answers it (ns): the IPC
    /// round trip state → command, including the controller's compute and both sides' polling.
    pub round_trip: Histogram,
}

fn setup_err(what: &'static str) -> impl Fn(&dyn core::fmt::Debug) -> SetupError {
    move |e| SetupError::Port {
        kind: what,
        name: String::new(),
        why: format!("{e:?}"),
    }
}

/// Runs a lockstep kinematic arm on `prefix` until `stop` is raised. Joint angles move towards
/// goal angles by at most `max_velocity` (rad/s) × `dt` (s) per command; torques and holds keep
/// the pose; a reset teleports. Three joints and one tool point, at q scaled by 0.1 (only the
/// layout matters here).
pub fn run_kinematic_arm(
    prefix: &str,
    dt: f64,
    max_velocity: f64,
    stop: &AtomicBool,
) -> Result<ArmReport, SetupError> {
    run_kinematic_arm_with(prefix, dt, max_velocity, stop, |_| {})
}

/// [`run_kinematic_arm`] that calls `before_answer` with every command before applying and
/// answering it. A lockstep controller waits for that answer, so a test can do something at a
/// known point of the controller's episode sequence (e.g. publish a table while the controller
/// waits for the reset of episode k, so that it is taken at the boundary before episode k + 1)
/// instead of racing the loop. The controller gives up waiting after
/// `safety.stale_state_timeout_s`.
pub fn run_kinematic_arm_with(
    prefix: &str,
    dt: f64,
    max_velocity: f64,
    stop: &AtomicBool,
    before_answer: impl FnMut(&ArmCommand),
) -> Result<ArmReport, SetupError> {
    run_kinematic_arm_for(
        &StateLayout::REACH3,
        prefix,
        dt,
        max_velocity,
        stop,
        before_answer,
    )
}

/// [`run_kinematic_arm_with`] of an arm with `layout`'s joints and tool points (point i at
/// 0.1 q[..3] shifted by i × 0.1 m in z).
pub fn run_kinematic_arm_for(
    layout: &StateLayout,
    prefix: &str,
    dt: f64,
    max_velocity: f64,
    stop: &AtomicBool,
    mut before_answer: impl FnMut(&ArmCommand),
) -> Result<ArmReport, SetupError> {
    let names = ServiceNames::new(prefix);
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| SetupError::Node(format!("{e:?}")))?;
    let state_svc = services::ARM_STATE_QOS
        .open_or_create::<ArmState>(&node, &names.arm_state()?)
        .map_err(|e| setup_err("service")(&e))?;
    let cmd_svc = services::ARM_COMMAND_QOS
        .open_or_create::<ArmCommand>(&node, &names.arm_command()?)
        .map_err(|e| setup_err("service")(&e))?;
    let state_pub = state_svc
        .publisher_builder()
        .create()
        .map_err(|e| setup_err("publisher")(&e))?;
    let cmd_sub = cmd_svc
        .subscriber_builder()
        .create()
        .map_err(|e| setup_err("subscriber")(&e))?;

    let mut report = ArmReport {
        commands: 0,
        resets: 0,
        holds: 0,
        round_trip: Histogram::new(),
    };
    let (n, p) = (layout.joints(), layout.tool_points());
    let mut state = ArmState {
        status: ArmStatus::READY,
        joints: n as u32,
        tool_points: p as u32,
        ..ArmState::default()
    };
    let publish = |state: &mut ArmState| {
        state.seq += 1;
        state.stamp_ns = monotonic_ns();
        for i in 0..p.min(MAX_TOOL_POINTS) {
            state.points[i] = core::array::from_fn(|j| 0.1 * state.q[j]);
            state.points[i][2] += 0.1 * i as f64;
        }
        let _ = state_pub.send_copy(*state);
        state.stamp_ns
    };
    let mut last_pub = publish(&mut state);
    let step = max_velocity * dt;
    let mut idle: u32 = 0;
    while !stop.load(Ordering::Relaxed) {
        let cmd = match cmd_sub.receive() {
            Ok(Some(c)) => *c,
            _ => {
                idle += 1;
                if idle % 64 == 0 {
                    // Delivers the history (the last state) to a controller that joins late.
                    let _ = state_pub.update_connections();
                    std::thread::yield_now();
                } else {
                    core::hint::spin_loop();
                }
                if idle > 100_000 {
                    std::thread::sleep(core::time::Duration::from_micros(200));
                }
                continue;
            }
        };
        idle = 0;
        report
            .round_trip
            .record(monotonic_ns().saturating_sub(last_pub));
        before_answer(&cmd);
        report.commands += 1;
        match cmd.kind() {
            Ok(CommandKind::Reset) => {
                report.resets += 1;
                let q = cmd.reset_pose();
                state.set_joints(q, &[0.0; MAX_JOINTS][..q.len()]);
            }
            Ok(CommandKind::GoalAngles) => {
                for j in 0..cmd.values().len() {
                    let dq = (cmd.values[j] - state.q[j]).clamp(-step, step);
                    state.q[j] += dq;
                    state.qd[j] = dq / dt;
                }
            }
            Ok(CommandKind::Hold) => {
                report.holds += 1;
                state.qd = [0.0; MAX_JOINTS];
            }
            Ok(CommandKind::Torques) | Err(_) => state.qd = [0.0; MAX_JOINTS],
        }
        state.episode = cmd.episode;
        state.last_command_seq = cmd.seq;
        last_pub = publish(&mut state);
    }
    Ok(report)
}

/// The six-joint pose task of T = `horizon` on the UR5 (the controller's default model): the
/// model's start pose with its wrist, and as goal the tool's pose at other joint angles.
pub fn pose_task(horizon: usize) -> ur5_shared::config::TaskConfig {
    use ur5_shared::kinematics::UrKinematics;
    use ur5_shared::model::UrModel;
    let kin = UrKinematics::new(UrModel::Ur5, UrModel::Ur5.default_ee_offset());
    let goal = ur5_shared::pose::ur_pose(&kin.tool_pose(&[0.3, -1.7, 2.0, -1.8, -1.5, 0.2]));
    ur5_shared::config::TaskConfig {
        horizon,
        ..ur5_shared::config::TaskConfig::pose_for_model(UrModel::Ur5, goal)
    }
}

/// A table that commands the constant goal `q_goal` (rad) with exploration noise of standard
/// deviation `sigma` (rad) on every joint: K = 0, k = 0, ŝ = 0, â = q_goal, L = σ I. Sealed.
pub fn constant_goal_table(
    version: u64,
    horizon: usize,
    q_goal: [f64; DU],
    sigma: f64,
) -> Box<GainTable> {
    constant_goal_table_for(&StateLayout::REACH3, version, horizon, &q_goal, sigma)
}

/// [`constant_goal_table`] for any layout: `q_goal` has dU entries.
pub fn constant_goal_table_for(
    layout: &StateLayout,
    version: u64,
    horizon: usize,
    q_goal: &[f64],
    sigma: f64,
) -> Box<GainTable> {
    let mut t = GainTable::new_boxed_for(layout);
    t.set_version(version);
    t.set_horizon(horizon)
        .expect("horizon within 1..=MAX_HORIZON");
    for s in 0..horizon {
        let mut st = t.step_mut(s);
        st.a_hat.copy_from_slice(q_goal);
        for i in 0..layout.du() {
            st.set_l(i, i, sigma);
        }
    }
    t.seal();
    t
}

/// A seeded random policy table (docs/design.md §3.11) in goal-angle mode: heads of hidden
/// widths `hidden` with Glorot-uniform weights (tanh layers) and an output layer scaled by
/// `out_scale` (so that μ, the goal offset from q in rad, stays of order `out_scale`), input
/// normalisation m = 0, r = 1, σ = `sigma` rad on every joint. Sealed.
pub fn random_policy_table(
    version: u64,
    hidden: &[usize],
    out_scale: f64,
    sigma: f64,
    seed: u64,
) -> Box<PolicyTable> {
    random_policy_table_for(
        &StateLayout::REACH3,
        version,
        hidden,
        out_scale,
        sigma,
        seed,
    )
}

/// [`random_policy_table`] for any layout.
pub fn random_policy_table_for(
    layout: &StateLayout,
    version: u64,
    hidden: &[usize],
    out_scale: f64,
    sigma: f64,
    seed: u64,
) -> Box<PolicyTable> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let (dx, du) = (layout.dx(), layout.du());
    let mut theta = Vec::with_capacity(ur5_shared::policy::flat_len(dx, du, hidden));
    theta.extend(core::iter::repeat_n(0.0, dx));
    theta.extend(core::iter::repeat_n(1.0, dx));
    for _ in 0..du {
        let mut prev = dx;
        for (l, &n) in hidden.iter().chain(&[1]).enumerate() {
            let a = (6.0 / (prev + n) as f64).sqrt();
            let scale = if l == hidden.len() { out_scale } else { 1.0 };
            theta.extend((0..prev * n).map(|_| scale * rng.random_range(-a..a)));
            theta.extend((0..n).map(|_| 0.0));
            prev = n;
        }
    }
    theta.extend(core::iter::repeat_n(sigma.ln(), du));
    let mut p = PolicyTable::new_boxed();
    p.fill(version, layout, ActionMode::GoalAngles, hidden, &theta)
        .expect("a policy within the table's limits");
    p
}
