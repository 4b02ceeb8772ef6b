//! The simulated arm as a UR controller sees it: the physics advanced one arm cycle at a time,
//! the program's servo goal, the robot/safety/runtime modes, and the RTDE snapshot every
//! connection reads. Shared by the physics clock, the program and the RTDE connections
//! through one mutex and a condition variable that signals each new cycle.

use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

use ur5_shared::kinematics::Joints6;
use ur_protocol::state::runtime_state;
use ur_protocol::{RobotMode, RobotState, SafetyMode};

use crate::Ur5Sim;

/// Deceleration of `stopj(4.0)` (rad/s²), as the project's program calls it.
pub const STOPJ_DECELERATION: f64 = 4.0;

/// Joint speed below which a stopping arm counts as at rest (rad/s).
const AT_REST: f64 = 1e-3;

/// What the robot-side program is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// No program: the arm holds its last goal.
    Idle,
    /// The project's program runs (servoj toward the goal).
    Running,
    /// `stopj`: decelerating to rest; then the program ends.
    Stopping,
}

/// How `ur-sim` turns the program's servoj targets into the sim's position-servo goal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ServojModel {
    /// The target is the goal at once; `lookahead_time` and `gain` change nothing (the
    /// default: the arm of `hil-sim serve`, whose results the RTDE path reproduces).
    #[default]
    Ideal,
    /// [`ServojFilter`]: smoothing over `lookahead_time`, then proportional tracking at `gain`.
    Tracking,
}

/// servoj's tracking as `ur-sim` models it (docs/ur.md, "servoj"): the target is smoothed by
/// a first-order low-pass of time constant `lookahead_time` (URScript: "smoothens the
/// trajectory with this lookahead time"; the lag of a first-order filter equals its time
/// constant, the lag users report), and the commanded position follows the smoothed target at
/// a rate of `gain` per second times the error (URScript: "proportional gain for following
/// target position"), so 1/gain (0.5–10 ms) is the tracking time constant. Both are
/// discretised exactly per arm cycle, `x += (1 − exp(−dt/τ))·(target − x)`, stable for
/// every setting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServojFilter {
    /// Per-cycle factor of the smoothing.
    a_smooth: f64,
    /// Per-cycle factor of the tracking.
    a_track: f64,
    smoothed: Joints6,
    commanded: Joints6,
}

impl ServojFilter {
    /// At rest at `q` (rad, six joints), for `lookahead_time_s` (s), `gain` (1/s) and arm
    /// cycle `dt` (s).
    pub fn new(lookahead_time_s: f64, gain: f64, dt: f64, q: Joints6) -> Self {
        Self {
            a_smooth: 1.0 - (-dt / lookahead_time_s).exp(),
            a_track: 1.0 - (-dt * gain).exp(),
            smoothed: q,
            commanded: q,
        }
    }

    /// One arm cycle toward `target` (rad): the position servo's goal.
    pub fn step(&mut self, target: &Joints6) -> Joints6 {
        for j in 0..6 {
            self.smoothed[j] += self.a_smooth * (target[j] - self.smoothed[j]);
            self.commanded[j] += self.a_track * (self.smoothed[j] - self.commanded[j]);
        }
        self.commanded
    }
}

/// The arm and the modes the controller reports.
pub struct Arm {
    sim: Ur5Sim,
    /// Arm cycles since start.
    pub cycle: u64,
    /// Arm cycle (s): 0.002 (e-Series) or 0.008 (CB3).
    pub dt: f64,
    /// Servo goal of the six joints (rad); a locked wrist's entries are its lock angles.
    goal: Joints6,
    /// Program phase.
    pub phase: Phase,
    /// Incremented per program start, so a stale program thread cannot act on a new one.
    pub program: u64,
    /// Safety mode (NORMAL, or PROTECTIVE_STOP after a limit violation).
    pub safety: SafetyMode,
    /// Arm cycle of the newest protective stop (the dashboard's 5 s unlock rule counts from it).
    pub stop_cycle: Option<u64>,
    /// Robot mode: POWER_OFF, IDLE (powered, brakes on) or RUNNING (brakes released); the
    /// dashboard's `power on`, `brake release` and `power off` change it.
    pub robot_mode: RobotMode,
    /// What RTDE connections send.
    pub snapshot: RobotState,
    /// A playback moving the arm by hand (`--playback`), if loaded.
    pub playback: Option<super::playback::Player>,
    /// The running program's servoj tracking ([`ServojModel::Tracking`]); `None`: ideal.
    pub servoj: Option<ServojFilter>,
}

