//! The arm model: the URDF parsed with `urdf-rs`, checked, and prepared for rapier3d.
//!
//! Preparation does three things the simulator relies on:
//! - the three active joints ([`ur5_shared::layout::ACTIVE_JOINTS`]) must exist and be revolute
//!   with limits; their limits are read from the URDF (rapier ignores effort and velocity limits,
//!   so the simulator enforces them itself);
//! - with three active joints (the default), every other movable joint (the UR5's wrist) is
//!   locked at its configured angle by turning it into a fixed joint whose origin absorbs the
//!   rotation, so the rapier multibody has exactly three degrees of freedom; with six
//!   ([`ArmModel::load_joints`]) the wrist joints are active too (revolute with limits, checked
//!   like the others) and nothing is locked;
//! - link masses and inertias are scaled by the mass perturbation (the nominal copy is kept for
//!   the arm's own gravity compensation).

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use ur5_shared::layout::{ACTIVE_JOINTS, N_JOINTS};
use ur5_shared::UrModel;
use urdf_rs::{JointType, Robot};

use crate::SimError;

/// The UR5 URDF shipped with hil-sim (see the comment at its top for the sources of every
/// number); every model's: [`crate::urdf::bundled_urdf`].
pub const BUNDLED_URDF: &str = include_str!("../urdf/ur5.urdf");

/// Where the bundled UR5 URDF lives in the source tree; every model's:
/// [`crate::urdf::bundled_urdf_path`].
pub fn bundled_urdf_path() -> PathBuf {
    crate::urdf::bundled_urdf_path(UrModel::Ur5)
}

/// Limits of one active joint, as written in the URDF.
#[derive(Clone, Debug, PartialEq)]
pub struct JointLimits {
    /// URDF joint name.
    pub name: String,
    /// Lower position limit (rad).
    pub lower: f64,
    /// Upper position limit (rad).
    pub upper: f64,
    /// Effort limit (N·m).
    pub effort: f64,
    /// Velocity limit (rad/s).
    pub velocity: f64,
}

/// A checked arm description, ready to be built into a rapier multibody.
#[derive(Clone, Debug)]
pub struct ArmModel {
    /// The robot as parsed from the URDF, unmodified (wrists still revolute, nominal masses).
    pub urdf: Robot,
    /// The robot handed to rapier3d-urdf: wrists fixed at [`Self::wrist_q`].
    pub locked: Robot,
    /// Where the URDF came from.
    pub source: PathBuf,
    /// The first three active joints in layout order (shoulder pan, shoulder lift, elbow).
    pub active: [JointLimits; N_JOINTS],
    /// How many joints move: 3 (wrist locked) or 6 (the wrist joints active too).
    pub n_active: usize,
    /// Limits of the three wrist joints in chain order, as written in the URDF (checked only
    /// with six active joints; a locked wrist's limits are not used).
    pub wrist_limits: Vec<JointLimits>,
    /// Names of the wrist joints in chain order: locked with three active joints, active (after
    /// [`Self::active`]) with six.
    pub wrist_joints: Vec<String>,
    /// Angles the wrist joints are locked at with three active joints; with six, where the
    /// wrist rests when only three angles are given (rad).
    pub wrist_q: [f64; 3],
    /// Link whose origin plus [`Self::ee_offset`] is the end-effector point.
    pub ee_link: String,
    /// End-effector offset in `ee_link`'s frame (m).
    pub ee_offset: [f64; 3],
}

impl ArmModel {
    /// Loads a URDF file (or the bundled URDF of `model` when `path` is `None`) and checks it,
    /// with three active joints (the wrist locked at `wrist_q`).
    pub fn load(
        path: Option<&Path>,
        model: UrModel,
        wrist_q: [f64; 3],
        ee_link: &str,
        ee_offset: [f64; 3],
    ) -> Result<Self, SimError> {
        Self::load_joints(path, model, wrist_q, ee_link, ee_offset, N_JOINTS)
    }

