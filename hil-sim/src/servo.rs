//! The arm's own joint servo (goal-angle mode), the way a UR5 executes `servoj`: it tracks the
//! latest goal angles at the physics rate with torques limited to the effort limits.

use ur5_shared::config::ServoConfig;
use ur5_shared::layout::N_JOINTS;

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
    let mut tau = [0.0; N_JOINTS];
    for j in 0..N_JOINTS {
        let (effort, v_limit) = limits[j];
        let v_max = cfg.max_velocity.min(v_limit);
        let v_des = (cfg.position_gain * (q_goal[j] - q[j])).clamp(-v_max, v_max);
        tau[j] = (tau_g[j] + cfg.velocity_gain[j] * (v_des - qd[j])).clamp(-effort, effort);
    }
    tau
}

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
