//! MDGPS with the critic's cost (docs/design.md §6): one global policy for many goals, learned
//! from state-only demonstrations (Montgomery & Levine 2016, *Guided Policy Search via
//! Approximate Mirror Descent*; GPS `AlgorithmMDGPS`). Conditions are the demonstrated goals;
//! each has its own linear-Gaussian controller, dynamics fit and LQR state
//! ([`LqrIteration`]); one critic D(s, s') serves all of them. One iteration
//! ([`Mdgps::learn`]), in order:
//!
//! ```text
//! 1.   execute    N noisy episodes of every condition's controller, and the global policy
//!                 once without noise per condition (the evaluation): Mdgps::execute
//! 2.   dynamics   each condition's fit (GMM prior + Bayesian regression)
//! 3.   critic     one WGAN-GP update, the demonstrations of every goal against the
//!                 controllers' transitions of every condition
//! 4–5. cost       each condition's composite cost and its expansion
//!                 (iteration 0 only: the S-step onto the initial controllers, so that the
//!                 policy has caught up with them before the first C-step, as GPS does)
//! 6a.  linearise  the global policy at each condition's mean sample states
//! 6b.  C-step     each condition's KL-bounded LQR with the bound and KL term towards that
//!                 linearisation (LqrIteration::improve_towards)
//! 7.   S-step     regress the policy onto the new controllers' action means at the sampled
//!                 states, weighted by their precision (mlp_policy::opt)
//! ```
//!
//! Every random draw is seeded from the run seed (noise per condition, GMM per condition,
//! critic, policy initialisation, minibatch order); nothing runs in parallel inside a run, so a
//! seed gives the same run bit for bit.

mod resume;

use std::time::Instant;

use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};
use ur5_shared::noise::Noise;
use ur5_shared::{EpisodePlan, GainTable, PolicyTable, StateLayout};

use crate::controller::{init_hold, to_gain_table};
use crate::cost::composite::{CompositeCost, CompositeWorkspace};
use crate::critic::{episode_transitions, expert_transitions, Critic};
use crate::demos::Demos;
use crate::discriminator::{Normalizer, TrainStats};
use crate::iteration::LqrIteration;
use crate::learn::Learn;
use crate::mlp_policy::global::{GlobalActor, GlobalPolicy};
use crate::mlp_policy::opt::{PolicyOpt, PolicyOptConfig, SStepReport, Targets};
use crate::rollout::{run_episode, run_episodes, Arms, Episode, SampleList};
use crate::settings::GaifoConfig;
use crate::ImitationError;
use gps::algorithm::update::Learner;
use gps::policy::lin_gauss::LinGaussPolicy;

/// Run-seed tags of MDGPS's own random streams (ASCII).
const SEED_GMM: u64 = 0x474d_4d00; // "GMM", as LQR+GAIfO's, mixed with the condition
const SEED_POLICY: u64 = 0x504f_4c49; // "POLI": the policy's initial weights
const SEED_SSTEP: u64 = 0x5353_5450; // "SSTP": the S-step's minibatch order

/// Settings of an MDGPS run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MdgpsConfig {
    /// Per-condition settings, LQR+GAIfO's own (docs/design.md §1.3): N noisy episodes per
    /// condition, initial controller, critic, GPS dynamics and LQR, seed and iterations. Its
    /// `algorithm.kl_step` is replaced by [`MdgpsConfig::kl_step`]; step adaptation is not used.
    pub lqr_gaifo: GaifoConfig,
    /// The C-step's KL bound towards the policy's linearisation, nats per time step (ε_KL =
    /// kl_step · T). Ours: 1.0, measured against 0.2 (LQR+GAIfO's) and 0.5 (docs/design.md §6.3).
    pub kl_step: f64,
    /// The global policy and its S-step.
    pub policy: PolicyOptConfig,
}

