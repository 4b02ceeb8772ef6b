//! Inverse kinematics of a UR arm (any [`UrModel`]) in closed form: joint angles from a tool
//! pose (six joints) or from a tool point with the wrist locked (three joints), the inverse of
//! [`crate::kinematics::UrKinematics`] (docs/design.md §4.16).
//!
//! UR arms have three parallel joint axes (shoulder lift, elbow, wrist 1) and fixed offsets
//! between the wrist's axes, which give the well-known closed form in UR's standard DH
//! convention (T_i = Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i), α = (π/2, 0, 0, π/2, −π/2, 0)):
//!
//! 1. the wrist centre O5 = O6 − d6 z6 lies at d4 along the shoulder's axis z1 =
//!    (sin θ1, −cos θ1, 0): r sin(θ1 − φ) = d4 with (r, φ) O5's polar coordinates: two θ1;
//! 2. the flange lies at d4 + d6 cos θ5 along z1: two θ5 = ±acos(·);
//! 3. z1 seen from the flange's frame is (sin θ5 cos θ6, −sin θ5 sin θ6, cos θ5): θ6 (any θ6
//!    when sin θ5 = 0, the wrist singularity: the reference's is kept);
//! 4. what remains, T_14, is a planar arm of links a2, a3 and the angle θ2 + θ3 + θ4: two
//!    elbows θ3 = ±acos(·), then θ2 and θ4.
//!
//! So up to 8 branches for a pose. With the wrist locked (the three-joint task), the tool
//! point is a fixed vector v in frame 3 (the wrist's angles and the tool offset): step 1 with
//! v's z1 component instead of d4 gives θ1, and a planar arm of links a2 and |v_xy| gives θ2,
//! θ3: up to 4 branches, exact, no iteration (a Newton search would need a start, could stall
//! at the workspace's edge, and could not say a target is out of reach).
//!
//! A branch's angles are shifted by whole turns to lie nearest a reference configuration
//! within the model's joint limits ([`UrModel::joint_limits`]); the nearest branch (Euclidean
//! distance in joint space) is the one a continuous motion follows. Nothing here allocates.

use core::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::kinematics::Joints6;
use crate::model::{DhTable, JointLimits6, UrModel};

/// Most branches of a pose: 2 shoulders × 2 wrists × 2 elbows.
pub const MAX_POSE_BRANCHES: usize = 8;
/// Most branches of a point with the wrist locked: 2 shoulders × 2 elbows.
pub const MAX_POINT_BRANCHES: usize = 4;

/// Tolerance on the cosines and sines of the closed form beyond ±1: a target this close to the
/// edge of the workspace is taken to be on it.
const EDGE: f64 = 1e-9;

/// A target the arm cannot reach, and why.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum IkError {
    /// A NaN or infinite coordinate.
    #[error("the target is not finite")]
    NotFinite,
    /// The wrist centre (or, wrist locked, the tool point) is closer to the base's vertical
    /// axis than the arm's sideways offset: no shoulder angle puts it there.
    #[error(
        "{radius:.4} m from the base's vertical axis, closer than the arm's sideways offset \
         {offset:.4} m"
    )]
    InsideShoulder {
        /// Distance from the base's z axis (m).
        radius: f64,
        /// The sideways offset the arm keeps (m).
        offset: f64,
    },
    /// No wrist angle θ5 puts the flange where the pose asks.
    #[error("the tool's orientation cannot be reached from there (cos θ5 would be {cos:.4})")]
    Wrist {
        /// The cosine the pose asks of θ5.
        cos: f64,
    },
    /// The wrist (or tool point) is farther from the shoulder than the stretched arm or
    /// closer than the folded one.
    #[error(
        "{distance:.4} m from the shoulder in the arm's plane, outside the {min:.4} to \
         {max:.4} m the upper arm and forearm reach"
    )]
    Elbow {
        /// Distance from the shoulder joint's axis (m).
        distance: f64,
        /// Shortest reachable (m).
        min: f64,
        /// Longest reachable (m).
        max: f64,
    },
    /// Every branch needs a joint beyond the model's limits.
    #[error("every solution needs joint {joint} ({value:.4} rad) beyond its limits")]
    Limits {
        /// The joint (0 = shoulder pan) of the nearest branch that is out.
        joint: usize,
        /// Its angle (rad).
        value: f64,
    },
}

