//! What an arm backend that streams six-joint position targets does between the controller's
//! commands (docs/design.md §3.10): hold (or ramp to) the goal, run a reset as a quintic
//! joint-space move and acknowledge it once settled, refuse commands it cannot send. Shared by
//! the `ur` arm (servoj targets per RTDE package) and the `ros2` arm (forward-controller
//! commands per joint state). No allocation.

use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::{ArmLimits, TaskConfig};
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::layout::MAX_TOOL_POINTS;
use ur5_shared::model::UrModel;
use ur5_shared::{ArmCommand, ArmFaults, ArmState, ArmStatus, CommandKind};

use crate::config::ServoTarget;

/// A reset to the start pose counts as done when every joint is this close (rad) …
pub const RESET_TOL_Q: f64 = 2e-3;
/// … and this slow (rad/s).
pub const RESET_TOL_QD: f64 = 1e-2;
/// After the reset motion ends, the arm has this long (s of arm time) to settle; then the
/// reset is acknowledged where the arm is.
pub const RESET_SETTLE_MAX_S: f64 = 3.0;
/// Shortest reset motion (s).
const RESET_MIN_S: f64 = 0.5;

/// What the arm is servoing to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Motion {
    /// The controller's goal (or a hold), as [`ServoTarget`] says.
    Servo,
    /// A quintic joint-space move from `from` to `to` starting at arm time `t0` (s), lasting
    /// `duration` (s); acknowledged with `seq` once settled.
    Reset {
        from: Joints6,
        to: Joints6,
        t0: f64,
        duration: f64,
        seq: u64,
    },
}

