//! GAIfO with PPO, one iteration in LQR+GAIfO's order so that the two
//! compare step for step:
//!
//! 1. execute the MLP policy N = 5 times with noise and once without (its mean) for the
//!    evaluation ([`super::rollout::execute_mlp`], [`Learn::execute`]);
//! 2. (no dynamics model);
//! 3. update the critic on expert vs policy transitions (s, s') exactly as LQR+GAIfO does:
//!    [`crate::gaifo::refit_critic`] on the first iteration, [`crate::gaifo::train_critic`];
//! 4. reward `r_t = −D(s_t, s_{t+1})` (D is low on expert transitions, so the reward is high
//!    there);
//! 5. (no expansion);
//! 6. a PPO update ([`super::Ppo::update`]) on those 5 episodes (docs/design.md §1.5).
//!
//! The log is LQR+GAIfO's [`GaifoLog`] and its CSV row, with `algorithm = gaifo-ppo`:
//! `kl` is PPO's approximate KL(old ‖ new) per sample (LQR's is the total over T), `eta` and
//! `step_mult` are NaN (no LQR step), `t_dynamics` is 0, `t_cost` is the reward computation
//! and `t_lqr` the PPO update.

use std::time::Instant;

use faer::Mat;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::DX;

use super::rollout::execute_mlp;
use super::{Ppo, PpoConfig, UpdateStats};
use crate::cost::composite::D_IN;
use crate::demos::Demos;
use crate::discriminator::{Discriminator, DiscriminatorConfig, Normalizer};
use crate::gaifo::{
    critic_config, episode_transitions, expert_transitions, refit_critic, train_critic,
    GaifoConfig, GaifoLog,
};
use crate::learn::Learn;
use crate::rollout::{Arm, Episode};
use crate::ImitationError;

/// Settings of a GAIfO (PPO) run. Everything the two algorithms share has LQR+GAIfO's value
/// ([`Self::from_gaifo`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaifoPpoConfig {
    /// The simulated arm.
    pub sim: SimConfig,
    /// Noisy episodes per iteration N (the paper's baseline: 5, as LQR+GAIfO).
    pub samples: usize,
    /// Iterations.
    pub iterations: usize,
    /// `Discriminator::train` calls per iteration (LQR+GAIfO's).
    pub critic_updates: usize,
    /// Half-life of the critic's learning rate, iterations; 0 = constant (LQR+GAIfO's).
    pub critic_lr_half_life: f64,
    /// The critic (LQR+GAIfO's).
    pub discriminator: DiscriminatorConfig,
    /// Seed of every random draw (noise, critic, nets, minibatches).
    pub seed: u64,
    /// PPO.
    pub ppo: PpoConfig,
}

impl Default for GaifoPpoConfig {
    fn default() -> Self {
        Self::from_gaifo(&GaifoConfig::default())
    }
}

impl GaifoPpoConfig {
    /// LQR+GAIfO's arm, N, iterations, critic and seed; PPO's defaults, with the initial σ
    /// from LQR+GAIfO's initial variance.
    pub fn from_gaifo(g: &GaifoConfig) -> Self {
        Self {
            sim: g.sim.clone(),
            samples: g.samples,
            iterations: g.iterations,
            critic_updates: g.critic_updates,
            critic_lr_half_life: g.critic_lr_half_life,
            discriminator: g.discriminator.clone(),
            seed: g.seed,
            ppo: PpoConfig {
                init_std: g.init_var.sqrt(),
                ..PpoConfig::default()
            },
        }
    }
}

/// The state of a GAIfO (PPO) run.
pub struct GaifoPpo {
    cfg: GaifoPpoConfig,
    task: TaskConfig,
    demos: Demos,
    expert: Mat<f64>,
    disc: Discriminator,
    disc_ws: crate::discriminator::Workspace,
    ppo: Ppo,
    iteration: usize,
    /// Statistics of the last PPO update.
    pub last_update: UpdateStats,
}

