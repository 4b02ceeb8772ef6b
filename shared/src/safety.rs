//! The action clamp: the one place where an action is made safe before it reaches an arm.
//!
//! Both the real-time loop and the learner's in-process rollouts call [`clamp_action`], so a
//! rollout in the learner sees exactly the actions the arm would execute (docs/design.md §2.4: goals
//! clamped to the joint limits and to at most the velocity limit × control period away from the
//! current angles; torques clamped to the effort limits).

use crate::config::{ActionMode, ArmLimits};

/// Clamps `a` (dU entries) in place for an arm at joint angles `q` (rad, dU entries) with
/// control period `dt` (s), against the first dU joints' `limits`. Returns `true` if any
/// entry changed. A non-finite entry is replaced by a hold: `q[j]` in goal-angle mode, 0 N·m in
/// torque mode. Allocation-free. Panics if `q` and `a` differ in length or the limits cover
/// fewer joints (a programming error: all come from one task's layout).
pub fn clamp_action(
    mode: ActionMode,
    limits: &ArmLimits,
    dt: f64,
    q: &[f64],
    a: &mut [f64],
) -> bool {
    assert!(
        q.len() == a.len() && limits.joints() >= a.len(),
        "one limit, angle and action per joint"
    );
    let mut changed = false;
    for j in 0..a.len() {
        let before = a[j];
        let v = match mode {
            ActionMode::GoalAngles => {
                let step = limits.velocity[j] * dt;
                let target = if before.is_finite() { before } else { q[j] };
                target
                    .clamp(q[j] - step, q[j] + step)
                    .clamp(limits.lower[j], limits.upper[j])
            }
            ActionMode::Torque => {
                if before.is_finite() {
                    before.clamp(-limits.effort[j], limits.effort[j])
                } else {
                    0.0
                }
            }
        };
        if v.to_bits() != before.to_bits() {
            changed = true;
        }
        a[j] = v;
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn goal_angles_are_limited_per_step_and_by_joint_limits() {
        let lim = ArmLimits::default();
        let q = [0.0, -1.0, 3.0];
        let mut a = [1.0, -1.1, 3.5];
        assert!(clamp_action(ActionMode::GoalAngles, &lim, 0.1, &q, &mut a));
        let step = std::f64::consts::PI * 0.1;
        assert_eq!(a, [step, -1.1, std::f64::consts::PI]);
        let mut b = [0.1, -1.0, 2.9];
        assert!(!clamp_action(ActionMode::GoalAngles, &lim, 0.1, &q, &mut b));
        assert_eq!(b, [0.1, -1.0, 2.9]);
    }

    #[test]
    fn non_finite_entries_become_a_hold() {
        let lim = ArmLimits::default();
        let q = [0.2, -1.0, 1.0];
        let mut a = [f64::NAN, f64::INFINITY, -0.9];
        assert!(clamp_action(ActionMode::GoalAngles, &lim, 0.1, &q, &mut a));
        assert_eq!(a[0], 0.2);
        assert_eq!(a[1], -1.0);
        let mut t = [f64::NAN, 500.0, -10.0];
        assert!(clamp_action(ActionMode::Torque, &lim, 0.1, &q, &mut t));
        assert_eq!(t, [0.0, 150.0, -10.0]);
    }
}
