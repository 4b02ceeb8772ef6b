//! The state and action layout of a task (docs/design.md §2.2): one value, [`StateLayout`],
//! built once from the task's settings and asked for every dimension and index range.
//!
//! As in Guided Policy Search (`state_include` with `sensor_dims`), the state is a list of named
//! parts, in this order:
//!
//! | part ([`Part`]) | size | unit | frame |
//! |---|---|---|---|
//! | joint angles q of the active joints | n | rad | joint |
//! | joint velocities q̇ | n | rad/s | joint |
//! | for each tool point i: its position minus its target | 3 each | m | arm base |
//! | for each tool point i: its linear velocity | 3 each | m/s | arm base |
//!
//! with n active joints (3: shoulder pan, shoulder lift, elbow, the wrist locked; or 6: the
//! whole arm) and one tool point for a point goal or three non-collinear ones for a pose goal
//! (three points fix the tool's pose, as in GPS's robot experiments). So dX = 2n + 6p and
//! dU = n: 12 and 3 for the paper's reaching task ([`StateLayout::REACH3`]), 30 and 6 for the
//! whole arm and a pose. The action is goal joint angles (rad), or joint torques (N·m) in torque
//! mode, in the joint order of the state.
//!
//! Tables and messages carry their dimensions at run time in storage of compile-time capacity
//! ([`MAX_DX`], [`MAX_DU`], [`MAX_HORIZON`]), so the controller's loop allocates nothing for any
//! task up to those sizes.
//!
//! The constants [`DX`], [`DU`], [`Q`], [`QD`], [`EE_MINUS_GOAL`], [`EE_VEL`] and the name
//! arrays describe [`StateLayout::REACH3`], the default task's layout, for the code that does
//! not yet take a layout value.

use core::fmt;
use core::ops::Range;

/// Most active joints a task can have (and so most action entries): a UR arm has 6; 7 leaves
/// room for a seven-joint arm.
pub const MAX_JOINTS: usize = 7;
/// Most tool points in a state (3 for a pose goal).
pub const MAX_TOOL_POINTS: usize = 3;
/// Capacity of every state array: the largest layout, [`MAX_JOINTS`] joints and
/// [`MAX_TOOL_POINTS`] tool points.
pub const MAX_DX: usize = 2 * MAX_JOINTS + 6 * MAX_TOOL_POINTS;
/// Capacity of every action array.
pub const MAX_DU: usize = MAX_JOINTS;
/// Largest horizon T a table can hold; the paper's episodes have T = 100, a drawn motion a few
/// hundred steps.
pub const MAX_HORIZON: usize = 400;

/// State dimension dX of [`StateLayout::REACH3`].
pub const DX: usize = 12;
/// Action dimension dU of [`StateLayout::REACH3`] (active joints).
pub const DU: usize = 3;
/// Number of active joints of [`StateLayout::REACH3`] (= [`DU`]).
pub const N_JOINTS: usize = DU;

/// Joint angles q (rad) in [`StateLayout::REACH3`].
pub const Q: Range<usize> = 0..3;
/// Joint velocities q̇ (rad/s) in [`StateLayout::REACH3`].
pub const QD: Range<usize> = 3..6;
/// End-effector point minus goal, base frame (m), in [`StateLayout::REACH3`].
pub const EE_MINUS_GOAL: Range<usize> = 6..9;
/// End-effector linear velocity, base frame (m/s), in [`StateLayout::REACH3`].
pub const EE_VEL: Range<usize> = 9..12;

/// Names of the state entries of [`StateLayout::REACH3`] in layout order, for files and logs
/// (what [`StateLayout::state_name`] gives for it).
#[rustfmt::skip]
pub const STATE_NAMES: [&str; DX] = [
    "q_shoulder_pan", "q_shoulder_lift", "q_elbow",
    "qd_shoulder_pan", "qd_shoulder_lift", "qd_elbow",
    "ee_minus_goal_x", "ee_minus_goal_y", "ee_minus_goal_z",
    "ee_vel_x", "ee_vel_y", "ee_vel_z",
];