/// Rewards `r_t = −D(s_t, s_{t+1})` of every transition of every episode.
pub fn critic_rewards(
    disc: &Discriminator,
    ws: &mut crate::discriminator::Workspace,
    episodes: &[Episode],
) -> Vec<Vec<f64>> {
    let mut x = [0.0; D_IN];
    episodes
        .iter()
        .map(|ep| {
            (0..ep.horizon() - 1)
                .map(|t| {
                    x[..DX].copy_from_slice(&ep.x[t * DX..(t + 1) * DX]);
                    x[DX..].copy_from_slice(&ep.x[(t + 1) * DX..(t + 2) * DX]);
                    -disc.value(&x, ws)
                })
                .collect()
        })
        .collect()
}

impl GaifoPpo {
    /// Sets up a run imitating `demos` (the task is theirs).
    pub fn new(cfg: GaifoPpoConfig, demos: Demos) -> Result<Self, ImitationError> {
        let task = demos.task()?;
        let expert = expert_transitions(&demos);
        let norm = Normalizer::from_data(expert.as_ref())?;
        let disc = Discriminator::new(D_IN, critic_config(&cfg.discriminator, cfg.seed), norm)?;
        let ppo = Ppo::new(cfg.ppo.clone(), cfg.sim.mode, cfg.seed ^ 0x5050_4f00) // "PPO"
            .map_err(ImitationError::Ppo)?;
        Ok(Self {
            disc_ws: disc.workspace(),
            iteration: 0,
            last_update: UpdateStats::default(),
            cfg,
            task,
            demos,
            expert,
            disc,
            ppo,
        })
    }

    /// PPO (nets, optimiser).
    pub fn ppo(&self) -> &Ppo {
        &self.ppo
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
    pub fn config(&self) -> &GaifoPpoConfig {
        &self.cfg
    }
}

impl Learn for GaifoPpo {
    type Log = GaifoLog;
    const ALGO: &'static str = "gaifo-ppo";

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
        self.iteration
    }
    fn done(&self) -> bool {
        self.iteration >= self.cfg.iterations
    }

    /// Step 1: the MLP policy with noise, and its mean for the evaluation.
    fn execute(&mut self, arm: &mut dyn Arm) -> Result<(Vec<Episode>, Episode), ImitationError> {
        let (version, seed, n) = (self.version(), self.cfg.seed, self.cfg.samples);
        let (pol, ws) = self.ppo.policy_and_workspace();
        execute_mlp(arm, &self.task, pol, ws, version, seed, n)
    }

    /// Steps 3, 4 and 6 of the module docs on the episodes of the current policy.
    fn learn(
        &mut self,
        episodes: &[Episode],
        eval: &Episode,
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        // 3. Update the critic on (s, s') of the policy vs the expert.
        let t1 = Instant::now();
        let c1 = crate::cpu::thread_cpu_s();
        let controller = episode_transitions(episodes);
        if self.iteration == 0 {
            self.disc = refit_critic(&self.expert, &controller, self.disc.config())?;
            self.disc_ws = self.disc.workspace();
        }
        let critic = train_critic(
            &mut self.disc,
            &mut self.disc_ws,
            &self.expert,
            &controller,
            self.cfg.critic_updates,
            self.iteration,
            self.cfg.critic_lr_half_life,
        )?;
        // 4. Reward from the critic.
        let t2 = Instant::now();
        let rewards = critic_rewards(&self.disc, &mut self.disc_ws, episodes);
        // 6. PPO update.
        let t3 = Instant::now();
        let st = self.ppo.update(episodes, &rewards);
        let t4 = Instant::now();
        let cpu_learner = crate::cpu::thread_cpu_s() - c1;

        let log = GaifoLog {
            kl: st.approx_kl,
            t_execute,
            t_critic: (t2 - t1).as_secs_f64(),
            t_cost: (t3 - t2).as_secs_f64(),
            t_lqr: (t4 - t3).as_secs_f64(),
            cpu_learner,
            ..GaifoLog::evaluated(self.iteration, eval, &self.demos, &critic)
        };
        self.last_update = st;
        self.iteration += 1;
        Ok(log)
    }

    fn eval_cost(log: &GaifoLog) -> f64 {
        log.task_cost
    }
}
