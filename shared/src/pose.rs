//! A tool pose as Universal Robots writes it, p[x, y, z, rx, ry, rz] (m; rotation vector in
//! rad, axis times angle; arm base frame: what the teach pendant and RTDE's `actual_TCP_pose`
//! show), the tool points that stand for it in a pose task's state, and the orientation error
//! measured from them (docs/design.md §2.1, "Pose goals").
//!
//! A pose task's state carries three tool points that are not on one line (GPS's robot
//! experiments put three points on the gripper): their positions minus their targets fix the
//! whole pose, so a cost on the points is a cost on position and orientation alike. Point i is
//! the tool centre point (TCP) plus `offsets[i]` in the flange frame (`wrist_3_link`, z the
//! tool axis); its target is the goal pose applied to the same offset.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The isometry of UR's pose `p` = [x, y, z, rx, ry, rz] (m, rad).
pub fn isometry(p: &[f64; 6]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(p[3], p[4], p[5])),
    )
}

/// The rotation vector of `r` (rad; axis times angle, angle in [0, π]): the orientation part
/// of UR's pose. From the unit quaternion (w ≥ 0) as 2 atan2(|v|, w) v/|v|, accurate at every
/// angle.
pub fn rotation_vector(r: &UnitQuaternion<f64>) -> [f64; 3] {
    let q = r.quaternion();
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let s = v.norm();
    if s == 0.0 {
        return [0.0; 3];
    }
    let k = 2.0 * s.atan2(w) / s;
    [k * v.x, k * v.y, k * v.z]
}

/// UR's pose p[x, y, z, rx, ry, rz] (m, rad) of `pose`.
pub fn ur_pose(pose: &Isometry3<f64>) -> [f64; 6] {
    let t = pose.translation.vector;
    let r = rotation_vector(&pose.rotation);
    [t.x, t.y, t.z, r[0], r[1], r[2]]
}

/// The tool points (m, base frame) of a tool at `pose` (its TCP pose): `pose` applied to each
/// of `offsets` (m, flange frame, relative to the TCP). Written into `out` (same length).
pub fn tool_points(pose: &Isometry3<f64>, offsets: &[[f64; 3]], out: &mut [[f64; 3]]) {
    assert_eq!(offsets.len(), out.len(), "one output per tool point");
    for (o, p) in offsets.iter().zip(out.iter_mut()) {
        let w = pose * Point3::from(*o);
        *p = [w.x, w.y, w.z];
    }
}

/// Orientation of the frame the three points `p` span (rows of the rotation's columns): x
/// along p1 − p0, z along (p1 − p0) × (p2 − p0), y completing it. `None` if they lie on one
/// line (closer than 1e-12 m² in the cross product).
fn frame_of(p: &[[f64; 3]; 3]) -> Option<Rotation3<f64>> {
    let v = |a: &[f64; 3], b: &[f64; 3]| Vector3::new(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
    let (a, b) = (v(&p[0], &p[1]), v(&p[0], &p[2]));
    let z = a.cross(&b);
    if z.norm() < 1e-12 || a.norm() == 0.0 {
        return None;
    }
    let x = a.normalize();
    let z = z.normalize();
    let y = z.cross(&x);
    Some(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
        x, y, z,
    ])))
}

/// The angle (rad, in [0, π]) of the rotation between the frames spanned by three tool
/// points `points` and by their `targets` (same offsets): the tool's orientation error, 0
/// when the tool is oriented as the goal. `None` if either triple lies on one line.
pub fn orientation_error(points: &[[f64; 3]; 3], targets: &[[f64; 3]; 3]) -> Option<f64> {
    let (r, g) = (frame_of(points)?, frame_of(targets)?);
    // 2 atan2(|v|, |w|) of the relative rotation's quaternion: accurate near 0, where the
    // trace's arccos loses half the digits.
    let q = UnitQuaternion::from_rotation_matrix(&(g.inverse() * r));
    let q = q.quaternion();
    Some(2.0 * q.imag().norm().atan2(q.w.abs()))
}

/// The tool pose whose tool points at `offsets` (m, flange frame, relative to the TCP) are at
/// `points` (m, base frame): the inverse of [`tool_points`] for three points not on one line.
/// The rotation maps the frame the offsets span onto the frame the points span; the
/// translation then puts offset 0 on point 0 (exact for points of a rigid tool, a least-effort
/// fit otherwise). `None` if either triple lies on one line.
pub fn pose_of_points(offsets: &[[f64; 3]; 3], points: &[[f64; 3]; 3]) -> Option<Isometry3<f64>> {
    let (fo, fp) = (frame_of(offsets)?, frame_of(points)?);
    let r = fp * fo.inverse();
    let t = Vector3::from(points[0]) - r * Vector3::from(offsets[0]);
    Some(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r),
    ))
}