/// Names of the action entries of [`StateLayout::REACH3`] in layout order.
pub const ACTION_NAMES: [&str; DU] = ["shoulder_pan", "shoulder_lift", "elbow"];

/// URDF names of the active joints of [`StateLayout::REACH3`] in layout order.
pub const ACTIVE_JOINTS: [&str; N_JOINTS] =
    ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"];

/// Short names of a UR arm's six joints, base to wrist 3; the active joints of a layout are the
/// first n of them.
pub const JOINT_NAMES: [&str; 6] = [
    "shoulder_pan",
    "shoulder_lift",
    "elbow",
    "wrist_1",
    "wrist_2",
    "wrist_3",
];

/// One part of the state (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Part {
    /// Joint angles of the active joints (rad).
    JointAngles,
    /// Joint velocities of the active joints (rad/s).
    JointVelocities,
    /// Tool point i's position minus its target (m, base frame).
    PointMinusTarget(usize),
    /// Tool point i's linear velocity (m/s, base frame).
    PointVelocity(usize),
}

impl Part {
    /// The part's name in files and messages (`q`, `qd`, `point0_minus_target`,
    /// `point0_vel`).
    pub fn name(self) -> String {
        match self {
            Part::JointAngles => "q".into(),
            Part::JointVelocities => "qd".into(),
            Part::PointMinusTarget(i) => format!("point{i}_minus_target"),
            Part::PointVelocity(i) => format!("point{i}_vel"),
        }
    }
}

/// A layout that cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    /// Joints outside 1..=[`MAX_JOINTS`] (a UR arm: 3 with the wrist locked, or 6).
    #[error("a task has 1 to {MAX_JOINTS} active joints (3 with the wrist locked, 6 for the whole arm), not {0}")]
    Joints(usize),
    /// Tool points outside 1..=[`MAX_TOOL_POINTS`].
    #[error("a task has 1 tool point (a point goal) or 3 (a pose goal), at most {MAX_TOOL_POINTS}, not {0}")]
    ToolPoints(usize),
}

/// Two layouts, or a layout and an array, that do not agree: names both sides.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{what} has dX = {got_dx}, dU = {got_du}, but the task's layout has dX = {dx}, dU = {du} ({layout}): they were made for different tasks (joints and goal kind)")]
pub struct DimensionMismatch {
    /// What was checked (a table, a file, a peer).
    pub what: &'static str,
    /// Its state dimension.
    pub got_dx: usize,
    /// Its action dimension.
    pub got_du: usize,
    /// The layout's state dimension.
    pub dx: usize,
    /// The layout's action dimension.
    pub du: usize,
    /// The layout.
    pub layout: StateLayout,
}

/// The layout of a task's state and action (module docs): n active joints and p tool points.
/// Small and `Copy`; every index range and dimension comes from here.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct StateLayout {
    joints: usize,
    points: usize,
}

impl Default for StateLayout {
    /// [`StateLayout::REACH3`].
    fn default() -> Self {
        Self::REACH3
    }
}

impl fmt::Display for StateLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} joints, {} tool point{}",
            self.joints,
            self.points,
            if self.points == 1 { "" } else { "s" }
        )
    }
}

impl StateLayout {
    /// The paper's reaching task: 3 joints (wrist locked), one tool point; dX = 12, dU = 3.
    pub const REACH3: StateLayout = StateLayout {
        joints: 3,
        points: 1,
    };
    /// The whole arm and a pose: 6 joints, three tool points; dX = 30, dU = 6.
    pub const POSE6: StateLayout = StateLayout {
        joints: 6,
        points: 3,
    };

    /// The layout of the task whose state has `dx` entries: a task moves 3 or 6 joints and
    /// has one tool point (a point goal) or three (a pose goal, six joints only), and their
    /// dX (12, 18, 30) differ; `None` for any other `dx`.
    pub fn of_task_state(dx: usize) -> Option<Self> {
        [(3, 1), (6, 1), (6, 3)]
            .into_iter()
            .map(|(joints, points)| Self { joints, points })
            .find(|l| l.dx() == dx)
    }

