//! IPC payloads (docs/design.md §3.2): fixed-size `#[repr(C)]` `Copy` types that iceoryx2 moves
//! through shared memory. The gain table is in [`crate::gains`].
//!
//! | service ([`crate::services`]) | publisher | payload |
//! |---|---|---|
//! | `arm/state` | arm (hil-sim or real driver) | [`ArmState`] |
//! | `arm/command` | rt-controller | [`ArmCommand`] |
//! | `learner/samples` | rt-controller | [`StepSample`] |
//! | `controller/gains` | learner | [`crate::gains::GainTable`] |
//!
//! Conventions: timestamps are `CLOCK_MONOTONIC` nanoseconds of the host (`stamp_ns`);
//! sequence numbers start at 1 and increase by one per message of that publisher (0 = "none");
//! episodes are numbered by the controller from 0. Flags and enums travel as plain integers so
//! that no bit pattern written by another process can be undefined behaviour here; decode them
//! with the methods ([`ArmCommand::kind`], [`StepSample::is_noisy`]). Joint order and units are
//! those of [`crate::layout`]; Cartesian quantities are in the arm base frame.

use iceoryx2::prelude::ZeroCopySend;

use crate::layout::{
    DimensionMismatch, StateLayout, DX, MAX_DU, MAX_DX, MAX_JOINTS, MAX_TOOL_POINTS,
};

/// One executed step, published by the controller on `learner/samples` for the learner's
/// dynamics fit and discriminator (docs/design.md §3.2; the dynamics use a_sent, §5 D18).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Default, ZeroCopySend)]
#[type_name("ur5_shared::StepSample.v3")]
pub struct StepSample {
    /// Version of the gain table that computed `a`.
    pub table_version: u64,
    /// Episode number.
    pub episode: u64,
    /// Time step within the episode, 0 ≤ t < T.
    pub t: u32,
    /// 1 if `a` included exploration noise L_t ε, 0 for the noise-free evaluation run.
    pub noise: u32,
    /// [`crate::GainTable::epoch`] or [`crate::PolicyTable::epoch`] of the table that computed
    /// `a`: which publication of `table_version` the episode ran (`StepSample.v2`; v1 had no
    /// such field).
    pub table_epoch: u32,
    /// State dimension dX: `s[..dx]` is the state (`StepSample.v3`; v2 had the reaching
    /// task's fixed sizes).
    pub dx: u32,
    /// Action dimension dU: `a[..du]` and `a_sent[..du]` are the actions.
    pub du: u32,
    /// Keeps the layout free of implicit padding; write 0.
    pub reserved: u32,
    /// State s_t the action was computed from, in `s[..dx]` (the task's layout,
    /// [`crate::layout::StateLayout`]); the rest is 0.
    pub s: [f64; MAX_DX],
    /// Action a_t as computed by [`crate::law::controller_action`], before the controller's
    /// safety clamp (rad goal angles, or N·m in torque mode), in `a[..du]`.
    pub a: [f64; MAX_DU],
    /// Action actually sent to the arm, after clamping to joint, velocity and effort limits, in
    /// `a_sent[..du]`.
    pub a_sent: [f64; MAX_DU],
    /// `seq` of the [`ArmState`] s_t came from.
    pub state_seq: u64,
    /// `stamp_ns` of that [`ArmState`] (monotonic ns).
    pub state_stamp_ns: u64,
    /// When the command carrying `a_sent` was published (monotonic ns).
    pub command_stamp_ns: u64,
}

impl StepSample {
    /// The state s_t (`s[..dx]`, clamped to the capacity).
    pub fn state(&self) -> &[f64] {
        &self.s[..(self.dx as usize).min(MAX_DX)]
    }

    /// The action a_t before the clamp (`a[..du]`, clamped to the capacity).
    pub fn action(&self) -> &[f64] {
        &self.a[..(self.du as usize).min(MAX_DU)]
    }

    /// The action sent (`a_sent[..du]`, clamped to the capacity).
    pub fn action_sent(&self) -> &[f64] {
        &self.a_sent[..(self.du as usize).min(MAX_DU)]
    }

    /// Sets `dx` and the state. Panics if `s` exceeds [`MAX_DX`].
    pub fn set_state(&mut self, s: &[f64]) {
        self.dx = s.len() as u32;
        self.s[..s.len()].copy_from_slice(s);
        self.s[s.len()..].fill(0.0);
    }

