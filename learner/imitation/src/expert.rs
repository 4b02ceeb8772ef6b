//! The expert (docs/design.md §1.4): the one LQR iteration ([`LqrIteration`]) with learned
//! dynamics on the true task cost, run in process (lockstep, no IPC) or served, then executed to
//! record demonstrations. Its iteration is Algorithm 1 without the critic: 1 execute, 2 fit the
//! dynamics, 4–5 expand the task cost ([`TaskCostConfig`] as a [`crate::cost::Cost`]), 6 the
//! KL-bounded LQR step with GPS's step adaptation.

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::noise::Noise;

use crate::controller::{init_hold, to_gain_table};
use crate::cost::task::TaskCostConfig;
use crate::demos::Demos;
use crate::iteration::LqrIteration;
use crate::learn::{Learn, LinGaussLearn};
use crate::rollout::{run_episode, run_episodes, Arms, Episode, SampleList};
use crate::ImitationError;
use gps::algorithm::update::Learner;
use gps::algorithm::AlgorithmConfig;
use gps::dynamics::lr_prior::LrPriorConfig;
use gps::dynamics::prior_gmm::PriorGmmConfig;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::traj_opt::lqr::TrajOptConfig;

/// Run-seed offsets of the independent random streams (ASCII tags).
const SEED_RANDOM: u64 = 0x5241_4e44; // "RAND": random-policy baseline episodes
const SEED_GMM: u64 = 0x474d_4d00; // "GMM": cluster initialisation
const SEED_DEMOS: u64 = 0x4445_4d4f; // "DEMO": demonstration episodes

/// Everything that defines an expert run (TOML: `learner expert --config FILE`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExpertConfig {
    /// The task (goal, start pose, T, dt).
    pub task: TaskConfig,
    /// The simulated arm.
    pub sim: SimConfig,
    /// The task cost's weights.
    pub cost: TaskCostConfig,
    /// Noisy episodes per iteration N. Paper §5: 5.
    pub samples: usize,
    /// Largest number of iterations of a three-joint task. The expert is expected to converge
    /// within 15 (75 noisy episodes); a task of dU joints gets up to iterations × dU / 3
    /// ([`Self::iterations_for`]; docs/design.md §5 D41), `patience` ending a converged run
    /// earlier.
    pub iterations: usize,
    /// Stop after this many iterations without a better noise-free episode.
    pub patience: usize,
    /// Initial controller: hold the start pose with exploration variance `init_var` (rad²) on
    /// every goal angle. Ours: 0.05 rad² (σ ≈ 0.22 rad, about the 0.31 rad a goal may move per
    /// control period).
    pub init_var: f64,
    /// Episodes of the initial controller used to measure the random-policy cost.
    pub random_episodes: usize,
    /// Demonstrations recorded from the final controller. Paper §5: 5.
    pub demos: usize,
    /// Whether demonstrations are executed with the controller's exploration noise (true) or
    /// noise-free (false: all demonstrations would be identical on a noise-free arm).
    pub demo_noise: bool,
    /// Half side of the generalisation square around the goal (m), for `--square`. Ours: 0.1 m.
    pub square_half_side: f64,
    /// Seed of every random draw of the run.
    pub seed: u64,
    /// GPS algorithm settings (KL step, step multiplier bounds, …).
    pub algorithm: AlgorithmConfig,
    /// GPS dynamics-prior settings.
    pub prior: PriorGmmConfig,
    /// GPS dynamics-fit settings.
    pub fit: LrPriorConfig,
    /// GPS trajectory-optimisation settings.
    pub traj_opt: TrajOptConfig,
}

