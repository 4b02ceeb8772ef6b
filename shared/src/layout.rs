//! Dimensions and the state layout of the reaching task (docs/design.md §2.2).
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
#[rustfmt::skip]
pub const STATE_NAMES: [&str; DX] = [
    "q_shoulder_pan", "q_shoulder_lift", "q_elbow",
    "qd_shoulder_pan", "qd_shoulder_lift", "qd_elbow",
    "ee_minus_goal_x", "ee_minus_goal_y", "ee_minus_goal_z",
    "ee_vel_x", "ee_vel_y", "ee_vel_z",
];

/// Names of the action entries in layout order.
pub const ACTION_NAMES: [&str; DU] = ["shoulder_pan", "shoulder_lift", "elbow"];

/// URDF names of the active joints in layout order.
pub const ACTIVE_JOINTS: [&str; N_JOINTS] =
    ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"];

/// Assembles the state vector s from its parts: the single place the layout is filled.
///
/// - `q`: joint angles (rad), `qd`: joint velocities (rad/s), active joints in layout order;
/// - `ee_pos`: end-effector point (m), `ee_vel`: its linear velocity (m/s), `goal`: goal point
///   (m), all in the arm base frame.
///
/// The learner, the controller and the recorder of demonstrations all build s through here.
pub fn state_vector(
    q: &[f64; N_JOINTS],
    qd: &[f64; N_JOINTS],
    ee_pos: &[f64; 3],
    ee_vel: &[f64; 3],
    goal: &[f64; 3],
) -> [f64; DX] {
    let mut s = [0.0; DX];
    s[Q].copy_from_slice(q);
    s[QD].copy_from_slice(qd);
    for (k, i) in EE_MINUS_GOAL.enumerate() {
        s[i] = ee_pos[k] - goal[k];
    }
    s[EE_VEL].copy_from_slice(ee_vel);
    s
}

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

    #[test]
    fn state_vector_fills_each_range() {
        let s = state_vector(
            &[0.1, 0.2, 0.3],
            &[-1.0, -2.0, -3.0],
            &[0.5, 0.0, 0.75],
            &[0.01, 0.02, 0.03],
            &[0.25, -0.5, 0.5],
        );
        assert_eq!(
            s,
            [0.1, 0.2, 0.3, -1.0, -2.0, -3.0, 0.25, 0.5, 0.25, 0.01, 0.02, 0.03]
        );
    }
}
