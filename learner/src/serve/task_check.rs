//! The checks that the controller and the arm run the learner's task (docs/design.md §3.6,
//! "The task must be the controller's and the arm's").

use imitation::rollout::{run_episode, Arm, Episode, Policy};
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};
use ur5_shared::layout::{MAX_DU, MAX_HORIZON};
use ur5_shared::noise::Noise;
use ur5_shared::services::ServiceNames;
use ur5_shared::{policy_action, PolicyScratch, PolicyTable, StepSample};

use super::learner::{Publication, ServeLearner};
use super::ports::AnyTable;
use super::ServeError;
use super::ServeOptions;
use crate::arm::SimArm;
use crate::error::ensure;

/// Checks what `serve` needs of the configuration.
pub(super) fn validate(
    task: &TaskConfig,
    samples: usize,
    init_var: f64,
    opts: &ServeOptions,
) -> Result<(), ServeError> {
    task.validate()?;
    ensure!(
        task.horizon <= MAX_HORIZON,
        ServeError::Range(format!(
            "task.horizon = {} exceeds the gain table's MAX_HORIZON = {MAX_HORIZON}",
            task.horizon
        ))
    );
    ensure!(
        samples >= 2,
        ServeError::Range(format!(
            "samples = {samples} noisy episodes per iteration: the dynamics fit needs at least 2"
        ))
    );
    ensure!(
        init_var > 0.0 && init_var.is_finite(),
        ServeError::Range("init_var must be finite and > 0 (rad²)".into())
    );
    ensure!(
        opts.wait_report_s.is_finite() && opts.wait_report_s > 0.0,
        ServeError::Range(format!(
            "serve.wait_report_s = {} must be > 0 (s)",
            opts.wait_report_s
        ))
    );
    ensure!(
        opts.task_tolerance.is_finite() && opts.task_tolerance > 0.0,
        ServeError::Range(format!(
            "serve.task_tolerance = {} must be > 0",
            opts.task_tolerance
        ))
    );
    ServiceNames::new(&opts.prefix).learner_samples()?;
    Ok(())
}

/// Σ Δq·q̄̇ / Σ q̄̇² over the steps of `ep` (q̄̇ the mean joint velocity of a step's two ends):
/// about the control period for slow motion, larger for a fast servo; `None` without motion.
pub fn motion_per_step(ep: &Episode) -> Option<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    let (q, qd) = (ep.layout.q(), ep.layout.qd());
    for t in 0..ep.horizon().saturating_sub(1) {
        let (a, b) = (ep.state(t), ep.state(t + 1));
        for j in 0..ep.du() {
            let v = 0.5 * (a[qd.start + j] + b[qd.start + j]);
            num += (b[q.start + j] - a[q.start + j]) * v;
            den += v * v;
        }
    }
    (den > 1e-12 && num.is_finite()).then(|| num / den)
}

/// What an episode of the learner's current publication must match: its goal's task, the
/// gain table its noisy episodes ran and their noise.
pub(super) struct Reference<'a> {
    /// The publication's goal's task.
    pub(super) task: &'a TaskConfig,
    /// The learner's model of the arm.
    pub(super) sim: &'a SimConfig,
    /// The publication.
    pub(super) version: u64,
    pub(super) epoch: u32,
    /// The table its noisy episodes run (`None`: a noise-free policy table, an evaluation).
    pub(super) table: Option<&'a AnyTable>,
    /// The run seed (for messages) and the seed of the publication's noise.
    pub(super) seed: u64,
    pub(super) noise_seed: u64,
    /// Noisy episodes per publication N.
    pub(super) samples: usize,
    /// The learner publishes one table per version (one goal): the start is checked on any
    /// version's episode, the seed and dt on any publication of the version's.
    pub(super) single: bool,
    /// Where the task comes from (for messages).
    pub(super) source: &'static str,
}

