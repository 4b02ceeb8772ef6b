//! LQR+GAIfO (Torabi et al. 2019, Algorithm 1). One function per line of the algorithm, called
//! in the paper's order:
//!
//! 1. [`execute`]: run the controller N times with noise and once without;
//! 2. `update_dynamics`: refit p(s'|s,a) = N(F_t [s;a] + f_t, Σ_t) (GMM prior + regression);
//! 3. [`LqrGaifo::update_discriminator`]: WGAN-GP steps on expert vs controller transitions;
//! 4. [`composite_cost_derivs`]: C_t(s,a) = D(s, F_t [s;a] + f_t) and
//! 5. its second-order expansion around the samples;
//! 6. [`improve`]: the KL-bounded LQR step.
//!
//! Line 1 and the rest are separate: [`LqrGaifo::learn`] is lines 2–6 (and the switch to the new
//! controller) on episodes executed elsewhere; [`LqrGaifo::iterate`] is [`execute`] on an
//! in-process arm followed by `learn` (`learner train`), and `learner serve --algo lqr-gaifo`
//! calls `learn` on the episodes the real-time loop streams. Same episodes, same result.
//!
//! # Checkpoints and resuming
//! [`LqrGaifo::checkpoint`] writes, before every iteration, the controller it executes
//! (`iter_NNN_table.npz`, NNN = iterations done) and the critic (`iter_NNN_critic.json`:
//! weights, input normalisation, Adam moments and step count, minibatch RNG position).
//! [`LqrGaifo::resume`] continues from the latest complete pair: the critic exactly, the
//! controller as its gain table (K, k, L; Σ = L Lᵀ is recomputed). The GPS learner state — the
//! GMM dynamics prior (and the transitions it was fitted on), the previous controller and the
//! step size — is not checkpointed and starts afresh, so a resumed run's first iteration executes
//! the same episodes and makes the same critic update as the uninterrupted run would, but its
//! dynamics fit, and hence its LQR step, differ from there on.
//!
//! Only state transitions of the expert are used (`Demos::states`); its actions are never read.

use std::path::{Path, PathBuf};
use std::time::Instant;

use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::{DU, DX};

use crate::algorithm::eval_cost::CostDerivs;
use crate::algorithm::update::Learner;
use crate::algorithm::AlgorithmConfig;
use crate::bench::thread_cpu_s;
use crate::cost::composite::{composite_cost_derivs, CompositeWorkspace, D_IN};
use crate::discriminator::{
    AdamConfig, Discriminator, DiscriminatorConfig, Normalizer, TrainStats,
};
use crate::dynamics::lr_prior::LrPriorConfig;
use crate::dynamics::prior_gmm::PriorGmmConfig;
use crate::expert::{init_hold, policy_from_gain_table, to_gain_table};
use crate::io::demos::Demos;
use crate::io::table::{load_table, save_table};
use crate::iteration::{execute, improve, sim_err, stack};
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::rollout::Episode;
use crate::traj_opt::lqr::TrajOptConfig;
use crate::LearnerError;
use hil_sim::Ur5Sim;