    /// The layout of a task moving `joints` joints toward a point (`pose_goal` false: one tool
    /// point) or a pose (three tool points, which fix it): the one rule of the task settings,
    /// the demonstrations and their files.
    pub fn of_task(joints: usize, pose_goal: bool) -> Result<Self, LayoutError> {
        Self::new(joints, if pose_goal { 3 } else { 1 })
    }

    /// The layout of `joints` active joints and `points` tool points.
    pub fn new(joints: usize, points: usize) -> Result<Self, LayoutError> {
        if !(1..=MAX_JOINTS).contains(&joints) {
            return Err(LayoutError::Joints(joints));
        }
        if !(1..=MAX_TOOL_POINTS).contains(&points) {
            return Err(LayoutError::ToolPoints(points));
        }
        Ok(Self { joints, points })
    }

    /// The layout whose dimensions are `dx`, `du` (the inverse of [`StateLayout::dx`],
    /// [`StateLayout::du`]), or `None` if no layout has them.
    pub fn from_dims(dx: usize, du: usize) -> Option<Self> {
        let rest = dx.checked_sub(2 * du)?;
        if rest % 6 != 0 {
            return None;
        }
        Self::new(du, rest / 6).ok()
    }

    /// Active joints n.
    pub fn joints(&self) -> usize {
        self.joints
    }

    /// Tool points p.
    pub fn tool_points(&self) -> usize {
        self.points
    }

    /// State dimension dX = 2n + 6p.
    pub fn dx(&self) -> usize {
        2 * self.joints + 6 * self.points
    }

    /// Action dimension dU = n.
    pub fn du(&self) -> usize {
        self.joints
    }

    /// Joint angles q (rad).
    pub fn q(&self) -> Range<usize> {
        0..self.joints
    }

    /// Joint velocities q̇ (rad/s).
    pub fn qd(&self) -> Range<usize> {
        self.joints..2 * self.joints
    }

    /// All tool points minus their targets, point after point (m, base frame): 3p entries.
    pub fn points(&self) -> Range<usize> {
        let start = 2 * self.joints;
        start..start + 3 * self.points
    }

    /// All tool point velocities, point after point (m/s, base frame): 3p entries.
    pub fn point_velocities(&self) -> Range<usize> {
        let start = 2 * self.joints + 3 * self.points;
        start..start + 3 * self.points
    }

    /// Tool point i minus its target (m). Panics if i ≥ p.
    pub fn point(&self, i: usize) -> Range<usize> {
        assert!(i < self.points, "tool point {i} of {}", self.points);
        let start = self.points().start + 3 * i;
        start..start + 3
    }

    /// Tool point i's velocity (m/s). Panics if i ≥ p.
    pub fn point_velocity(&self, i: usize) -> Range<usize> {
        assert!(i < self.points, "tool point {i} of {}", self.points);
        let start = self.point_velocities().start + 3 * i;
        start..start + 3
    }

    /// The parts in order with their index ranges.
    pub fn parts(&self) -> Vec<(Part, Range<usize>)> {
        let mut parts = vec![
            (Part::JointAngles, self.q()),
            (Part::JointVelocities, self.qd()),
        ];
        parts.extend((0..self.points).map(|i| (Part::PointMinusTarget(i), self.point(i))));
        parts.extend((0..self.points).map(|i| (Part::PointVelocity(i), self.point_velocity(i))));
        parts
    }

    /// Name of state entry `i` for files and logs: `q_elbow`, `qd_wrist_1`, and for one tool
    /// point `ee_minus_goal_x`, `ee_vel_x` (the reaching task's names), for several
    /// `point1_minus_target_y`, `point1_vel_y`. Panics if i ≥ dX.
    pub fn state_name(&self, i: usize) -> String {
        assert!(i < self.dx(), "state entry {i} of {}", self.dx());
        let axis = ["x", "y", "z"];
        for (part, range) in self.parts() {
            if range.contains(&i) {
                let k = i - range.start;
                return match part {
                    Part::JointAngles => format!("q_{}", joint_name(k)),
                    Part::JointVelocities => format!("qd_{}", joint_name(k)),
                    Part::PointMinusTarget(_) if self.points == 1 => {
                        format!("ee_minus_goal_{}", axis[k])
                    }
                    Part::PointVelocity(_) if self.points == 1 => format!("ee_vel_{}", axis[k]),
                    p => format!("{}_{}", p.name(), axis[k]),
                };
            }
        }
        unreachable!("the parts tile the state")
    }