impl<'a> Reference<'a> {
    /// The reference of `learner`'s publication `p`; `publications`: how many per version.
    pub(super) fn of<L: ServeLearner>(
        learner: &'a L,
        p: &'a Publication,
        publications: usize,
    ) -> Self {
        let (version, epoch) = p.table.publication();
        Self {
            task: learner.goal_tasks()[p.goal],
            sim: learner.sim_config(),
            version,
            epoch,
            table: (p.noisy > 0).then_some(&p.table),
            seed: learner.seed(),
            noise_seed: p.noise_seed,
            samples: learner.samples(),
            single: publications == 1,
            source: L::TASK_SOURCE,
        }
    }
}

/// A table as the controller runs it: a gain table through the controller law, a policy
/// table through `ur5_shared::policy_action` (an action it cannot compute is NaN, which no
/// recorded action matches).
fn actor(table: &AnyTable) -> Box<dyn Policy + '_> {
    match table {
        AnyTable::Gain(t) => Box::new(&**t),
        AnyTable::Policy(t) => Box::new(PolicyActor {
            table: t,
            scratch: PolicyScratch::default(),
        }),
    }
}

/// A policy table as a [`Policy`].
struct PolicyActor<'a> {
    table: &'a PolicyTable,
    scratch: PolicyScratch,
}

impl Policy for PolicyActor<'_> {
    fn horizon(&self) -> usize {
        usize::MAX
    }

    fn act(&mut self, _t: usize, s: &[f64], eps: &[f64], _: ActionMode, a: &mut [f64]) {
        if policy_action(self.table, s, eps, &mut self.scratch, a).is_err() {
            a.fill(f64::NAN);
        }
    }
}

/// The checks of docs/design.md §3.6 ("The task must be the controller's and the arm's").
#[derive(Default)]
pub(super) struct TaskCheck {
    /// The first state of the first complete episode (any version) was the task's.
    start_checked: bool,
    /// The first complete noisy episode of the learner's version moved as the task's dt does.
    dt_checked: bool,
    /// Length of the last partial episodes and how many in a row had it.
    short: (usize, u32),
    /// The first noisy episode of the learner's version carried the learner's own noise.
    seed_checked: bool,
    /// Versions from which the seed is checked: those the controller starts at episode k = 0.
    pub(super) seed_from_version: u64,
}

impl TaskCheck {
    pub(super) fn sample<L: ServeLearner>(
        &self,
        s: &StepSample,
        learner: &L,
    ) -> Result<(), ServeError> {
        let t_len = learner.task().horizon;
        ensure!((s.t as usize) < t_len, ServeError::TaskMismatch(format!("the controller runs episodes longer than the task's T = {t_len} steps (episode {} \
             has step t = {}): run rt-controller and hil-sim with [task] horizon = {t_len}, as in {}", s.episode, s.t, L::TASK_SOURCE)));
        Ok(())
    }

    pub(super) fn partial<L: ServeLearner>(
        &mut self,
        have: usize,
        learner: &L,
    ) -> Result<(), ServeError> {
        self.short = if self.short.0 == have {
            (have, self.short.1 + 1)
        } else {
            (have, 1)
        };
        ensure!(self.short.1 < 3, ServeError::TaskMismatch(format!("the controller's episodes end after {have} steps (3 in a row), the task has T = {} \
             steps: run rt-controller and hil-sim with [task] horizon = {}, as in {}", learner.task().horizon, learner.task().horizon, L::TASK_SOURCE)));
        Ok(())
    }

    /// The controller draws exploration noise from the learner's seed: the
    /// action it computed at t = 0 of a noisy episode of the learner's table must be the law's
    /// with the noise of one of that version's episodes k = 0…N under the learner's seed
    /// (docs/design.md §3.7). Another seed gives other draws, off by about L_0 (ε − ε′).
    fn check_seed(
        &mut self,
        ep: &Episode,
        table: &AnyTable,
        r: &Reference,
    ) -> Result<(), ServeError> {
        let version = r.version;
        let s0 = ep.state(0);
        let du = ep.du();
        let got = &ep.u_policy[..du];
        let seed = r.seed;
        // k beyond N + 1 only if episodes were lost before this one; allow a few.
        let mut law = actor(table);
        let matches = (0..=4 * (r.samples as u64 + 1)).any(|k| {
            let (mut eps, mut a) = ([0.0; MAX_DU], [0.0; MAX_DU]);
            Noise::new(r.noise_seed, version, k).next_into(&mut eps[..du]);
            law.act(0, s0, &eps[..du], r.sim.mode, &mut a[..du]);
            (0..du).all(|i| (a[i] - got[i]).abs() <= 1e-9 * (1.0 + got[i].abs()))
        });
        ensure!(
            matches,
            ServeError::TaskMismatch(format!(
                "the controller's exploration noise is not that of the learner's seed {seed} (its \
             action at t = 0 of a noisy episode of table v{version} is {got:?}, which no episode \
             of that version under seed {seed} gives): run rt-controller with seed = {seed}, or \
             the learner with the controller's seed"
            ))
        );
        self.seed_checked = true;
        Ok(())
    }

