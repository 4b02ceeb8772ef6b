//! The arm's own joint servo (goal-angle mode), the way a UR5 executes `servoj`: it tracks the
//! latest goal angles at the physics rate with torques limited to the effort limits.

use ur5_shared::config::ServoConfig;
use ur5_shared::layout::N_JOINTS;
use ur5_shared::UrModel;

/// Servo torque (N·m) for joint angles `q` (rad), velocities `qd` (rad/s), goal angles
/// `q_goal` (rad) and the nominal gravity torque `tau_g` (N·m); `limits[j]` = (effort N·m,
/// velocity rad/s) from the URDF.
///
/// Per joint: v_des = clamp(ω_p (q_goal − q), ±min(v_max, v_limit)), then
/// τ = τ_g + k_v (v_des − q̇), clamped to ±effort. The position loop commands a velocity that
/// never exceeds the velocity limit; the velocity loop with gravity feed-forward tracks it.
pub fn servo_torque(
    cfg: &ServoConfig,
    limits: &[(f64, f64); N_JOINTS],
    q: [f64; N_JOINTS],
    qd: [f64; N_JOINTS],
    q_goal: [f64; N_JOINTS],
    tau_g: [f64; N_JOINTS],
) -> [f64; N_JOINTS] {
    core::array::from_fn(|j| {
        joint_servo_torque(
            cfg,
            cfg.velocity_gain[j],
            limits[j],
            q[j],
            qd[j],
            q_goal[j],
            tau_g[j],
        )
    })
}

/// One joint of [`servo_torque`] with velocity gain `k_v` (N·m·s/rad): what every active joint
/// runs, the wrist joints with [`wrist_velocity_gain`].
pub fn joint_servo_torque(
    cfg: &ServoConfig,
    k_v: f64,
    (effort, v_limit): (f64, f64),
    q: f64,
    qd: f64,
    q_goal: f64,
    tau_g: f64,
) -> f64 {
    let v_max = cfg.max_velocity.min(v_limit);
    let v_des = (cfg.position_gain * (q_goal - q)).clamp(-v_max, v_max);
    (tau_g + k_v * (v_des - qd)).clamp(-effort, effort)
}

/// Velocity-loop gains k_v of the three wrist joints of `model` (N·m·s/rad), for a six-joint
/// arm. The rule the other joints' gains follow (`ServoConfig::for_model`): the UR5's
/// velocity-loop bandwidth, k_v / I = 150 / 3 = 50 /s at the shoulder (`ServoConfig`'s docs:
/// about 50× the largest joint inertia), for every joint. A wrist's inertia cannot be taken
/// from point masses (wrist 3's link sits on its own axis), so I here is the largest diagonal
/// entry of the arm's mass matrix for that joint over the poses of the joints after it (the
/// only ones it depends on), computed by Pinocchio's CRBA from the bundled URDF
/// (`scripts/sim-reference/pinocchio_reference.py`, committed in
/// `hil-sim/tests/data/pinocchio6.json` as `wrist_inertia`); k_v = 50 I rounded to two
/// digits. The test `every_models_wrist_gains_follow_its_wrist_inertia` checks the table
/// against that file.
pub fn wrist_velocity_gain(model: UrModel) -> [f64; 3] {
    match model {
        UrModel::Ur3 => WRIST_GAIN[0],
        UrModel::Ur5 => WRIST_GAIN[1],
        UrModel::Ur10 => WRIST_GAIN[2],
        UrModel::Ur3e => WRIST_GAIN[3],
        UrModel::Ur5e => WRIST_GAIN[4],
        UrModel::Ur7e => WRIST_GAIN[5],
        UrModel::Ur10e => WRIST_GAIN[6],
        UrModel::Ur12e => WRIST_GAIN[7],
        UrModel::Ur16e => WRIST_GAIN[8],
        UrModel::Ur15 => WRIST_GAIN[9],
        UrModel::Ur18 => WRIST_GAIN[10],
        UrModel::Ur20 => WRIST_GAIN[11],
        UrModel::Ur30 => WRIST_GAIN[12],
    }
}

/// [`wrist_velocity_gain`] in the order of `UrModel::ALL`.
const WRIST_GAIN: [[f64; 3]; 13] = [
    [0.69, 0.19, 0.009],  // UR3
    [0.91, 0.19, 0.0066], // UR5
    [1.9, 0.24, 0.017],   // UR10
    [0.69, 0.19, 0.009],  // UR3e
    [1.3, 0.31, 0.0066],  // UR5e
    [1.2, 0.27, 0.013],   // UR7e
    [2.3, 0.42, 0.017],   // UR10e
    [2.3, 0.42, 0.017],   // UR12e
    [2.3, 0.42, 0.042],   // UR16e
    [3.3, 0.66, 0.05],    // UR15
    [3.3, 0.66, 0.05],    // UR18
    [6.8, 1.3, 0.059],    // UR20
    [6.4, 1.1, 0.042],    // UR30
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_with_gravity_feed_forward_and_respects_limits() {
        let cfg = ServoConfig::default();
        let limits = [(150.0, 3.14); 3];
        // At the goal, at rest: exactly the gravity torque.
        let tau = servo_torque(
            &cfg,
            &limits,
            [0.1, 0.2, 0.3],
            [0.0; 3],
            [0.1, 0.2, 0.3],
            [10.0, -20.0, 5.0],
        );
        assert_eq!(tau, [10.0, -20.0, 5.0]);
        // Far from the goal: clamped to the effort limit, with the sign of the error.
        let tau = servo_torque(
            &cfg,
            &limits,
            [0.0; 3],
            [0.0; 3],
            [3.0, -3.0, 3.0],
            [0.0; 3],
        );
        assert_eq!(tau, [150.0, -150.0, cfg.velocity_gain[2] * 3.14]);
        // Already at the velocity limit towards the goal: no further push beyond gravity.
        let tau = servo_torque(&cfg, &limits, [0.0; 3], [3.14; 3], [3.0; 3], [0.0; 3]);
        assert_eq!(tau, [0.0; 3]);
    }
}