impl ExpertConfig {
    /// The largest number of iterations of a task of `du` joints: [`Self::iterations`] × dU / 3,
    /// rounded up (docs/design.md §5 D41). The expert's KL bound per step is the same for six
    /// joints as for three (GPS's own step adaptation, §5 D40), shared by twice the action
    /// dimensions, so six joints need more iterations to settle: measured, the five pose
    /// goals' experts at 15 iterations ended 24 of 25 runs within 1 mm, one 6.5 mm away and
    /// still converging. Three joints: [`Self::iterations`], the same runs.
    pub fn iterations_for(&self, du: usize) -> usize {
        (self.iterations * du).div_ceil(3)
    }

    /// Refuses settings that cannot work, naming the setting and its range
    /// (docs/reliability.md): counts in their ranges up to
    /// [`crate::settings::MAX_COUNT`] (samples ≥ 2 for the dynamics fit), `init_var` in (0, 10] rad², the cost weights finite and ≥ 0 with
    /// α > 0, the square's half side in (0, 1] m, then the task, the arm and GPS's settings.
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_counts(
            &[
                ("samples", self.samples, 2),
                ("iterations", self.iterations, 1),
                ("patience", self.patience, 1),
                ("random_episodes", self.random_episodes, 1),
                ("demos", self.demos, 1),
            ],
            crate::settings::MAX_COUNT,
        )
        .map_err(ImitationError::Config)?;
        let c = &self.cost;
        crate::error::check_reals(&[
            (
                "init_var",
                self.init_var,
                self.init_var > 0.0 && self.init_var <= 10.0,
                "in (0, 10] rad²",
            ),
            (
                "square_half_side",
                self.square_half_side,
                self.square_half_side > 0.0 && self.square_half_side <= 1.0,
                "in (0, 1] m",
            ),
            (
                "cost.l1",
                c.l1,
                c.l1 >= 0.0 && c.l1.is_finite(),
                "finite and >= 0",
            ),
            (
                "cost.l2",
                c.l2,
                c.l2 >= 0.0 && c.l2.is_finite(),
                "finite and >= 0",
            ),
            (
                "cost.alpha",
                c.alpha,
                c.alpha > 0.0 && c.alpha.is_finite(),
                "finite and > 0 m²",
            ),
            (
                "cost.final_weight",
                c.final_weight,
                c.final_weight >= 0.0 && c.final_weight.is_finite(),
                "finite and >= 0",
            ),
            (
                "cost.action_weight",
                c.action_weight,
                c.action_weight >= 0.0 && c.action_weight.is_finite(),
                "finite and >= 0",
            ),
        ])
        .map_err(ImitationError::Config)?;
        self.task.validate().map_err(ImitationError::Task)?;
        crate::error::check_arm_and_gps(
            &self.sim,
            &self.algorithm,
            &self.prior,
            &self.fit,
            &self.traj_opt,
        )
    }
}

impl Default for ExpertConfig {
    fn default() -> Self {
        Self {
            task: TaskConfig::default(),
            sim: SimConfig::default(),
            cost: TaskCostConfig::default(),
            samples: 5,
            iterations: 15,
            patience: 4,
            init_var: 0.05,
            random_episodes: 10,
            demos: 5,
            demo_noise: true,
            square_half_side: 0.1,
            seed: 0,
            algorithm: AlgorithmConfig::default(),
            prior: PriorGmmConfig::default(),
            fit: LrPriorConfig::default(),
            traj_opt: TrajOptConfig::default(),
        }
    }
}

/// What one iteration measured (also the progress line; its serde form is the CSV row of
/// `expert_log.csv`, `learner::io::log`).
#[derive(Clone, Debug, Serialize)]
pub struct IterationLog {
    /// Iteration number (0-based).
    pub iteration: usize,
    /// Task cost C(τ) of the noise-free evaluation episode.
    pub eval_cost: f64,
    /// Mean task cost of the N noisy episodes.
    pub mean_sample_cost: f64,
    /// Final end-effector distance of the evaluation episode (m).
    #[serde(rename = "final_distance_m")]
    pub final_distance: f64,
    /// (C_random − C_eval) / C_random: the share of the random policy's cost removed (the
    /// normalised performance needs C_expert, which is not known yet).
    pub performance_proxy: f64,
    /// KL(new ‖ old) of the step taken (total over T).
    pub kl: f64,
    /// Dual variable η after the search.
    pub eta: f64,
    /// Step multiplier used for this step.
    pub step_mult: f64,
    /// Wall time of the iteration (s): episodes, dynamics fit, LQR.
    pub seconds: f64,
}