    /// Names of every state entry in layout order.
    pub fn state_names(&self) -> Vec<String> {
        (0..self.dx()).map(|i| self.state_name(i)).collect()
    }

    /// Names of the action entries (the active joints' short names).
    pub fn action_names(&self) -> Vec<String> {
        (0..self.du()).map(|i| joint_name(i).to_string()).collect()
    }

    /// URDF names of the active joints (`shoulder_pan_joint`, …).
    pub fn joint_urdf_names(&self) -> Vec<String> {
        (0..self.du())
            .map(|i| format!("{}_joint", joint_name(i)))
            .collect()
    }

    /// `Ok` if an array of dimensions `dx`, `du` belongs to this layout; otherwise the mismatch,
    /// naming `what` and both sides.
    pub fn check_dims(
        &self,
        what: &'static str,
        dx: usize,
        du: usize,
    ) -> Result<(), DimensionMismatch> {
        if dx == self.dx() && du == self.du() {
            Ok(())
        } else {
            Err(DimensionMismatch {
                what,
                got_dx: dx,
                got_du: du,
                dx: self.dx(),
                du: self.du(),
                layout: *self,
            })
        }
    }

    /// Writes the state s into `s` (length dX) from its parts: the single place a state vector
    /// is assembled.
    ///
    /// - `q`, `qd`: joint angles (rad) and velocities (rad/s) of the active joints, n each;
    /// - `points`, `velocities`: the tool points (m) and their linear velocities (m/s), p each;
    /// - `targets`: each point's target (m); all in the arm base frame.
    ///
    /// Panics if a length differs from the layout's (a programming error: the caller builds
    /// its arrays from the same layout).
    pub fn fill_state(
        &self,
        q: &[f64],
        qd: &[f64],
        points: &[[f64; 3]],
        velocities: &[[f64; 3]],
        targets: &[[f64; 3]],
        s: &mut [f64],
    ) {
        let (n, p) = (self.joints, self.points);
        assert!(
            q.len() == n
                && qd.len() == n
                && points.len() == p
                && velocities.len() == p
                && targets.len() == p
                && s.len() == self.dx(),
            "state parts of the layout's sizes ({self})"
        );
        s[self.q()].copy_from_slice(q);
        s[self.qd()].copy_from_slice(qd);
        for i in 0..p {
            for (k, j) in self.point(i).enumerate() {
                s[j] = points[i][k] - targets[i][k];
            }
            s[self.point_velocity(i)].copy_from_slice(&velocities[i]);
        }
    }
}

/// Short name of joint k (`wrist_1`), or `joint7` past a UR arm's six.
fn joint_name(k: usize) -> String {
    JOINT_NAMES
        .get(k)
        .map(|s| s.to_string())
        .unwrap_or_else(|| format!("joint{}", k + 1))
}

