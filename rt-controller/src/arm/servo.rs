//! What an arm backend that streams six-joint position targets does between the controller's
//! commands (docs/design.md §3.10): hold (or ramp to) the goal, run a reset as a quintic
//! joint-space move and acknowledge it once settled, refuse commands it cannot send. Shared by
//! the `ur` arm (servoj targets per RTDE package) and the `ros2` arm (forward-controller
//! commands per joint state). No allocation.

use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ArmLimits;
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::layout::N_JOINTS;
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
}

impl Servo {
    /// Holding `q` from arm time `ts` (s).
    pub fn new(q: Joints6, ts: f64, cycle_s: f64, period_s: f64) -> Self {
        Self {
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

    /// Takes a controller command with the arm at `here` (six joints) at arm time `ts`; false
    /// if it could not be sent as it is (non-finite, outside `limits`, torques: then the arm
    /// holds where it is and `refused` counts it).
    pub fn take_command(
        &mut self,
        cmd: &ArmCommand,
        limits: &ArmLimits,
        wrist_q: &[f64; 3],
        reset_speed_rad_s: f64,
        servo_target: ServoTarget,
        here: Joints6,
        ts: f64,
    ) -> bool {
        self.last_command_seq = cmd.seq;
        self.episode = cmd.episode;
        let hold_here = UrKinematics::six(&[here[0], here[1], here[2]], wrist_q);
        // The active joints' values of a command for them within their limits (None: for
        // another number of joints, refused as out of limits are).
        let valid = |v: &[f64]| {
            <[f64; N_JOINTS]>::try_from(v).ok().filter(|q| {
                (0..N_JOINTS)
                    .all(|j| q[j].is_finite() && q[j] >= limits.lower[j] && q[j] <= limits.upper[j])
            })
        };
        let (goal, ok) = match (cmd.kind(), valid(cmd.values()), valid(cmd.reset_pose())) {
            (Ok(CommandKind::GoalAngles), Some(q), _) => (UrKinematics::six(&q, wrist_q), true),
            (Ok(CommandKind::Hold), ..) => (hold_here, true),
            (Ok(CommandKind::Reset), _, Some(q)) => {
                let to = UrKinematics::six(&q, wrist_q);
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

/// The controller's [`ArmState`] from a measured six-joint state: the three active joints,
/// the end-effector point and velocity from all six (`ur5_shared::kinematics`). No fault bits.
pub(crate) fn arm_state(
    kin: &UrKinematics,
    q: &Joints6,
    qd: &Joints6,
    seq: u64,
    last_command_seq: u64,
    episode: u64,
    status: ArmStatus,
) -> ArmState {
    let (ee_pos, ee_vel) = kin.ee_point_velocity(q, qd);
    ArmState {
        seq,
        stamp_ns: monotonic_ns(),
        episode,
        last_command_seq,
        status,
        faults: ArmFaults::default(),
        ..ArmState::of_joints(&q[..N_JOINTS], &qd[..N_JOINTS], ee_pos, ee_vel)
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