    /// [`Self::load`] with `joints` active joints: 3 (wrist locked) or 6 (wrist active).
    pub fn load_joints(
        path: Option<&Path>,
        model: UrModel,
        wrist_q: [f64; 3],
        ee_link: &str,
        ee_offset: [f64; 3],
        joints: usize,
    ) -> Result<Self, SimError> {
        let (text, source) = match path {
            Some(p) => (
                std::fs::read_to_string(p).map_err(|e| SimError::UrdfRead {
                    path: p.to_owned(),
                    source: e,
                })?,
                p.to_owned(),
            ),
            None => (
                crate::urdf::bundled_urdf(model).to_owned(),
                crate::urdf::bundled_urdf_path(model),
            ),
        };
        Self::from_str_joints(&text, source, wrist_q, ee_link, ee_offset, joints)
    }

    /// Parses and checks URDF text with three active joints; `source` is only used in messages.
    pub fn from_str(
        text: &str,
        source: PathBuf,
        wrist_q: [f64; 3],
        ee_link: &str,
        ee_offset: [f64; 3],
    ) -> Result<Self, SimError> {
        Self::from_str_joints(text, source, wrist_q, ee_link, ee_offset, N_JOINTS)
    }

    /// [`Self::from_str`] with `joints` active joints: 3 (wrist locked) or 6 (wrist active).
    pub fn from_str_joints(
        text: &str,
        source: PathBuf,
        wrist_q: [f64; 3],
        ee_link: &str,
        ee_offset: [f64; 3],
        joints: usize,
    ) -> Result<Self, SimError> {
        if joints != 3 && joints != 6 {
            return Err(SimError::BadJoint {
                name: "<joints>".into(),
                why: format!("{joints} active joints: the simulator moves 3 (wrist locked) or 6"),
            });
        }
        let parse_error = |message: String| SimError::UrdfParse {
            path: source.clone(),
            message,
        };
        if text.len() > MAX_URDF_BYTES {
            return Err(parse_error(format!(
                "{} bytes, more than the {MAX_URDF_BYTES} a robot description needs",
                text.len()
            )));
        }
        let depth = xml_depth(text);
        if depth > MAX_XML_DEPTH {
            return Err(parse_error(format!(
                "elements nested {depth} deep, more than {MAX_XML_DEPTH} (a URDF needs 4)"
            )));
        }
        let urdf = urdf_rs::read_from_string(text).map_err(|e| parse_error(e.to_string()))?;
        check_structure(&urdf)?;
        let joint_names = || {
            urdf.joints
                .iter()
                .map(|j| j.name.clone())
                .collect::<Vec<_>>()
        };

        let mut active = Vec::with_capacity(N_JOINTS);
        for name in ACTIVE_JOINTS {
            let j = urdf.joints.iter().find(|j| j.name == name).ok_or_else(|| {
                SimError::UnknownJoint {
                    name: name.into(),
                    available: joint_names(),
                }
            })?;
            active.push(active_limits(j)?);
        }

        if !urdf.links.iter().any(|l| l.name == ee_link) {
            return Err(SimError::UnknownLink {
                name: ee_link.into(),
                available: urdf.links.iter().map(|l| l.name.clone()).collect(),
            });
        }
        for link in &urdf.links {
            check_inertial(link)?;
        }

        // The movable joints that are not among the first three, in chain order from the root:
        // the wrist, locked (three active joints) or active (six).
        let order = chain_order(&urdf)?;
        let mut locked = urdf.clone();
        let mut wrist_joints = Vec::new();
        let mut wrist_limits = Vec::new();
        for ji in order {
            let j = &urdf.joints[ji];
            if ACTIVE_JOINTS.contains(&j.name.as_str()) || j.joint_type == JointType::Fixed {
                continue;
            }
            if j.joint_type != JointType::Revolute && j.joint_type != JointType::Continuous {
                return Err(SimError::BadJoint {
                    name: j.name.clone(),
                    why: "only revolute wrist joints can be locked".into(),
                });
            }
            let k = wrist_joints.len();
            if k >= wrist_q.len() {
                return Err(SimError::BadJoint {
                    name: j.name.clone(),
                    why: format!(
                        "more than {} movable joints besides the active ones",
                        wrist_q.len()
                    ),
                });
            }
            wrist_joints.push(j.name.clone());
            if joints == N_JOINTS {
                let lj = &mut locked.joints[ji];
                lj.origin = lock_origin(&j.origin, j.axis.xyz.0, wrist_q[k]);
                lj.joint_type = JointType::Fixed;
                wrist_limits.push(JointLimits {
                    name: j.name.clone(),
                    lower: j.limit.lower,
                    upper: j.limit.upper,
                    effort: j.limit.effort,
                    velocity: j.limit.velocity,
                });
            } else {
                wrist_limits.push(active_limits(j)?);
            }
        }
        if wrist_joints.len() != wrist_q.len() {
            return Err(SimError::BadJoint {
                name: "<wrist>".into(),
                why: format!(
                    "expected {} wrist joints to lock, found {:?}",
                    wrist_q.len(),
                    wrist_joints
                ),
            });
        }

        Ok(Self {
            urdf,
            locked,
            source,
            active: active.try_into().expect("three active joints"),
            n_active: joints,
            wrist_limits,
            wrist_joints,
            wrist_q,
            ee_link: ee_link.into(),
            ee_offset,
        })
    }