/// Quintic time scaling: 0 → 1 with zero velocity and acceleration at both ends.
fn quintic(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

/// The servo side of a position-streaming arm: the goal in force, the reset in progress, the
/// command sequence and episode the arm's states acknowledge.
#[derive(Clone, Debug)]
pub(crate) struct Servo {
    pub motion: Motion,
    /// The goal in force (six joints, rad) and, for `ramp`, the target it ramps from and the
    /// arm time (s) of the state it answered.
    pub goal: Joints6,
    pub ramp_from: Joints6,
    pub goal_ts: f64,
    /// Arm cycle (s): one target per cycle.
    pub cycle_s: f64,
    /// Control period (s of arm time).
    pub period_s: f64,
    pub last_command_seq: u64,
    pub episode: u64,
    /// Resets completed, of them unsettled, and commands refused.
    pub resets: u64,
    pub unsettled: u64,
    pub refused: u64,
    /// The task's active joints (3: the wrist held at `wrist_q`; 6: the whole arm commanded).
    joints: usize,
    wrist_q: [f64; 3],
}

impl Servo {
    /// Holding `q` from arm time `ts` (s), taking commands for the first `joints` joints (3
    /// or 6; with 3 the wrist's goal is `wrist_q`, rad).
    pub fn new(
        q: Joints6,
        ts: f64,
        cycle_s: f64,
        period_s: f64,
        joints: usize,
        wrist_q: [f64; 3],
    ) -> Self {
        assert!(joints == 3 || joints == 6, "a UR task moves 3 or 6 joints");
        Self {
            joints,
            wrist_q,
            motion: Motion::Servo,
            goal: q,
            ramp_from: q,
            goal_ts: ts,
            cycle_s,
            period_s,
            last_command_seq: 0,
            episode: 0,
            resets: 0,
            unsettled: 0,
            refused: 0,
        }
    }

    /// Holds the active joints where they are (`here`, six joints, rad) from arm time `ts`,
    /// ending any reset: the wrist at `wrist_q` when three joints are active.
    pub fn hold_here(&mut self, here: &Joints6, ts: f64) {
        let q = self.six(&here[..self.joints]);
        self.hold(q, ts);
    }

    /// Holds `q` from arm time `ts`, ending any reset.
    pub fn hold(&mut self, q: Joints6, ts: f64) {
        self.motion = Motion::Servo;
        self.goal = q;
        self.ramp_from = q;
        self.goal_ts = ts;
    }

    pub fn resetting(&self) -> bool {
        matches!(self.motion, Motion::Reset { .. })
    }

    /// A measured state (all six joints) at arm time `ts` during a reset: once the motion has
    /// ended and the arm settled (or [`RESET_SETTLE_MAX_S`] passed), the reset is acknowledged
    /// (`last_command_seq`) and the arm holds its pose; `Some(settled)` then.
    pub fn reset_done(&mut self, q: &Joints6, qd: &Joints6, ts: f64) -> Option<bool> {
        let Motion::Reset {
            to,
            t0,
            duration,
            seq,
            ..
        } = self.motion
        else {
            return None;
        };
        let settled =
            (0..6).all(|j| (q[j] - to[j]).abs() < RESET_TOL_Q && qd[j].abs() < RESET_TOL_QD);
        let end = t0 + duration;
        if ts >= end && (settled || ts >= end + RESET_SETTLE_MAX_S) {
            self.resets += 1;
            self.unsettled += u64::from(!settled);
            self.hold(to, ts);
            self.last_command_seq = seq;
            return Some(settled);
        }
        None
    }

    /// The six joint goals (rad) of goals `active` for the task's joints: the wrist's at
    /// `wrist_q` when three joints are active.
    fn six(&self, active: &[f64]) -> Joints6 {
        if self.joints == 6 {
            core::array::from_fn(|j| active[j])
        } else {
            UrKinematics::six(&[active[0], active[1], active[2]], &self.wrist_q)
        }
    }

    /// Takes a controller command with the arm at `here` (six joints) at arm time `ts`; false
    /// if it could not be sent as it is (non-finite, outside `limits`, for another number of
    /// joints, torques: then the arm holds where it is and `refused` counts it).
    pub fn take_command(
        &mut self,
        cmd: &ArmCommand,
        limits: &ArmLimits,
        reset_speed_rad_s: f64,
        servo_target: ServoTarget,
        here: Joints6,
        ts: f64,
    ) -> bool {
        self.last_command_seq = cmd.seq;
        self.episode = cmd.episode;
        let n = self.joints;
        let hold_here = self.six(&here[..n]);
        // The six joint goals of a command for the active joints within their limits (None:
        // for another number of joints, refused as out of limits are).
        let valid = |v: &[f64]| {
            let ok = v.len() == n
                && (0..n).all(|j| {
                    v[j].is_finite() && v[j] >= limits.lower[j] && v[j] <= limits.upper[j]
                });
            ok.then(|| self.six(v))
        };
        let (goal, ok) = match (cmd.kind(), valid(cmd.values()), valid(cmd.reset_pose())) {
            (Ok(CommandKind::GoalAngles), Some(q), _) => (q, true),
            (Ok(CommandKind::Hold), ..) => (hold_here, true),
            (Ok(CommandKind::Reset), _, Some(to)) => {
                match &mut self.motion {
                    // The same reset again (the controller's retry): it goes on.
                    Motion::Reset { to: t, seq, .. } if *t == to => *seq = cmd.seq,
                    _ => {
                        let dist = (0..6).fold(0.0f64, |m, j| m.max((to[j] - here[j]).abs()));
                        // Peak speed of the quintic: 15/8 · distance / duration.
                        let duration = (1.875 * dist / reset_speed_rad_s).max(RESET_MIN_S);
                        self.motion = Motion::Reset {
                            from: here,
                            to,
                            t0: ts,
                            duration,
                            seq: cmd.seq,
                        };
                    }
                }
                // Acknowledged when done ([`Self::reset_done`]).
                self.last_command_seq = cmd.seq.saturating_sub(1);
                return true;
            }
            _ => (hold_here, false),
        };
        if !ok {
            self.refused += 1;
        }
        self.ramp_from = self.target(servo_target, ts);
        self.motion = Motion::Servo;
        self.goal = goal;
        self.goal_ts = ts;
        ok
    }

    /// The target for the cycle after the state of arm time `ts`.
    pub fn target(&self, servo_target: ServoTarget, ts: f64) -> Joints6 {
        match self.motion {
            Motion::Reset {
                from,
                to,
                t0,
                duration,
                ..
            } => {
                let s = quintic((ts + self.cycle_s - t0) / duration);
                core::array::from_fn(|j| from[j] + s * (to[j] - from[j]))
            }
            Motion::Servo => match servo_target {
                ServoTarget::Hold => self.goal,
                ServoTarget::Ramp => {
                    let f = ((ts + self.cycle_s - self.goal_ts) / self.period_s).clamp(0.0, 1.0);
                    core::array::from_fn(|j| {
                        self.ramp_from[j] + f * (self.goal[j] - self.ramp_from[j])
                    })
                }
            },
        }
    }
}

/// What a position-streaming backend reports of the arm for the task: its active joints and
/// the task's tool points by forward kinematics (`ur5_shared::kinematics`) from all six
/// measured joints.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ArmSensor {
    kin: UrKinematics,
    joints: usize,
    offsets: [[f64; 3]; MAX_TOOL_POINTS],
    points: usize,
}

impl ArmSensor {
    /// The sensor of `model` with the end-effector point `ee_offset` (m, `wrist_3_link` frame)
    /// for `task`'s joints and tool points.
    pub fn new(model: UrModel, ee_offset: [f64; 3], task: &TaskConfig) -> Self {
        let tool = task.tool_offsets();
        let mut offsets = [[0.0; 3]; MAX_TOOL_POINTS];
        offsets[..tool.len()].copy_from_slice(tool);
        Self {
            kin: UrKinematics::new(model, ee_offset),
            joints: task.joints,
            offsets,
            points: tool.len(),
        }
    }