/// The mean of poses close to one another: the mean position, and the mean of their unit
/// quaternions (each on the first one's side of the double cover), normalised: for rotations
/// a few degrees apart this is the rotation nearest them in the chordal sense (Markley et
/// al. 2007). Panics on an empty slice.
pub fn mean_pose(poses: &[Isometry3<f64>]) -> Isometry3<f64> {
    assert!(!poses.is_empty(), "the mean of no pose");
    let n = poses.len() as f64;
    let first = poses[0].rotation.coords;
    let (mut t, mut q) = (Vector3::zeros(), nalgebra::Vector4::zeros());
    for p in poses {
        t += p.translation.vector / n;
        let c = p.rotation.coords;
        q += if c.dot(&first) < 0.0 { -c } else { c };
    }
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(q)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_vector_round_trips_at_every_angle() {
        for (axis, angle) in [
            ([0.0, 0.0, 1.0], 0.3),
            ([1.0, 2.0, -0.5], 2.9),
            ([0.0, 1.0, 0.0], std::f64::consts::PI - 1e-9),
            ([0.3, -0.1, 0.2], 1e-9),
        ] {
            let a = Vector3::from(axis).normalize() * angle;
            let p = [0.1, -0.2, 0.3, a.x, a.y, a.z];
            let back = ur_pose(&isometry(&p));
            for k in 0..6 {
                assert!((back[k] - p[k]).abs() < 1e-12, "{p:?} → {back:?}");
            }
        }
        assert_eq!(rotation_vector(&UnitQuaternion::identity()), [0.0; 3]);
    }

    #[test]
    fn orientation_error_is_the_angle_between_the_poses() {
        let offsets = [[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]];
        let goal = isometry(&[-0.4, -0.2, 0.3, 2.0, -1.0, 0.5]);
        let turn = UnitQuaternion::from_scaled_axis(Vector3::new(0.01, -0.02, 0.015));
        let moved = Isometry3::from_parts(
            Translation3::new(0.01, 0.02, -0.03) * goal.translation,
            goal.rotation * turn,
        );
        let (mut g, mut p) = ([[0.0; 3]; 3], [[0.0; 3]; 3]);
        tool_points(&goal, &offsets, &mut g);
        tool_points(&moved, &offsets, &mut p);
        let e = orientation_error(&p, &g).unwrap();
        assert!((e - turn.angle()).abs() < 1e-12, "{e} vs {}", turn.angle());
        assert!(orientation_error(&g, &g).unwrap() < 1e-15);
        let line = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert_eq!(orientation_error(&line, &g), None);
    }

    #[test]
    fn the_pose_of_a_tools_points_is_the_pose_they_came_from() {
        let offsets = [[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]];
        let odd = [[0.01, -0.02, 0.03], [0.12, 0.0, 0.01], [0.0, 0.09, -0.02]];
        for o in [offsets, odd] {
            for p in [
                [-0.4, -0.2, 0.3, 2.0, -1.0, 0.5],
                [0.1, 0.5, 0.2, 0.0, 3.1, 0.0],
                [0.3, 0.0, 0.6, 1e-7, 0.0, 0.0],
            ] {
                let mut pts = [[0.0; 3]; 3];
                tool_points(&isometry(&p), &o, &mut pts);
                let back = ur_pose(&pose_of_points(&o, &pts).unwrap());
                for k in 0..6 {
                    assert!((back[k] - p[k]).abs() < 1e-12, "{p:?} → {back:?}");
                }
            }
        }
        let line = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert!(pose_of_points(&offsets, &line).is_none());
    }

    #[test]
    fn the_mean_pose_of_nearby_poses_lies_between_them() {
        let a = isometry(&[0.1, 0.2, 0.3, 0.0, 0.0, 0.2]);
        let b = isometry(&[0.3, 0.0, 0.1, 0.0, 0.0, 0.4]);
        let m = ur_pose(&mean_pose(&[a, b]));
        let want = [0.2, 0.1, 0.2, 0.0, 0.0, 0.3];
        for k in 0..6 {
            assert!((m[k] - want[k]).abs() < 1e-12, "{m:?}");
        }
        // The double cover: the same rotation as −q does not cancel out.
        let flipped = Isometry3::from_parts(
            a.translation,
            UnitQuaternion::new_unchecked(-a.rotation.into_inner()),
        );
        let m = ur_pose(&mean_pose(&[a, flipped]));
        let p = ur_pose(&a);
        for k in 0..6 {
            assert!((m[k] - p[k]).abs() < 1e-12, "{m:?}");
        }
    }
}