    /// On every complete episode (publication `version`, `epoch`), against the learner's
    /// current publication `r`.
    pub(super) fn episode(
        &mut self,
        ep: &Episode,
        (version, epoch): (u64, u32),
        r: &Reference,
        tolerance: f64,
    ) -> Result<(), ServeError> {
        self.short = (0, 0);
        // With several publications per version only the current one's goal and noise are
        // known: the others' episodes are not checked.
        let current = version == r.version && (r.single || epoch == r.epoch);
        let own = ep.noisy && current;
        let table = r.table.filter(|_| own);
        let check_dt = !self.dt_checked && table.is_some();
        if !self.seed_checked && version >= self.seed_from_version {
            if let Some(table) = table {
                self.check_seed(ep, table, r)?;
            }
        }
        let check_start = !self.start_checked && (r.single || current);
        if !check_start && !check_dt {
            return Ok(());
        }
        let task = r.task;
        let mut sim = SimArm::for_task(r.sim.clone(), task).map_err(ServeError::Model)?;
        if check_start {
            // Joint angles and tool points minus targets (velocities: sensor noise only).
            let layout = task.layout();
            let mut want = vec![0.0; layout.dx()];
            sim.reset(task, &mut want).map_err(ServeError::ModelReset)?;
            let parts = |s: &[f64]| -> Vec<f64> {
                s[layout.q()]
                    .iter()
                    .chain(&s[layout.points()])
                    .copied()
                    .collect()
            };
            let (got, want) = (parts(ep.state(0)), parts(&want));
            let n = layout.joints();
            let diff = (0..got.len().min(want.len()))
                .map(|i| (got[i] - want[i]).abs())
                .fold(0.0, f64::max);
            ensure!(
                diff <= tolerance,
                ServeError::TaskMismatch(format!(
                    "the controller's episodes start at joint angles {:.4?} rad with end effector \
                 minus goal {:.4?} m; the task's start is {:.4?} rad, {:.4?} m (start_q {:?}, \
                 goal {:?}): they differ by {diff:.3e} > serve.task_tolerance = {tolerance}; run \
                 rt-controller and hil-sim with the [task] start_q and goal of {}",
                    &got[..n],
                    &got[n..],
                    &want[..n],
                    &want[n..],
                    task.start_q,
                    task.goal,
                    r.source
                ))
            );
            self.start_checked = true;
        }
        if let (true, Some(table)) = (check_dt, table) {
            let mut noise = Noise::new(r.noise_seed, version, 0);
            let replay = run_episode(&mut sim, task, &mut *actor(table), Some(&mut noise))
                .map_err(ServeError::FirstEpisode)?;
            if let (Some(a), Some(b)) = (motion_per_step(ep), motion_per_step(&replay)) {
                let ratio = a / b;
                ensure!(
                    (0.5..=2.0).contains(&ratio),
                    ServeError::TaskMismatch(format!(
                        "the arm moves {ratio:.2}x as far per step as the task's control period \
                     dt = {} s gives on the learner's model of the arm (allowed 1/2 to 2): the \
                     arm or the controller runs another dt (or, in real time, the arm cannot \
                     keep up with its clock); run both with the [task] dt of {}",
                        task.dt, r.source
                    ))
                );
            }
            self.dt_checked = true;
        }
        Ok(())
    }
}