    /// Limits of active joint `j` (layout order: the three of [`Self::active`], then the wrist
    /// joints when six are active).
    pub fn joint(&self, j: usize) -> &JointLimits {
        if j < N_JOINTS {
            &self.active[j]
        } else {
            &self.wrist_limits[j - N_JOINTS]
        }
    }

    /// The locked robot with every link's mass and inertia multiplied by `scale` (the base is
    /// fixed, so scaling it changes nothing).
    pub fn locked_with_mass_scale(&self, scale: f64) -> Robot {
        let mut r = self.locked.clone();
        for link in &mut r.links {
            link.inertial.mass.value *= scale;
            let i = &mut link.inertial.inertia;
            for v in [
                &mut i.ixx, &mut i.ixy, &mut i.ixz, &mut i.iyy, &mut i.iyz, &mut i.izz,
            ] {
                *v *= scale;
            }
        }
        r
    }

    /// The robot the simulator builds: [`Self::locked`] with masses and inertias multiplied by
    /// `mass_scale` and every link that hangs on a fixed joint merged into its parent, so that
    /// each rigid body of the arm is one multibody link (see [`merge_fixed_links`]). With the
    /// wrists locked the UR5 is four links (base, shoulder, upper arm, forearm carrying the
    /// wrists) instead of seven; the multibody's work per physics step (forward kinematics,
    /// mass matrix, Jacobians) grows with its links. Link and joint names of the links that
    /// remain are those of the URDF.
    pub fn rigid_robot(&self, mass_scale: f64) -> Robot {
        merge_fixed_links(&self.locked_with_mass_scale(mass_scale))
    }

    /// Where link `name` of the URDF ends up in [`Self::rigid_robot`]: the link that carries it
    /// and the pose of `name`'s frame in that link's frame (identity if it was not merged).
    /// `None` for an unknown link.
    pub fn carrier_of(&self, name: &str) -> Option<(String, Isometry3<f64>)> {
        let mut link = self
            .locked
            .links
            .iter()
            .find(|l| l.name == name)?
            .name
            .clone();
        let mut pose = Isometry3::identity();
        while let Some(j) = self
            .locked
            .joints
            .iter()
            .find(|j| j.child.link == link && j.joint_type == JointType::Fixed)
        {
            pose = urdf_pose_to_isometry(&j.origin) * pose;
            link = j.parent.link.clone();
        }
        Some((link, pose))
    }

    /// Upper bound of the distance from the shoulder-lift joint to the end-effector point (m):
    /// the sum of the lengths of the joint offsets after it, plus the end-effector offset.
    pub fn reach(&self) -> f64 {
        let mut reach = Vector3::from(self.ee_offset).norm();
        let mut past_lift = false;
        for ji in chain_order(&self.urdf).unwrap_or_default() {
            let j = &self.urdf.joints[ji];
            if past_lift {
                reach += Vector3::from(j.origin.xyz.0).norm();
            }
            if j.name == ACTIVE_JOINTS[1] {
                past_lift = true;
            }
        }
        reach
    }
}

/// The limits of joint `j`, which must be revolute with lower < upper and positive effort and
/// velocity limits to be active.
fn active_limits(j: &urdf_rs::Joint) -> Result<JointLimits, SimError> {
    if j.joint_type != JointType::Revolute {
        return Err(SimError::BadJoint {
            name: j.name.clone(),
            why: "must be revolute".into(),
        });
    }
    let l = &j.limit;
    if !(l.lower < l.upper && l.effort > 0.0 && l.velocity > 0.0) {
        return Err(SimError::BadJoint {
            name: j.name.clone(),
            why: format!(
                "needs lower < upper and positive effort and velocity limits, got lower {} upper {} effort {} velocity {}",
                l.lower, l.upper, l.effort, l.velocity
            ),
        });
    }
    Ok(JointLimits {
        name: j.name.clone(),
        lower: l.lower,
        upper: l.upper,
        effort: l.effort,
        velocity: l.velocity,
    })
}

