//! Behavioural cloning from observation, BCO(α) (Torabi, Warnell, Stone 2018): an inverse
//! dynamics model learned from the arm's own episodes labels the demonstrations' transitions
//! (s, s') with actions, and the policy is cloned on those labels (docs/design.md §7).
//!
//! One iteration ([`Bco::learn_goals`]), in the order of Algorithm 1's steps that it has:
//!
//! ```text
//! 1. execute   N noisy episodes of the current policy and one noise-free (Learn::execute)
//! 2. model     add their transitions (s_t, s_{t+1}, executed offset Δ_t) to the inverse
//!              model's data and refit it on all of them (module inverse)
//! 3. label     Δ*_{d,t} = M(s_t, s_{t+1}) for every demonstrated transition
//! 4. clone     regress the policy's mean offset onto Δ* at the demonstrated states (the
//!              S-step's regression of MDGPS with unit weights, mlp_policy::opt)
//! ```
//!
//! BCO(α): the first `pre_iterations` iterations run the initial policy (it holds the start
//! pose, with exploration noise), whose `pre_iterations · N` episodes are the paper's
//! pre-demonstration interactions I^pre; steps 2–4 run from the last of them on, and every
//! later iteration adds N episodes of the current policy, α = 1 / `pre_iterations`
//! (α |I^pre| = N).
//!
//! The policy is the project's state-feedback MLP ([`GlobalPolicy`]: normalised state, one
//! tanh head per joint, offset from the current joint angles, σ fixed at `explore_std`), not a
//! time-varying one: BC regresses actions on states, and a state-feedback policy is what turns
//! five demonstrations of one motion into a controller that also acts off them (after noise, a
//! servo lag or a perturbed arm); a time-varying linear policy would need dX + 1 parameters per
//! joint and step from five labelled samples per step. The controller runs it as a policy
//! table ([`GlobalPolicy::to_table`]).
//!
//! Every random draw is seeded from the run seed: the exploration noise (per version and
//! episode, as every learner's), the policy's and the model's initial weights and their
//! minibatch orders; nothing runs in parallel inside an iteration, so a seed gives the same run
//! bit for bit.

pub mod inverse;
mod resume;

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::{PolicyTable, StateLayout};

use crate::demos::Demos;
use crate::discriminator::Normalizer;
use crate::iteration_log::GaifoLog;
use crate::learn::Learn;
use crate::mlp_policy::action_base;
use crate::mlp_policy::global::GlobalPolicy;
use crate::mlp_policy::opt::{PolicyOpt, PolicyOptConfig, Targets};
use crate::rollout::{execute, Arms, Episode};
use crate::settings::MAX_COUNT;
use crate::ImitationError;
use inverse::{FitReport, InverseModel, InverseModelConfig};
pub use resume::ITERATION;

/// Run-seed tags of BCO's own random streams (ASCII).
const SEED_POLICY: u64 = 0x4243_4f50; // "BCOP": the policy's initial weights
const SEED_CLONE: u64 = 0x4243_4f43; // "BCOC": the cloning's minibatch order
const SEED_MODEL: u64 = 0x4243_4f4d; // "BCOM": the inverse model's weights and minibatches

/// Settings of a BCO(α) run (TOML: `learner train --algo bco --config FILE`). The task comes
/// from the demonstrations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BcoConfig {
    /// The simulated arm of in-process runs.
    pub sim: SimConfig,
    /// Noisy episodes per iteration N (LQR+GAIfO's 5).
    pub samples: usize,
    /// Iterations in all, the pre-demonstration ones included.
    pub iterations: usize,
    /// Iterations of the initial policy before the first cloning: |I^pre| = pre_iterations · N
    /// episodes, α = 1 / pre_iterations. Ours: 1 (α = 1: as many new episodes per iteration as
    /// before the first cloning, the project's budget of 5 a iteration).
    pub pre_iterations: usize,
    /// σ of the exploration noise on every joint's action (rad in goal-angle mode), the initial
    /// policy's and the cloned one's: LQR+GAIfO's initial √0.05.
    pub explore_std: f64,
    /// Seed of every random draw of the run.
    pub seed: u64,
    /// The inverse dynamics model (`[model]`).
    pub model: InverseModelConfig,
    /// The cloned policy and its regression (`[policy]`: MDGPS's global policy and S-step
    /// settings; `min_std` bounds `explore_std` from below).
    pub policy: PolicyOptConfig,
}

impl Default for BcoConfig {
    fn default() -> Self {
        Self {
            sim: SimConfig::default(),
            samples: 5,
            iterations: 20,
            pre_iterations: 1,
            explore_std: 0.05f64.sqrt(),
            seed: 0,
            model: InverseModelConfig::default(),
            policy: PolicyOptConfig {
                steps: 500,
                ..PolicyOptConfig::default()
            },
        }
    }
}