    /// Sets `du` and both actions (of equal length). Panics if they differ or exceed
    /// [`MAX_DU`].
    pub fn set_actions(&mut self, a: &[f64], a_sent: &[f64]) {
        assert_eq!(a.len(), a_sent.len(), "a and a_sent of one step");
        self.du = a.len() as u32;
        self.a[..a.len()].copy_from_slice(a);
        self.a[a.len()..].fill(0.0);
        self.a_sent[..a.len()].copy_from_slice(a_sent);
        self.a_sent[a.len()..].fill(0.0);
    }

    /// `self` with the state and both actions set ([`StepSample::set_state`],
    /// [`StepSample::set_actions`]).
    pub fn with_parts(mut self, s: &[f64], a: &[f64], a_sent: &[f64]) -> Self {
        self.set_state(s);
        self.set_actions(a, a_sent);
        self
    }

    /// Whether `a` included exploration noise.
    pub fn is_noisy(&self) -> bool {
        self.noise != 0
    }
}

/// Status bits of an [`ArmState`] (`status` field). Unknown bits are ignored.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, ZeroCopySend)]
pub struct ArmStatus(pub u32);

impl ArmStatus {
    /// The arm is up and executing commands.
    pub const READY: ArmStatus = ArmStatus(1 << 0);
    /// The arm is holding its pose (a Hold command, a stale command, or a fault).
    pub const HOLDING: ArmStatus = ArmStatus(1 << 1);
    /// A reset to a start pose is in progress; states are not part of an episode.
    pub const RESETTING: ArmStatus = ArmStatus(1 << 2);
    /// The last command was clamped (joint, velocity or effort limit).
    pub const SATURATED: ArmStatus = ArmStatus(1 << 3);

    /// All bits of `other` are set.
    pub fn contains(self, other: ArmStatus) -> bool {
        self.0 & other.0 == other.0
    }
    /// Sets the bits of `other`.
    pub fn insert(&mut self, other: ArmStatus) {
        self.0 |= other.0;
    }
    /// Clears the bits of `other`.
    pub fn remove(&mut self, other: ArmStatus) {
        self.0 &= !other.0;
    }
}

/// Fault bits of an [`ArmState`] (`faults` field); 0 = no fault. Unknown bits count as faults.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, ZeroCopySend)]
pub struct ArmFaults(pub u32);

impl ArmFaults {
    /// No command arrived within the arm's timeout; the arm holds.
    pub const STALE_COMMAND: ArmFaults = ArmFaults(1 << 0);
    /// A command had a non-finite value; it was ignored and the arm holds.
    pub const NON_FINITE_COMMAND: ArmFaults = ArmFaults(1 << 1);
    /// A command had an unknown `kind`; it was ignored and the arm holds.
    pub const UNKNOWN_COMMAND: ArmFaults = ArmFaults(1 << 2);
    /// A joint is at or past its limit.
    pub const JOINT_LIMIT: ArmFaults = ArmFaults(1 << 3);
    /// The simulator's state became non-finite or diverged (hil-sim only).
    pub const PHYSICS: ArmFaults = ArmFaults(1 << 4);
    /// The real arm's driver reported an error or protective stop.
    pub const DRIVER: ArmFaults = ArmFaults(1 << 5);
    /// A command for another number of joints than the arm's active ones; it was ignored and
    /// the arm holds.
    pub const WRONG_JOINTS: ArmFaults = ArmFaults(1 << 6);

    /// Any fault bit is set.
    pub fn any(self) -> bool {
        self.0 != 0
    }
    /// All bits of `other` are set.
    pub fn contains(self, other: ArmFaults) -> bool {
        self.0 & other.0 == other.0
    }
    /// Sets the bits of `other`.
    pub fn insert(&mut self, other: ArmFaults) {
        self.0 |= other.0;
    }
}