impl IterationLog {
    /// Column names of [`IterationLog::progress_line`].
    pub const PROGRESS_HEADER: &'static str =
        "iter  eval_cost  mean_cost   final_m   proxy        kl       eta   mult    sec";

    /// The progress line of this iteration (the columns of `learner expert`).
    pub fn progress_line(&self) -> String {
        format!(
            "{:>4} {:>10.4} {:>10.4} {:>9.4} {:>7.3} {:>9.3} {:>9.2e} {:>6.2} {:>6.2}",
            self.iteration,
            self.eval_cost,
            self.mean_sample_cost,
            self.final_distance,
            self.performance_proxy,
            self.kl,
            self.eta,
            self.step_mult,
            self.seconds
        )
    }
}

/// The outcome of training.
pub struct ExpertRun {
    /// Best controller found (lowest noise-free task cost), GPS absolute form.
    pub policy: LinGaussPolicy,
    /// Its noise-free evaluation episode.
    pub eval: Episode,
    /// Per-iteration log.
    pub log: Vec<IterationLog>,
    /// Mean task cost of the initial (random) controller.
    pub cost_random: f64,
}

/// Mean task cost of `count` episodes of `pol` with exploration noise; episode k draws its
/// noise from `Noise::new(seed, 0, k)`; the episodes run in parallel, each on its own arm
/// from `arms` ([`run_episodes`]).
pub fn mean_noisy_cost(
    arms: &dyn Arms,
    task: &TaskConfig,
    pol: &LinGaussPolicy,
    count: usize,
    seed: u64,
) -> Result<f64, ImitationError> {
    let table = to_gain_table(pol, 0);
    let episodes = run_episodes(
        arms,
        count,
        |k| (seed, 0, k as u64),
        |k, arm| {
            let mut noise = Noise::new(seed, 0, k as u64);
            run_episode(arm, task, &mut &*table, Some(&mut noise))
        },
    )?;
    let total: f64 = episodes.iter().map(Episode::task_cost).sum();
    Ok(total / count.max(1) as f64)
}

/// The expert's learner as a state machine: one [`ExpertLearner::update`] is one iteration of
/// Algorithm 1 on the true task cost, given the episodes step 1 executed (in process by
/// [`train`], over IPC by `learner serve`). It owns the GPS learner state, the controller to
/// execute next, the previous one (for the step adjustment) and the best one seen.
pub struct ExpertLearner {
    cfg: ExpertConfig,
    lqr: LqrIteration,
    cost_random: Option<f64>,
    best: Option<(LinGaussPolicy, Episode)>,
    since_best: usize,
}

impl ExpertLearner {
    /// A learner that starts from the initial controller ([`init_hold`]). `cost_random` is the
    /// random policy's mean task cost for the progress proxy; `None` takes the mean cost of the
    /// first iteration's noisy episodes (those of the initial controller).
    pub fn new(cfg: ExpertConfig, cost_random: Option<f64>) -> Self {
        let pol = init_hold(&cfg.task, cfg.init_var);
        Self::resume(cfg, pol, 0, cost_random)
    }

