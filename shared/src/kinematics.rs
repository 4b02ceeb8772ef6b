//! Forward kinematics of the UR5 of `hil-sim/urdf/ur5.urdf` in f64, without the simulator:
//! the end-effector point and its linear velocity from all six measured joint angles
//! (docs/design.md §2.1, §3.10). The `ur` arm backend builds the state s from an RTDE package
//! with it, so the state means the same on a real arm as in hil-sim whatever TCP and base
//! feature the robot's installation has configured.
//!
//! The chain is the bundled URDF's: Universal Robots' published UR5 DH parameters laid out with
//! the joint origins of ROS 2 `ur_description` (base_link = the DH base frame, z up, joint
//! angles = DH angles). Each joint: a fixed origin transform (xyz, then URDF rpy = Rz·Ry·Rx),
//! then a rotation q about its z axis. The end-effector point is the origin of `wrist_3_link`
//! plus `ee_offset` expressed in that link's frame (`sim.ee_offset`). hil-sim's tests check
//! this chain against the rapier3d multibody built from the URDF, and the velocity against
//! finite differences of the point.
//!
//! Nothing here allocates.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::layout::N_JOINTS;

/// All six joints of a UR arm, base to wrist 3 (rad or rad/s).
pub type Joints6 = [f64; 6];

/// Joint origins of the bundled UR5 URDF: (xyz in m, rpy in rad), base to wrist 3.
const UR5_ORIGINS: [([f64; 3], [f64; 3]); 6] = [
    ([0.0, 0.0, 0.089159], [0.0, 0.0, 0.0]),
    ([0.0, 0.0, 0.0], [core::f64::consts::FRAC_PI_2, 0.0, 0.0]),
    ([-0.425, 0.0, 0.0], [0.0, 0.0, 0.0]),
    ([-0.39225, 0.0, 0.10915], [0.0, 0.0, 0.0]),
    (
        [0.0, -0.09465, 0.0],
        [core::f64::consts::FRAC_PI_2, 0.0, 0.0],
    ),
    (
        [0.0, 0.0823, 0.0],
        [
            core::f64::consts::FRAC_PI_2,
            core::f64::consts::PI,
            core::f64::consts::PI,
        ],
    ),
];

/// The UR5's kinematic chain and the end-effector point on its last link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ur5Kinematics {
    origins: [Isometry3<f64>; 6],
    /// End-effector point in the `wrist_3_link` frame (m).
    pub ee_offset: [f64; 3],
}

impl Ur5Kinematics {
    /// The bundled UR5 with the end-effector point `ee_offset` (m, `wrist_3_link` frame).
    pub fn ur5(ee_offset: [f64; 3]) -> Self {
        let origins = UR5_ORIGINS.map(|(xyz, rpy)| {
            Isometry3::from_parts(
                Translation3::new(xyz[0], xyz[1], xyz[2]),
                UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
            )
        });
        Self { origins, ee_offset }
    }

    /// Joint frames after each joint's rotation (base frame), base to wrist 3.
    fn frames(&self, q: &Joints6) -> [Isometry3<f64>; 6] {
        let mut t = Isometry3::identity();
        core::array::from_fn(|j| {
            let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), q[j]);
            t = t * self.origins[j] * Isometry3::from_parts(Translation3::identity(), rot);
            t
        })
    }

    /// The end-effector point (m, base frame) at joint angles `q` (rad).
    pub fn ee_point(&self, q: &Joints6) -> [f64; 3] {
        let f = self.frames(q);
        let p = f[5] * Point3::from(self.ee_offset);
        [p.x, p.y, p.z]
    }

    /// The points of the chain (m, base frame) at joint angles `q` (rad), for drawing the arm:
    /// the base, the origin of each joint's frame (shoulder pan to wrist 3) and the
    /// end-effector point, in that order.
    pub fn chain_points(&self, q: &Joints6) -> [[f64; 3]; 8] {
        let f = self.frames(q);
        let p = f[5] * Point3::from(self.ee_offset);
        let mut out = [[0.0; 3]; 8];
        for (o, fj) in out[1..7].iter_mut().zip(&f) {
            let t = fj.translation.vector;
            *o = [t.x, t.y, t.z];
        }
        out[7] = [p.x, p.y, p.z];
        out
    }

    /// The end-effector point (m) and its linear velocity (m/s), base frame, at joint angles
    /// `q` (rad) and velocities `qd` (rad/s): v = Σ_j q̇_j z_j × (p − o_j).
    pub fn ee_point_velocity(&self, q: &Joints6, qd: &Joints6) -> ([f64; 3], [f64; 3]) {
        let f = self.frames(q);
        let p = f[5] * Point3::from(self.ee_offset);
        let mut v = Vector3::zeros();
        for (j, fj) in f.iter().enumerate() {
            let z = fj.rotation * Vector3::z();
            v += qd[j] * z.cross(&(p - Point3::from(fj.translation.vector)));
        }
        ([p.x, p.y, p.z], [v.x, v.y, v.z])
    }

    /// The six joint values of the arm with the active joints at `active` and the wrist at
    /// `wrist` (layout order: pan, lift, elbow, wrist 1–3).
    pub fn six(active: &[f64; N_JOINTS], wrist: &[f64; 3]) -> Joints6 {
        [
            active[0], active[1], active[2], wrist[0], wrist[1], wrist[2],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chain_starts_at_the_base_and_ends_at_the_end_effector() {
        let k = Ur5Kinematics::ur5([0.01, -0.02, 0.03]);
        let q = [0.3, -1.9, 2.2, -1.4, 1.6, 0.2];
        let c = k.chain_points(&q);
        assert_eq!(c[0], [0.0; 3]);
        assert_eq!(
            c[1],
            [0.0, 0.0, 0.089159],
            "shoulder pan origin: the URDF's"
        );
        assert_eq!(c[7], k.ee_point(&q));
    }

    #[test]
    fn the_velocity_is_the_derivative_of_the_point() {
        let k = Ur5Kinematics::ur5([0.01, -0.02, 0.03]);
        let q = [0.3, -1.9, 2.2, -1.4, 1.6, 0.2];
        let qd = [0.7, -0.4, 1.1, 0.3, -0.2, 0.5];
        let (p, v) = k.ee_point_velocity(&q, &qd);
        assert_eq!(p, k.ee_point(&q));
        let h = 1e-6;
        let plus = k.ee_point(&core::array::from_fn(|j| q[j] + h * qd[j]));
        let minus = k.ee_point(&core::array::from_fn(|j| q[j] - h * qd[j]));
        for r in 0..3 {
            let fd = (plus[r] - minus[r]) / (2.0 * h);
            assert!((fd - v[r]).abs() < 1e-7, "row {r}: {fd} vs {}", v[r]);
        }
    }

    #[test]
    fn the_zero_pose_is_the_dh_table_stretched_out() {
        let k = Ur5Kinematics::ur5([0.0; 3]);
        let p = k.ee_point(&[0.0; 6]);
        // Closed form of UR's DH forward kinematics at q = 0:
        // x = a2 + a3 = −0.81725, y = −(d4 + d6) = −0.19145, z = d1 − d5 = −0.005491.
        let want = [-0.81725, -0.19145, -0.005491];
        for r in 0..3 {
            assert!((p[r] - want[r]).abs() < 1e-12, "{p:?} vs {want:?}");
        }
    }
}