/// The arm's measured state, published by the arm on `arm/state` once per control period (or
/// per physics step in lockstep, as the arm chooses).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Default, ZeroCopySend)]
#[type_name("ur5_shared::ArmState.v3")]
pub struct ArmState {
    /// Message sequence number of this publisher (from 1).
    pub seq: u64,
    /// Time of the measurement (monotonic ns; sim time mapped onto it in lockstep).
    pub stamp_ns: u64,
    /// Episode of the last command applied (copied from [`ArmCommand::episode`]).
    pub episode: u64,
    /// `seq` of the last [`ArmCommand`] applied (0 = none yet).
    pub last_command_seq: u64,
    /// Joint angles q (rad) of the active joints in `q[..joints]`, base to wrist; the rest 0.
    pub q: [f64; MAX_JOINTS],
    /// Joint velocities q̇ (rad/s) in `qd[..joints]`.
    pub qd: [f64; MAX_JOINTS],
    /// Positions (m, arm base frame) of the task's tool points in `points[..tool_points]`
    /// (`TaskConfig::tool_offsets`, in the end-effector link frame from the end-effector
    /// point; one point, the end-effector point, for a point goal); the rest 0
    /// (`ArmState.v3`; v2 had the end-effector point only).
    pub points: [[f64; 3]; MAX_TOOL_POINTS],
    /// Linear velocities (m/s, arm base frame) of the tool points in `point_vels[..tool_points]`.
    pub point_vels: [[f64; 3]; MAX_TOOL_POINTS],
    /// Status bits.
    pub status: ArmStatus,
    /// Fault bits.
    pub faults: ArmFaults,
    /// Active joints n, 1..=[`MAX_JOINTS`] (`ArmState.v2`; v1 had the reaching task's 3 in
    /// arrays of 3).
    pub joints: u32,
    /// Tool points p in `points`, 1..=[`MAX_TOOL_POINTS`] (`ArmState.v3`).
    pub tool_points: u32,
}

impl ArmState {
    /// A state of the joints `q` (rad) and `qd` (rad/s), n each, the end-effector point
    /// `ee_pos` (m) and its velocity `ee_vel` (m/s); the rest default. Panics if n exceeds
    /// [`MAX_JOINTS`] or the lengths differ.
    pub fn of_joints(q: &[f64], qd: &[f64], ee_pos: [f64; 3], ee_vel: [f64; 3]) -> Self {
        let mut s = Self::default();
        s.set_joints(q, qd);
        s.set_points(&[ee_pos], &[ee_vel]);
        s
    }

    /// Sets `tool_points` and the tool points' positions (m) and velocities (m/s) (the rest of
    /// the arrays 0). Panics if there are more than [`MAX_TOOL_POINTS`] or the lengths differ.
    pub fn set_points(&mut self, points: &[[f64; 3]], velocities: &[[f64; 3]]) {
        assert_eq!(points.len(), velocities.len(), "a velocity per point");
        let p = points.len();
        self.tool_points = p as u32;
        self.points = [[0.0; 3]; MAX_TOOL_POINTS];
        self.point_vels = [[0.0; 3]; MAX_TOOL_POINTS];
        self.points[..p].copy_from_slice(points);
        self.point_vels[..p].copy_from_slice(velocities);
    }

    /// The tool points' positions `points[..tool_points]` (clamped to the capacity).
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points[..(self.tool_points as usize).min(MAX_TOOL_POINTS)]
    }

    /// The tool points' velocities `point_vels[..tool_points]` (clamped to the capacity).
    pub fn point_vels(&self) -> &[[f64; 3]] {
        &self.point_vels[..(self.tool_points as usize).min(MAX_TOOL_POINTS)]
    }

    /// Whether every value the arm reports (joints, tool points) is finite.
    pub fn is_finite(&self) -> bool {
        self.q
            .iter()
            .chain(&self.qd)
            .chain(self.points.as_flattened())
            .chain(self.point_vels.as_flattened())
            .all(|v| v.is_finite())
    }

    /// Sets `joints` and the joint angles and velocities (the rest of the arrays 0). Panics if
    /// n exceeds [`MAX_JOINTS`] or the lengths differ.
    pub fn set_joints(&mut self, q: &[f64], qd: &[f64]) {
        assert_eq!(q.len(), qd.len(), "q and q̇ of the same joints");
        let n = q.len();
        self.joints = n as u32;
        self.q = [0.0; MAX_JOINTS];
        self.qd = [0.0; MAX_JOINTS];
        self.q[..n].copy_from_slice(q);
        self.qd[..n].copy_from_slice(qd);
    }

    /// The active joints' angles `q[..joints]` (clamped to the capacity).
    pub fn q(&self) -> &[f64] {
        &self.q[..(self.joints as usize).min(MAX_JOINTS)]
    }

    /// The active joints' velocities `qd[..joints]` (clamped to the capacity).
    pub fn qd(&self) -> &[f64] {
        &self.qd[..(self.joints as usize).min(MAX_JOINTS)]
    }

    /// `Ok` if the arm's active joints are `layout`'s; otherwise the mismatch, naming both (an
    /// arm reports joints, not a state: its dimensions are those of the layout with its
    /// joints).
    pub fn check_layout(&self, layout: &StateLayout) -> Result<(), DimensionMismatch> {
        let (n, p) = (self.joints as usize, self.tool_points as usize);
        layout.check_dims("the arm's state", 2 * n + 6 * p, n)
    }

    /// The state vector s of `layout` into `s` (dX of it), with the tool points' targets
    /// `targets` (m, base frame, one per tool point), through [`StateLayout::fill_state`]. Call
    /// it for an arm whose [`ArmState::check_layout`] passed (else it panics).
    pub fn fill_state(&self, layout: &StateLayout, targets: &[[f64; 3]], s: &mut [f64]) {
        layout.fill_state(
            self.q(),
            self.qd(),
            self.points(),
            self.point_vels(),
            targets,
            s,
        );
    }

    /// The state vector s of the reaching task ([`StateLayout::REACH3`]) for `goal` (m, arm
    /// base frame), through [`StateLayout::fill_state`]. Reads the first three joints: call it
    /// for an arm whose [`ArmState::check_layout`] passed.
    pub fn state_vector(&self, goal: &[f64; 3]) -> [f64; DX] {
        let (q, qd) = (&self.q, &self.qd);
        crate::layout::state_vector(
            &[q[0], q[1], q[2]],
            &[qd[0], qd[1], qd[2]],
            &self.points[0],
            &self.point_vels[0],
            goal,
        )
    }
}

