//! The double-buffered controller tables (docs/design.md §3.4, §3.11, §5 D19): the loop reads
//! the active half; a new table is copied into the inactive half, validated there and made
//! active by flipping an index, at an episode boundary only. There are two kinds, gain tables
//! ([`GainTable`]) and policy tables ([`PolicyTable`]), each with its own two halves; versions
//! form one sequence, so the newest table of either kind is the active controller and a swap
//! from one kind to the other is the same flip. All four halves are allocated at setup;
//! nothing here allocates.
//!
//! The copy comes before the validation, unlike the order "validate, copy, flip" one might
//! expect: the private copy cannot change while it is checked, whereas the shared-memory sample
//! is written by another process. A rejected table only ever overwrites the inactive half.

use ur5_shared::config::ActionMode;
use ur5_shared::layout::DimensionMismatch;
use ur5_shared::{
    GainBounds, GainTable, GainTableError, PolicyBounds, PolicyTable, PolicyTableError, StateLayout,
};

/// Why a received table was not taken.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum Rejection {
    /// [`GainTable::validate`] failed.
    #[error(transparent)]
    Invalid(#[from] GainTableError),
    /// [`PolicyTable::validate`] failed.
    #[error(transparent)]
    InvalidPolicy(#[from] PolicyTableError),
    /// A valid table of another task's dimensions than the controller's layout.
    #[error("{0}: learner and controller disagree about the task")]
    LayoutMismatch(DimensionMismatch),
    /// A policy table's action mode is not the controller's `action_mode`.
    #[error("policy table version {version} acts in {table:?}, the controller in {expected:?} (action_mode): learner and controller disagree about the task")]
    ModeMismatch {
        /// Table version.
        version: u64,
        /// The table's mode.
        table: ActionMode,
        /// `action_mode`.
        expected: ActionMode,
    },
    /// A policy table trained on another arm model than the controller drives.
    #[error("policy table version {version} was trained on the {table}, the controller drives the {expected} (arm.ur.model): the same joint angles put the other arm's end effector elsewhere; serve a policy of the {expected}")]
    ModelMismatch {
        /// Table version.
        version: u64,
        /// The table's model.
        table: ur5_shared::UrModel,
        /// The controller's (`arm.ur.model`).
        expected: ur5_shared::UrModel,
    },
    /// The table's horizon differs from the controller's episode length.
    #[error("gain table version {version} has horizon T = {horizon}, the controller runs episodes of T = {expected} (task.horizon): learner and controller disagree about the task")]
    HorizonMismatch {
        /// Table version.
        version: u64,
        /// Its horizon.
        horizon: u64,
        /// `task.horizon`.
        expected: u64,
    },
    /// The table's episode plan sets a goal point, but the task's goal is a pose (several tool
    /// points): a point cannot say where they go.
    #[error("table version {version} sets a goal point for its episodes, but the task's goal is a pose ({points} tool points, task.goal_pose): learner and controller disagree about the task")]
    GoalPointForPose {
        /// Table version.
        version: u64,
        /// The layout's tool points.
        points: usize,
    },
    /// The version is not newer than the active table's (versions increase, docs/design.md §3.3).
    #[error("gain table version {version} is not newer than the active version {active}; ignored")]
    StaleVersion {
        /// Received version.
        version: u64,
        /// Active version.
        active: u64,
    },
}

impl Rejection {
    /// A rejection that says the learner and the controller run different tasks (horizon,
    /// action mode): waiting cannot fix it (docs/design.md §3.12). Wrong dimensions are not
    /// counted here: a damaged header shows as them before the checksum is looked at.
    pub fn is_task_mismatch(&self) -> bool {
        matches!(
            self,
            Rejection::HorizonMismatch { .. }
                | Rejection::ModeMismatch { .. }
                | Rejection::ModelMismatch { .. }
                | Rejection::LayoutMismatch(_)
                | Rejection::GoalPointForPose { .. }
        )
    }
}

/// What [`TableBuffer::offer`] did with a table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Offer {
    /// The table is now active.
    Swapped {
        /// Time to copy it into the inactive half (ns).
        copy_ns: u64,
        /// Time to validate the copy (ns).
        validate_ns: u64,
    },
    /// Same version as the active table (e.g. redelivered history): nothing to do.
    Unchanged,
}

