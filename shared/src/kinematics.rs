//! Forward kinematics of a UR arm (any [`UrModel`]) in f64, without the simulator: the
//! end-effector point and its linear velocity from all six measured joint angles
//! (docs/design.md §2.1, §3.10; docs/ur.md, "Arm models"). The `ur` arm backend builds the
//! state s from an RTDE package with it, so the state means the same on a real arm as in
//! hil-sim whatever TCP and base feature the robot's installation has configured.
//!
//! The chain is the bundled URDFs' (`hil-sim/urdf/<model>.urdf`): the model's DH table
//! ([`UrModel::dh`]) laid out with the joint origins of ROS 2 `ur_description` (base_link = the
//! DH base frame, z up, joint angles = DH angles). Each joint: a fixed origin transform (xyz,
//! then URDF rpy = Rz·Ry·Rx), then a rotation q about its z axis:
//!
//! | joint | origin xyz (m) | origin rpy (rad) |
//! |---|---|---|
//! | shoulder pan | (0, 0, d1) | 0 |
//! | shoulder lift | 0 | (π/2, 0, 0) |
//! | elbow | (a2, 0, 0) | 0 |
//! | wrist 1 | (a3, 0, d4) | 0 |
//! | wrist 2 | (0, −d5, 0) | (π/2, 0, 0) |
//! | wrist 3 | (0, d6, 0) | (π/2, π, π) |
//!
//! The frame after each joint differs from the DH frame by a constant rotation only, and the
//! origin of `wrist_3_link` is the DH flange (frame 6's origin). The end-effector point is that
//! origin plus `ee_offset` expressed in `wrist_3_link`'s frame (`sim.ee_offset`). hil-sim's
//! tests check this chain against the rapier3d multibody built from each URDF, and the
//! velocity against finite differences of the point; this module's tests check it (the flange's
//! position and orientation, and a tool point) against the product of UR's DH matrices.
//!
//! Nothing here allocates.

use core::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::layout::N_JOINTS;
use crate::model::UrModel;

/// All six joints of a UR arm, base to wrist 3 (rad or rad/s).
pub type Joints6 = [f64; 6];

/// Joint origins of the bundled URDF of `model`: (xyz in m, rpy in rad), base to wrist 3
/// (module docs' table).
pub fn urdf_origins(model: UrModel) -> [([f64; 3], [f64; 3]); 6] {
    let t = model.dh();
    [
        ([0.0, 0.0, t.d[0]], [0.0, 0.0, 0.0]),
        ([0.0, 0.0, 0.0], [FRAC_PI_2, 0.0, 0.0]),
        ([t.a[1], 0.0, 0.0], [0.0, 0.0, 0.0]),
        ([t.a[2], 0.0, t.d[3]], [0.0, 0.0, 0.0]),
        ([0.0, -t.d[4], 0.0], [FRAC_PI_2, 0.0, 0.0]),
        ([0.0, t.d[5], 0.0], [FRAC_PI_2, PI, PI]),
    ]
}

/// A UR arm's kinematic chain and the end-effector point on its last link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UrKinematics {
    origins: [Isometry3<f64>; 6],
    /// End-effector point in the `wrist_3_link` frame (m).
    pub ee_offset: [f64; 3],
}

