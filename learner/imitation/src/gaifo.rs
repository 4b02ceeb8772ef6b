//! LQR+GAIfO (Torabi et al. 2019, Algorithm 1; docs/design.md §1). One function per step of
//! the algorithm, called in the paper's order by [`LqrGaifo::learn`]:
//!
//! 1. execute the controller N times with noise and once without ([`crate::learn::Learn::execute`]
//!    in process, or the real-time loop over IPC);
//! 2. `update_dynamics`: refit p(s'|s,a) = N(F_t [s;a] + f_t, Σ_t) (GMM prior + regression);
//! 3. [`LqrGaifo::update_discriminator`]: WGAN-GP steps on expert vs controller transitions;
//! 4. [`CompositeCost`] in [`LqrIteration::expand`]: C_t(s,a) = D(s, F_t [s;a] + f_t) and
//! 5. its second-order expansion around the samples;
//! 6. [`LqrIteration::improve`]: the KL-bounded LQR step.
//!
//! [`LqrGaifo::learn`] is steps 2–6 (and the switch to the new controller) on episodes executed
//! elsewhere: `learner train` executes them in process, `learner serve --algo lqr-gaifo` gets
//! them from the real-time loop. Same episodes, same result.
//!
//! # Checkpoints and resuming
//! A checkpoint (written by the `learner` application before every iteration) holds the
//! critic (weights, input normalisation, Adam moments and step count, minibatch RNG position)
//! and the rest of the run's state as a [`Snapshot`] ([`LqrGaifo::snapshot`]: the controller
//! executed next and the previous one with every array, the GMM dynamics prior and the
//! trajectories it is fitted on, the trajectory info, η, the step multiplier, the prior's RNG
//! position, the iteration). [`LqrGaifo::from_snapshot`] continues from one exactly: the same
//! episodes, critic updates, dynamics fits and LQR steps as the uninterrupted run, bit for bit
//! (docs/design.md §4.11). The exploration noise needs no state: it is a function of (seed,
//! table version, episode).
//!
//! Only state transitions of the expert are used (`Demos::states`); its actions are never read.

use std::time::Instant;

use faer::Mat;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{SimConfig, TaskConfig};

use crate::controller::init_hold;
use crate::cost::composite::{CompositeCost, CompositeWorkspace};
use crate::cost::tracking::{Tracking, WithTracking};
use crate::cpu::thread_cpu_s;
use crate::critic::{
    episode_transitions, expert_transitions, with_phase, with_terminal_pairs, Critic,
};
use crate::demos::Demos;
use crate::discriminator::{Discriminator, TrainStats};
use crate::iteration::LqrIteration;
pub use crate::iteration_log::GaifoLog;
use crate::learn::{Learn, LinGaussLearn};
use crate::rollout::{Arms, Episode, SampleList};
/// LQR+GAIfO's settings; they live in [`crate::settings`] because MDGPS runs each of its
/// conditions with them and GAIfO (PPO) takes its shared values from them.
pub use crate::settings::GaifoConfig;
use crate::ImitationError;
use gps::algorithm::update::Learner;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::snapshot::Snapshot;

/// The state of an LQR+GAIfO run; [`LqrGaifo::learn`] runs steps 2–6 of Algorithm 1.
pub struct LqrGaifo {
    cfg: GaifoConfig,
    task: TaskConfig,
    demos: Demos,
    lqr: LqrIteration,
    critic: Critic,
    cost_ws: CompositeWorkspace,
    /// The demonstrations' per-step tracking term when `cfg.path.tracking_weight` > 0.
    tracking: Option<Tracking>,
}

/// The critic's rows for trajectories of horizon `horizon` (the demonstrations' or the noisy
/// episodes'): their `transitions`, with the phase when the critic takes it (docs/design.md §5
/// D39), then the resting pairs of their `finals` (§5 D44). Expert and controller rows are built
/// alike here, so the critic sees both sides in one layout.
fn critic_rows(
    cfg: &GaifoConfig,
    transitions: Mat<f64>,
    horizon: usize,
    finals: &[&[f64]],
) -> Mat<f64> {
    let rows = if cfg.path.critic_phase {
        with_phase(&transitions, horizon)
    } else {
        transitions
    };
    with_terminal_pairs(rows, finals, cfg.critic_terminal_pairs)
}