/// Inverse kinematics of one model with a tool point `ee_offset` (m, `wrist_3_link` frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UrIk {
    dh: DhTable,
    limits: JointLimits6,
    /// Tool point in the `wrist_3_link` frame (m), as [`crate::kinematics::UrKinematics`].
    pub ee_offset: [f64; 3],
}

/// DH transform of joint i at angle θ: Rz(θ) Tz(d) Tx(a) Rx(α).
fn dh_transform(t: &DhTable, i: usize, theta: f64) -> Isometry3<f64> {
    let (s, c) = theta.sin_cos();
    Isometry3::from_parts(
        Translation3::new(t.a[i] * c, t.a[i] * s, t.d[i]),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), theta)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), t.alpha[i]),
    )
}

/// `x` clamped to [−1, 1] if within [`EDGE`] of it.
fn unit(x: f64) -> Option<f64> {
    (x.abs() <= 1.0 + EDGE).then(|| x.clamp(-1.0, 1.0))
}

/// Angle wrapped to (−π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI {
        w - TAU
    } else {
        w
    }
}

/// The tool pose (tool point position, `wrist_3_link` orientation; base frame) from a position
/// (m) and a rotation vector (rad: axis × angle), the convention of UR's `p[x, y, z, rx, ry,
/// rz]`.
pub fn pose_from_rotation_vector(p: [f64; 3], r: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
    )
}

/// The rotation a fraction `w` (0 to 1) of the way from rotation vector `r0` to `r1` (rad,
/// axis × angle) along the shortest arc (spherical linear interpolation), as a rotation vector.
pub fn interpolate_rotation_vector(r0: [f64; 3], r1: [f64; 3], w: f64) -> [f64; 3] {
    let q = |r: [f64; 3]| UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2]));
    let (a, mut b) = (q(r0), q(r1));
    if a.coords.dot(&b.coords) < 0.0 {
        b = UnitQuaternion::new_unchecked(-b.into_inner());
    }
    let v = a.slerp(&b, w).scaled_axis();
    [v.x, v.y, v.z]
}

impl UrIk {
    /// The bundled `model` with the tool point `ee_offset` (m, `wrist_3_link` frame).
    pub fn new(model: UrModel, ee_offset: [f64; 3]) -> Self {
        Self {
            dh: model.dh(),
            limits: model.joint_limits(),
            ee_offset,
        }
    }

    /// Step 1 (module docs): the two shoulder angles that put `p` (base frame) at `offset`
    /// along z1.
    fn shoulder(&self, p: [f64; 3], offset: f64) -> Result<[f64; 2], IkError> {
        let r = p[0].hypot(p[1]);
        let s = unit(offset / r).ok_or(IkError::InsideShoulder {
            radius: r,
            offset: offset.abs(),
        })?;
        let phi = p[1].atan2(p[0]);
        let a = s.asin();
        Ok([wrap(phi + a), wrap(phi + PI - a)])
    }

    /// The two solutions (θ2, θ3) of the planar arm of links a2 and `link` (the second one at
    /// angle `beta` to its joint's x axis) that puts its end at `p` (x, y).
    fn planar(&self, p: [f64; 2], link: f64, beta: f64) -> Result<[[f64; 2]; 2], IkError> {
        let a2 = self.dh.a[1];
        let d2 = p[0] * p[0] + p[1] * p[1];
        let c = unit((d2 - a2 * a2 - link * link) / (2.0 * a2 * link)).ok_or(IkError::Elbow {
            distance: d2.sqrt(),
            min: (a2.abs() - link.abs()).abs(),
            max: a2.abs() + link.abs(),
        })?;
        let psi = c.acos();
        Ok([psi, -psi].map(|psi| {
            let th2 = p[1].atan2(p[0]) - (link * psi.sin()).atan2(a2 + link * psi.cos());
            [wrap(th2), wrap(psi - beta)]
        }))
    }