impl BcoConfig {
    /// Refuses settings that cannot work, naming the setting and its range.
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_counts(
            &[
                ("samples", self.samples, 1),
                ("iterations", self.iterations, 1),
                ("pre_iterations", self.pre_iterations, 1),
            ],
            MAX_COUNT,
        )
        .and_then(|()| {
            crate::error::check_reals(&[(
                "explore_std",
                self.explore_std,
                self.explore_std > 0.0 && self.explore_std <= 10.0,
                "in (0, 10] (rad in goal-angle mode)",
            )])
        })
        .map_err(ImitationError::Config)?;
        self.sim
            .validate()
            .map_err(|e| ImitationError::Config(e.to_string()))?;
        self.model.validate()?;
        self.policy.validate()
    }
}

/// What the model and cloning steps of one iteration did (NaN before the first cloning).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BcoStats {
    /// The inverse model's fit.
    pub model: FitReport,
    /// Demonstrated transitions labelled.
    pub labelled: usize,
    /// Root mean square of the labels ‖Δ*‖ (action units).
    pub label_rms: f64,
    /// The cloning loss ½ mean ‖μ(s) − Δ*‖² / σ² before and after.
    pub clone_before: f64,
    pub clone_after: f64,
}

impl Default for BcoStats {
    fn default() -> Self {
        Self {
            model: FitReport {
                transitions: 0,
                rmse_linear: f64::NAN,
                rmse: f64::NAN,
            },
            labelled: 0,
            label_rms: f64::NAN,
            clone_before: f64::NAN,
            clone_after: f64::NAN,
        }
    }
}

/// The state of a BCO(α) run; [`Bco::learn_goals`] runs one iteration (module docs).
pub struct Bco {
    cfg: BcoConfig,
    task: TaskConfig,
    demos: Demos,
    layout: StateLayout,
    model: InverseModel,
    policy: GlobalPolicy,
    opt: PolicyOpt,
    iteration: usize,
    /// What the last iteration's steps 2–4 did.
    pub last: BcoStats,
}

impl Bco {
    /// Sets up a run imitating `demos` (the task is theirs). The dimensions come from the
    /// demonstrations (their states' dX and the task's joints), checked against the task's
    /// layout; the policy and the inverse model take them.
    pub fn new(cfg: BcoConfig, demos: Demos) -> Result<Self, ImitationError> {
        cfg.validate()?;
        let task = demos.task()?;
        let rows = demos.count * demos.horizon;
        if rows == 0 || demos.horizon < 2 || demos.states.len() % rows != 0 {
            return Err(ImitationError::Episodes(format!(
                "BCO needs demonstrations of T >= 2 steps; got {} demonstrations of T = {} with \
                 {} state values",
                demos.count,
                demos.horizon,
                demos.states.len()
            )));
        }
        let dx = demos.states.len() / rows;
        let du = task.start_q.len();
        let layout = StateLayout::from_dims(dx, du).ok_or_else(|| {
            ImitationError::Episodes(format!(
                "demonstrations with dX = {dx} for {du} joints match no task layout"
            ))
        })?;
        task.layout()
            .check_dims("the demonstrations' states", layout.dx(), layout.du())
            .map_err(|e| ImitationError::Episodes(e.to_string()))?;
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ SEED_POLICY);
        let mut policy = GlobalPolicy::new(layout, &cfg.policy.hidden, cfg.explore_std, &mut rng);
        let x = faer::Mat::from_fn(rows, dx, |r, c| demos.states[r * dx + c]);
        policy.set_normalizer(Normalizer::from_data(x.as_ref())?);
        let opt = PolicyOpt::new(cfg.policy.clone(), &policy, cfg.seed ^ SEED_CLONE);
        let model = InverseModel::new(cfg.model.clone(), dx, du, cfg.seed ^ SEED_MODEL)?;
        Ok(Self {
            iteration: 0,
            last: BcoStats::default(),
            cfg,
            task,
            demos,
            layout,
            model,
            policy,
            opt,
        })
    }

    /// The settings.
    pub fn config(&self) -> &BcoConfig {
        &self.cfg
    }

    /// The policy executed next.
    pub fn policy(&self) -> &GlobalPolicy {
        &self.policy
    }

    /// The inverse dynamics model.
    pub fn model(&self) -> &InverseModel {
        &self.model
    }

    /// The task's state layout (from the demonstrations).
    pub fn layout(&self) -> &StateLayout {
        &self.layout
    }

    /// α of BCO(α): new episodes per iteration over pre-demonstration episodes.
    pub fn alpha(&self) -> f64 {
        1.0 / self.cfg.pre_iterations as f64
    }

    /// The policy as a policy table of version [`Learn::version`] acting in the arm's mode
    /// (what a served run publishes).
    pub fn table(&self) -> Result<Box<PolicyTable>, ImitationError> {
        self.policy
            .to_table(self.version(), self.cfg.sim.mode)
            .map_err(|e| ImitationError::Table(e.to_string()))
    }

    /// Step 2: the transitions of `episodes` into the model's data.
    fn add_transitions(&mut self, episodes: &[Episode]) -> Result<(), ImitationError> {
        let mode = self.cfg.sim.mode;
        let (dx, du) = (self.layout.dx(), self.layout.du());
        for (k, ep) in episodes.iter().enumerate() {
            let t_len = ep.horizon();
            if ep.layout != self.layout || ep.x.len() != t_len * dx || ep.u.len() != t_len * du {
                return Err(ImitationError::Episodes(format!(
                    "episode {k}: {} state and {} action values for T = {t_len} ({}): not states \
                     of dX = {dx} and actions of dU = {du} ({})",
                    ep.x.len(),
                    ep.u.len(),
                    ep.layout,
                    self.layout
                )));
            }
            for t in 0..t_len.saturating_sub(1) {
                let s = ep.state(t);
                let mut delta = action_base(mode, du, s);
                for (j, d) in delta.iter_mut().enumerate() {
                    *d = ep.u[t * du + j] - *d;
                }
                self.model.push(s, ep.state(t + 1), &delta);
            }
        }
        Ok(())
    }

    /// Step 3: the labelled demonstrations, with the cloning's weights P = I / σ².
    fn label(&mut self) -> Result<Targets, ImitationError> {
        let d = &self.demos;
        let prc = 1.0 / (self.cfg.explore_std * self.cfg.explore_std);
        let (dx, du) = (self.layout.dx(), self.layout.du());
        let mut p = vec![0.0; du * du];
        for j in 0..du {
            p[j * du + j] = prc;
        }
        let mut out = Targets::new(dx, du);
        for i in 0..d.count {
            for t in 0..d.horizon - 1 {
                let (s, s_next) = (d.state(i, t), d.state(i, t + 1));
                let label = self.model.predict(s, s_next)?;
                out.push(s, &label, &p);
            }
        }
        Ok(out)
    }

    /// Steps 2–4 on the noisy episodes of the current policy.
    fn improve(&mut self, episodes: &[Episode]) -> Result<[f64; 3], ImitationError> {
        let t0 = Instant::now();
        self.add_transitions(episodes)?;
        if self.iteration + 1 < self.cfg.pre_iterations {
            return Ok([t0.elapsed().as_secs_f64(), 0.0, 0.0]);
        }
        self.last.model = self.model.fit()?;
        let t1 = Instant::now();
        let targets = self.label()?;
        self.last.labelled = targets.len();
        self.last.label_rms = (targets
            .offsets
            .chunks_exact(targets.du)
            .map(|o| o.iter().map(|v| v * v).sum::<f64>())
            .sum::<f64>()
            / targets.len() as f64)
            .sqrt();
        let t2 = Instant::now();
        let report = self.opt.update(&mut self.policy, &targets)?;
        self.last.clone_before = report.loss_before;
        self.last.clone_after = report.loss_after;
        Ok([
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            t2.elapsed().as_secs_f64(),
        ])
    }

    /// The progress line of an iteration.
    pub fn progress_line(&self, log: &GaifoLog) -> String {
        format!(
            "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>7} {:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e} {:>7.1}",
            log.iteration,
            log.task_cost,
            log.performance,
            log.final_distance,
            self.last.model.transitions,
            self.last.model.rmse_linear,
            self.last.model.rmse,
            self.last.clone_before,
            self.last.clone_after,
            1e3 * log.cpu_learner
        )
    }

    /// Header of [`Bco::progress_line`].
    pub const PROGRESS_HEADER: &'static str = "iter task_cost    perf  final_m   trans  M_rmse_lin    M_rmse  bc_before  bc_after  cpu_ms";
}