/// What an [`ArmCommand`] asks for. Travels as `u32` in [`ArmCommand::kind`].
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandKind {
    /// Hold the current pose; `values` ignored. 0 so that a zeroed command is safe.
    Hold = 0,
    /// `values` are goal joint angles (rad) for the arm's servo (the paper's set-up).
    GoalAngles = 1,
    /// `values` are joint torques (N·m) (research option, docs/design.md §2.3).
    Torques = 2,
    /// Move (real arm) or teleport (sim) to `reset_pose` at rest; `values` ignored.
    Reset = 3,
}

/// An [`ArmCommand::kind`] value that is not a [`CommandKind`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown arm command kind {0}; known: 0 hold, 1 goal angles, 2 torques, 3 reset")]
pub struct UnknownCommandKind(pub u32);

impl TryFrom<u32> for CommandKind {
    type Error = UnknownCommandKind;
    fn try_from(v: u32) -> Result<Self, Self::Error> {
        match v {
            0 => Ok(CommandKind::Hold),
            1 => Ok(CommandKind::GoalAngles),
            2 => Ok(CommandKind::Torques),
            3 => Ok(CommandKind::Reset),
            other => Err(UnknownCommandKind(other)),
        }
    }
}

/// A command to the arm on `arm/command`, one per control period.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Default, ZeroCopySend)]
#[type_name("ur5_shared::ArmCommand.v2")]
pub struct ArmCommand {
    /// Message sequence number of this publisher (from 1).
    pub seq: u64,
    /// When the command was sent (monotonic ns).
    pub stamp_ns: u64,
    /// Episode this command belongs to; the arm echoes it in [`ArmState::episode`].
    pub episode: u64,
    /// A [`CommandKind`] as u32; decode with [`ArmCommand::kind`].
    pub kind: u32,
    /// Keeps the layout free of implicit padding; write 0.
    pub reserved: u32,
    /// Goal joint angles (rad) or joint torques (N·m) of the active joints in
    /// `values[..joints]`, base to wrist; the rest 0.
    pub values: [f64; MAX_DU],
    /// For [`CommandKind::Reset`]: start pose q (rad) in `reset_pose[..joints]`, reached at
    /// rest (q̇ = 0). Otherwise 0.
    pub reset_pose: [f64; MAX_JOINTS],
    /// Joints n the command is for, 1..=[`MAX_JOINTS`]; an arm with other active joints
    /// ignores it and holds ([`ArmFaults::WRONG_JOINTS`]). 0 in a hold (any arm holds).
    /// (`ArmCommand.v2`; v1 had the reaching task's 3 in arrays of 3.)
    pub joints: u32,
    /// Keeps the layout free of implicit padding; write 0.
    pub reserved2: u32,
}

impl ArmCommand {
    fn new(seq: u64, stamp_ns: u64, episode: u64, kind: CommandKind) -> Self {
        Self {
            seq,
            stamp_ns,
            episode,
            kind: kind as u32,
            ..Self::default()
        }
    }

    /// Hold the current pose.
    pub fn hold(seq: u64, stamp_ns: u64, episode: u64) -> Self {
        Self::new(seq, stamp_ns, episode, CommandKind::Hold)
    }