    /// Every branch (≤ [`MAX_POSE_BRANCHES`], angles in (−π, π], no limits applied) that puts
    /// the tool at `pose` (tool point position and `wrist_3_link` orientation, base frame); θ6
    /// at the wrist singularity is `theta6_hint`'s. Returns the branches and how many there are.
    pub fn pose_branches(
        &self,
        pose: &Isometry3<f64>,
        theta6_hint: f64,
    ) -> Result<([Joints6; MAX_POSE_BRANCHES], usize), IkError> {
        let t = &self.dh;
        let (v, r) = (pose.translation.vector, pose.rotation);
        if !(v.iter().all(|x| x.is_finite()) && r.coords.iter().all(|x| x.is_finite())) {
            return Err(IkError::NotFinite);
        }
        // The flange (frame 6) from the tool point.
        let o6 = v - r * Vector3::from(self.ee_offset);
        let z6 = r * Vector3::z();
        let o5 = o6 - t.d[5] * z6;
        let mut out = [[0.0; 6]; MAX_POSE_BRANCHES];
        let mut n = 0;
        let mut first_err = None;
        for th1 in self.shoulder([o5.x, o5.y, o5.z], t.d[3])? {
            let (s1, c1) = th1.sin_cos();
            let cos5 = (o6.x * s1 - o6.y * c1 - t.d[3]) / t.d[5];
            let Some(cos5) = unit(cos5) else {
                first_err.get_or_insert(IkError::Wrist { cos: cos5 });
                continue;
            };
            let z1 = Vector3::new(s1, -c1, 0.0);
            let w = r.inverse() * z1;
            for th5 in [cos5.acos(), -cos5.acos()] {
                let s5 = th5.sin();
                let th6 = if s5.abs() < 1e-12 {
                    theta6_hint
                } else {
                    (-w.y / s5).atan2(w.x / s5)
                };
                let t06 = Isometry3::from_parts(Translation3::from(o6), r);
                let t14 = dh_transform(t, 0, th1).inverse()
                    * t06
                    * dh_transform(t, 5, th6).inverse()
                    * dh_transform(t, 4, th5).inverse();
                let p = t14.translation.vector;
                let sols = match self.planar([p.x, p.y], t.a[2], 0.0) {
                    Ok(s) => s,
                    Err(e) => {
                        first_err.get_or_insert(e);
                        continue;
                    }
                };
                let x4 = t14.rotation * Vector3::x();
                let th234 = x4.y.atan2(x4.x);
                for [th2, th3] in sols {
                    out[n] = [th1, th2, th3, wrap(th234 - th2 - th3), th5, wrap(th6)];
                    n += 1;
                }
            }
        }
        match (n, first_err) {
            (0, Some(e)) => Err(e),
            _ => Ok((out, n)),
        }
    }

    /// Every branch (≤ [`MAX_POINT_BRANCHES`], angles in (−π, π], no limits applied) of the
    /// shoulder pan, shoulder lift and elbow that puts the tool point at `p` (m, base frame)
    /// with the wrist locked at `wrist` (rad, wrist 1–3).
    pub fn point_branches(
        &self,
        p: [f64; 3],
        wrist: [f64; 3],
    ) -> Result<([[f64; 3]; MAX_POINT_BRANCHES], usize), IkError> {
        if !p.iter().chain(&wrist).all(|x| x.is_finite()) {
            return Err(IkError::NotFinite);
        }
        let t = &self.dh;
        // The tool point in frame 3, plus the forearm a3: the second link of the planar arm.
        let c = dh_transform(t, 3, wrist[0])
            * dh_transform(t, 4, wrist[1])
            * dh_transform(t, 5, wrist[2])
            * Point3::from(self.ee_offset);
        let v = Vector3::new(c.x + t.a[2], c.y, c.z);
        let (link, beta) = (v.x.hypot(v.y), v.y.atan2(v.x));
        let mut out = [[0.0; 3]; MAX_POINT_BRANCHES];
        let mut n = 0;
        let mut first_err = None;
        for th1 in self.shoulder(p, v.z)? {
            let p1 = dh_transform(t, 0, th1).inverse() * Point3::from(p);
            match self.planar([p1.x, p1.y], link, beta) {
                Ok(sols) => {
                    for [th2, th3] in sols {
                        out[n] = [th1, th2, th3];
                        n += 1;
                    }
                }
                Err(e) => {
                    first_err.get_or_insert(e);
                }
            }
        }
        match (n, first_err) {
            (0, Some(e)) => Err(e),
            _ => Ok((out, n)),
        }
    }