impl LqrGaifo {
    /// Sets up a run imitating `demos` (the task — goal, start pose, T, dt — is theirs).
    pub fn new(cfg: GaifoConfig, demos: Demos) -> Result<Self, ImitationError> {
        cfg.validate()?;
        let task = demos.task()?;
        let finals: Vec<&[f64]> = (0..demos.count)
            .map(|d| demos.state(d, demos.horizon - 1))
            .collect();
        let expert = critic_rows(&cfg, expert_transitions(&demos), demos.horizon, &finals);
        let critic = Critic::from_settings(expert, cfg.critic(), cfg.seed)?;
        let tracking = if cfg.path.tracking_weight > 0.0 {
            Some(Tracking::from_demos(
                &demos,
                cfg.path.tracking_weight,
                cfg.path.tracking_floor,
            )?)
        } else {
            None
        };
        let learner = Learner::new(
            cfg.algorithm_for(task.layout().du()),
            cfg.prior.clone(),
            cfg.fit.clone(),
            cfg.traj_opt.clone(),
            task.horizon,
            task.layout().dx(),
            task.layout().du(),
            cfg.samples,
            ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x474d_4d00),
        );
        let pol = init_hold(&task, cfg.init_var);
        Ok(Self {
            cost_ws: CompositeWorkspace::new(critic.discriminator()).with_psd(cfg.psd_hessian),
            lqr: LqrIteration::new(learner, pol, 0),
            cfg,
            task,
            demos,
            critic,
            tracking,
        })
    }

    /// The controller that the next iteration executes.
    pub fn policy(&self) -> &LinGaussPolicy {
        self.lqr.policy()
    }

    /// The critic.
    pub fn discriminator(&self) -> &Discriminator {
        self.critic.discriminator()
    }

    /// The critic with its expert transitions and schedule (its checkpoint: [`Critic::save`]).
    pub fn critic(&self) -> &Critic {
        &self.critic
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
        self.lqr.iteration()
    }

    /// Gain-table version of [`LqrGaifo::policy`]: iteration + 1 (the initial controller is 1).
    pub fn version(&self) -> u64 {
        self.iteration() as u64 + 1
    }

    /// `cfg.iterations` done.
    pub fn done(&self) -> bool {
        self.iteration() >= self.cfg.iterations
    }

    /// Step 3 of Algorithm 1 (docs/design.md §1.3): the critic's update on expert vs these
    /// controller transitions ([`Critic::update`]: refitted at iteration 0, then
    /// `critic_updates` WGAN-GP calls).
    pub fn update_discriminator(
        &mut self,
        controller: &Mat<f64>,
    ) -> Result<TrainStats, ImitationError> {
        self.critic.update(controller, self.lqr.iteration())
    }

    /// Steps 2–6 of Algorithm 1 (docs/design.md §1.3) on the `episodes` (`cfg.samples` noisy ones) and the noise-free
    /// `eval` episode executed with [`LqrGaifo::policy`] (as table version
    /// [`LqrGaifo::version`]); then that controller is replaced by the new one. `t_execute`
    /// (s) is logged as the time step 1 took.
    pub fn learn(
        &mut self,
        episodes: &[Episode],
        eval: &Episode,
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        let (n, t_len) = (self.cfg.samples, self.task.horizon);
        if episodes.len() != n || episodes.iter().chain([eval]).any(|e| e.horizon() != t_len) {
            return Err(ImitationError::Episodes(format!(
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
        let iteration = self.lqr.iteration();
        let samples = SampleList::new(episodes);
        // 2. Fit the dynamics.
        let t1 = Instant::now();
        let c1 = thread_cpu_s();
        self.lqr.fit_dynamics(&samples)?;
        // 3. Update the discriminator on (s, s') of the controller vs the expert.
        let t2 = Instant::now();
        let finals: Vec<&[f64]> = episodes.iter().map(|e| e.state(t_len - 1)).collect();
        let controller = critic_rows(&self.cfg, episode_transitions(episodes), t_len, &finals);
        let critic = self.update_discriminator(&controller)?;
        // 4–5. Composite cost D(s, F_t[s;a] + f_t) (plus the tracking term, when on) and its
        // second-order expansion.
        let t3 = Instant::now();
        let mut cost = WithTracking {
            inner: CompositeCost {
                disc: self.critic.cost_discriminator(),
                ws: &mut self.cost_ws,
            },
            inner_weight: self.cfg.path.critic_weight,
            tracking: self.tracking.as_ref(),
        };
        self.lqr.expand(&mut cost, episodes);
        // 6. KL-bounded LQR step.
        let t4 = Instant::now();
        let step = self.lqr.improve(&samples, self.cfg.adapt_step)?;
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
            demo_gap: crate::iteration_log::demo_gap(episodes, &self.demos),
            ..GaifoLog::evaluated(iteration, eval, &self.demos, &critic)
        };
        Ok(log)
    }

    /// Everything but the critic that the next iteration depends on (module docs); the critic
    /// is saved on its own ([`Discriminator::save`]).
    pub fn snapshot(&self) -> Snapshot {
        let mut s = Snapshot::default();
        self.lqr.snapshot(&mut s);
        s
    }

    /// A run that continues exactly where the run whose [`LqrGaifo::snapshot`] is `snap` and
    /// whose critic is `disc` stood (a checkpoint: `learner train --resume`). The critic must
    /// have been trained with this run's settings and seed, and the snapshot taken of a run on
    /// demonstrations of the same horizon with the same settings.
    pub fn from_snapshot(
        cfg: GaifoConfig,
        demos: Demos,
        snap: &Snapshot,
        disc: Discriminator,
    ) -> Result<Self, ImitationError> {
        let mut run = Self::new(cfg, demos)?;
        run.critic.restore(disc)?;
        run.lqr.restore(snap).map_err(|e| {
            ImitationError::Checkpoint(format!(
                "{e} (a checkpoint of another task horizon or other settings: resume with the \
                 run's own demonstrations and --config)"
            ))
        })?;
        Ok(run)
    }
}

impl Learn for LqrGaifo {
    type Log = GaifoLog;
    const ALGO: &'static str = "lqr-gaifo";

    fn task(&self) -> &TaskConfig {
        &self.task
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
        LqrGaifo::iteration(self)
    }
    fn done(&self) -> bool {
        LqrGaifo::done(self)
    }
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        crate::learn::execute_table(self, arms)
    }
    fn learn_goals(
        &mut self,
        noisy: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        LqrGaifo::learn(self, noisy, crate::learn::single_eval(evals)?, t_execute)
    }
    fn eval_cost(log: &GaifoLog) -> f64 {
        log.task_cost
    }
}

impl LinGaussLearn for LqrGaifo {
    fn policy(&self) -> &LinGaussPolicy {
        self.lqr.policy()
    }
}