/// A limit violation that triggers a protective stop.
#[derive(Debug, Clone, PartialEq)]
pub struct Violation(pub String);

impl Arm {
    /// The arm at rest at `start_q` (rad, six joints; a locked wrist's are ignored: it rests
    /// at its lock angles), arm cycle `dt` (s).
    pub fn new(
        mut sim: Ur5Sim,
        start_q: [f64; 6],
        goal_point: [f64; 3],
        dt: f64,
    ) -> Result<Self, crate::SimError> {
        if sim.joints() == 6 {
            sim.reset_all(&start_q, goal_point)?;
        } else {
            sim.reset([start_q[0], start_q[1], start_q[2]], goal_point)?;
        }
        let goal = sim.arm_joints().0;
        let mut arm = Self {
            sim,
            cycle: 0,
            dt,
            goal,
            phase: Phase::Idle,
            program: 0,
            safety: SafetyMode::Normal,
            stop_cycle: None,
            robot_mode: RobotMode::Running,
            snapshot: RobotState::default(),
            playback: None,
            servoj: None,
        };
        arm.refresh();
        Ok(arm)
    }

    /// Checks a servo target (six joints, rad) of the active joints against the URDF limits.
    pub fn check_target(&self, q: &Joints6) -> Result<(), Violation> {
        for j in 0..self.sim.joints() {
            let l = self.sim.model().joint(j);
            if !(q[j].is_finite() && q[j] >= l.lower && q[j] <= l.upper) {
                return Err(Violation(format!(
                    "joint `{}` target {} rad is outside its limits [{}, {}]",
                    l.name, q[j], l.lower, l.upper
                )));
            }
        }
        Ok(())
    }

    /// The locked wrist angles (rad).
    pub fn wrist_q(&self) -> [f64; 3] {
        self.sim.model().wrist_q
    }

    /// Active joints: 3 (wrist locked) or 6.
    pub fn joints(&self) -> usize {
        self.sim.joints()
    }

    /// Sets the servo goal of the active joints (SERVOJ target, six joints, rad; a locked
    /// wrist's targets are ignored).
    pub fn set_goal(&mut self, q: Joints6) {
        let n = self.sim.joints();
        self.goal[..n].copy_from_slice(&q[..n]);
    }

    /// Holds where the arm is now.
    pub fn hold_here(&mut self) {
        self.goal = self.sim.arm_joints().0;
    }

    /// Where the six joints are (rad; a locked wrist at its lock angles).
    pub fn q(&self) -> Joints6 {
        self.sim.arm_joints().0
    }

    /// Starts `stopj`: the goal becomes the point where a deceleration of
    /// [`STOPJ_DECELERATION`] would bring each joint to rest; the servo decelerates toward it.
    pub fn begin_stop(&mut self) {
        if self.phase == Phase::Running {
            let (q, qd) = self.sim.arm_joints();
            self.goal =
                core::array::from_fn(|j| q[j] + qd[j] * qd[j].abs() / (2.0 * STOPJ_DECELERATION));
            self.phase = Phase::Stopping;
        }
    }

    /// The dashboard's `stop`: the running program ends at once (its thread sees another
    /// program generation and closes the reverse connection; the runtime state is STOPPED from
    /// this cycle) and the arm decelerates as `stopj` does, to where [`Arm::begin_stop`] would
    /// bring it. Whether a program was running.
    pub fn stop_program(&mut self) -> bool {
        if self.phase != Phase::Running {
            return false;
        }
        self.begin_stop();
        self.program += 1;
        self.phase = Phase::Idle;
        self.refresh();
        true
    }