/// Largest URDF text accepted (bytes). A robot description is kilobytes; ours is 9 kB.
pub const MAX_URDF_BYTES: usize = 16 << 20;

/// Deepest element nesting accepted. A URDF nests 4 deep (robot, link, inertial, origin); the
/// XML parser recurses per level, so a file nested 200,000 deep would overflow the stack.
pub const MAX_XML_DEPTH: usize = 64;

/// Heaviest link accepted (kg). A UR5 link weighs at most 3.9 kg.
pub const MAX_LINK_MASS: f64 = 1e4;

/// The deepest element nesting of XML text, counted without parsing it (start tags that do not
/// close themselves open a level, end tags close one; declarations, comments and processing
/// instructions do not count).
fn xml_depth(text: &str) -> usize {
    let b = text.as_bytes();
    let (mut depth, mut max, mut i) = (0usize, 0usize, 0usize);
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        if b[i..].starts_with(b"<!--") {
            i = text[i..].find("-->").map_or(b.len(), |k| i + k + 3);
            continue;
        }
        let end = text[i..].find('>').map_or(b.len(), |k| i + k);
        match b.get(i + 1) {
            Some(b'/') => depth = depth.saturating_sub(1),
            Some(b'?') | Some(b'!') => {}
            _ if b[end.saturating_sub(1)] == b'/' => {}
            _ => {
                depth += 1;
                max = max.max(depth);
            }
        }
        i = end + 1;
    }
    max
}

/// The structure a tree of links needs, each problem named: unique link and joint names, every
/// joint between two existing links, no link the child of two joints, finite joint origins and
/// limits, non-zero finite axes of movable joints.
fn check_structure(robot: &Robot) -> Result<(), SimError> {
    use std::collections::HashSet;
    let mut links = HashSet::new();
    for l in &robot.links {
        if !links.insert(l.name.as_str()) {
            return Err(SimError::BadLink {
                name: l.name.clone(),
                why: "defined twice (link names must be unique)".into(),
            });
        }
    }
    let mut joints = HashSet::new();
    let mut children = HashSet::new();
    for j in &robot.joints {
        let bad = |why: String| SimError::BadJoint {
            name: j.name.clone(),
            why,
        };
        if !joints.insert(j.name.as_str()) {
            return Err(bad("defined twice (joint names must be unique)".into()));
        }
        for (role, link) in [("parent", &j.parent.link), ("child", &j.child.link)] {
            if !links.contains(link.as_str()) {
                return Err(bad(format!("its {role} link `{link}` is not defined")));
            }
        }
        if !children.insert(j.child.link.as_str()) {
            return Err(bad(format!(
                "link `{}` is already the child of another joint (a URDF is a tree)",
                j.child.link
            )));
        }
        let o = &j.origin;
        if o.xyz.0.iter().chain(o.rpy.0.iter()).any(|v| !v.is_finite()) {
            return Err(bad(format!(
                "origin xyz {:?} rpy {:?} must be finite",
                o.xyz.0, o.rpy.0
            )));
        }
        if j.joint_type != JointType::Fixed {
            let a = j.axis.xyz.0;
            let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            if !(n.is_finite() && n > 1e-9) {
                return Err(bad(format!("axis {a:?} must be finite and non-zero")));
            }
            let l = &j.limit;
            if [l.lower, l.upper, l.effort, l.velocity]
                .iter()
                .any(|v| !v.is_finite())
            {
                return Err(bad(format!(
                    "limits lower {} upper {} effort {} velocity {} must be finite",
                    l.lower, l.upper, l.effort, l.velocity
                )));
            }
        }
    }
    Ok(())
}