impl UrKinematics {
    /// The bundled `model` with the end-effector point `ee_offset` (m, `wrist_3_link` frame).
    pub fn new(model: UrModel, ee_offset: [f64; 3]) -> Self {
        let origins = urdf_origins(model).map(|(xyz, rpy)| {
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

    /// The tool's pose (base frame): the end-effector point and `wrist_3_link`'s orientation
    /// (the DH flange frame's), at joint angles `q` (rad).
    pub fn tool_pose(&self, q: &Joints6) -> Isometry3<f64> {
        let f = self.frames(q)[5];
        let p = f * Point3::from(self.ee_offset);
        Isometry3::from_parts(Translation3::from(p.coords), f.rotation)
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

    /// The tool points at `offsets` (m, `wrist_3_link` frame, from the end-effector point; one
    /// per entry of `points` and `velocities`) and their linear velocities (m/s), base frame,
    /// at joint angles `q` (rad) and velocities `qd` (rad/s): the points of
    /// [`crate::pose::tool_points`] on [`UrKinematics::tool_pose`], each moving as
    /// [`UrKinematics::ee_point_velocity`]'s point does. Offset 0 is the end-effector point.
    pub fn tool_points_velocity(
        &self,
        q: &Joints6,
        qd: &Joints6,
        offsets: &[[f64; 3]],
        points: &mut [[f64; 3]],
        velocities: &mut [[f64; 3]],
    ) {
        assert!(offsets.len() == points.len() && offsets.len() == velocities.len());
        let f = self.frames(q);
        for ((o, pt), vel) in offsets.iter().zip(points).zip(velocities) {
            let local = Vector3::from(self.ee_offset) + Vector3::from(*o);
            let p = f[5] * Point3::from(local);
            let mut v = Vector3::zeros();
            for (j, fj) in f.iter().enumerate() {
                let z = fj.rotation * Vector3::z();
                v += qd[j] * z.cross(&(p - Point3::from(fj.translation.vector)));
            }
            *pt = [p.x, p.y, p.z];
            *vel = [v.x, v.y, v.z];
        }
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
        let k = UrKinematics::new(UrModel::Ur5, [0.01, -0.02, 0.03]);
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
        let k = UrKinematics::new(UrModel::Ur5, [0.01, -0.02, 0.03]);
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
    fn tool_points_are_the_poses_points_and_move_as_their_derivative() {
        let k = UrKinematics::new(UrModel::Ur5e, [0.01, -0.02, 0.03]);
        let q = [0.3, -1.9, 2.2, -1.4, 1.6, 0.2];
        let qd = [0.7, -0.4, 1.1, 0.3, -0.2, 0.5];
        let offsets = [[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.05]];
        let (mut p, mut v) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
        k.tool_points_velocity(&q, &qd, &offsets, &mut p, &mut v);
        assert_eq!(p[0], k.ee_point(&q));
        assert_eq!(v[0], k.ee_point_velocity(&q, &qd).1);
        let mut want = [[0.0; 3]; 3];
        crate::pose::tool_points(&k.tool_pose(&q), &offsets, &mut want);
        let h = 1e-6;
        let (mut plus, mut minus, mut scratch) = ([[0.0; 3]; 3], [[0.0; 3]; 3], [[0.0; 3]; 3]);
        let qp: Joints6 = core::array::from_fn(|j| q[j] + h * qd[j]);
        let qm: Joints6 = core::array::from_fn(|j| q[j] - h * qd[j]);
        k.tool_points_velocity(&qp, &qd, &offsets, &mut plus, &mut scratch);
        k.tool_points_velocity(&qm, &qd, &offsets, &mut minus, &mut scratch);
        for i in 0..3 {
            for r in 0..3 {
                assert!((p[i][r] - want[i][r]).abs() < 1e-12, "{p:?} vs {want:?}");
                let fd = (plus[i][r] - minus[i][r]) / (2.0 * h);
                assert!(
                    (fd - v[i][r]).abs() < 1e-7,
                    "point {i} row {r}: {fd} vs {}",
                    v[i][r]
                );
            }
        }
    }

    #[test]
    fn the_zero_pose_is_the_dh_table_stretched_out() {
        let k = UrKinematics::new(UrModel::Ur5, [0.0; 3]);
        let p = k.ee_point(&[0.0; 6]);
        // Closed form of UR's DH forward kinematics at q = 0:
        // x = a2 + a3 = −0.81725, y = −(d4 + d6) = −0.19145, z = d1 − d5 = −0.005491.
        let want = [-0.81725, -0.19145, -0.005491];
        for r in 0..3 {
            assert!((p[r] - want[r]).abs() < 1e-12, "{p:?} vs {want:?}");
        }
    }

    /// The joint origins today's UR5 chain was built from (the bundled `ur5.urdf`'s numbers),
    /// before the chain was derived from the model's DH table.
    const UR5_URDF_ORIGINS: [([f64; 3], [f64; 3]); 6] = [
        ([0.0, 0.0, 0.089159], [0.0, 0.0, 0.0]),
        ([0.0, 0.0, 0.0], [FRAC_PI_2, 0.0, 0.0]),
        ([-0.425, 0.0, 0.0], [0.0, 0.0, 0.0]),
        ([-0.39225, 0.0, 0.10915], [0.0, 0.0, 0.0]),
        ([0.0, -0.09465, 0.0], [FRAC_PI_2, 0.0, 0.0]),
        ([0.0, 0.0823, 0.0], [FRAC_PI_2, PI, PI]),
    ];

    #[test]
    fn the_ur5_chain_is_bit_for_bit_the_bundled_urdfs() {
        let got = urdf_origins(UrModel::Ur5);
        for (g, w) in got.iter().zip(&UR5_URDF_ORIGINS) {
            for k in 0..3 {
                assert_eq!(g.0[k].to_bits(), w.0[k].to_bits(), "{got:?}");
                assert_eq!(g.1[k].to_bits(), w.1[k].to_bits(), "{got:?}");
            }
        }
    }

    /// T = Π_i Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i), written out entry by entry from the table.
    fn dh_product(t: &crate::model::DhTable, q: &Joints6) -> nalgebra::Matrix4<f64> {
        let mut m = nalgebra::Matrix4::identity();
        for i in 0..6 {
            let (st, ct) = q[i].sin_cos();
            let (sa, ca) = t.alpha[i].sin_cos();
            #[rustfmt::skip]
            let ti = nalgebra::Matrix4::new(
                ct, -st * ca,  st * sa, t.a[i] * ct,
                st,  ct * ca, -ct * sa, t.a[i] * st,
                0.0,      sa,       ca,      t.d[i],
                0.0,     0.0,      0.0,         1.0,
            );
            m *= ti;
        }
        m
    }

    /// Forward kinematics of every model against UR's DH table (within 1e-6 m and 1e-6 rad):
    /// the flange's position (m) and orientation (rad: the angle of the rotation between
    /// `wrist_3_link`'s frame and DH frame 6, which coincide), and a tool point off the flange,
    /// over seeded random joint angles in (−π, π).
    #[test]
    fn every_models_flange_pose_is_the_product_of_its_dh_matrices() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(27);
        for model in UrModel::ALL {
            let tool = [0.03, -0.02, 0.15];
            let (k, kt) = (
                UrKinematics::new(model, [0.0; 3]),
                UrKinematics::new(model, tool),
            );
            let t = model.dh();
            let (mut worst_p, mut worst_r, mut worst_tool) = (0.0f64, 0.0f64, 0.0f64);
            for _ in 0..200 {
                let q: Joints6 = core::array::from_fn(|_| rng.random_range(-PI..PI));
                let m = dh_product(&t, &q);
                let p = k.ee_point(&q);
                let dp = (0..3).map(|r| (p[r] - m[(r, 3)]).powi(2)).sum::<f64>();
                worst_p = worst_p.max(dp.sqrt());
                // ‖R − R_dh‖_F = 2√2 sin(θ/2) for the angle θ between them (well conditioned
                // at θ ≈ 0, unlike acos of the trace).
                let r = k.frames(&q)[5].rotation.to_rotation_matrix().into_inner();
                let dr = (r - m.fixed_view::<3, 3>(0, 0)).norm();
                worst_r = worst_r.max(2.0 * (dr / (2.0 * core::f64::consts::SQRT_2)).asin());
                let pt = kt.ee_point(&q);
                let mt = m * nalgebra::Vector4::new(tool[0], tool[1], tool[2], 1.0);
                let dt = (0..3).map(|r| (pt[r] - mt[r]).powi(2)).sum::<f64>();
                worst_tool = worst_tool.max(dt.sqrt());
            }
            eprintln!(
                "{model}: max |flange − DH| = {worst_p:.2e} m, angle {worst_r:.2e} rad, \
                 tool point {worst_tool:.2e} m"
            );
            assert!(worst_p <= 1e-6, "{model}: |flange − DH| = {worst_p:.3e} m");
            assert!(
                worst_r <= 1e-6,
                "{model}: flange orientation off by {worst_r:.3e} rad"
            );
            assert!(
                worst_tool <= 1e-6,
                "{model}: tool point off by {worst_tool:.3e} m"
            );
        }
    }

    #[test]
    fn every_default_goal_is_the_ur5_goal_posture_on_that_model() {
        let q = [0.2934450379808978, -1.3789616300188625, 2.092271110094234];
        let w = UrModel::Ur5.default_wrist_q();
        let six = UrKinematics::six(&q, &w);
        let ur5 = UrKinematics::new(UrModel::Ur5, [0.0; 3]).ee_point(&six);
        let g = UrModel::Ur5.default_goal();
        assert!((0..3).all(|r| (ur5[r] - g[r]).abs() < 1e-9), "{ur5:?}");
        for model in UrModel::ALL {
            let p = UrKinematics::new(model, [0.0; 3]).ee_point(&six);
            let g = model.default_goal();
            assert!(
                (0..3).all(|r| (p[r] - g[r]).abs() <= 0.005 + 1e-9),
                "{model}: the goal posture reaches {p:?}, default goal {g:?}"
            );
        }
    }
}
