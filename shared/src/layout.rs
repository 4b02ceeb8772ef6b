//! Dimensions and the state layout of the reaching task (DESIGN.md §2).
//!
//! The state s ∈ R^12 is, in this order:
//!
//! | indices | quantity | unit | frame |
//! |---|---|---|---|
//! | [`Q`] = 0..3 | joint angles (shoulder pan, shoulder lift, elbow) | rad | joint |
//! | [`QD`] = 3..6 | joint velocities | rad/s | joint |
//! | [`EE_MINUS_GOAL`] = 6..9 | end-effector point minus goal | m | arm base |
//! | [`EE_VEL`] = 9..12 | end-effector linear velocity | m/s | arm base |
//!
//! The action a ∈ R^3 is goal joint angles (rad) in the paper's set-up, or joint torques (N·m)
//! in torque mode, in the same joint order.

use core::ops::Range;

/// State dimension dX.
pub const DX: usize = 12;
/// Action dimension dU (active joints).
pub const DU: usize = 3;
/// Number of active joints (= [`DU`]).
pub const N_JOINTS: usize = DU;
/// Largest horizon T a gain table can hold; the paper's episodes have T = 100.
pub const MAX_HORIZON: usize = 128;

/// Joint angles q (rad).
pub const Q: Range<usize> = 0..3;
/// Joint velocities q̇ (rad/s).
pub const QD: Range<usize> = 3..6;
/// End-effector point minus goal, base frame (m).
pub const EE_MINUS_GOAL: Range<usize> = 6..9;
/// End-effector linear velocity, base frame (m/s).
pub const EE_VEL: Range<usize> = 9..12;

/// Names of the state entries in layout order, for files and logs.
pub const STATE_NAMES: [&str; DX] = [
    "q_shoulder_pan", "q_shoulder_lift", "q_elbow",
    "qd_shoulder_pan", "qd_shoulder_lift", "qd_elbow",
    "ee_minus_goal_x", "ee_minus_goal_y", "ee_minus_goal_z",
    "ee_vel_x", "ee_vel_y", "ee_vel_z",
];

/// Names of the action entries in layout order.
pub const ACTION_NAMES: [&str; DU] = ["shoulder_pan", "shoulder_lift", "elbow"];

/// URDF names of the active joints in layout order.
pub const ACTIVE_JOINTS: [&str; N_JOINTS] = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_tile_the_state() {
        assert_eq!(Q.end, QD.start);
        assert_eq!(QD.end, EE_MINUS_GOAL.start);
        assert_eq!(EE_MINUS_GOAL.end, EE_VEL.start);
        assert_eq!(EE_VEL.end, DX);
        assert_eq!(STATE_NAMES.len(), DX);
    }
}