/// A link's mass and inertia must describe a rigid body: mass finite, > 0 and at most
/// [`MAX_LINK_MASS`]; inertia tensor finite with positive principal moments that satisfy the
/// triangle inequality (each at most the sum of the other two).
fn check_inertial(link: &urdf_rs::Link) -> Result<(), SimError> {
    let m = link.inertial.mass.value;
    let i = &link.inertial.inertia;
    let bad = |why: String| SimError::BadLink {
        name: link.name.clone(),
        why,
    };
    if !(m.is_finite() && m > 0.0 && m <= MAX_LINK_MASS) {
        return Err(bad(format!(
            "mass {m:?} kg must be finite, > 0 and at most {MAX_LINK_MASS} kg (every link needs an <inertial>)"
        )));
    }
    let t = nalgebra::Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    if t.iter().any(|v| !v.is_finite()) {
        return Err(bad(format!("inertia {t:?} kg·m² must be finite")));
    }
    let e = t.symmetric_eigenvalues();
    let (p, tol) = ([e[0], e[1], e[2]], 1e-9 * e.amax().max(1e-12));
    let triangle = (0..3).all(|k| p[k] <= p[(k + 1) % 3] + p[(k + 2) % 3] + tol);
    if !(p.iter().all(|&v| v > 0.0) && triangle) {
        return Err(bad(format!(
            "inertia principal moments {p:?} kg·m² must be > 0 and each at most the sum of the \
             other two (ixx {} iyy {} izz {} ixy {} ixz {} iyz {})",
            i.ixx, i.iyy, i.izz, i.ixy, i.ixz, i.iyz
        )));
    }
    Ok(())
}

/// Joint indices ordered from the root to the leaves (the URDF must be a tree; names and links
/// are checked by [`check_structure`] first).
fn chain_order(robot: &Robot) -> Result<Vec<usize>, SimError> {
    let is_child = |name: &str| robot.joints.iter().any(|j| j.child.link == name);
    let roots: Vec<&str> = robot
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|n| !is_child(n))
        .collect();
    if roots.is_empty() {
        return Err(SimError::BadJoint {
            name: "<tree>".into(),
            why: "every link is some joint's child: the joints form a cycle".into(),
        });
    }
    if roots.len() > 1 {
        return Err(SimError::BadLink {
            name: format!("{roots:?}"),
            why: "these links hang from no joint: the URDF must be one tree with one root link \
                  (a joint missing?)"
                .into(),
        });
    }
    let mut order = Vec::new();
    let mut stack = vec![roots[0]];
    while let Some(link) = stack.pop() {
        for (i, j) in robot.joints.iter().enumerate() {
            if j.parent.link == link {
                order.push(i);
                stack.push(j.child.link.as_str());
            }
        }
    }
    if order.len() != robot.joints.len() {
        return Err(SimError::BadJoint {
            name: "<tree>".into(),
            why: "some joints are not reachable from the root link (loop or dangling parent)"
                .into(),
        });
    }
    Ok(order)
}

/// `robot` with the child of every fixed joint merged into the parent link: one link with the
/// summed mass, the mass-weighted centre of mass and the inertia of both about it (each link's
/// inertia rotated into the parent's frame and moved by the parallel-axis theorem), written
/// with its origin at that centre of mass, axes of the parent frame (rpy 0) and the full
/// symmetric tensor. Joints that hung from the merged child hang from the parent, their origin
/// composed with the fixed joint's. A rigid assembly moves the same either way; the merged
/// form is what the multibody integrates faster.
pub fn merge_fixed_links(robot: &Robot) -> Robot {
    let mut r = robot.clone();
    while let Some(ji) = r
        .joints
        .iter()
        .position(|j| j.joint_type == JointType::Fixed)
    {
        let joint = r.joints.remove(ji);
        let (parent, child) = (joint.parent.link.clone(), joint.child.link.clone());
        let to_parent = urdf_pose_to_isometry(&joint.origin);
        let ci = r
            .links
            .iter()
            .position(|l| l.name == child)
            .expect("joint child exists (checked)");
        let child_link = r.links.remove(ci);
        let pl = r
            .links
            .iter_mut()
            .find(|l| l.name == parent)
            .expect("joint parent exists (checked)");
        pl.inertial = merge_inertials(&pl.inertial, &child_link.inertial, &to_parent);
        for j in r.joints.iter_mut().filter(|j| j.parent.link == child) {
            j.parent.link = parent.clone();
            j.origin = isometry_to_urdf_pose(&(to_parent * urdf_pose_to_isometry(&j.origin)));
        }
    }
    r
}