    /// `branch` with each angle shifted by whole turns nearest `near` (joints `first..`), or
    /// the first joint that no shift brings within the limits.
    fn nearest_turns(&self, branch: &mut [f64], near: &[f64], first: usize) -> Result<(), usize> {
        for (j, (q, r)) in branch.iter_mut().zip(near).enumerate() {
            let (lo, hi) = (self.limits.lower[first + j], self.limits.upper[first + j]);
            let mut best = *q + ((r - *q) / TAU).round() * TAU;
            if best < lo {
                best += TAU;
            } else if best > hi {
                best -= TAU;
            }
            if best < lo || best > hi {
                return Err(first + j);
            }
            *q = best;
        }
        Ok(())
    }

    /// Of `branches`, the one nearest `near` (each angle shifted by whole turns nearest it,
    /// within the limits), or the limit error of the nearest one.
    fn nearest<const N: usize>(
        &self,
        branches: &[[f64; N]],
        near: &[f64; N],
    ) -> Result<[f64; N], IkError> {
        let mut best: Option<([f64; N], f64)> = None;
        let mut out_of_limits = None;
        for b in branches {
            let mut b = *b;
            match self.nearest_turns(&mut b, near, 0) {
                Ok(()) => {
                    let d: f64 = b.iter().zip(near).map(|(x, y)| (x - y).powi(2)).sum();
                    if best.map_or(true, |(_, bd)| d < bd) {
                        best = Some((b, d));
                    }
                }
                Err(joint) => {
                    out_of_limits.get_or_insert(IkError::Limits {
                        joint,
                        value: b[joint],
                    });
                }
            }
        }
        best.map(|(b, _)| b)
            .ok_or(out_of_limits.unwrap_or(IkError::NotFinite))
    }

    /// The six joint angles (rad) nearest `near` that put the tool at `pose` (tool point
    /// position and `wrist_3_link` orientation, base frame), within the model's limits.
    pub fn nearest_pose(&self, pose: &Isometry3<f64>, near: &Joints6) -> Result<Joints6, IkError> {
        let (b, n) = self.pose_branches(pose, near[5])?;
        self.nearest(&b[..n], near)
    }