    /// A learner that continues from controller `pol` at `iteration` (its table version is
    /// `iteration + 1`). The GPS learner state (dynamics prior, step size, previous controller)
    /// starts afresh, as on a first iteration: it is not part of a checkpoint.
    pub fn resume(
        cfg: ExpertConfig,
        pol: LinGaussPolicy,
        iteration: usize,
        cost_random: Option<f64>,
    ) -> Self {
        let (t_len, n) = (cfg.task.horizon, cfg.samples);
        // Independent streams: random baseline, GMM initialisation; the exploration noise of
        // the k-th episode of table version v is `Noise::new(cfg.seed, v, k)`, as in the RT loop.
        let rng_gmm = ChaCha8Rng::seed_from_u64(cfg.seed ^ SEED_GMM);
        let learner = Learner::new(
            cfg.algorithm.clone(),
            cfg.prior.clone(),
            cfg.fit.clone(),
            cfg.traj_opt.clone(),
            t_len,
            cfg.task.layout().dx(),
            cfg.task.layout().du(),
            n,
            rng_gmm,
        );
        Self {
            lqr: LqrIteration::new(learner, pol, iteration),
            cost_random,
            best: None,
            since_best: 0,
            cfg,
        }
    }

    /// Restores the best controller executed before a resume, its noise-free episode and the
    /// iterations since (`patience` counts on from there), as a checkpoint recorded them.
    pub fn with_best(mut self, best: Option<(LinGaussPolicy, Episode)>, since_best: usize) -> Self {
        self.best = best;
        self.since_best = since_best;
        self
    }

    /// Iterations in a row without a better noise-free episode than the best one.
    pub fn since_best(&self) -> usize {
        self.since_best
    }

    /// The configuration.
    pub fn config(&self) -> &ExpertConfig {
        &self.cfg
    }

    /// The controller to execute next.
    pub fn policy(&self) -> &LinGaussPolicy {
        self.lqr.policy()
    }

    /// Its gain-table version: iteration + 1 (the initial controller is version 1).
    pub fn version(&self) -> u64 {
        self.iteration() as u64 + 1
    }

    /// Iterations done (counting those before a resume).
    pub fn iteration(&self) -> usize {
        self.lqr.iteration()
    }

    /// The random policy's cost used by the progress proxy, once known.
    pub fn cost_random(&self) -> Option<f64> {
        self.cost_random
    }

    /// [`ExpertConfig::iterations_for`] the task done, or `cfg.patience` iterations in a row
    /// without a better noise-free episode.
    pub fn done(&self) -> bool {
        self.iteration() >= self.cfg.iterations_for(self.cfg.task.layout().du())
            || (self.best.is_some() && self.since_best >= self.cfg.patience)
    }

    /// Best controller executed so far (lowest noise-free task cost) and its evaluation episode.
    pub fn best(&self) -> Option<(&LinGaussPolicy, &Episode)> {
        self.best.as_ref().map(|(p, e)| (p, e))
    }