    /// Servo towards goal joint angles `q_goal` (rad, one per active joint). Panics past
    /// [`MAX_JOINTS`].
    pub fn goal_angles(seq: u64, stamp_ns: u64, episode: u64, q_goal: impl AsRef<[f64]>) -> Self {
        Self::new(seq, stamp_ns, episode, CommandKind::GoalAngles).with_values(q_goal.as_ref())
    }

    /// Apply joint torques `tau` (N·m, one per active joint). Panics past [`MAX_JOINTS`].
    pub fn torques(seq: u64, stamp_ns: u64, episode: u64, tau: impl AsRef<[f64]>) -> Self {
        Self::new(seq, stamp_ns, episode, CommandKind::Torques).with_values(tau.as_ref())
    }

    /// Reset to the start pose `q0` (rad, one per active joint) at rest. Panics past
    /// [`MAX_JOINTS`].
    pub fn reset(seq: u64, stamp_ns: u64, episode: u64, q0: impl AsRef<[f64]>) -> Self {
        let q0 = q0.as_ref();
        let mut c = Self::new(seq, stamp_ns, episode, CommandKind::Reset);
        c.joints = q0.len() as u32;
        c.reset_pose[..q0.len()].copy_from_slice(q0);
        c
    }

    fn with_values(mut self, v: &[f64]) -> Self {
        self.joints = v.len() as u32;
        self.values[..v.len()].copy_from_slice(v);
        self
    }

    /// The command's values `values[..joints]` (clamped to the capacity).
    pub fn values(&self) -> &[f64] {
        &self.values[..(self.joints as usize).min(MAX_DU)]
    }

    /// The reset pose `reset_pose[..joints]` (clamped to the capacity).
    pub fn reset_pose(&self) -> &[f64] {
        &self.reset_pose[..(self.joints as usize).min(MAX_JOINTS)]
    }

