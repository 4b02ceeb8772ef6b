//! GAIfO with PPO, one iteration in LQR+GAIfO's order so that the two
//! compare step for step:
//!
//! 1. execute the MLP policy N = 5 times with noise and once without (its mean) for the
//!    evaluation ([`super::rollout::execute_mlp`], [`Learn::execute`]);
//! 2. (no dynamics model);
//! 3. update the critic on expert vs policy transitions (s, s') exactly as LQR+GAIfO does:
//!    the same [`Critic`] (refitted on the first iteration, then trained);
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

use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};

use super::rollout::execute_mlp;
use super::{Ppo, PpoConfig, UpdateStats};
use crate::critic::{episode_transitions, expert_transitions, Critic};
use crate::demos::Demos;
use crate::discriminator::{Discriminator, DiscriminatorConfig};
use crate::iteration_log::GaifoLog;
use crate::learn::Learn;
use crate::rollout::{Arms, Episode};
use crate::settings::{CriticSettings, GaifoConfig, MAX_COUNT};
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
    /// Where PPO's reward comes from: the critic (GAIfO, the default) or, as a diagnostic
    /// only, the true task cost (then it is reinforcement learning, not imitation: used to
    /// tell PPO's own behaviour from the critic's, docs/design.md §5 D14).
    pub reward: PpoReward,
}

/// PPO's reward ([`GaifoPpoConfig::reward`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PpoReward {
    /// `r_t = −D(s_t, s_{t+1})`: GAIfO.
    #[default]
    Critic,
    /// `r_t = −((t+1)/n) d_{t+1}`, and `−d_n` more on the last transition, so that the
    /// episode's return is `−C(τ) + 0·d_0` (`ur5_shared::cost`): RL with the task cost, a
    /// diagnostic that sees the goal; not imitation from observation.
    TaskCost,
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
            reward: PpoReward::Critic,
        }
    }

    /// The critic's settings.
    pub fn critic(&self) -> CriticSettings<'_> {
        CriticSettings::new(
            self.critic_updates,
            self.critic_lr_half_life,
            &self.discriminator,
        )
    }

    /// Refuses settings that cannot work, naming the setting and its range (counts up to
    /// [`MAX_COUNT`]; the critic as [`CriticSettings::validate`]; PPO as
    /// [`PpoConfig::validate`]).
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_counts(
            &[
                ("samples", self.samples, 1),
                ("iterations", self.iterations, 1),
            ],
            MAX_COUNT,
        )
        .map_err(ImitationError::Config)?;
        self.critic().validate()?;
        self.sim
            .validate()
            .map_err(|e| ImitationError::Config(e.to_string()))?;
        self.ppo.validate().map_err(ImitationError::Ppo)
    }
}

/// Rewards of [`PpoReward::TaskCost`] for every transition of every episode: the episode's
/// return is `−C(τ)` less its `d_0` term, which no action changes (d the distance of every
/// tool point to its target, `ur5_shared::cost::goal_distance`).
pub fn task_rewards(episodes: &[Episode]) -> Vec<Vec<f64>> {
    episodes
        .iter()
        .map(|ep| {
            let n = ep.horizon() - 1;
            (0..n)
                .map(|t| {
                    let d = ur5_shared::cost::goal_distance(&ep.layout, ep.state(t + 1));
                    let w = (t + 1) as f64 / n as f64 + if t + 1 == n { 1.0 } else { 0.0 };
                    -w * d
                })
                .collect()
        })
        .collect()
}

/// The state of a GAIfO (PPO) run.
pub struct GaifoPpo {
    cfg: GaifoPpoConfig,
    task: TaskConfig,
    demos: Demos,
    critic: Critic,
    ppo: Ppo,
    iteration: usize,
    /// Statistics of the last PPO update.
    pub last_update: UpdateStats,
}

impl GaifoPpo {
    /// Sets up a run imitating `demos` (the task is theirs; the nets take its layout's dX and
    /// dU).
    pub fn new(cfg: GaifoPpoConfig, demos: Demos) -> Result<Self, ImitationError> {
        cfg.validate()?;
        let task = demos.task()?;
        let critic = Critic::from_settings(expert_transitions(&demos), cfg.critic(), cfg.seed)?;
        let ppo = Ppo::new(
            cfg.ppo.clone(),
            cfg.sim.mode,
            task.layout(),
            cfg.seed ^ 0x5050_4f00, // "PPO"
        )
        .map_err(ImitationError::Ppo)?;
        Ok(Self {
            iteration: 0,
            last_update: UpdateStats::default(),
            cfg,
            task,
            demos,
            critic,
            ppo,
        })
    }