    /// A protective stop: the program stops the arm and ends, safety reports PROTECTIVE_STOP.
    pub fn protective_stop(&mut self) {
        self.safety = SafetyMode::ProtectiveStop;
        self.stop_cycle = Some(self.cycle);
        self.begin_stop();
        if self.phase == Phase::Idle {
            self.hold_here();
        }
        self.refresh();
    }

    /// Advances one arm cycle under the goal and refreshes the snapshot. Returns a violation
    /// if the arm ended outside its joint limits (the caller raises a protective stop).
    pub fn step(&mut self) -> Option<Violation> {
        if let Some(p) = self.playback.as_mut() {
            // Freedrive: the hand moves the arm; the physics and the servo goal stand still.
            // A hand moves it only while it is powered, its brakes released and no stop holds
            // it.
            self.cycle += 1;
            let moves = self.robot_mode == RobotMode::Running && self.safety == SafetyMode::Normal;
            p.advance(self.cycle as f64 * self.dt, moves);
            self.refresh();
            return None;
        }
        let n = self.sim.joints();
        match (self.phase, self.servoj.as_mut()) {
            (Phase::Running, Some(f)) => self.sim.step_all(&f.step(&self.goal)[..n]),
            _ => self.sim.step_all(&self.goal[..n]),
        };
        self.cycle += 1;
        let (q, qd) = self.sim.arm_joints();
        if self.phase == Phase::Stopping && qd.iter().all(|v| v.abs() < AT_REST) {
            self.goal = q;
            self.phase = Phase::Idle;
        }
        self.refresh();
        // The sim clamps goals to the limits; an overshoot beyond them is a violation.
        let margin = 1e-3;
        (0..n)
            .map(|j| (j, self.sim.model().joint(j)))
            .find_map(|(j, l)| {
                (!(q[j] >= l.lower - margin && q[j] <= l.upper + margin)).then(|| {
                    Violation(format!(
                        "joint `{}` at {} rad is outside its limits [{}, {}]",
                        l.name, q[j], l.lower, l.upper
                    ))
                })
            })
    }

    /// Arm time (s) since the newest protective stop, if the arm is in one.
    pub fn since_stop_s(&self) -> Option<f64> {
        (self.safety == SafetyMode::ProtectiveStop)
            .then(|| self.stop_cycle.map(|c| (self.cycle - c) as f64 * self.dt))
            .flatten()
    }

    /// Recomputes the snapshot after a change of modes (the dashboard's commands).
    pub fn refresh(&mut self) {
        let obs = self.sim.true_observation();
        let (q, qd) = self.sim.arm_joints();
        let s = &mut self.snapshot;
        s.timestamp = self.cycle as f64 * self.dt;
        s.actual_q = q;
        s.actual_qd = qd;
        s.target_q = self.goal;
        // Joint torques (N·m) stand in for currents: the sim has no motor model.
        s.actual_current = self.sim.last_torque_all();
        // Position of the project's end-effector point; its orientation is not modelled.
        s.actual_tcp_pose = [obs.ee_pos[0], obs.ee_pos[1], obs.ee_pos[2], 0.0, 0.0, 0.0];
        s.actual_tcp_speed = [obs.ee_vel[0], obs.ee_vel[1], obs.ee_vel[2], 0.0, 0.0, 0.0];
        s.target_tcp_pose = s.actual_tcp_pose;
        s.target_moment = s.actual_current;
        s.joint_temperatures = [30.0; 6];
        // A powered arm's bus voltages (V); not modelled further.
        s.actual_main_voltage = 48.0;
        s.actual_robot_voltage = 48.0;
        s.actual_joint_voltage = [48.0; 6];
        s.robot_mode = self.robot_mode.code();
        s.safety_mode = self.safety.code();
        s.safety_status = self.safety.code();
        // 253: the joints' RUNNING mode.
        s.joint_mode = [253; 6];
        s.runtime_state = match self.phase {
            Phase::Idle => runtime_state::STOPPED,
            Phase::Running | Phase::Stopping => runtime_state::PLAYING,
        };
        s.speed_scaling = 1.0;
        s.target_speed_fraction = 1.0;
        s.actual_execution_time = 0.1;
        if let Some(p) = &self.playback {
            let played = p.state();
            s.actual_q = played.q;
            s.actual_qd = played.qd;
            s.target_q = played.q;
            s.actual_tcp_pose = [played.ee[0], played.ee[1], played.ee[2], 0.0, 0.0, 0.0];
            s.actual_tcp_speed = [
                played.ee_vel[0],
                played.ee_vel[1],
                played.ee_vel[2],
                0.0,
                0.0,
                0.0,
            ];
            s.target_tcp_pose = s.actual_tcp_pose;
        }
    }