/// Settings of an LQR+GAIfO run (TOML: `learner train --config FILE`). The task (goal, start
/// pose, T, dt) comes from the demonstrations file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaifoConfig {
    /// The simulated arm.
    pub sim: SimConfig,
    /// Noisy episodes per iteration N. Paper §5: 5.
    pub samples: usize,
    /// Iterations. Issue 6 acceptance: 20.
    pub iterations: usize,
    /// Initial controller: hold the start pose with this exploration variance (rad²), as the
    /// expert starts (`ExpertConfig::init_var`).
    pub init_var: f64,
    /// `Discriminator::train` calls per iteration, each `discriminator.n_critic` Adam steps
    /// followed by one full-batch Wasserstein estimate. Ours: 1 call of 100 steps: the critic
    /// needs a few hundred steps to separate the two sets, the controller moves only a KL step
    /// per iteration, and one estimate per iteration is all the log needs.
    pub critic_updates: usize,
    /// Adapt the KL step from predicted vs actual improvement (GPS `_stepadjust`). Off by
    /// default: GPS compares the cost model of the previous iteration with this one's, and here
    /// the cost is the critic, which changes every iteration and learns to score the current
    /// controller worse — the "actual improvement" comes out negative and the step shrinks to
    /// its floor while the controller has not moved (measured: step multiplier at 0.01 within
    /// 10 iterations, no progress). With it off every step has KL ≤ kl_step · T.
    pub adapt_step: bool,
    /// Project ∇²D on the positive semi-definite cone (negative eigenvalues set to 0) before
    /// the chain rule ∇²C = M_tᵀ ∇²D M_t. On by default, and the one addition beyond GPS's
    /// own regularisation: with the exact, indefinite ∇²D the LQR step had to raise η until
    /// Q_uu was positive definite, η grew to 1e3–1e8 as the critic sharpened, the steps stopped
    /// following the cost and the normalised performance stalled at 0.3–0.5 (measured, default
    /// goal, seed 0, `learner train` with this off); with the projection η stays below 1 and the
    /// same run reaches 0.94 by iteration 9. The projected Hessian is the Gauss–Newton-like
    /// convex part of the critic's curvature: it keeps the exact gradient and never rewards
    /// moving along a direction of negative curvature more than the gradient does.
    pub psd_hessian: bool,
    /// The critic and its training: WGAN-GP (Gulrajani et al. 2017: λ = 10, 5 critic steps per
    /// call, batch 64, Adam β2 = 0.9) with our changes, measured on the default task: 100
    /// critic steps per call (not 5), two hidden layers of 32 (not 64), Adam lr 1e-3 and
    /// β1 = 0.5 (not 1e-4 and 0): at 1e-4 the
    /// critic needs thousands of steps to separate 500 + 500 transitions, more than 20
    /// iterations give it. Batch 16 (not 64), for the learner-time budget: 100 × 16 draws still
    /// see each of the ~500 controller transitions about 3 times per iteration; measured over
    /// 5 seeds (with the prior below) the mean normalised performance at iterations 4/9/14/19
    /// is 0.54/0.90/0.92/0.94 against 0.55/0.96/0.92/0.93 with batch 64, at 14 instead of
    /// 45 ms per iteration.
    pub discriminator: DiscriminatorConfig,
    /// Seed of every random draw of the run (noise, GMM, critic).
    pub seed: u64,
    /// GPS algorithm settings.
    pub algorithm: AlgorithmConfig,
    /// GPS dynamics prior. GPS's settings (20 clusters, 40 points per cluster) except, for
    /// the learner-time budget: the last 10 trajectories (two iterations; `max_samples` 11, not
    /// 20) and at most 5 EM iterations per refit (not 100; warm-started from the last
    /// iteration's mixture, which the data shares half with). The GMM on 19 trajectories took
    /// 70–460 ms per iteration (18–91 EM iterations to GPS's 1e-5 relative tolerance); this
    /// takes about 15 ms, and the 5-seed learning curves did not change measurably (mean
    /// normalised performance at iterations 4/9/14/19: 0.55/0.96/0.92/0.93 with GPS's
    /// settings, 0.54/0.94/0.93/0.93 with these; critic batch 64 in both).
    pub prior: PriorGmmConfig,
    /// GPS dynamics fit.
    pub fit: LrPriorConfig,
    /// GPS trajectory optimisation.
    pub traj_opt: TrajOptConfig,
}

impl Default for GaifoConfig {
    fn default() -> Self {
        Self {
            sim: SimConfig::default(),
            samples: 5,
            iterations: 20,
            init_var: 0.05,
            critic_updates: 1,
            adapt_step: false,
            psd_hessian: true,
            discriminator: DiscriminatorConfig {
                hidden: vec![32, 32],
                n_critic: 100,
                adam: AdamConfig {
                    lr: 1e-3,
                    beta1: 0.5,
                    beta2: 0.9,
                    eps: 1e-8,
                },
                batch_size: 16,
                ..DiscriminatorConfig::default()
            },
            seed: 0,
            algorithm: AlgorithmConfig::default(),
            prior: PriorGmmConfig {
                max_samples: 11,
                max_iterations: 5,
                ..PriorGmmConfig::default()
            },
            fit: LrPriorConfig::default(),
            traj_opt: TrajOptConfig::default(),
        }
    }
}