    /// The decoded kind; an unknown value is an error (the arm then holds).
    pub fn kind(&self) -> Result<CommandKind, UnknownCommandKind> {
        CommandKind::try_from(self.kind)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::{EE_MINUS_GOAL, EE_VEL, Q, QD};

    #[test]
    fn command_constructors_and_kind_round_trip() {
        let c = ArmCommand::goal_angles(3, 100, 2, [0.1, -0.2, 0.3]);
        assert_eq!(c.kind(), Ok(CommandKind::GoalAngles));
        assert_eq!((c.seq, c.stamp_ns, c.episode), (3, 100, 2));
        assert_eq!(c.values(), [0.1, -0.2, 0.3]);
        assert_eq!(c.joints, 3);
        let six = ArmCommand::goal_angles(3, 100, 2, [0.5; 6]);
        assert_eq!((six.joints, six.values()), (6, &[0.5; 6][..]));
        assert_eq!(six.values[6], 0.0);
        assert_eq!(
            ArmCommand::torques(1, 0, 0, [1.0; 3]).kind(),
            Ok(CommandKind::Torques)
        );
        let r = ArmCommand::reset(4, 0, 5, [0.0, -1.5, 2.0]);
        assert_eq!(r.kind(), Ok(CommandKind::Reset));
        assert_eq!(r.reset_pose(), [0.0, -1.5, 2.0]);
        assert_eq!(r.values(), [0.0; 3]);
        assert_eq!(ArmCommand::hold(1, 0, 0).kind(), Ok(CommandKind::Hold));
        // A zeroed command decodes as Hold.
        assert_eq!(ArmCommand::default().kind(), Ok(CommandKind::Hold));
        for k in [
            CommandKind::Hold,
            CommandKind::GoalAngles,
            CommandKind::Torques,
            CommandKind::Reset,
        ] {
            assert_eq!(CommandKind::try_from(k as u32), Ok(k));
        }
        let bad = ArmCommand {
            kind: 9,
            ..ArmCommand::default()
        };
        let err = bad.kind().unwrap_err();
        assert_eq!(err, UnknownCommandKind(9));
        assert!(err.to_string().contains("unknown arm command kind 9"));
    }

    #[test]
    fn arm_state_assembles_the_layout() {
        let st = ArmState {
            ..ArmState::of_joints(
                &[1.0, 2.0, 3.0],
                &[4.0, 5.0, 6.0],
                [0.5, 0.25, 1.0],
                [10.0, 11.0, 12.0],
            )
        };
        st.check_layout(&StateLayout::REACH3).unwrap();
        let e = st
            .check_layout(&StateLayout::new(6, 1).unwrap())
            .unwrap_err();
        assert!(e.to_string().contains("dX = 12, dU = 3"), "{e}");
        assert!(e.to_string().contains("dX = 18, dU = 6"), "{e}");
        let six = ArmState::of_joints(&[0.1; 6], &[0.2; 6], [0.0; 3], [0.0; 3]);
        assert_eq!((six.q(), six.qd()), (&[0.1; 6][..], &[0.2; 6][..]));
        assert!(six.check_layout(&StateLayout::REACH3).is_err());
        six.check_layout(&StateLayout::new(6, 1).unwrap()).unwrap();
        let goal = [0.25, 0.25, 0.5];
        let s = st.state_vector(&goal);
        assert_eq!(s[Q], [1.0, 2.0, 3.0]);
        assert_eq!(s[QD], [4.0, 5.0, 6.0]);
        assert_eq!(s[EE_MINUS_GOAL], [0.25, 0.0, 0.5]);
        assert_eq!(s[EE_VEL], [10.0, 11.0, 12.0]);
        let mut full = st;
        full.fill_state(&StateLayout::REACH3, &[goal], &mut [0.0; DX]);
        // Six joints and three tool points: the pose layout, and its state from the targets.
        let mut pose = ArmState::of_joints(&[0.1; 6], &[0.2; 6], [0.0; 3], [0.0; 3]);
        assert!(pose.check_layout(&StateLayout::POSE6).is_err());
        pose.set_points(
            &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]],
            &[[0.5; 3], [0.25; 3], [0.125; 3]],
        );
        pose.check_layout(&StateLayout::POSE6).unwrap();
        let e = pose
            .check_layout(&StateLayout::new(6, 1).unwrap())
            .unwrap_err();
        assert!(e.to_string().contains("dX = 30, dU = 6"), "{e}");
        let mut s6 = [0.0; 30];
        pose.fill_state(
            &StateLayout::POSE6,
            &[[1.0; 3], [2.0; 3], [3.0; 3]],
            &mut s6,
        );
        let l = StateLayout::POSE6;
        assert_eq!(s6[l.point(2)], [4.0, 5.0, 6.0]);
        assert_eq!(s6[l.point_velocity(1)], [0.25; 3]);
        assert_eq!(s6[l.qd()], [0.2; 6]);
        full.points[0][1] = f64::NAN;
        assert!(!full.is_finite() && st.is_finite());
    }

    #[test]
    fn flags() {
        let mut s = ArmStatus::default();
        s.insert(ArmStatus::READY);
        s.insert(ArmStatus::HOLDING);
        assert!(s.contains(ArmStatus::READY) && s.contains(ArmStatus::HOLDING));
        s.remove(ArmStatus::HOLDING);
        assert!(!s.contains(ArmStatus::HOLDING));
        let mut f = ArmFaults::default();
        assert!(!f.any());
        f.insert(ArmFaults::STALE_COMMAND);
        assert!(f.any() && f.contains(ArmFaults::STALE_COMMAND));
        assert!(!f.contains(ArmFaults::PHYSICS));
        let sample = StepSample {
            noise: 1,
            ..StepSample::default()
        };
        assert!(sample.is_noisy() && !StepSample::default().is_noisy());
        let mut sample = StepSample::default();
        sample.set_state(&[1.0; 30]);
        sample.set_actions(&[2.0; 6], &[3.0; 6]);
        assert_eq!((sample.dx, sample.du), (30, 6));
        assert_eq!(sample.state(), &[1.0; 30]);
        assert_eq!(
            (sample.action(), sample.action_sent()),
            (&[2.0; 6][..], &[3.0; 6][..])
        );
        sample.set_state(&[4.0; 12]);
        assert_eq!(sample.state(), &[4.0; 12]);
        assert!(sample.s[12..].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn payloads_have_no_implicit_padding() {
        assert_eq!(
            core::mem::size_of::<StepSample>(),
            8 * 2 + 4 * 6 + 8 * (MAX_DX + 2 * MAX_DU) + 8 * 3
        );
        assert_eq!(
            core::mem::size_of::<ArmState>(),
            8 * 4 + 8 * (2 * MAX_JOINTS + 6 * MAX_TOOL_POINTS) + 4 * 4
        );
        assert_eq!(
            core::mem::size_of::<ArmCommand>(),
            8 * 3 + 4 * 2 + 8 * (MAX_DU + MAX_JOINTS) + 4 * 2
        );
    }
}