/// Assembles the state vector s of [`StateLayout::REACH3`] from its parts (see
/// [`StateLayout::fill_state`], which it calls).
///
/// - `q`: joint angles (rad), `qd`: joint velocities (rad/s), active joints in layout order;
/// - `ee_pos`: end-effector point (m), `ee_vel`: its linear velocity (m/s), `goal`: goal point
///   (m), all in the arm base frame.
pub fn state_vector(
    q: &[f64; N_JOINTS],
    qd: &[f64; N_JOINTS],
    ee_pos: &[f64; 3],
    ee_vel: &[f64; 3],
    goal: &[f64; 3],
) -> [f64; DX] {
    let mut s = [0.0; DX];
    StateLayout::REACH3.fill_state(q, qd, &[*ee_pos], &[*ee_vel], &[*goal], &mut s);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_tile_the_state() {
        for layout in [
            StateLayout::REACH3,
            StateLayout::POSE6,
            StateLayout::new(6, 1).unwrap(),
            StateLayout::new(3, 3).unwrap(),
            StateLayout::new(MAX_JOINTS, MAX_TOOL_POINTS).unwrap(),
        ] {
            let mut next = 0;
            for (_, r) in layout.parts() {
                assert_eq!(r.start, next, "{layout}");
                next = r.end;
            }
            assert_eq!(next, layout.dx());
            assert!(layout.dx() <= MAX_DX && layout.du() <= MAX_DU);
            assert_eq!(
                StateLayout::from_dims(layout.dx(), layout.du()),
                Some(layout)
            );
            let names = layout.state_names();
            let unique: std::collections::HashSet<_> = names.iter().collect();
            assert_eq!(unique.len(), layout.dx(), "{names:?}");
        }
        assert_eq!(
            StateLayout::new(MAX_JOINTS, MAX_TOOL_POINTS).unwrap().dx(),
            MAX_DX
        );
        assert_eq!((StateLayout::POSE6.dx(), StateLayout::POSE6.du()), (30, 6));
    }

    /// The reaching task's layout is the one the constants describe, names included.
    #[test]
    fn reach3_is_the_constants() {
        let l = StateLayout::REACH3;
        assert_eq!((l.dx(), l.du()), (DX, DU));
        assert_eq!((l.q(), l.qd()), (Q, QD));
        assert_eq!((l.point(0), l.point_velocity(0)), (EE_MINUS_GOAL, EE_VEL));
        assert_eq!(l.state_names(), STATE_NAMES);
        assert_eq!(l.action_names(), ACTION_NAMES);
        assert_eq!(l.joint_urdf_names(), ACTIVE_JOINTS);
    }

    #[test]
    fn pose6_names_and_ranges() {
        let l = StateLayout::POSE6;
        assert_eq!(l.q(), 0..6);
        assert_eq!(l.qd(), 6..12);
        assert_eq!(l.point(2), 18..21);
        assert_eq!(l.point_velocity(0), 21..24);
        assert_eq!(l.state_name(5), "q_wrist_3");
        assert_eq!(l.state_name(15), "point1_minus_target_x");
        assert_eq!(l.state_name(29), "point2_vel_z");
        assert_eq!(l.joint_urdf_names()[3], "wrist_1_joint");
    }

    #[test]
    fn refuses_impossible_layouts_and_names_mismatches() {
        assert_eq!(StateLayout::new(0, 1), Err(LayoutError::Joints(0)));
        assert_eq!(StateLayout::new(8, 1), Err(LayoutError::Joints(8)));
        assert_eq!(StateLayout::new(6, 4), Err(LayoutError::ToolPoints(4)));
        assert_eq!(StateLayout::from_dims(13, 3), None);
        assert_eq!(StateLayout::from_dims(4, 3), None);
        let e = StateLayout::REACH3
            .check_dims("gain table", 30, 6)
            .unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("gain table has dX = 30, dU = 6"), "{msg}");
        assert!(msg.contains("dX = 12, dU = 3"), "{msg}");
        StateLayout::REACH3.check_dims("gain table", 12, 3).unwrap();
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
        let l = StateLayout::POSE6;
        let mut s = [f64::NAN; 30];
        let pts = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
        let tgt = [[1.0; 3], [2.0; 3], [3.0; 3]];
        let vel = [[0.1; 3], [0.2; 3], [0.3; 3]];
        l.fill_state(&[0.5; 6], &[-0.5; 6], &pts, &vel, &tgt, &mut s);
        assert_eq!(&s[12..21], &[0.0, 1.0, 2.0, 2.0, 3.0, 4.0, 4.0, 5.0, 6.0]);
        assert_eq!(&s[27..30], &[0.3; 3]);
        assert!(s.iter().all(|v| v.is_finite()));
    }
}