/// Per-iteration log (progress line and CSV row).
#[derive(Clone, Debug, Serialize)]
pub struct GaifoLog {
    /// Iteration (0-based).
    pub iteration: usize,
    /// True task cost C(τ) of the noise-free episode.
    pub task_cost: f64,
    /// Its normalised performance (C_random − C) / (C_random − C_expert).
    pub performance: f64,
    /// Final end-effector distance of the noise-free episode (m).
    pub final_distance: f64,
    /// Mean critic loss of this iteration's critic steps.
    pub critic_loss: f64,
    /// Critic's Wasserstein-1 estimate E_controller[D] − E_expert[D] after the update.
    pub wasserstein: f64,
    /// KL of the LQR step.
    pub kl: f64,
    /// η after the search.
    pub eta: f64,
    /// Step multiplier.
    pub step_mult: f64,
    /// Seconds per phase: executing episodes (simulator).
    pub t_execute: f64,
    /// Dynamics fit (GMM prior + regression).
    pub t_dynamics: f64,
    /// Discriminator update.
    pub t_critic: f64,
    /// Composite cost and its expansion (Hessians).
    pub t_cost: f64,
    /// KL-bounded LQR (cost averaging, step size, η search).
    pub t_lqr: f64,
    /// Thread CPU seconds of the learner phases (dynamics, critic, cost, LQR): the learner
    /// time of one iteration on one core, unaffected by waiting for a core on a busy machine.
    pub cpu_learner: f64,
}

impl GaifoLog {
    /// The log of iteration `iteration` with the evaluation of its noise-free episode `eval`
    /// (task cost, normalised performance against `demos`, final distance) and the critic's
    /// statistics filled in; the step (`kl`, `eta`, `step_mult`) NaN and the times 0, for the
    /// algorithm to set. Shared by LQR+GAIfO and the PPO baseline.
    pub fn evaluated(iteration: usize, eval: &Episode, demos: &Demos, critic: &TrainStats) -> Self {
        let c = eval.task_cost();
        Self {
            iteration,
            task_cost: c,
            performance: ur5_shared::normalised_performance(
                c,
                demos.cost_random,
                demos.cost_expert,
            )
            .unwrap_or(f64::NAN),
            final_distance: eval.final_distance(),
            critic_loss: critic.critic_loss,
            wasserstein: critic.wasserstein,
            kl: f64::NAN,
            eta: f64::NAN,
            step_mult: f64::NAN,
            t_execute: 0.0,
            t_dynamics: 0.0,
            t_critic: 0.0,
            t_cost: 0.0,
            t_lqr: 0.0,
            cpu_learner: 0.0,
        }
    }

    /// Learner time (everything but executing episodes), s.
    pub fn learner_seconds(&self) -> f64 {
        self.t_dynamics + self.t_critic + self.t_cost + self.t_lqr
    }

    /// Column names of [`GaifoLog::progress_line`].
    pub const PROGRESS_HEADER: &'static str = "iter task_cost    perf  final_m    critic   W1_est       kl       eta   mult  lrn_ms  sim_ms";

    /// The progress line of this iteration (`learner train`, `learner serve --algo lqr-gaifo`;
    /// `sim_ms` is [`GaifoLog::t_execute`]).
    pub fn progress_line(&self) -> String {
        format!(
            "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>9.4} {:>8.4} {:>8.3} {:>9.2e} {:>6.2} {:>7.1} {:>7.1}",
            self.iteration,
            self.task_cost,
            self.performance,
            self.final_distance,
            self.critic_loss,
            self.wasserstein,
            self.kl,
            self.eta,
            self.step_mult,
            1e3 * self.learner_seconds(),
            1e3 * self.t_execute
        )
    }
}

/// Expert transitions [s_t; s_{t+1}] of every demonstration, one per row.
pub fn expert_transitions(demos: &Demos) -> Mat<f64> {
    let rows = demos.count * (demos.horizon - 1);
    Mat::from_fn(rows, D_IN, |r, c| {
        let (d, t) = (r / (demos.horizon - 1), r % (demos.horizon - 1));
        if c < DX {
            demos.state(d, t)[c]
        } else {
            demos.state(d, t + 1)[c - DX]
        }
    })
}

/// Controller transitions of the given episodes, one per row.
pub fn episode_transitions(episodes: &[Episode]) -> Mat<f64> {
    let t_len = episodes[0].horizon();
    let rows = episodes.len() * (t_len - 1);
    Mat::from_fn(rows, D_IN, |r, c| {
        let (i, t) = (r / (t_len - 1), r % (t_len - 1));
        let ep = &episodes[i];
        if c < DX {
            ep.x[t * DX + c]
        } else {
            ep.x[(t + 1) * DX + c - DX]
        }
    })
}