impl Learn for Bco {
    type Log = GaifoLog;
    const ALGO: &'static str = "bco";

    crate::learn::run_accessors!();

    /// Step 1: the policy with noise N times, and its mean once.
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        let (noisy, eval) = execute(
            arms,
            &self.task,
            &self.policy,
            self.version(),
            self.cfg.seed,
            self.cfg.samples,
        )?;
        Ok((noisy, vec![eval]))
    }

    /// Steps 2–4 of the module docs. The log is LQR+GAIfO's row: the critic's columns and
    /// the step's (`kl`, `eta`, `step_mult`) NaN, `t_dynamics` the model's fit, `t_cost` the
    /// labelling, `t_lqr` the cloning.
    fn learn_goals(
        &mut self,
        noisy: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        let eval = crate::learn::single_eval(evals)?;
        if noisy.len() != self.cfg.samples {
            return Err(ImitationError::Episodes(format!(
                "BCO learns from samples = {} noisy episodes per iteration, got {}",
                self.cfg.samples,
                noisy.len()
            )));
        }
        let c0 = crate::cpu::thread_cpu_s();
        let [t_model, t_label, t_clone] = self.improve(noisy)?;
        let cpu_learner = crate::cpu::thread_cpu_s() - c0;
        let none = crate::discriminator::TrainStats {
            critic_loss: f64::NAN,
            gradient_penalty: f64::NAN,
            wasserstein: f64::NAN,
        };
        let log = GaifoLog {
            t_execute,
            t_dynamics: t_model,
            t_cost: t_label,
            t_lqr: t_clone,
            cpu_learner,
            ..GaifoLog::evaluated(self.iteration, eval, &self.demos, &none)
        };
        self.iteration += 1;
        Ok(log)
    }

    fn eval_cost(log: &GaifoLog) -> f64 {
        log.task_cost
    }
}

#[cfg(test)]
mod tests;