    /// The shoulder pan, shoulder lift and elbow angles (rad) nearest `near` that put the tool
    /// point at `p` (m, base frame) with the wrist locked at `wrist`, within the limits.
    pub fn nearest_point(
        &self,
        p: [f64; 3],
        wrist: [f64; 3],
        near: &[f64; 3],
    ) -> Result<[f64; 3], IkError> {
        let (b, n) = self.point_branches(p, wrist)?;
        self.nearest(&b[..n], near)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::UrKinematics;
    use rand::{Rng, SeedableRng};

    const TOOL: [f64; 3] = [0.03, -0.02, 0.15];

    /// Position error (m) and rotation angle (rad) between two poses.
    fn pose_err(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        (
            (a.translation.vector - b.translation.vector).norm(),
            a.rotation.angle_to(&b.rotation),
        )
    }

    fn angle_diff(a: f64, b: f64) -> f64 {
        wrap(a - b).abs()
    }

    /// Every branch of a reachable pose goes back through forward kinematics (the URDF chain,
    /// not the DH matrices the solution is written in) to the pose within 1e-6 m and 1e-6 rad,
    /// and one branch is the configuration the pose came from; over seeded random joint angles
    /// for every model.
    #[test]
    fn every_pose_branch_round_trips_on_every_model() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(43);
        for model in UrModel::ALL {
            let (fk, ik) = (UrKinematics::new(model, TOOL), UrIk::new(model, TOOL));
            let (mut worst_p, mut worst_r, mut worst_q) = (0.0f64, 0.0f64, 0.0f64);
            for _ in 0..300 {
                let q: Joints6 = core::array::from_fn(|_| rng.random_range(-PI..PI));
                let pose = fk.tool_pose(&q);
                let (b, n) = ik.pose_branches(&pose, q[5]).unwrap();
                assert!(n >= 2, "{model}: {n} branches");
                let mut nearest = f64::INFINITY;
                for s in &b[..n] {
                    let (dp, dr) = pose_err(&fk.tool_pose(s), &pose);
                    worst_p = worst_p.max(dp);
                    worst_r = worst_r.max(dr);
                    let dq = (0..6).map(|j| angle_diff(s[j], q[j])).fold(0.0, f64::max);
                    nearest = nearest.min(dq);
                }
                worst_q = worst_q.max(nearest);
            }
            eprintln!("{model}: {worst_p:.1e} m, {worst_r:.1e} rad, q back within {worst_q:.1e}");
            assert!(
                worst_p <= 1e-6 && worst_r <= 1e-6,
                "{model}: {worst_p} m {worst_r} rad"
            );
            assert!(
                worst_q <= 1e-6,
                "{model}: the source configuration is no branch: {worst_q}"
            );
        }
    }