/// The critic's config for run seed `seed`: `dcfg` with its seed mixed with the run's, so
/// that runs with different seeds get different critics. Shared with the PPO baseline.
pub fn critic_config(dcfg: &DiscriminatorConfig, seed: u64) -> DiscriminatorConfig {
    let mut dcfg = dcfg.clone();
    dcfg.seed = seed ^ dcfg.seed ^ 0x4352_4954; // "CRIT"
    dcfg
}

/// A fresh critic (`dcfg`, weights drawn again from its seed) whose input normalisation is
/// fitted on expert ∪ `controller` transitions; LQR+GAIfO and the PPO baseline call it once,
/// on the first iteration's samples (why: [`LqrGaifo`]'s `refit_normalizer`).
pub fn refit_critic(
    expert: &Mat<f64>,
    controller: &Mat<f64>,
    dcfg: &DiscriminatorConfig,
) -> Result<Discriminator, LearnerError> {
    let (ne, nc) = (expert.nrows(), controller.nrows());
    let both = Mat::from_fn(ne + nc, D_IN, |r, c| {
        if r < ne {
            expert[(r, c)]
        } else {
            controller[(r - ne, c)]
        }
    });
    let norm =
        Normalizer::from_data(both.as_ref()).map_err(|e| LearnerError::Shape(e.to_string()))?;
    Discriminator::new(D_IN, dcfg.clone(), norm).map_err(|e| LearnerError::Shape(e.to_string()))
}

/// Line 3 of Algorithm 1: `updates` (at least one) WGAN-GP calls on expert vs `controller`
/// transitions; returns the last call's statistics. Shared with the PPO baseline.
pub fn train_critic(
    disc: &mut Discriminator,
    ws: &mut crate::discriminator::Workspace,
    expert: &Mat<f64>,
    controller: &Mat<f64>,
    updates: usize,
) -> Result<TrainStats, LearnerError> {
    let mut stats = None;
    for _ in 0..updates.max(1) {
        stats = Some(
            disc.train(expert.as_ref(), controller.as_ref(), ws)
                .map_err(|e| LearnerError::Shape(format!("discriminator: {e}")))?,
        );
    }
    Ok(stats.expect("at least one update"))
}

/// Header of the per-iteration CSV (`gaifo_log.csv`), the same for both algorithms.
pub const CSV_HEADER: &str = "iteration,seed,algorithm,normalised_performance,task_cost,final_distance_m,critic_loss,wasserstein,kl,eta,step_mult,t_execute_s,t_dynamics_s,t_critic_s,t_cost_s,t_lqr_s,cpu_learner_s";

/// One CSV row (columns of [`CSV_HEADER`]) of run `seed` of `algorithm`.
pub fn write_csv_row(
    f: &mut impl std::io::Write,
    log: &GaifoLog,
    seed: u64,
    algorithm: &str,
) -> std::io::Result<()> {
    writeln!(
        f,
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        log.iteration,
        seed,
        algorithm,
        log.performance,
        log.task_cost,
        log.final_distance,
        log.critic_loss,
        log.wasserstein,
        log.kl,
        log.eta,
        log.step_mult,
        log.t_execute,
        log.t_dynamics,
        log.t_critic,
        log.t_cost,
        log.t_lqr,
        log.cpu_learner
    )
}

/// The state of an LQR+GAIfO run; [`LqrGaifo::iterate`] runs one iteration of Algorithm 1.
pub struct LqrGaifo {
    cfg: GaifoConfig,
    task: TaskConfig,
    demos: Demos,
    expert: Mat<f64>,
    /// The in-process arm of [`LqrGaifo::iterate`], built on first use (`learn` needs none).
    sim: Option<Ur5Sim>,
    learner: Learner,
    disc: Discriminator,
    cost_ws: CompositeWorkspace,
    disc_ws: crate::discriminator::Workspace,
    derivs: CostDerivs,
    pol: LinGaussPolicy,
    prev_pol: Option<LinGaussPolicy>,
    new_pol: LinGaussPolicy,
    iteration: usize,
}