    /// Steps 2, 4–6 of Algorithm 1 on the `noisy` episodes (`cfg.samples` of them) and the
    /// noise-free `eval` episode of [`ExpertLearner::policy`]: fit the dynamics, expand the
    /// task cost, take the KL-bounded LQR step (docs/design.md §1.4: the expert has no step 3).
    /// Returns the iteration's log (`seconds`: this update only) and the new controller, which
    /// [`ExpertLearner::policy`] returns from now on.
    pub fn update(
        &mut self,
        noisy: &[Episode],
        eval: &Episode,
    ) -> Result<(IterationLog, &LinGaussPolicy), ImitationError> {
        let t0 = Instant::now();
        let (t_len, n) = (self.cfg.task.horizon, self.cfg.samples);
        if noisy.len() != n || noisy.iter().chain([eval]).any(|e| e.horizon() != t_len) {
            return Err(ImitationError::Episodes(format!(
                "an expert iteration needs {n} noisy episodes and one noise-free episode of \
                 T = {t_len} steps; got {} noisy, horizons {:?}",
                noisy.len(),
                noisy
                    .iter()
                    .chain([eval])
                    .map(Episode::horizon)
                    .collect::<Vec<_>>()
            )));
        }
        let iteration = self.iteration();
        let eval_cost_value = eval.task_cost();
        // The best controller is the one these episodes executed: record it before the step.
        if self
            .best
            .as_ref()
            .is_none_or(|(_, e)| eval_cost_value < e.task_cost())
        {
            self.best = Some((self.lqr.policy().clone(), eval.clone()));
            self.since_best = 0;
        } else {
            self.since_best += 1;
        }
        let samples = SampleList::new(noisy);
        // 2. Fit the dynamics.
        self.lqr.fit_dynamics(&samples)?;
        // 4–5. The task cost and its second-order expansion around every sample.
        self.lqr.expand(&mut self.cfg.cost, noisy);
        // 6. KL-bounded LQR step (GPS step adaptation on).
        let step = self.lqr.improve(&samples, true)?;

        let mean_sample_cost = noisy.iter().map(Episode::task_cost).sum::<f64>() / n as f64;
        let cost_random = *self.cost_random.get_or_insert(mean_sample_cost);
        let entry = IterationLog {
            iteration,
            eval_cost: eval_cost_value,
            mean_sample_cost,
            final_distance: eval.final_distance(),
            performance_proxy: (cost_random - eval_cost_value) / cost_random,
            kl: step.kl,
            eta: step.eta,
            step_mult: step.step_mult,
            seconds: t0.elapsed().as_secs_f64(),
        };
        Ok((entry, self.lqr.policy()))
    }
}

/// The mean task cost of the random (initial) controller of `cfg` on its task over
/// `cfg.random_episodes` noisy episodes on arms from `arms`: the C_random of normalised performance
/// (docs/design.md §1.6).
pub fn random_policy_cost(cfg: &ExpertConfig, arms: &dyn Arms) -> Result<f64, ImitationError> {
    let task = &cfg.task;
    mean_noisy_cost(
        arms,
        task,
        &init_hold(task, cfg.init_var),
        cfg.random_episodes,
        cfg.seed ^ SEED_RANDOM,
    )
}

/// Trains the expert in process on arms from `arms` (lockstep, no IPC): the random policy's cost, then
/// [`crate::learn::iterate`] until [`ExpertLearner::done`]. `progress` receives each
/// iteration's log (`seconds`: episodes and update) as soon as it is done.
pub fn train(
    cfg: &ExpertConfig,
    arms: &dyn Arms,
    mut progress: impl FnMut(&IterationLog),
) -> Result<ExpertRun, ImitationError> {
    cfg.validate()?;
    let cost_random = random_policy_cost(cfg, arms)?;
    let mut el = ExpertLearner::new(cfg.clone(), Some(cost_random));
    let mut log = Vec::new();
    while !el.done() {
        let (entry, _) = crate::learn::iterate(&mut el, arms)?;
        progress(&entry);
        log.push(entry);
    }
    let (policy, eval) = el.best.expect("at least one iteration");
    Ok(ExpertRun {
        policy,
        eval,
        log,
        cost_random,
    })
}

/// Records `cfg.demos` demonstrations of `policy` (with its exploration noise when
/// `cfg.demo_noise`), seeded from `cfg.seed`, in parallel on arms from `arms`.
pub fn record_demos(
    cfg: &ExpertConfig,
    arms: &dyn Arms,
    policy: &LinGaussPolicy,
    cost_random: f64,
) -> Result<Demos, ImitationError> {
    let task = &cfg.task;
    let table = to_gain_table(policy, 0);
    let layout = task.layout();
    let mut states = Vec::with_capacity(cfg.demos * task.horizon * layout.dx());
    let mut actions = Vec::with_capacity(cfg.demos * task.horizon * layout.du());
    let mut total = 0.0;
    let seed = cfg.seed ^ SEED_DEMOS;
    let episodes = run_episodes(
        arms,
        cfg.demos,
        |k| (seed, 0, k as u64),
        |k, arm| {
            let mut noise = Noise::new(seed, 0, k as u64);
            let noise = cfg.demo_noise.then_some(&mut noise);
            run_episode(arm, task, &mut &*table, noise)
        },
    )?;
    for ep in &episodes {
        total += ep.task_cost();
        states.extend_from_slice(&ep.x);
        actions.extend_from_slice(&ep.u);
    }
    Ok(Demos {
        states,
        actions,
        model: cfg.sim.model,
        count: cfg.demos,
        horizon: task.horizon,
        goal: task.goal,
        goal_pose: task.goal_pose,
        tool_points: task.tool_points,
        start_q: task.start_q,
        dt: task.dt,
        seed: cfg.seed,
        cost_random,
        cost_expert: total / cfg.demos.max(1) as f64,
    })
}