    /// The controller's [`ArmState`] from a measured six-joint state (rad, rad/s): the active
    /// joints and the tool points. No fault bits.
    pub fn state(
        &self,
        q: &Joints6,
        qd: &Joints6,
        seq: u64,
        last_command_seq: u64,
        episode: u64,
        status: ArmStatus,
    ) -> ArmState {
        let p = self.points;
        let (mut points, mut vels) = ([[0.0; 3]; MAX_TOOL_POINTS], [[0.0; 3]; MAX_TOOL_POINTS]);
        self.kin
            .tool_points_velocity(q, qd, &self.offsets[..p], &mut points[..p], &mut vels[..p]);
        let mut s = ArmState {
            seq,
            stamp_ns: monotonic_ns(),
            episode,
            last_command_seq,
            status,
            faults: ArmFaults::default(),
            ..ArmState::default()
        };
        s.set_joints(&q[..self.joints], &qd[..self.joints]);
        s.set_points(&points[..p], &vels[..p]);
        s
    }
}

/// Whether a state is due at arm time `ts` (s): one per control period `period_s` of arm time,
/// taken at the arm cycle (`cycle_s`) nearest the deadline `next_emit_ts`, which then moves on by
/// a period (restarting from `ts` after a gap of more than a period).
pub(crate) fn state_due(next_emit_ts: &mut f64, ts: f64, cycle_s: f64, period_s: f64) -> bool {
    if !(ts >= *next_emit_ts - 0.49 * cycle_s) {
        return false;
    }
    *next_emit_ts += period_s;
    if *next_emit_ts <= ts {
        *next_emit_ts = ts + period_s;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits6() -> ArmLimits {
        ArmLimits::for_model_joints(UrModel::Ur5e, 6)
    }

    #[test]
    fn six_active_joints_command_the_wrist_three_hold_it_at_wrist_q() {
        let here = [0.1, -1.6, 2.0, -1.5, -1.6, 0.3];
        let wrist = [-1.57, -1.57, 0.0];
        let goal = [0.2, -1.7, 2.1, -1.4, -1.5, 0.5];
        let mut six = Servo::new(here, 0.0, 0.002, 0.1, 6, wrist);
        let cmd = ArmCommand::goal_angles(1, 0, 0, goal);
        assert!(six.take_command(&cmd, &limits6(), 1.0, ServoTarget::Hold, here, 0.0));
        assert_eq!(six.goal, goal);
        // A command for three joints is refused by a six-joint servo: it holds where it is.
        let three = ArmCommand::goal_angles(2, 0, 0, [0.2, -1.7, 2.1]);
        assert!(!six.take_command(&three, &limits6(), 1.0, ServoTarget::Hold, here, 0.0));
        assert_eq!((six.goal, six.refused), (here, 1));
        let mut locked = Servo::new(here, 0.0, 0.002, 0.1, 3, wrist);
        let l3 = ArmLimits::for_model_joints(UrModel::Ur5e, 3);
        assert!(locked.take_command(&three, &l3, 1.0, ServoTarget::Hold, here, 0.0));
        assert_eq!(locked.goal, [0.2, -1.7, 2.1, -1.57, -1.57, 0.0]);
        assert!(!locked.take_command(&cmd, &l3, 1.0, ServoTarget::Hold, here, 0.0));
        // A reset of six joints moves the wrist to the reset pose's.
        let reset = ArmCommand::reset(3, 0, 1, goal);
        assert!(six.take_command(&reset, &limits6(), 1.0, ServoTarget::Hold, here, 0.0));
        assert!(matches!(six.motion, Motion::Reset { to, .. } if to == goal));
    }

    #[test]
    fn the_sensor_reports_the_tasks_joints_and_tool_points() {
        let kin = UrKinematics::new(UrModel::Ur5e, [0.0; 3]);
        let q = [0.3, -1.9, 2.2, -1.4, 1.6, 0.2];
        let goal = ur5_shared::pose::ur_pose(&kin.tool_pose(&q));
        let task = TaskConfig::pose_for_model(UrModel::Ur5e, goal);
        let sensor = ArmSensor::new(UrModel::Ur5e, [0.0; 3], &task);
        let s = sensor.state(&q, &[0.0; 6], 1, 0, 0, ArmStatus::READY);
        s.check_layout(&task.layout()).unwrap();
        // At the goal pose every tool point is on its target.
        let targets = task.targets();
        for (p, t) in s.points().iter().zip(&targets) {
            for k in 0..3 {
                assert!((p[k] - t[k]).abs() < 1e-12, "{p:?} vs {t:?}");
            }
        }
        let reach = ArmSensor::new(UrModel::Ur5e, [0.0; 3], &TaskConfig::default());
        let s3 = reach.state(&q, &[0.0; 6], 1, 0, 0, ArmStatus::READY);
        s3.check_layout(&ur5_shared::StateLayout::REACH3).unwrap();
        assert_eq!(s3.points[0], kin.ee_point(&q));
    }
}