impl LqrGaifo {
    /// Sets up a run imitating `demos` (the task — goal, start pose, T, dt — is theirs).
    pub fn new(cfg: GaifoConfig, demos: Demos) -> Result<Self, LearnerError> {
        let task = TaskConfig {
            dt: demos.dt,
            horizon: demos.horizon,
            start_q: demos.start_q,
            goal: demos.goal,
        };
        task.validate()
            .map_err(|e| LearnerError::Shape(format!("demonstrations: {e}")))?;
        let expert = expert_transitions(&demos);
        let norm = Normalizer::from_data(expert.as_ref())
            .map_err(|e| LearnerError::Shape(e.to_string()))?;
        let disc = Discriminator::new(D_IN, critic_config(&cfg.discriminator, cfg.seed), norm)
            .map_err(|e| LearnerError::Shape(e.to_string()))?;
        let learner = Learner::new(
            cfg.algorithm.clone(),
            cfg.prior.clone(),
            cfg.fit.clone(),
            cfg.traj_opt.clone(),
            task.horizon,
            DX,
            DU,
            cfg.samples,
            ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x474d_4d00),
        );
        let pol = init_hold(&task, cfg.init_var);
        Ok(Self {
            cost_ws: CompositeWorkspace::new(&disc).with_psd(cfg.psd_hessian),
            disc_ws: disc.workspace(),
            new_pol: LinGaussPolicy::zeros(task.horizon, DX, DU),
            derivs: CostDerivs::default(),
            prev_pol: None,
            iteration: 0,
            cfg,
            task,
            demos,
            expert,
            sim: None,
            learner,
            disc,
            pol,
        })
    }

    /// The controller that the next iteration executes.
    pub fn policy(&self) -> &LinGaussPolicy {
        &self.pol
    }

    /// The critic.
    pub fn discriminator(&self) -> &Discriminator {
        &self.disc
    }

    /// The task being imitated.
    pub fn task(&self) -> &TaskConfig {
        &self.task
    }

    /// The settings of the run.
    pub fn config(&self) -> &GaifoConfig {
        &self.cfg
    }

    /// The demonstrations being imitated.
    pub fn demos(&self) -> &Demos {
        &self.demos
    }

    /// Iterations done (counting those before a resume).
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Gain-table version of [`LqrGaifo::policy`]: iteration + 1 (the initial controller is 1).
    pub fn version(&self) -> u64 {
        self.iteration as u64 + 1
    }

    /// `cfg.iterations` done.
    pub fn done(&self) -> bool {
        self.iteration >= self.cfg.iterations
    }

    /// Rebuilds the critic with its input normalisation fitted on expert ∪ `controller`
    /// transitions (done once, on the first iteration's samples). Fitted on the expert alone,
    /// the scales are those of an arm resting at the goal (most expert transitions), the
    /// controller's transitions sit many σ away, the tanh units saturate and the cost is flat
    /// where the controller is (measured: no progress in 20 iterations).
    fn refit_normalizer(&mut self, controller: &Mat<f64>) -> Result<(), LearnerError> {
        self.disc = refit_critic(&self.expert, controller, self.disc.config())?;
        self.cost_ws = CompositeWorkspace::new(&self.disc).with_psd(self.cfg.psd_hessian);
        Ok(())
    }

    /// Line 3 of Algorithm 1: `critic_updates` WGAN-GP calls on expert vs these transitions.
    pub fn update_discriminator(
        &mut self,
        controller: &Mat<f64>,
    ) -> Result<TrainStats, LearnerError> {
        train_critic(
            &mut self.disc,
            &mut self.disc_ws,
            &self.expert,
            controller,
            self.cfg.critic_updates,
        )
    }

    /// One iteration of Algorithm 1 in process: line 1 ([`execute`] on the in-process arm),
    /// then [`LqrGaifo::learn`]. Returns its log and the noise-free episode.
    pub fn iterate(&mut self) -> Result<(GaifoLog, Episode), LearnerError> {
        let sim = match self.sim.as_mut() {
            Some(sim) => sim,
            None => self
                .sim
                .insert(Ur5Sim::new(self.cfg.sim.clone(), self.task.dt).map_err(sim_err)?),
        };
        // 1. Execute the controller.
        let t0 = Instant::now();
        let (episodes, eval) = execute(
            sim,
            &self.task,
            &self.pol,
            self.iteration as u64 + 1,
            self.cfg.seed,
            self.cfg.samples,
        )?;
        let t_execute = t0.elapsed().as_secs_f64();
        let log = self.learn(&episodes, &eval, t_execute)?;
        Ok((log, eval))
    }

    /// Lines 2–6 of Algorithm 1 on the `episodes` (`cfg.samples` noisy ones) and the noise-free
    /// `eval` episode executed with [`LqrGaifo::policy`] (as table version
    /// [`LqrGaifo::version`]); then that controller is replaced by the new one. `t_execute`
    /// (s) is logged as the time line 1 took.
    pub fn learn(
        &mut self,
        episodes: &[Episode],
        eval: &Episode,
        t_execute: f64,
    ) -> Result<GaifoLog, LearnerError> {
        let (n, t_len) = (self.cfg.samples, self.task.horizon);
        if episodes.len() != n || episodes.iter().chain([eval]).any(|e| e.horizon() != t_len) {
            return Err(LearnerError::Shape(format!(
                "an LQR+GAIfO iteration needs {n} noisy episodes and one noise-free episode of \
                 T = {t_len} steps; got {} noisy, horizons {:?}",
                episodes.len(),
                episodes
                    .iter()
                    .chain([eval])
                    .map(Episode::horizon)
                    .collect::<Vec<_>>()
            )));
        }
        let (x, u) = stack(episodes);
        // 2. Fit the dynamics.
        let t1 = Instant::now();
        let c1 = thread_cpu_s();
        self.learner.update_dynamics(&x, &u, n)?;
        // 3. Update the discriminator on (s, s') of the controller vs the expert.
        let t2 = Instant::now();
        let controller = episode_transitions(episodes);
        if self.iteration == 0 {
            self.refit_normalizer(&controller)?;
        }
        let critic = self.update_discriminator(&controller)?;
        // 4–5. Composite cost D(s, F_t[s;a] + f_t) and its second-order expansion.
        let t3 = Instant::now();
        composite_cost_derivs(
            &self.disc,
            &self.learner.info.dynamics,
            episodes,
            &mut self.cost_ws,
            &mut self.derivs,
        );
        // 6. KL-bounded LQR step.
        let t4 = Instant::now();
        let step = improve(
            &mut self.learner,
            &x,
            &u,
            n,
            &self.derivs,
            self.prev_pol.as_ref(),
            &self.pol,
            &mut self.new_pol,
            self.cfg.adapt_step,
        )?;
        let t5 = Instant::now();
        let cpu_learner = thread_cpu_s() - c1;

        let log = GaifoLog {
            kl: step.kl,
            eta: step.eta,
            step_mult: step.step_mult,
            t_execute,
            t_dynamics: (t2 - t1).as_secs_f64(),
            t_critic: (t3 - t2).as_secs_f64(),
            t_cost: (t4 - t3).as_secs_f64(),
            t_lqr: (t5 - t4).as_secs_f64(),
            cpu_learner,
            ..GaifoLog::evaluated(self.iteration, eval, &self.demos, &critic)
        };
        match self.prev_pol.as_mut() {
            Some(p) => p.copy_from(&self.pol),
            None => self.prev_pol = Some(self.pol.clone()),
        }
        self.pol.copy_from(&self.new_pol);
        self.iteration += 1;
        Ok(log)
    }

    /// Saves the controller that the next iteration executes (`iter_NNN_table.npz`) and the
    /// critic (`iter_NNN_critic.json`) into `dir`, so the run can be resumed from there.
    pub fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        std::fs::create_dir_all(dir)?;
        let i = self.iteration;
        let table = dir.join(format!("iter_{i:03}_table.npz"));
        save_table(
            &table,
            &to_gain_table(&self.pol, i as u64 + 1),
            self.task.dt,
        )?;
        let critic = dir.join(format!("iter_{i:03}_critic.json"));
        self.disc.save(&critic)?;
        Ok((table, critic))
    }

    /// Continues a run from the latest checkpoint in `dir` ([`latest_checkpoint`]): the
    /// controller of `iter_NNN_table.npz` (executed next, as table version NNN + 1), the critic
    /// of `iter_NNN_critic.json`, NNN iterations done. `cfg` and `demos` must be the run's own:
    /// the critic's settings and seed are checked against `cfg`, the table's horizon and control
    /// period against the demonstrations. What is not checkpointed starts afresh (module docs).
    pub fn resume(cfg: GaifoConfig, demos: Demos, dir: &Path) -> anyhow::Result<Self> {
        use anyhow::Context;
        let (iteration, table_path, critic_path) = latest_checkpoint(dir)?;
        let mut run = Self::new(cfg, demos)?;
        let (table, dt) = load_table(&table_path, &ur5_shared::GainBounds::default())
            .with_context(|| format!("resuming from {}", table_path.display()))?;
        anyhow::ensure!(
            table.horizon() == run.task.horizon && dt.to_bits() == run.task.dt.to_bits(),
            "{}: a controller of T = {} steps at dt = {dt} s, the demonstrations have T = {} at \
             dt = {} s: resume with the run's own demonstrations",
            table_path.display(),
            table.horizon(),
            run.task.horizon,
            run.task.dt
        );
        anyhow::ensure!(
            table.version == iteration as u64 + 1,
            "{}: table version {}, expected {} for iteration {iteration}",
            table_path.display(),
            table.version,
            iteration + 1
        );
        run.pol = policy_from_gain_table(&table)
            .with_context(|| format!("resuming from {}", table_path.display()))?;
        let disc = Discriminator::load(&critic_path, D_IN)
            .with_context(|| format!("resuming from {}", critic_path.display()))?;
        let expected = critic_config(&run.cfg.discriminator, run.cfg.seed);
        anyhow::ensure!(
            *disc.config() == expected,
            "{}: the critic was trained with other [discriminator] settings or another seed than \
             this run's (seed {}): resume with the run's own --config and --seed",
            critic_path.display(),
            run.cfg.seed
        );
        run.cost_ws = CompositeWorkspace::new(&disc).with_psd(run.cfg.psd_hessian);
        run.disc_ws = disc.workspace();
        run.disc = disc;
        run.iteration = iteration;
        Ok(run)
    }
}