impl Default for MdgpsConfig {
    fn default() -> Self {
        Self {
            lqr_gaifo: GaifoConfig::default(),
            kl_step: 1.0,
            policy: PolicyOptConfig::default(),
        }
    }
}

impl MdgpsConfig {
    /// Checks every setting (LQR+GAIfO's, the KL step and the policy's). The path's terms
    /// (`[lqr_gaifo.path]`, docs/design.md §5 D39) are refused: MDGPS's conditions are reaches
    /// to several goals, and its composite cost has no per-step tracking term or phase input;
    /// so is `lqr_gaifo.critic_terminal_pairs` (§5 D44), which its critic does not take.
    pub fn validate(&self) -> Result<(), ImitationError> {
        self.lqr_gaifo.validate()?;
        if !self.lqr_gaifo.path.is_off() {
            return Err(ImitationError::Config(format!(
                "lqr_gaifo.path ({:?}): MDGPS imitates reaches to several goals and does not \
                 take the path's tracking term or phase input; remove [lqr_gaifo.path], or \
                 imitate the motion with --algo lqr-gaifo (docs/design.md §5 D39)",
                self.lqr_gaifo.path
            )));
        }
        if self.lqr_gaifo.critic_terminal_pairs != 0 {
            return Err(ImitationError::Config(format!(
                "lqr_gaifo.critic_terminal_pairs = {}: MDGPS's critic is not trained on the \
                 final states' resting pairs; remove it, or use --algo lqr-gaifo \
                 (docs/design.md §5 D44)",
                self.lqr_gaifo.critic_terminal_pairs
            )));
        }
        crate::error::check_reals(&[(
            "kl_step",
            self.kl_step,
            self.kl_step.is_finite() && self.kl_step > 0.0 && self.kl_step <= 100.0,
            "in (0, 100] nats per time step",
        )])
        .map_err(ImitationError::Config)?;
        self.policy.validate()
    }
}

/// What one MDGPS iteration reports. Per-condition vectors are in condition order.
#[derive(Clone, Debug, Default, Serialize)]
pub struct MdgpsLog {
    /// Iteration (0-based).
    pub iteration: usize,
    /// Task cost C(τ) of the global policy's noise-free episode at each condition.
    pub task_cost: Vec<f64>,
    /// Its normalised performance against that condition's demonstrations.
    pub performance: Vec<f64>,
    /// Its final distance to the condition's goal (m).
    pub final_distance: Vec<f64>,
    /// Mean task cost of each condition's noisy controller episodes.
    pub controller_cost: Vec<f64>,
    /// Critic statistics of step 3.
    pub critic_loss: f64,
    pub wasserstein: f64,
    /// Mean over conditions of the C-step's KL to the policy linearisation (nats) and of η.
    pub kl: f64,
    pub eta: f64,
    /// S-step loss before and after ([`crate::mlp_policy::opt`]).
    pub s_loss_before: f64,
    pub s_loss_after: f64,
    /// Wall seconds per phase: episodes (given by the caller), dynamics, critic, cost
    /// expansion, linearisation and C-step, S-step (with iteration 0's catch-up S-step).
    pub t_execute: f64,
    pub t_dynamics: f64,
    pub t_critic: f64,
    pub t_cost: f64,
    pub t_lqr: f64,
    pub t_policy: f64,
}

impl MdgpsLog {
    /// Mean normalised performance of the policy over the conditions.
    pub fn mean_performance(&self) -> f64 {
        mean(&self.performance)
    }

    /// Mean final distance (m) of the policy over the conditions.
    pub fn mean_final_distance(&self) -> f64 {
        mean(&self.final_distance)
    }

