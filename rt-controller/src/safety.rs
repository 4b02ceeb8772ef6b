//! The faults that make the controller hold ([`Fault`]) and the hold command (docs/design.md §3.4).
//! The action clamp itself is [`ur5_shared::safety::clamp_action`], shared with the learner's
//! rollouts.
//!
//! The hold is "PD to the last safe pose": in goal-angle mode the arm's own servo is that PD
//! (goal = last safe pose); in torque mode the controller computes it.

use serde::Serialize;
use ur5_shared::config::{ActionMode, ArmLimits};
use ur5_shared::layout::MAX_JOINTS;
use ur5_shared::ArmCommand;

use crate::config::Safety;

/// A fault that makes the controller hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// No fresh arm state within `safety.stale_state_timeout_s`.
    StaleState,
    /// The arm reported a fault bit.
    ArmFault,
    /// The arm state is not finite.
    NonFiniteState,
    /// The controller law produced a non-finite action (or failed).
    NonFiniteAction,
    /// No valid table.
    NoTable,
    /// The arm reports another number of active joints than the task's.
    WrongJoints,
}

impl Fault {
    /// What went wrong, for the log.
    pub fn name(self) -> &'static str {
        match self {
            Fault::StaleState => "stale arm state",
            Fault::ArmFault => "arm reports a fault",
            Fault::NonFiniteState => "non-finite arm state",
            Fault::NonFiniteAction => "non-finite action",
            Fault::NoTable => "no valid gain table",
            Fault::WrongJoints => "the arm reports another number of joints than the task has",
        }
    }
}

/// The hold command: PD to the last safe pose `q_safe` (rad, one per active joint; `q` and
/// `qd` of the same joints).
///
/// - Goal-angle mode: goal = `q_safe` clamped to the joint limits; the arm's servo holds it.
/// - Torque mode with a fresh state (`q`, `qd`): τ = K_p (q_safe − q) − K_d q̇, clamped to the
///   effort limits. Without a fresh state a torque is meaningless: [`ArmCommand::hold`], the
///   arm's own hold.
#[allow(clippy::too_many_arguments)]
pub fn hold_command(
    mode: ActionMode,
    lim: &ArmLimits,
    safety: &Safety,
    q_safe: &[f64],
    fresh: Option<(&[f64], &[f64])>,
    seq: u64,
    stamp_ns: u64,
    episode: u64,
) -> ArmCommand {
    let n = q_safe.len();
    let mut v = [0.0; MAX_JOINTS];
    match (mode, fresh) {
        (ActionMode::GoalAngles, _) => {
            for j in 0..n {
                v[j] = q_safe[j].clamp(lim.lower[j], lim.upper[j]);
            }
            ArmCommand::goal_angles(seq, stamp_ns, episode, &v[..n])
        }
        (ActionMode::Torque, Some((q, qd))) => {
            for j in 0..n {
                let (kp, kd) = safety.hold_gains(j);
                v[j] = (kp * (q_safe[j] - q[j]) - kd * qd[j]).clamp(-lim.effort[j], lim.effort[j]);
            }
            ArmCommand::torques(seq, stamp_ns, episode, &v[..n])
        }
        (ActionMode::Torque, None) => ArmCommand::hold(seq, stamp_ns, episode),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::CommandKind;

    #[test]
    fn hold_is_a_pd_to_the_last_safe_pose() {
        let l = ArmLimits::default();
        let s = Safety::default();
        let c = hold_command(
            ActionMode::GoalAngles,
            &l,
            &s,
            &[0.1, -1.0, 9.0],
            None,
            4,
            5,
            6,
        );
        assert_eq!(c.kind(), Ok(CommandKind::GoalAngles));
        assert_eq!(c.values(), [0.1, -1.0, std::f64::consts::PI]);
        assert_eq!((c.seq, c.stamp_ns, c.episode), (4, 5, 6));
        let c = hold_command(
            ActionMode::Torque,
            &l,
            &s,
            &[0.1, 0.0, 0.0],
            Some((&[0.0; 3], &[0.0, 1.0, 0.0])),
            1,
            0,
            0,
        );
        assert_eq!(c.kind(), Ok(CommandKind::Torques));
        assert_eq!(c.values(), [200.0 * 0.1, -20.0, 0.0]);
        let c = hold_command(ActionMode::Torque, &l, &s, &[0.1, 0.0, 0.0], None, 1, 0, 0);
        assert_eq!(c.kind(), Ok(CommandKind::Hold));
        // Six joints: every one held, the wrist with its own gains and limits.
        let l6 = ArmLimits::for_model_joints(ur5_shared::model::UrModel::Ur5e, 6);
        let c = hold_command(
            ActionMode::GoalAngles,
            &l6,
            &s,
            &[0.2, 0.0, 0.0, 0.0, 0.0, 9.0],
            None,
            1,
            0,
            0,
        );
        assert_eq!(c.joints, 6);
        assert_eq!(c.values()[5], l6.upper[5]);
        let c = hold_command(
            ActionMode::Torque,
            &l6,
            &s,
            &[0.0, 0.0, 0.0, 0.5, 0.0, 0.0],
            Some((&[0.0; 6], &[0.0, 0.0, 0.0, 0.0, 2.0, 0.0])),
            1,
            0,
            0,
        );
        assert_eq!(c.values(), [0.0, 0.0, 0.0, 10.0 * 0.5, -2.0, 0.0]);
    }
}