/// Mass, centre of mass (parent frame) and inertia about that centre (parent axes) of an
/// inertial whose link frame sits at `to_parent` in the parent's frame.
fn inertial_in_parent(
    i: &urdf_rs::Inertial,
    to_parent: &Isometry3<f64>,
) -> (f64, Vector3<f64>, Matrix3<f64>) {
    let at = to_parent * urdf_pose_to_isometry(&i.origin);
    let t = &i.inertia;
    let local = Matrix3::new(
        t.ixx, t.ixy, t.ixz, t.ixy, t.iyy, t.iyz, t.ixz, t.iyz, t.izz,
    );
    let rot = at.rotation.to_rotation_matrix();
    (
        i.mass.value,
        at.translation.vector,
        rot.matrix() * local * rot.matrix().transpose(),
    )
}

/// `parent`'s and `child`'s inertials as one, in the parent's frame (see [`merge_fixed_links`]).
fn merge_inertials(
    parent: &urdf_rs::Inertial,
    child: &urdf_rs::Inertial,
    child_to_parent: &Isometry3<f64>,
) -> urdf_rs::Inertial {
    let parts = [
        inertial_in_parent(parent, &Isometry3::identity()),
        inertial_in_parent(child, child_to_parent),
    ];
    let mass: f64 = parts.iter().map(|p| p.0).sum();
    let com = if mass > 0.0 {
        parts.iter().map(|p| p.0 * p.1).sum::<Vector3<f64>>() / mass
    } else {
        Vector3::zeros()
    };
    // Parallel-axis theorem: I_com = Σ (I_i + m_i (|d|² E − d dᵀ)), d = com_i − com.
    let inertia: Matrix3<f64> = parts
        .iter()
        .map(|(m, c, i)| {
            let d = c - com;
            i + *m * (Matrix3::identity() * d.norm_squared() - d * d.transpose())
        })
        .sum();
    urdf_rs::Inertial {
        origin: urdf_rs::Pose {
            xyz: urdf_rs::Vec3(com.into()),
            rpy: urdf_rs::Vec3([0.0; 3]),
        },
        mass: urdf_rs::Mass { value: mass },
        inertia: urdf_rs::Inertia {
            ixx: inertia[(0, 0)],
            ixy: inertia[(0, 1)],
            ixz: inertia[(0, 2)],
            iyy: inertia[(1, 1)],
            iyz: inertia[(1, 2)],
            izz: inertia[(2, 2)],
        },
    }
}

/// The origin of a fixed joint equivalent to a revolute joint held at angle `q` about `axis`.
fn lock_origin(origin: &urdf_rs::Pose, axis: [f64; 3], q: f64) -> urdf_rs::Pose {
    let iso = urdf_pose_to_isometry(origin)
        * UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::from(axis)), q);
    isometry_to_urdf_pose(&iso)
}

/// URDF pose (xyz, fixed-axis roll-pitch-yaw) to an isometry.
pub fn urdf_pose_to_isometry(p: &urdf_rs::Pose) -> Isometry3<f64> {
    let [r, pi, y] = p.rpy.0;
    Isometry3::from_parts(
        Translation3::from(Vector3::from(p.xyz.0)),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(r, pi, y)),
    )
}