    /// PPO (nets, optimiser).
    pub fn ppo(&self) -> &Ppo {
        &self.ppo
    }

    /// The critic.
    pub fn discriminator(&self) -> &Discriminator {
        self.critic.discriminator()
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

    crate::learn::run_accessors!();

    /// Step 1: the MLP policy with noise, and its mean for the evaluation.
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        let (version, seed, n) = (self.version(), self.cfg.seed, self.cfg.samples);
        let (pol, _) = self.ppo.policy_and_workspace();
        let (noisy, eval) = execute_mlp(arms, &self.task, pol, version, seed, n)?;
        Ok((noisy, vec![eval]))
    }

    /// Steps 3, 4 and 6 of the module docs on the episodes of the current policy.
    fn learn_goals(
        &mut self,
        episodes: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        let eval = crate::learn::single_eval(evals)?;
        // 3. Update the critic on (s, s') of the policy vs the expert.
        let t1 = Instant::now();
        let c1 = crate::cpu::thread_cpu_s();
        let controller = episode_transitions(episodes);
        let critic = self.critic.update(&controller, self.iteration)?;
        // 4. Reward from the critic.
        let t2 = Instant::now();
        let rewards = match self.cfg.reward {
            PpoReward::Critic => self.critic.rewards(episodes),
            PpoReward::TaskCost => task_rewards(episodes),
        };
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

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::layout::{DX, EE_MINUS_GOAL};

    #[test]
    fn settings_that_cannot_work_are_refused_naming_the_setting() {
        assert!(GaifoPpoConfig::default().validate().is_ok());
        let cases: Vec<(&str, Box<dyn Fn(&mut GaifoPpoConfig)>)> = vec![
            ("samples", Box::new(|c| c.samples = 0)),
            ("samples", Box::new(|c| c.samples = 1_000_000_000)),
            ("iterations", Box::new(|c| c.iterations = 1_000_000_000_000)),
            ("critic_updates", Box::new(|c| c.critic_updates = 0)),
            (
                "critic_lr_half_life",
                Box::new(|c| c.critic_lr_half_life = f64::NAN),
            ),
            (
                "n_critic/batch_size",
                Box::new(|c| c.discriminator.batch_size = 0),
            ),
            (
                "pi_hidden",
                Box::new(|c| c.ppo.pi_hidden = vec![1_000_000_000]),
            ),
            ("v_hidden", Box::new(|c| c.ppo.v_hidden = vec![])),
            ("init_std", Box::new(|c| c.ppo.init_std = 1e300)),
            ("gamma", Box::new(|c| c.ppo.gamma = f64::NAN)),
            ("clip_range", Box::new(|c| c.ppo.clip_range = -0.2)),
            ("epochs", Box::new(|c| c.ppo.epochs = 1_000_000_000)),
            ("minibatch", Box::new(|c| c.ppo.minibatch = 0)),
        ];
        crate::error::assert_each_refused_naming(cases, GaifoPpoConfig::validate);
    }

    /// The task-cost rewards of an episode add up to −C(τ) + 0·d_0 (`ur5_shared::cost`).
    #[test]
    fn task_rewards_return_minus_the_task_cost() {
        let t = 7;
        let mut ep = Episode {
            layout: ur5_shared::StateLayout::REACH3,
            x: vec![0.0; t * DX],
            u: vec![],
            u_policy: vec![],
            eps: vec![],
            noisy: false,
        };
        let mut states = Vec::new();
        for i in 0..t {
            let s = &mut ep.x[i * DX..(i + 1) * DX];
            s[EE_MINUS_GOAL][0] = 0.3 / (1.0 + i as f64);
            s[EE_MINUS_GOAL][2] = -0.1 * (i % 3) as f64;
            states.push(<[f64; DX]>::try_from(&*s).unwrap());
        }
        let r = task_rewards(std::slice::from_ref(&ep));
        assert_eq!(r[0].len(), t - 1);
        let ret: f64 = r[0].iter().sum();
        let c = ur5_shared::cost::task_cost_from_states(&states).unwrap();
        // d_0 has weight 0 in C(τ).
        assert!((ret + c).abs() < 1e-12, "return {ret} vs −C {}", -c);
    }
}