/// The latest complete checkpoint in `dir`: (NNN, `iter_NNN_table.npz`, `iter_NNN_critic.json`)
/// with the largest NNN for which both files exist. A clear error when there is none.
pub fn latest_checkpoint(dir: &Path) -> anyhow::Result<(usize, PathBuf, PathBuf)> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        anyhow::anyhow!(
            "cannot resume from {}: {e} (expected the --out folder of an earlier \
             `learner train` or `learner serve --algo lqr-gaifo` run)",
            dir.display()
        )
    })?;
    let mut best: Option<usize> = None;
    for entry in entries {
        let name = entry?.file_name();
        let Some(n) = name
            .to_str()
            .and_then(|n| n.strip_prefix("iter_"))
            .and_then(|n| n.strip_suffix("_table.npz"))
            .filter(|n| n.len() >= 3 && n.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|n| n.parse::<usize>().ok())
        else {
            continue;
        };
        if dir.join(format!("iter_{n:03}_critic.json")).is_file() && best.is_none_or(|b| n > b) {
            best = Some(n);
        }
    }
    let n = best.ok_or_else(|| {
        anyhow::anyhow!(
            "cannot resume from {}: no checkpoint in it (no pair iter_NNN_table.npz + \
             iter_NNN_critic.json, written by `learner train` and `learner serve --algo lqr-gaifo`)",
            dir.display()
        )
    })?;
    Ok((
        n,
        dir.join(format!("iter_{n:03}_table.npz")),
        dir.join(format!("iter_{n:03}_critic.json")),
    ))
}