    /// The same for a tool point with the wrist locked at random angles.
    #[test]
    fn every_point_branch_round_trips_on_every_model() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(44);
        for model in UrModel::ALL {
            let (fk, ik) = (UrKinematics::new(model, TOOL), UrIk::new(model, TOOL));
            let (mut worst_p, mut worst_q) = (0.0f64, 0.0f64);
            for k in 0..300 {
                let wrist = if k % 2 == 0 {
                    model.default_wrist_q()
                } else {
                    core::array::from_fn(|_| rng.random_range(-PI..PI))
                };
                let q: [f64; 3] = core::array::from_fn(|_| rng.random_range(-PI..PI));
                let p = fk.ee_point(&UrKinematics::six(&q, &wrist));
                let (b, n) = ik.point_branches(p, wrist).unwrap();
                let mut nearest = f64::INFINITY;
                for s in &b[..n] {
                    let back = fk.ee_point(&UrKinematics::six(s, &wrist));
                    let d = (0..3).map(|r| (back[r] - p[r]).powi(2)).sum::<f64>().sqrt();
                    worst_p = worst_p.max(d);
                    nearest =
                        nearest.min((0..3).map(|j| angle_diff(s[j], q[j])).fold(0.0, f64::max));
                }
                worst_q = worst_q.max(nearest);
            }
            eprintln!("{model}: {worst_p:.1e} m, q back within {worst_q:.1e}");
            assert!(worst_p <= 1e-6, "{model}: {worst_p} m");
            assert!(worst_q <= 1e-6, "{model}: {worst_q} rad");
        }
    }

    /// Along a smooth motion, the branch nearest the previous solution is the motion itself
    /// (no jump between branches), within the joint limits, on every model.
    #[test]
    fn nearest_branch_follows_a_continuous_motion() {
        for model in UrModel::ALL {
            let (fk, ik) = (UrKinematics::new(model, TOOL), UrIk::new(model, TOOL));
            let wrist = model.default_wrist_q();
            let path = |s: f64| -> Joints6 {
                [
                    0.3 + 1.2 * s,
                    -1.9 + 0.8 * s,
                    2.2 - 1.0 * s,
                    -1.4 + 0.5 * s,
                    1.6 - 0.9 * s,
                    0.2 + 4.0 * s,
                ]
            };
            let (mut prev6, mut prev3) = (path(0.0), [0.0, -2.0, 2.4]);
            for k in 0..=200 {
                let q = path(k as f64 / 200.0);
                let got = ik.nearest_pose(&fk.tool_pose(&q), &prev6).unwrap();
                for j in 0..6 {
                    // Wrist 3 passes π: the nearest solution keeps turning, it does not wrap.
                    assert!(
                        (got[j] - q[j]).abs() < 1e-6,
                        "{model} step {k} joint {j}: {got:?} vs {q:?}"
                    );
                }
                prev6 = got;
                let q3 = [q[0], q[1], q[2]];
                let p = fk.ee_point(&UrKinematics::six(&q3, &wrist));
                let got3 = ik.nearest_point(p, wrist, &prev3).unwrap();
                if k > 0 {
                    assert!(
                        (0..3).all(|j| (got3[j] - q3[j]).abs() < 1e-6),
                        "{model} step {k}: {got3:?} vs {q3:?}"
                    );
                }
                prev3 = got3;
            }
        }
    }

    #[test]
    fn unreachable_targets_are_refused_with_the_reason() {
        let model = UrModel::Ur5;
        let ik = UrIk::new(model, [0.0; 3]);
        let wrist = model.default_wrist_q();
        let far = [2.0 * model.reach(), 0.0, 0.3];
        assert!(
            matches!(ik.point_branches(far, wrist), Err(IkError::Elbow { .. })),
            "{:?}",
            ik.point_branches(far, wrist)
        );
        let e = ik.nearest_point(far, wrist, &[0.0, -2.0, 2.4]).unwrap_err();
        assert!(e.to_string().contains("outside the"), "{e}");
        // On the base's axis: no shoulder angle keeps the sideways offset.
        assert!(matches!(
            ik.point_branches([0.0, 0.01, 0.5], wrist),
            Err(IkError::InsideShoulder { .. })
        ));
        let pose = pose_from_rotation_vector(far, [0.0, PI, 0.0]);
        assert!(ik.nearest_pose(&pose, &[0.0; 6]).is_err());
        assert_eq!(
            ik.point_branches([f64::NAN, 0.0, 0.0], wrist),
            Err(IkError::NotFinite)
        );
        // Within reach but beyond the elbow's ±π: the UR5's elbow limit is π, so a target only
        // reachable with the elbow folded back is refused; simulate it with a tight limit.
        let mut tight = ik;
        tight.limits.upper[2] = 0.1;
        tight.limits.lower[2] = -0.1;
        let p = UrKinematics::new(model, [0.0; 3])
            .ee_point(&UrKinematics::six(&[0.3, -1.4, 2.1], &wrist));
        assert!(matches!(
            tight.nearest_point(p, wrist, &[0.3, -1.4, 2.1]),
            Err(IkError::Limits { joint: 2, .. })
        ));
    }

    #[test]
    fn rotation_vectors_interpolate_along_the_shortest_arc() {
        let (a, b) = ([0.0, 0.0, 0.2], [0.0, 0.0, 0.6]);
        let m = interpolate_rotation_vector(a, b, 0.25);
        assert!((m[2] - 0.3).abs() < 1e-12 && m[0].abs() < 1e-15, "{m:?}");
        // Across ±π: 3.0 rad and −3.0 rad about z are 0.28 rad apart the short way.
        let m = interpolate_rotation_vector([0.0, 0.0, 3.0], [0.0, 0.0, -3.0], 0.5);
        let angle = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
        assert!((angle - PI).abs() < 1e-9, "{m:?}");
    }

    #[test]
    fn a_rotation_vector_is_urs_pose_convention() {
        let pose = pose_from_rotation_vector([0.1, 0.2, 0.3], [0.0, 0.0, PI / 2.0]);
        let x = pose.rotation * Vector3::x();
        assert!((x - Vector3::y()).norm() < 1e-12);
        assert_eq!(pose.translation.vector, Vector3::new(0.1, 0.2, 0.3));
    }
}