/// The generalisation set (docs/design.md §2.6): the 8 corners and mid-edges of a square of half
/// side `half_side` (m) around `centre`, in the horizontal plane, counter-clockwise from the
/// corner (−x, −y).
pub fn square_goals(centre: [f64; 3], half_side: f64) -> [[f64; 3]; 8] {
    let h = half_side;
    let offsets = [
        (-h, -h),
        (0.0, -h),
        (h, -h),
        (h, 0.0),
        (h, h),
        (0.0, h),
        (-h, h),
        (-h, 0.0),
    ];
    offsets.map(|(dx, dy)| [centre[0] + dx, centre[1] + dy, centre[2]])
}

impl Learn for ExpertLearner {
    type Log = IterationLog;
    const ALGO: &'static str = "expert";

    fn task(&self) -> &TaskConfig {
        &self.cfg.task
    }
    fn sim_config(&self) -> &SimConfig {
        &self.cfg.sim
    }
    fn samples(&self) -> usize {
        self.cfg.samples
    }
    fn seed(&self) -> u64 {
        self.cfg.seed
    }
    fn iteration(&self) -> usize {
        ExpertLearner::iteration(self)
    }
    fn done(&self) -> bool {
        ExpertLearner::done(self)
    }
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        crate::learn::execute_table(self, arms)
    }
    /// [`ExpertLearner::update`]; `seconds` counts `t_execute` too.
    fn learn_goals(
        &mut self,
        noisy: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<IterationLog, ImitationError> {
        let (mut entry, _) = self.update(noisy, crate::learn::single_eval(evals)?)?;
        entry.seconds += t_execute;
        Ok(entry)
    }
    fn eval_cost(log: &IterationLog) -> f64 {
        log.eval_cost
    }
}

impl LinGaussLearn for ExpertLearner {
    fn policy(&self) -> &LinGaussPolicy {
        self.lqr.policy()
    }
}

#[cfg(test)]
mod validate_tests {
    use super::*;

    #[test]
    fn settings_that_cannot_work_are_refused_naming_the_setting() {
        assert!(ExpertConfig::default().validate().is_ok());
        let cases: Vec<(&str, Box<dyn Fn(&mut ExpertConfig)>)> = vec![
            ("samples", Box::new(|c| c.samples = 1)),
            ("iterations", Box::new(|c| c.iterations = 1_000_000_000_000)),
            ("patience", Box::new(|c| c.patience = 0)),
            ("random_episodes", Box::new(|c| c.random_episodes = 0)),
            ("demos", Box::new(|c| c.demos = 1_000_000_000)),
            ("init_var", Box::new(|c| c.init_var = f64::NAN)),
            ("square_half_side", Box::new(|c| c.square_half_side = 1e9)),
            ("cost.alpha", Box::new(|c| c.cost.alpha = 0.0)),
            ("cost.l2", Box::new(|c| c.cost.l2 = -1.0)),
            ("kl_step", Box::new(|c| c.algorithm.kl_step = -1.0)),
            ("max_clusters", Box::new(|c| c.prior.max_clusters = 0)),
        ];
        crate::error::assert_each_refused_naming(cases, ExpertConfig::validate);
    }
}