/// An imitation run the shared training loop drives: LQR+GAIfO here, the PPO baseline in
/// `crate::ppo`.
pub trait Imitation {
    /// One iteration: its log and the noise-free episode.
    fn iterate(&mut self) -> Result<(GaifoLog, Episode), LearnerError>;
    /// Saves what a resumed run needs into `dir`.
    fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)>;
}

impl Imitation for LqrGaifo {
    fn iterate(&mut self) -> Result<(GaifoLog, Episode), LearnerError> {
        LqrGaifo::iterate(self)
    }
    fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        LqrGaifo::checkpoint(self, dir)
    }
}

/// Runs `iterations` iterations of `run`, calling `progress` after each, writing
/// `gaifo_log.csv` (column `algorithm` = `algo`) and per-iteration checkpoints into `out` when
/// it is given.
pub fn run_iterations<R: Imitation>(
    run: &mut R,
    iterations: usize,
    seed: u64,
    algo: &str,
    out: Option<&Path>,
    progress: impl FnMut(&GaifoLog, &R),
) -> anyhow::Result<Vec<GaifoLog>> {
    let csv = match out {
        Some(dir) => {
            std::fs::create_dir_all(dir)?;
            let f = open_log(&dir.join("gaifo_log.csv"), None)?;
            run.checkpoint(dir)?;
            Some((f, dir))
        }
        None => None,
    };
    drive(run, iterations, seed, algo, csv, progress)
}