    /// The progress line of this iteration.
    pub fn progress_line(&self) -> String {
        format!(
            "iter {:>3}  policy perf {:>6.3}  final {:>7.4} m  controllers' cost {:>7.3}  W1 {:>7.4}  kl {:>6.2}  S-loss {:>9.3e} -> {:>9.3e}  {:.1} s",
            self.iteration,
            self.mean_performance(),
            self.mean_final_distance(),
            mean(&self.controller_cost),
            self.wasserstein,
            self.kl,
            self.s_loss_before,
            self.s_loss_after,
            self.t_execute + self.t_dynamics + self.t_critic + self.t_cost + self.t_lqr + self.t_policy
        )
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// One condition: a demonstrated goal, its demonstrations (task and normalisation), its LQR
/// state and the policy's linearisation there.
struct Condition {
    demos: Demos,
    task: TaskConfig,
    lqr: LqrIteration,
    lin: LinGaussPolicy,
}

/// The state of an MDGPS run; [`Mdgps::learn`] runs one iteration (module docs).
pub struct Mdgps {
    cfg: MdgpsConfig,
    conds: Vec<Condition>,
    critic: Critic,
    cost_ws: CompositeWorkspace,
    policy: GlobalPolicy,
    opt: PolicyOpt,
    iteration: usize,
}

impl Mdgps {
    /// Sets up a run with one condition per demonstration set (each set's goal; all with the
    /// same start pose, T, dt and task layout). The policy and the controllers take the
    /// layout's dimensions. A pose task (three tool points) runs with one goal only: the
    /// episode plan that moves the real-time controller to each condition's goal
    /// ([`Mdgps::plan`]) carries a goal point, not a pose, so a served run could not set a
    /// condition's pose.
    pub fn new(cfg: MdgpsConfig, demos: Vec<Demos>) -> Result<Self, ImitationError> {
        cfg.validate()?;
        let first = demos
            .first()
            .ok_or_else(|| ImitationError::Config("MDGPS needs at least one condition".into()))?;
        let layout = first.layout();
        if first.goal_pose.is_some() && demos.len() > 1 {
            return Err(ImitationError::Config(format!(
                "MDGPS on a pose task ({layout}) takes the demonstrations of one goal pose, got                  {}: the episode plan that sets each condition's goal on the real-time                  controller carries a goal point, not a pose",
                demos.len()
            )));
        }
        if let Some(d) = demos.iter().find(|d| {
            d.horizon != first.horizon
                || d.dt != first.dt
                || d.start_q != first.start_q
                || d.layout() != first.layout()
        }) {
            return Err(ImitationError::Config(format!(
                "the demonstrations of goal {:?} have another T, dt, start pose or task layout than those of \
                 goal {:?}: every condition must share them",
                d.goal, first.goal
            )));
        }
        let g = &cfg.lqr_gaifo;
        let expert = stack(&demos.iter().map(expert_transitions).collect::<Vec<_>>());
        let critic = Critic::from_settings(expert, g.critic(), g.seed)?;
        let mut conds = Vec::with_capacity(demos.len());
        for (m, d) in demos.into_iter().enumerate() {
            let task = d.task()?;
            let learner = Learner::new(
                gps::algorithm::AlgorithmConfig {
                    kl_step: cfg.kl_step,
                    ..g.algorithm.clone()
                },
                g.prior.clone(),
                g.fit.clone(),
                g.traj_opt.clone(),
                task.horizon,
                layout.dx(),
                layout.du(),
                g.samples,
                ChaCha8Rng::seed_from_u64(condition_seed(g.seed ^ SEED_GMM, m)),
            );
            conds.push(Condition {
                lqr: LqrIteration::new(learner, init_hold(&task, g.init_var), 0),
                lin: LinGaussPolicy::zeros(task.horizon, layout.dx(), layout.du()),
                demos: d,
                task,
            });
        }
        let policy = GlobalPolicy::new(
            layout,
            &cfg.policy.hidden,
            g.init_var.sqrt(),
            &mut ChaCha8Rng::seed_from_u64(g.seed ^ SEED_POLICY),
        );
        Ok(Self {
            opt: PolicyOpt::new(cfg.policy.clone(), &policy, g.seed ^ SEED_SSTEP),
            cost_ws: CompositeWorkspace::new(critic.discriminator()).with_psd(g.psd_hessian),
            cfg,
            conds,
            critic,
            policy,
            iteration: 0,
        })
    }

    /// The settings of the run.
    pub fn config(&self) -> &MdgpsConfig {
        &self.cfg
    }

    /// Number of conditions M.
    pub fn conditions(&self) -> usize {
        self.conds.len()
    }

    /// The task (goal) of condition `m`.
    pub fn task(&self, m: usize) -> &TaskConfig {
        &self.conds[m].task
    }

    /// The demonstrations of condition `m`.
    pub fn demos(&self, m: usize) -> &Demos {
        &self.conds[m].demos
    }

    /// The controller condition `m` executes next.
    pub fn controller(&self, m: usize) -> &LinGaussPolicy {
        self.conds[m].lqr.policy()
    }

    /// The one critic of every condition (its checkpoint: [`Critic::save`]).
    pub fn critic(&self) -> &Critic {
        &self.critic
    }

    /// The global policy.
    pub fn policy(&self) -> &GlobalPolicy {
        &self.policy
    }

    /// Iterations done.
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Version of the controllers executed next: iteration + 1.
    pub fn version(&self) -> u64 {
        self.iteration as u64 + 1
    }

    /// Seed of condition `m`'s exploration noise: noisy episode k of version v draws
    /// `Noise::new(noise_seed(m), v, k)`.
    pub fn noise_seed(&self, m: usize) -> u64 {
        condition_seed(self.cfg.lqr_gaifo.seed, m)
    }

    /// The episode plan of condition `m`'s noisy episodes on the real-time controller
    /// (docs/design.md §3.3): its goal and its noise stream m + 1, so that the controller,
    /// under the run seed, draws [`Mdgps::noise_seed`]`(m)`'s noise.
    pub fn plan(&self, m: usize) -> EpisodePlan {
        EpisodePlan::to_goal(self.conds[m].task.goal).with_noise_stream(condition_stream(m))
    }

    /// Condition `m`'s controller as the gain table the real-time controller runs its N noisy
    /// episodes with: version [`Mdgps::version`], epoch `epoch`, [`Mdgps::plan`]`(m)`, sealed.
    /// Its episodes k = 0 … N−1 are those [`Mdgps::execute`] runs in process.
    pub fn gain_table(&self, m: usize, epoch: u32) -> Box<GainTable> {
        let mut table = to_gain_table(self.conds[m].lqr.policy(), self.version());
        table.epoch = epoch;
        table.plan = self.plan(m);
        table.seal();
        table
    }

    /// The global policy as the policy table of condition `m`'s evaluation: version
    /// [`Mdgps::version`], epoch `epoch`, goal m's plan with every episode noise-free, sealed.
    /// Its first episode is the evaluation [`Mdgps::execute`] runs in process.
    pub fn eval_table(&self, m: usize, epoch: u32) -> Result<Box<PolicyTable>, ImitationError> {
        let mut table = self
            .policy
            .to_table(self.version(), self.mode())
            .map_err(|e| ImitationError::Config(format!("the global policy as a table: {e}")))?;
        table.epoch = epoch;
        table.plan = self.plan(m).noise_free();
        table.model = ur5_shared::policy::model_code(self.cfg.lqr_gaifo.sim.model);
        table.seal();
        Ok(table)
    }

    /// Step 1 in process: per condition, N noisy episodes of its controller and one noise-free
    /// episode of the global policy at its goal (the evaluation, never trained on): all M (N + 1)
    /// in parallel, each on its own arm from `arms` ([`run_episodes`]; condition m's episode k
    /// keyed by (`noise_seed(m)`, version, k), the evaluation k = N).
    #[allow(clippy::type_complexity)]
    pub fn execute(
        &self,
        arms: &dyn Arms,
    ) -> Result<(Vec<Vec<Episode>>, Vec<Episode>), ImitationError> {
        let n = self.cfg.lqr_gaifo.samples;
        let version = self.version();
        let tables: Vec<_> = self
            .conds
            .iter()
            .map(|c| to_gain_table(c.lqr.policy(), version))
            .collect();
        let per = n + 1;
        let key = |i: usize| (self.noise_seed(i / per), version, (i % per) as u64);
        let mut all = run_episodes(arms, self.conds.len() * per, key, |i, arm| {
            let (m, k) = (i / per, i % per);
            let task = &self.conds[m].task;
            if k < n {
                let mut noise = Noise::new(self.noise_seed(m), version, k as u64);
                run_episode(arm, task, &mut &*tables[m], Some(&mut noise))
            } else {
                let mut ws = self.policy.workspace();
                let mut actor = GlobalActor::new(&self.policy, &mut ws);
                run_episode(arm, task, &mut actor, None)
            }
        })?
        .into_iter();
        let mut samples = Vec::with_capacity(self.conds.len());
        let mut evals = Vec::with_capacity(self.conds.len());
        for _ in &self.conds {
            samples.push(all.by_ref().take(n).collect());
            evals.push(all.next().expect("M (N + 1) episodes"));
        }
        Ok((samples, evals))
    }

    /// Steps 2–7 (module docs) on the noisy `samples` of every condition's controller and the
    /// policy's noise-free `evals`, executed by [`Mdgps::execute`]; `t_execute` (s) is logged.
    pub fn learn(
        &mut self,
        samples: &[Vec<Episode>],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<MdgpsLog, ImitationError> {
        self.check_episodes(samples, evals)?;
        let lists: Vec<SampleList> = samples.iter().map(|e| SampleList::new(e)).collect();
        let t0 = Instant::now();
        self.fit_dynamics(&lists)?;
        let t1 = Instant::now();
        let critic = self.update_discriminator(samples)?;
        let t2 = Instant::now();
        self.expand_costs(samples);
        let t3 = Instant::now();
        if self.iteration == 0 {
            self.fit_policy_normalizer(samples)?;
            self.s_step(samples)?;
        }
        let t_catch_up = t3.elapsed();
        self.linearise_policy(samples);
        let (kl, eta) = self.c_step(&lists)?;
        let t4 = Instant::now();
        let s = self.s_step(samples)?;
        let t5 = Instant::now();
        let log = self.log(samples, evals, &critic, (kl, eta), s);
        self.iteration += 1;
        Ok(MdgpsLog {
            t_execute,
            t_dynamics: (t1 - t0).as_secs_f64(),
            t_critic: (t2 - t1).as_secs_f64(),
            t_cost: (t3 - t2).as_secs_f64(),
            t_lqr: (t4 - t3 - t_catch_up).as_secs_f64(),
            t_policy: (t5 - t4 + t_catch_up).as_secs_f64(),
            ..log
        })
    }

    fn check_episodes(
        &self,
        samples: &[Vec<Episode>],
        evals: &[Episode],
    ) -> Result<(), ImitationError> {
        let (m, n) = (self.conds.len(), self.cfg.lqr_gaifo.samples);
        let t_len = self.conds[0].task.horizon;
        let ok = samples.len() == m
            && evals.len() == m
            && samples.iter().all(|s| s.len() == n)
            && samples
                .iter()
                .flatten()
                .chain(evals)
                .all(|e| e.horizon() == t_len);
        if ok {
            Ok(())
        } else {
            Err(ImitationError::Episodes(format!(
                "an MDGPS iteration needs {n} noisy episodes of T = {t_len} steps for each of \
                 {m} conditions and one evaluation episode per condition; got {} conditions \
                 with {:?} episodes and {} evaluations",
                samples.len(),
                samples.iter().map(Vec::len).collect::<Vec<_>>(),
                evals.len()
            )))
        }
    }

    /// Step 2: each condition's dynamics.
    fn fit_dynamics(&mut self, lists: &[SampleList]) -> Result<(), ImitationError> {
        for (c, l) in self.conds.iter_mut().zip(lists) {
            c.lqr.fit_dynamics(l)?;
        }
        Ok(())
    }

    /// Step 3: the one critic on the demonstrations of every goal against every condition's
    /// controller transitions (its input normalisation refitted on both at iteration 0,
    /// docs/design.md §5 D2).
    fn update_discriminator(
        &mut self,
        samples: &[Vec<Episode>],
    ) -> Result<TrainStats, ImitationError> {
        let controller = episode_transitions(&samples.concat());
        self.critic.update(&controller, self.iteration)
    }

    /// Steps 4–5: each condition's composite cost expanded around its samples.
    fn expand_costs(&mut self, samples: &[Vec<Episode>]) {
        for (c, eps) in self.conds.iter_mut().zip(samples) {
            let mut cost = CompositeCost {
                disc: self.critic.cost_discriminator(),
                ws: &mut self.cost_ws,
            };
            c.lqr.expand(&mut cost, eps);
        }
    }

    /// The policy's input normalisation, once: the states of the demonstrations of every goal
    /// and of the first iteration's samples (docs/design.md §6.4).
    fn fit_policy_normalizer(&mut self, samples: &[Vec<Episode>]) -> Result<(), ImitationError> {
        let dx = self.layout().dx();
        let mut rows: Vec<&[f64]> = Vec::new();
        for c in &self.conds {
            let d = &c.demos;
            rows.extend((0..d.count).flat_map(|i| (0..d.horizon).map(move |t| d.state(i, t))));
        }
        for ep in samples.iter().flatten() {
            rows.extend((0..ep.horizon()).map(|t| ep.state(t)));
        }
        let x = Mat::from_fn(rows.len(), dx, |r, c| rows[r][c]);
        self.policy
            .set_normalizer(Normalizer::from_data(x.as_ref())?);
        Ok(())
    }

    /// Step 6a: the policy's linear-Gaussian linearisation at each condition, about the mean
    /// of that condition's sample states at each t (docs/design.md §6.2): K_t = ∂ā/∂s(s̄_t),
    /// k_t = ā(s̄_t) − K_t s̄_t, Σ_t = diag(σ²).
    fn linearise_policy(&mut self, samples: &[Vec<Episode>]) {
        let mode = self.mode();
        let (dx, du) = (self.layout().dx(), self.layout().du());
        let mut ws = self.policy.workspace();
        let std = self.policy.std();
        let (mut s_bar, mut jac) = (vec![0.0; dx], vec![0.0; du * dx]);
        for (c, eps) in self.conds.iter_mut().zip(samples) {
            for t in 0..c.task.horizon {
                s_bar.fill(0.0);
                for ep in eps {
                    for (v, x) in s_bar.iter_mut().zip(ep.state(t)) {
                        *v += x / eps.len() as f64;
                    }
                }
                jac.fill(0.0);
                let a = self
                    .policy
                    .mean_action_jacobian(&s_bar, mode, &mut ws, &mut jac);
                linear_gaussian_step(&mut c.lin, t, &s_bar, &a, &jac, &std);
            }
        }
    }

    /// Step 6b, the C-step: each condition's KL-bounded LQR towards the policy's
    /// linearisation; returns the mean KL and η over the conditions.
    fn c_step(&mut self, lists: &[SampleList]) -> Result<(f64, f64), ImitationError> {
        let (mut kl, mut eta) = (0.0, 0.0);
        for (c, l) in self.conds.iter_mut().zip(lists) {
            let Condition { lqr, lin, .. } = c;
            let r = lqr.improve_towards(l, lin)?;
            kl += r.kl;
            eta += r.eta;
        }
        let m = self.conds.len() as f64;
        Ok((kl / m, eta / m))
    }

    /// Step 7, the S-step: the policy regressed onto the controllers executed next, at this
    /// iteration's sample states ([`crate::mlp_policy::opt`]).
    fn s_step(&mut self, samples: &[Vec<Episode>]) -> Result<SStepReport, ImitationError> {
        let targets = self.targets(samples);
        self.opt.update(&mut self.policy, &targets)
    }

    /// The S-step's targets: at every sample state s of condition m at step t, the offset
    /// K_t s + k_t − base(s) of condition m's controller and its precision Σ_t⁻¹.
    pub fn targets(&self, samples: &[Vec<Episode>]) -> Targets {
        let mode = self.mode();
        let (dx, du) = (self.layout().dx(), self.layout().du());
        let mut out = Targets::new(dx, du);
        let zeros = vec![0.0; du];
        let mut a = vec![0.0; du];
        for (c, eps) in self.conds.iter().zip(samples) {
            let pol = c.lqr.policy();
            for ep in eps {
                for t in 0..ep.horizon() {
                    let s = ep.state(t);
                    pol.act(t, s, &zeros, &mut a);
                    let mut offset = crate::mlp_policy::action_base(mode, du, s);
                    for (o, a) in offset.iter_mut().zip(&a) {
                        *o = a - *o;
                    }
                    out.push(s, &offset, pol.inv_pol_covar.slice(t));
                }
            }
        }
        out
    }

    /// The task's state layout (every condition's).
    pub fn layout(&self) -> StateLayout {
        self.policy.layout()
    }

    fn mode(&self) -> ActionMode {
        self.cfg.lqr_gaifo.sim.mode
    }

    fn log(
        &self,
        samples: &[Vec<Episode>],
        evals: &[Episode],
        critic: &TrainStats,
        (kl, eta): (f64, f64),
        s: SStepReport,
    ) -> MdgpsLog {
        let perf = |c: &Condition, e: &Episode| {
            ur5_shared::normalised_performance(
                e.task_cost(),
                c.demos.cost_random,
                c.demos.cost_expert,
            )
            .unwrap_or(f64::NAN)
        };
        MdgpsLog {
            iteration: self.iteration,
            task_cost: evals.iter().map(Episode::task_cost).collect(),
            performance: self
                .conds
                .iter()
                .zip(evals)
                .map(|(c, e)| perf(c, e))
                .collect(),
            final_distance: evals.iter().map(Episode::final_distance).collect(),
            controller_cost: samples
                .iter()
                .map(|eps| mean(&eps.iter().map(Episode::task_cost).collect::<Vec<_>>()))
                .collect(),
            critic_loss: critic.critic_loss,
            wasserstein: critic.wasserstein,
            kl,
            eta,
            s_loss_before: s.loss_before,
            s_loss_after: s.loss_after,
            ..MdgpsLog::default()
        }
    }
}

/// MDGPS through the one driver interface: its goals are the conditions, its noisy episodes
/// the controllers' (condition-major), its evaluations the global policy's, one per condition.
impl Learn for Mdgps {
    type Log = MdgpsLog;
    const ALGO: &'static str = "mdgps";

    /// Condition 0's task (every condition shares its start pose, T and dt).
    fn task(&self) -> &TaskConfig {
        &self.conds[0].task
    }
    fn goal_tasks(&self) -> Vec<&TaskConfig> {
        self.conds.iter().map(|c| &c.task).collect()
    }
    fn sim_config(&self) -> &SimConfig {
        &self.cfg.lqr_gaifo.sim
    }
    fn samples(&self) -> usize {
        self.cfg.lqr_gaifo.samples
    }
    fn seed(&self) -> u64 {
        self.cfg.lqr_gaifo.seed
    }
    fn iteration(&self) -> usize {
        self.iteration
    }
    fn done(&self) -> bool {
        self.iteration >= self.cfg.lqr_gaifo.iterations
    }
    /// [`Mdgps::execute`], its noisy episodes concatenated in condition order.
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        let (samples, evals) = Mdgps::execute(self, arms)?;
        Ok((samples.into_iter().flatten().collect(), evals))
    }
    /// [`Mdgps::learn`] on the noisy episodes split into the conditions' (N each).
    fn learn_goals(
        &mut self,
        noisy: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<MdgpsLog, ImitationError> {
        let n = self.cfg.lqr_gaifo.samples.max(1);
        let samples: Vec<Vec<Episode>> = noisy.chunks(n).map(<[Episode]>::to_vec).collect();
        Mdgps::learn(self, &samples, evals, t_execute)
    }
    /// Mean task cost of the policy's evaluations.
    fn eval_cost(log: &MdgpsLog) -> f64 {
        mean(&log.task_cost)
    }
}

/// Noise stream of condition `m`: m + 1 (stream 0 is the run seed itself).
fn condition_stream(m: usize) -> u32 {
    u32::try_from(m + 1).expect("fewer than 2^32 conditions")
}

/// Seed of condition `m` derived from `seed` (distinct per condition, reproducible): noise
/// stream m + 1 ([`ur5_shared::noise::stream_seed`]), which a table's episode plan names.
fn condition_seed(seed: u64, m: usize) -> u64 {
    ur5_shared::noise::stream_seed(seed, condition_stream(m))
}

/// Rows of every matrix, stacked.
fn stack(parts: &[Mat<f64>]) -> Mat<f64> {
    let rows: usize = parts.iter().map(Mat::nrows).sum();
    let cols = parts.first().map_or(0, Mat::ncols);
    let mut out = Mat::zeros(rows, cols);
    let mut r0 = 0;
    for p in parts {
        out.as_mut()
            .submatrix_mut(r0, 0, p.nrows(), cols)
            .copy_from(p);
        r0 += p.nrows();
    }
    out
}

/// Step t of `lin` := the linear-Gaussian controller a = K (s − s̄) + ā with K = `jac` and
/// Σ = diag(`std`²), in GPS's absolute form (k = ā − K s̄; R = diag(σ), Σ⁻¹ = diag(σ⁻²)).
/// `jac` is dU × dX row-major, `s_bar` dX, `a` and `std` dU.
fn linear_gaussian_step(
    lin: &mut LinGaussPolicy,
    t: usize,
    s_bar: &[f64],
    a: &[f64],
    jac: &[f64],
    std: &[f64],
) {
    let (dx, du) = (s_bar.len(), a.len());
    lin.gain.slice_mut(t).copy_from_slice(jac);
    let k = lin.k.slice_mut(t);
    for j in 0..du {
        k[j] = a[j] - (0..dx).map(|i| jac[j * dx + i] * s_bar[i]).sum::<f64>();
    }
    for m in [
        &mut lin.pol_covar,
        &mut lin.chol_pol_covar,
        &mut lin.inv_pol_covar,
    ] {
        m.slice_mut(t).fill(0.0);
    }
    for j in 0..du {
        lin.pol_covar.slice_mut(t)[j * du + j] = std[j] * std[j];
        lin.chol_pol_covar.slice_mut(t)[j * du + j] = std[j];
        lin.inv_pol_covar.slice_mut(t)[j * du + j] = 1.0 / (std[j] * std[j]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The path's terms are refused with a message that names them and the way out; the
    /// defaults pass.
    #[test]
    fn the_paths_terms_are_refused() {
        MdgpsConfig::default().validate().unwrap();
        let mut c = MdgpsConfig::default();
        c.lqr_gaifo.path = crate::settings::PathSettings::for_motions();
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("lqr_gaifo.path") && e.contains("--algo lqr-gaifo"),
            "{e}"
        );
        let mut c = MdgpsConfig::default();
        c.lqr_gaifo.critic_terminal_pairs = 10;
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("lqr_gaifo.critic_terminal_pairs = 10") && e.contains("--algo lqr-gaifo"),
            "{e}"
        );
    }
}