/// Isometry to URDF pose. The roll-pitch-yaw angles (R = R_z(y) R_y(p) R_x(r)) are taken as
/// y = atan2(R₁₀, R₀₀), then p and r from R_z(−y) R = R_y(p) R_x(r), which stays exact at
/// p = ±π/2, where nalgebra's `euler_angles` returns a different rotation (a wrist locked at
/// ±π/2 composed with the next joint's origin lands there).
fn isometry_to_urdf_pose(iso: &Isometry3<f64>) -> urdf_rs::Pose {
    let m = iso.rotation.to_rotation_matrix().into_inner();
    let y = m[(1, 0)].atan2(m[(0, 0)]);
    let (sy, cy) = y.sin_cos();
    let p = (-m[(2, 0)]).atan2(cy * m[(0, 0)] + sy * m[(1, 0)]);
    let r = (sy * m[(0, 2)] - cy * m[(1, 2)]).atan2(cy * m[(1, 1)] - sy * m[(0, 1)]);
    urdf_rs::Pose {
        xyz: urdf_rs::Vec3(iso.translation.vector.into()),
        rpy: urdf_rs::Vec3([r, p, y]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mass, first moment and inertia about the frame origin of an inertial at `pose`.
    fn moments(i: &urdf_rs::Inertial, pose: &Isometry3<f64>) -> (f64, Vector3<f64>, Matrix3<f64>) {
        let (m, c, ic) = inertial_in_parent(i, pose);
        let shift = m * (Matrix3::identity() * c.norm_squared() - c * c.transpose());
        (m, m * c, ic + shift)
    }

    #[test]
    fn urdf_pose_round_trips_through_gimbal_lock() {
        let half_pi = std::f64::consts::FRAC_PI_2;
        for rpy in [
            [0.0, 0.0, 0.0],
            [0.3, -0.4, 2.9],
            [0.0, -half_pi, 3.0],
            [1.1, half_pi, -0.2],
            [-0.7, half_pi - 1e-9, 0.4],
        ] {
            let pose = urdf_rs::Pose {
                xyz: urdf_rs::Vec3([0.1, -0.2, 0.3]),
                rpy: urdf_rs::Vec3(rpy),
            };
            let iso = urdf_pose_to_isometry(&pose);
            let back = urdf_pose_to_isometry(&isometry_to_urdf_pose(&iso));
            let err = (back.to_homogeneous() - iso.to_homogeneous()).abs().max();
            assert!(err < 1e-14, "rpy {rpy:?}: {err:e}");
        }
    }

    #[test]
    fn merging_keeps_mass_centre_and_inertia_of_the_rigid_assembly() {
        for wrist_q in [
            [-1.5707963267948966, 1.5707963267948966, 0.0],
            [0.3, -0.7, 1.1],
        ] {
            let model =
                ArmModel::load(None, UrModel::Ur5, wrist_q, "wrist_3_link", [0.0, 0.0, 0.1])
                    .unwrap();
            let merged = model.rigid_robot(1.0);
            let names: Vec<&str> = merged.links.iter().map(|l| l.name.as_str()).collect();
            assert_eq!(
                names,
                [
                    "base_link",
                    "shoulder_link",
                    "upper_arm_link",
                    "forearm_link"
                ]
            );
            assert_eq!(merged.joints.len(), 3);
            // The forearm and the three wrist links, each at its pose in the forearm frame.
            let (mut m, mut first, mut inertia) = (0.0, Vector3::zeros(), Matrix3::zeros());
            for name in [
                "forearm_link",
                "wrist_1_link",
                "wrist_2_link",
                "wrist_3_link",
            ] {
                let (carrier, pose) = model.carrier_of(name).unwrap();
                assert_eq!(carrier, "forearm_link");
                let link = model.locked.links.iter().find(|l| l.name == name).unwrap();
                let (mi, fi, ii) = moments(&link.inertial, &pose);
                m += mi;
                first += fi;
                inertia += ii;
            }
            let forearm = merged
                .links
                .iter()
                .find(|l| l.name == "forearm_link")
                .unwrap();
            let (mm, fm, im) = moments(&forearm.inertial, &Isometry3::identity());
            assert!((mm - m).abs() < 1e-12);
            assert!((fm - first).norm() < 1e-12, "{fm} vs {first}");
            assert!((im - inertia).abs().max() < 1e-12, "{im} vs {inertia}");
            // Links that were not merged keep their inertials.
            let upper = |r: &Robot| {
                r.links
                    .iter()
                    .find(|l| l.name == "upper_arm_link")
                    .unwrap()
                    .inertial
                    .clone()
            };
            assert_eq!(
                format!("{:?}", upper(&merged)),
                format!("{:?}", upper(&model.locked))
            );
            // The end-effector link sits where the locked joints put it.
            let (_, ee) = model.carrier_of("wrist_3_link").unwrap();
            let chain = ["wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
                .iter()
                .map(|n| {
                    let j = model.locked.joints.iter().find(|j| j.name == *n).unwrap();
                    urdf_pose_to_isometry(&j.origin)
                })
                .fold(Isometry3::identity(), |a, b| a * b);
            assert!((ee.to_homogeneous() - chain.to_homogeneous()).abs().max() < 1e-12);
        }
    }
}