    /// Loads a playback: from now on the arm is where it says ([`super::playback`]).
    pub fn load_playback(&mut self, player: super::playback::Player) {
        self.playback = Some(player);
        self.refresh();
    }

    /// Starts a loaded playback now, if it has not started.
    pub fn start_playback(&mut self) {
        let time = self.cycle as f64 * self.dt;
        if let Some(p) = self.playback.as_mut() {
            p.start(time);
        }
    }

    /// Once, when a loaded playback has passed its last row: the message that says so.
    pub fn playback_end_message(&mut self) -> Option<String> {
        self.playback.as_mut()?.end_message()
    }
}

/// The arm shared between threads.
pub struct Plant {
    arm: Mutex<Arm>,
    cycled: Condvar,
}

impl Plant {
    /// Shares `arm`.
    pub fn new(arm: Arm) -> Self {
        Self {
            arm: Mutex::new(arm),
            cycled: Condvar::new(),
        }
    }

    /// Locks the arm (a panicked holder does not poison the plant: the arm data stays usable).
    pub fn lock(&self) -> MutexGuard<'_, Arm> {
        self.arm.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Wakes every thread waiting for a new cycle (after a step, or on shutdown).
    pub fn notify(&self) {
        self.cycled.notify_all();
    }

    /// Waits until the cycle count passes `after` or `wake()` holds, at most `timeout`;
    /// returns the guard.
    pub fn wait_cycle(
        &self,
        after: u64,
        timeout: Duration,
        wake: impl Fn() -> bool,
    ) -> MutexGuard<'_, Arm> {
        let guard = self.lock();
        match self
            .cycled
            .wait_timeout_while(guard, timeout, |a| a.cycle <= after && !wake())
        {
            Ok((g, _)) => g,
            Err(e) => e.into_inner().0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_servoj_filter_smooths_over_the_lookahead_and_tracks_at_the_gain() {
        let dt = 0.002;
        // Smoothing alone (a gain so high the tracking is immediate): 1 − 1/e of a step after
        // one lookahead time.
        let mut f = ServojFilter::new(0.1, 1e9, dt, [0.0; 6]);
        let mut y = [0.0; 6];
        for _ in 0..50 {
            y = f.step(&[1.0, 2.0, -1.0, 0.5, 0.0, 3.0]);
        }
        let e = 1.0 - (-1.0f64).exp();
        assert!(
            (y[0] - e).abs() < 1e-9 && (y[1] - 2.0 * e).abs() < 1e-9,
            "{y:?}"
        );
        // Each setting converges to the target and stays between start and target.
        for (l, g) in [(0.03, 100.0), (0.2, 2000.0), (0.03, 2000.0)] {
            let mut f = ServojFilter::new(l, g, 0.008, [0.0; 6]);
            let mut last = 0.0;
            for _ in 0..1000 {
                let y = f.step(&[1.0; 6])[0];
                assert!(y >= last && y <= 1.0, "monotone: {l} {g}");
                last = y;
            }
            assert!((last - 1.0).abs() < 1e-9, "{l} {g}: {last}");
        }
    }
}