/// The iterations of [`run_iterations`] and [`train_resumed`]: iterate, report, log, checkpoint.
fn drive<R: Imitation>(
    run: &mut R,
    iterations: usize,
    seed: u64,
    algo: &str,
    mut csv: Option<(std::fs::File, &Path)>,
    mut progress: impl FnMut(&GaifoLog, &R),
) -> anyhow::Result<Vec<GaifoLog>> {
    use std::io::Write;
    let mut logs = Vec::with_capacity(iterations);
    for _ in 0..iterations {
        let (log, _) = run.iterate()?;
        progress(&log, run);
        if let Some((f, dir)) = csv.as_mut() {
            write_csv_row(f, &log, seed, algo)?;
            f.flush()?;
            run.checkpoint(dir)?;
        }
        logs.push(log);
    }
    Ok(logs)
}

/// Opens the per-iteration CSV `path` ([`CSV_HEADER`]) for appending rows. `resume_at: None`
/// starts a new file. `Some(i)`, a run resumed at iteration i, keeps the rows of iterations
/// before i and appends after them (creating the file if it is missing); rows of iteration i
/// and later — written after the checkpoint it resumes from, by a run that was stopped before
/// its next checkpoint — are dropped, as the resumed run writes them again.
pub fn open_log(path: &Path, resume_at: Option<usize>) -> anyhow::Result<std::fs::File> {
    use anyhow::Context;
    use std::io::Write;
    let Some(start) = resume_at.filter(|_| path.exists()) else {
        let mut f =
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        writeln!(f, "{CSV_HEADER}")?;
        return Ok(f);
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    anyhow::ensure!(
        lines.next() == Some(CSV_HEADER),
        "{}: not a per-iteration log of this build (its first line is not the header {CSV_HEADER:?})",
        path.display()
    );
    let mut kept = String::new();
    let mut dropped = 0;
    for (k, line) in lines.enumerate() {
        let it: usize = line
            .split(',')
            .next()
            .and_then(|c| c.parse().ok())
            .with_context(|| format!("{} line {}: no iteration number", path.display(), k + 2))?;
        if it < start {
            kept.push_str(line);
            kept.push('\n');
        } else {
            dropped += 1;
        }
    }
    if dropped > 0 {
        eprintln!(
            "{}: dropping {dropped} row(s) of iteration {start} and later, written after the \
             checkpoint this run resumes from",
            path.display()
        );
        let mut f = std::fs::File::create(path)?;
        write!(f, "{CSV_HEADER}\n{kept}")?;
        return Ok(f);
    }
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))
}

/// Runs `cfg.iterations` iterations of LQR+GAIfO on `demos` ([`run_iterations`]).
pub fn train(
    cfg: &GaifoConfig,
    demos: Demos,
    out: Option<&Path>,
    mut progress: impl FnMut(&GaifoLog),
) -> anyhow::Result<Vec<GaifoLog>> {
    let mut run = LqrGaifo::new(cfg.clone(), demos)?;
    run_iterations(
        &mut run,
        cfg.iterations,
        cfg.seed,
        "lqr-gaifo",
        out,
        |l, _| progress(l),
    )
}

/// Continues the LQR+GAIfO run whose checkpoints are in `dir` ([`LqrGaifo::resume`]) up to
/// `cfg.iterations` iterations in all, appending to `dir/gaifo_log.csv` ([`open_log`]) and
/// writing the next checkpoints into `dir`. Iterations are numbered on from the checkpoint.
pub fn train_resumed(
    cfg: &GaifoConfig,
    demos: Demos,
    dir: &Path,
    mut progress: impl FnMut(&GaifoLog),
) -> anyhow::Result<Vec<GaifoLog>> {
    let mut run = LqrGaifo::resume(cfg.clone(), demos, dir)?;
    let start = run.iteration();
    anyhow::ensure!(
        start < cfg.iterations,
        "{} already holds {start} iterations, as many as iterations = {} asks for: nothing to \
         resume (raise --iterations)",
        dir.display(),
        cfg.iterations
    );
    let csv = open_log(&dir.join("gaifo_log.csv"), Some(start))?;
    drive(
        &mut run,
        cfg.iterations - start,
        cfg.seed,
        "lqr-gaifo",
        Some((csv, dir)),
        |l, _| progress(l),
    )
}