/// The active controller: a gain table or a policy table.
#[derive(Clone, Copy, Debug)]
pub enum Active<'a> {
    /// A time-varying linear-Gaussian controller.
    Gains(&'a GainTable),
    /// A Gaussian MLP policy.
    Policy(&'a PolicyTable),
}

impl Active<'_> {
    /// The table's version.
    pub fn version(&self) -> u64 {
        match self {
            Active::Gains(t) => t.version,
            Active::Policy(p) => p.version,
        }
    }

    /// The table's episode plan ([`ur5_shared::EpisodePlan`]: goal, noise stream, noise-free).
    pub fn plan(&self) -> &ur5_shared::EpisodePlan {
        match self {
            Active::Gains(t) => &t.plan,
            Active::Policy(p) => &p.plan,
        }
    }

    /// The table's publication of its version ([`GainTable::epoch`], [`PolicyTable::epoch`]).
    pub fn epoch(&self) -> u32 {
        match self {
            Active::Gains(t) => t.epoch,
            Active::Policy(p) => p.epoch,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Gains,
    Policy,
}

/// Two preallocated tables of each kind and which one is active.
pub struct TableBuffer {
    halves: [Box<GainTable>; 2],
    policies: [Box<PolicyTable>; 2],
    active: Option<(Kind, usize)>,
    bounds: GainBounds,
    policy_bounds: PolicyBounds,
    horizon: usize,
    mode: ActionMode,
    layout: StateLayout,
    /// The arm model policy tables that state one must have (`None`: any).
    model: Option<ur5_shared::UrModel>,
}

impl TableBuffer {
    /// Allocates all halves (setup). `horizon` is the episode length gain tables must have;
    /// `mode` the action mode policy tables must have; `layout` the task whose dimensions
    /// tables of both kinds must have.
    pub fn new(
        bounds: GainBounds,
        policy_bounds: PolicyBounds,
        horizon: usize,
        mode: ActionMode,
        layout: StateLayout,
    ) -> Self {
        Self {
            halves: [GainTable::new_boxed(), GainTable::new_boxed()],
            policies: [PolicyTable::new_boxed(), PolicyTable::new_boxed()],
            active: None,
            bounds,
            policy_bounds,
            horizon,
            mode,
            layout,
            model: None,
        }
    }

    /// Refuses policy tables trained on another arm model than `model` (tables that state
    /// none are taken).
    pub fn for_arm_model(mut self, model: ur5_shared::UrModel) -> Self {
        self.model = Some(model);
        self
    }

    /// The task's layout every table must have (and the arm's joints with it).
    pub fn layout(&self) -> &StateLayout {
        &self.layout
    }

    /// The active controller, if any table was ever accepted.
    #[inline]
    pub fn active(&self) -> Option<Active<'_>> {
        self.active.map(|(kind, i)| match kind {
            Kind::Gains => Active::Gains(&self.halves[i]),
            Kind::Policy => Active::Policy(&self.policies[i]),
        })
    }

    /// Version of the active table.
    pub fn active_version(&self) -> Option<u64> {
        self.active().map(|t| t.version())
    }

    /// `Some(Unchanged)` for the active version in the same or an earlier publication
    /// (`epoch`), `Err` for an older version, `None` to go on (a newer version, or the active
    /// one published again by a resumed learner: docs/design.md §3.3).
    fn check_version(&self, version: u64, epoch: u32) -> Option<Result<Offer, Rejection>> {
        let active = self.active()?;
        let (v, e) = (active.version(), active.epoch());
        if version == v {
            return (epoch <= e).then_some(Ok(Offer::Unchanged));
        }
        (version < v).then_some(Err(Rejection::StaleVersion { version, active: v }))
    }

    /// A plan's goal is a point: only for a task of one tool point.
    fn check_plan(&self, version: u64, plan: &ur5_shared::EpisodePlan) -> Result<(), Rejection> {
        let points = self.layout.tool_points();
        if plan.goal().is_some() && points != 1 {
            return Err(Rejection::GoalPointForPose { version, points });
        }
        Ok(())
    }

    /// The half of `kind` that is not active.
    fn inactive(&self, kind: Kind) -> usize {
        match self.active {
            Some((k, i)) if k == kind => 1 - i,
            _ => 0,
        }
    }

    /// Takes the policy table `incoming` if it is valid, newer than the active table of either
    /// kind and acts in the controller's action mode: copy into the inactive policy half,
    /// validate the copy, flip. Call only at an episode boundary.
    pub fn offer_policy(
        &mut self,
        incoming: &PolicyTable,
        now: impl Fn() -> u64,
    ) -> Result<Offer, Rejection> {
        if let Some(r) = self.check_version(incoming.version, incoming.epoch) {
            return r;
        }
        let inactive = self.inactive(Kind::Policy);
        let t0 = now();
        self.policies[inactive].copy_from(incoming);
        let t1 = now();
        let table = &self.policies[inactive];
        let checked = table.validate(&self.policy_bounds);
        let t2 = now();
        checked?;
        table
            .check_layout(&self.layout)
            .map_err(Rejection::LayoutMismatch)?;
        self.check_plan(table.version, &table.plan)?;
        let mode = table.mode().expect("validated");
        if mode != self.mode {
            return Err(Rejection::ModeMismatch {
                version: table.version,
                table: mode,
                expected: self.mode,
            });
        }
        if let (Some(model), Some(expected)) = (table.arm_model(), self.model) {
            if model != expected {
                return Err(Rejection::ModelMismatch {
                    version: table.version,
                    table: model,
                    expected,
                });
            }
        }
        self.active = Some((Kind::Policy, inactive));
        Ok(Offer::Swapped {
            copy_ns: t1 - t0,
            validate_ns: t2 - t1,
        })
    }

    /// Takes the gain table `incoming` if it is valid and newer than the active table of
    /// either kind (a higher version, or the active version in a later `epoch`): copy into the
    /// inactive half, validate the copy, flip. Call only at an episode boundary. `now` is a
    /// clock for the timings (ns).
    pub fn offer(
        &mut self,
        incoming: &GainTable,
        now: impl Fn() -> u64,
    ) -> Result<Offer, Rejection> {
        if let Some(r) = self.check_version(incoming.version, incoming.epoch) {
            return r;
        }
        let inactive = self.inactive(Kind::Gains);
        let t0 = now();
        self.halves[inactive].copy_from(incoming);
        let t1 = now();
        let table = &self.halves[inactive];
        let checked = table.validate(&self.bounds);
        let t2 = now();
        checked?;
        table
            .check_layout(&self.layout)
            .map_err(Rejection::LayoutMismatch)?;
        self.check_plan(table.version, &table.plan)?;
        if table.horizon() != self.horizon {
            return Err(Rejection::HorizonMismatch {
                version: table.version,
                horizon: table.horizon() as u64,
                expected: self.horizon as u64,
            });
        }
        self.active = Some((Kind::Gains, inactive));
        Ok(Offer::Swapped {
            copy_ns: t1 - t0,
            validate_ns: t2 - t1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::RejectCounts;
    use ur5_shared::MAX_HORIZON;

    fn buffer(horizon: usize) -> TableBuffer {
        TableBuffer::new(
            GainBounds::default(),
            PolicyBounds::default(),
            horizon,
            ActionMode::GoalAngles,
            StateLayout::REACH3,
        )
    }

    fn gains<'a>(b: &'a TableBuffer) -> &'a GainTable {
        match b.active() {
            Some(Active::Gains(t)) => t,
            other => panic!("active: {other:?}"),
        }
    }

    /// A policy table with one hidden layer of 4 whose output bias is `bias`.
    fn policy(version: u64, bias: f64) -> Box<PolicyTable> {
        let hidden = [4];
        let n = ur5_shared::policy::flat_len(12, 3, &hidden);
        let mut theta = vec![0.0; n];
        theta[12..24].fill(1.0);
        theta[n - 4] = bias; // head 2's output bias
        let mut p = PolicyTable::new_boxed();
        p.fill(
            version,
            &StateLayout::REACH3,
            ActionMode::GoalAngles,
            &hidden,
            &theta,
        )
        .unwrap();
        p
    }

    #[test]
    fn swaps_between_kinds_in_one_version_sequence() {
        let clock = || 0;
        let mut b = buffer(100);
        b.offer(&table(1, 100, 0.5), clock).unwrap();
        assert!(matches!(
            b.offer_policy(&policy(2, 0.25), clock),
            Ok(Offer::Swapped { .. })
        ));
        assert!(matches!(b.active(), Some(Active::Policy(p)) if p.version == 2));
        // Same version redelivered; older of either kind is stale.
        assert_eq!(
            b.offer_policy(&policy(2, 0.25), clock),
            Ok(Offer::Unchanged)
        );
        // The same policy version published again by a resumed learner (a later epoch) is
        // taken again, as a gain table's is; an earlier or the same epoch is not.
        let mut again = policy(2, 0.25);
        again.epoch = 3;
        assert!(matches!(
            b.offer_policy(&again, clock),
            Ok(Offer::Swapped { .. })
        ));
        assert_eq!(b.active().map(|a| a.epoch()), Some(3));
        again.epoch = 2;
        assert_eq!(b.offer_policy(&again, clock), Ok(Offer::Unchanged));
        again.epoch = 3;
        assert_eq!(b.offer_policy(&again, clock), Ok(Offer::Unchanged));
        assert!(matches!(
            b.offer(&table(1, 100, 0.5), clock),
            Err(Rejection::StaleVersion {
                version: 1,
                active: 2
            })
        ));
        // A bad policy keeps the active one and counts as invalid_policy.
        let mut counts = RejectCounts::default();
        let mut nan = policy(3, 0.25);
        nan.params[30] = f64::NAN;
        nan.seal();
        let r = b.offer_policy(&nan, clock).unwrap_err();
        counts.add(&r);
        let mut torque = policy(4, 0.25);
        torque.action_mode = 1;
        torque.seal();
        let r = b.offer_policy(&torque, clock).unwrap_err();
        assert!(r.to_string().contains("Torque"), "{r}");
        counts.add(&r);
        assert_eq!((counts.invalid_policy, counts.mode_mismatch), (1, 1));
        assert_eq!(b.active_version(), Some(2));
        // Policy → gains → policy: each flip lands in the other kind's inactive half.
        b.offer(&table(5, 100, 0.75), clock).unwrap();
        assert_eq!(gains(&b).step(0).a_hat, [0.75; 3]);
        b.offer_policy(&policy(6, -0.5), clock).unwrap();
        match b.active() {
            Some(Active::Policy(p)) => {
                assert_eq!(p.version, 6);
                assert_eq!(p.theta()[p.n_params as usize - 4], -0.5);
            }
            other => panic!("{other:?}"),
        }
        b.offer_policy(&policy(7, 0.125), clock).unwrap();
        assert_eq!(b.active_version(), Some(7));
    }

    /// A controller driving a UR5 refuses a policy trained on a UR5e as a task mismatch
    /// (learner and controller stop), takes one of the UR5 and one that states no model; a
    /// model code of no arm is an invalid table.
    #[test]
    fn a_policy_of_another_arm_model_is_refused() {
        use ur5_shared::UrModel;
        let clock = || 0;
        let mut b = buffer(100).for_arm_model(UrModel::Ur5);
        let mut ur5e = policy(1, 0.25);
        ur5e.set_arm_model(UrModel::Ur5e);
        let r = b.offer_policy(&ur5e, clock).unwrap_err();
        assert!(r.is_task_mismatch(), "{r}");
        let text = r.to_string();
        assert!(
            text.contains("trained on the ur5e") && text.contains("drives the ur5"),
            "{text}"
        );
        let mut counts = RejectCounts::default();
        counts.add(&r);
        assert_eq!((counts.model_mismatch, counts.total()), (1, 1));
        assert_eq!(b.active_version(), None);
        let mut ur5 = policy(2, 0.25);
        ur5.set_arm_model(UrModel::Ur5);
        assert!(matches!(
            b.offer_policy(&ur5, clock),
            Ok(Offer::Swapped { .. })
        ));
        assert!(matches!(
            b.offer_policy(&policy(3, 0.25), clock),
            Ok(Offer::Swapped { .. })
        ));
        let mut bad = policy(4, 0.25);
        bad.model = 999;
        bad.seal();
        assert!(matches!(
            b.offer_policy(&bad, clock),
            Err(Rejection::InvalidPolicy(_))
        ));
        assert_eq!(b.active_version(), Some(3));
    }

    fn table(version: u64, horizon: usize, a_hat: f64) -> Box<GainTable> {
        let mut t = GainTable::new_boxed();
        t.set_version(version);
        t.set_horizon(horizon).unwrap();
        for s in 0..horizon {
            let st = t.step_mut(s);
            st.a_hat.copy_from_slice(&[a_hat; 3]);
            st.chol
                .copy_from_slice(&[0.1, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 0.1]);
        }
        t.seal();
        t
    }

    #[test]
    fn swaps_valid_tables_and_keeps_the_old_one_on_rejection() {
        let clock = || 0;
        let mut b = buffer(100);
        assert!(b.active().is_none());
        assert!(matches!(
            b.offer(&table(1, 100, 0.5), clock),
            Ok(Offer::Swapped { .. })
        ));
        assert_eq!(b.active_version(), Some(1));
        assert_eq!(b.offer(&table(1, 100, 0.5), clock), Ok(Offer::Unchanged));
        // The same version published again by a resumed learner (a later epoch) is taken
        // again; an earlier or the same epoch is not.
        let mut again = table(1, 100, 0.5);
        again.epoch = 2;
        assert!(matches!(b.offer(&again, clock), Ok(Offer::Swapped { .. })));
        assert_eq!(b.active().map(|a| a.epoch()), Some(2));
        again.epoch = 1;
        assert_eq!(b.offer(&again, clock), Ok(Offer::Unchanged));
        again.epoch = 2;
        assert_eq!(b.offer(&again, clock), Ok(Offer::Unchanged));

        let mut counts = RejectCounts::default();
        let mut nan = table(2, 100, 0.5);
        nan.step_mut(3).k_vec[1] = f64::NAN;
        nan.seal();
        let mut dims = table(3, 100, 0.5);
        dims.dx = 13;
        dims.seal();
        let mut sum = table(4, 100, 0.5);
        sum.step_mut(0).a_hat[0] = 0.25;
        // A valid table of the whole arm and a pose (dX = 30, dU = 6) is another task's.
        let mut pose = GainTable::new_boxed_for(&StateLayout::POSE6);
        pose.set_version(6);
        pose.set_horizon(100).unwrap();
        for s in 0..100 {
            let mut st = pose.step_mut(s);
            for i in 0..6 {
                st.set_l(i, i, 0.1);
            }
        }
        pose.seal();
        for (bad, field) in [
            (nan, "non_finite"),
            (dims, "dimensions"),
            (sum, "checksum"),
            (table(5, 50, 0.5), "horizon_mismatch"),
            (pose, "layout_mismatch"),
        ] {
            let r = b.offer(&bad, clock).unwrap_err();
            if field == "layout_mismatch" {
                let msg = r.to_string();
                assert!(
                    msg.contains("dX = 30, dU = 6") && msg.contains("dX = 12, dU = 3"),
                    "{msg}"
                );
                assert!(r.is_task_mismatch());
            }
            counts.add(&r);
            assert_eq!(b.active_version(), Some(1), "{field}");
            assert_eq!(gains(&b).step(0).a_hat, [0.5; 3]);
        }
        assert_eq!(
            (
                counts.non_finite,
                counts.dimensions,
                counts.checksum,
                counts.horizon_mismatch,
                counts.layout_mismatch
            ),
            (1, 1, 1, 1, 1)
        );

        assert!(matches!(
            b.offer(&table(7, 100, 0.75), clock),
            Ok(Offer::Swapped { .. })
        ));
        assert_eq!(gains(&b).step(99).a_hat, [0.75; 3]);
        let r = b.offer(&table(6, 100, 0.5), clock).unwrap_err();
        assert!(matches!(
            r,
            Rejection::StaleVersion {
                version: 6,
                active: 7
            }
        ));
        assert_eq!(b.active_version(), Some(7));
        // A full-horizon table passes when the task runs that long.
        let mut long = buffer(MAX_HORIZON);
        long.offer(&table(1, MAX_HORIZON, 0.0), clock).unwrap();
    }
}
