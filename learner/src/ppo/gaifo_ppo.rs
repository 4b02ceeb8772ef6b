//! GAIfO with PPO, in process (lockstep), one iteration in LQR+GAIfO's order so that the two
//! compare step for step:
//!
//! 1. execute the MLP policy N = 5 times with noise and once without (its mean) for the
//!    evaluation ([`super::rollout::execute_mlp`]);
//! 2. (no dynamics model);
//! 3. update the critic on expert vs policy transitions (s, s') exactly as LQR+GAIfO does:
//!    [`crate::gaifo::refit_critic`] on the first iteration, [`crate::gaifo::train_critic`];
//! 4. reward `r_t = −D(s_t, s_{t+1})` (D is low on expert transitions, so the reward is high
//!    there);
//! 5. a PPO update ([`super::Ppo::update`]) on those 5 episodes.
//!
//! The log is LQR+GAIfO's [`GaifoLog`] and its CSV row, with `algorithm = gaifo-ppo`:
//! `kl` is PPO's approximate KL(old ‖ new) per sample (LQR's is the total over T), `eta` and
//! `step_mult` are NaN (no LQR step), `t_dynamics` is 0, `t_cost` is the reward computation
//! and `t_lqr` the PPO update.

use std::path::{Path, PathBuf};
use std::time::Instant;

use faer::Mat;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::DX;

use super::rollout::execute_mlp;
use super::{Ppo, PpoConfig, UpdateStats};
use crate::cost::composite::D_IN;
use crate::discriminator::{Discriminator, DiscriminatorConfig, Normalizer};
use crate::gaifo::{
    critic_config, episode_transitions, expert_transitions, refit_critic, run_iterations,
    train_critic, GaifoConfig, GaifoLog, Imitation,
};
use crate::io::demos::Demos;
use crate::iteration::sim_err;
use crate::rollout::Episode;
use crate::LearnerError;
use hil_sim::Ur5Sim;

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
    sim: Ur5Sim,
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
    pub fn new(cfg: GaifoPpoConfig, demos: Demos) -> Result<Self, LearnerError> {
        let task = TaskConfig {
            dt: demos.dt,
            horizon: demos.horizon,
            start_q: demos.start_q,
            goal: demos.goal,
        };
        task.validate()
            .map_err(|e| LearnerError::Shape(format!("demonstrations: {e}")))?;
        let sim = Ur5Sim::new(cfg.sim.clone(), task.dt).map_err(sim_err)?;
        let expert = expert_transitions(&demos);
        let norm = Normalizer::from_data(expert.as_ref())
            .map_err(|e| LearnerError::Shape(e.to_string()))?;
        let disc = Discriminator::new(D_IN, critic_config(&cfg.discriminator, cfg.seed), norm)
            .map_err(|e| LearnerError::Shape(e.to_string()))?;
        let ppo = Ppo::new(cfg.ppo.clone(), cfg.sim.mode, cfg.seed ^ 0x5050_4f00) // "PPO"
            .map_err(LearnerError::Shape)?;
        Ok(Self {
            disc_ws: disc.workspace(),
            iteration: 0,
            last_update: UpdateStats::default(),
            cfg,
            task,
            demos,
            expert,
            sim,
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

    /// One iteration; returns its log and the noise-free episode.
    pub fn iterate(&mut self) -> Result<(GaifoLog, Episode), LearnerError> {
        let n = self.cfg.samples;
        let version = self.iteration as u64 + 1;
        // 1. Execute the policy.
        let t0 = Instant::now();
        let (pol, ws) = self.ppo.policy_and_workspace();
        let (episodes, eval) = execute_mlp(
            &mut self.sim,
            &self.task,
            pol,
            ws,
            version,
            self.cfg.seed,
            n,
        )?;
        // 3. Update the critic on (s, s') of the policy vs the expert.
        let t1 = Instant::now();
        let c1 = crate::bench::thread_cpu_s();
        let controller = episode_transitions(&episodes);
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
        )?;
        // 4. Reward from the critic.
        let t2 = Instant::now();
        let rewards = critic_rewards(&self.disc, &mut self.disc_ws, &episodes);
        // 5. PPO.
        let t3 = Instant::now();
        let st = self.ppo.update(&episodes, &rewards);
        let t4 = Instant::now();
        let cpu_learner = crate::bench::thread_cpu_s() - c1;

        let log = GaifoLog {
            kl: st.approx_kl,
            t_execute: (t1 - t0).as_secs_f64(),
            t_critic: (t2 - t1).as_secs_f64(),
            t_cost: (t3 - t2).as_secs_f64(),
            t_lqr: (t4 - t3).as_secs_f64(),
            cpu_learner,
            ..GaifoLog::evaluated(self.iteration, &eval, &self.demos, &critic)
        };
        self.last_update = st;
        self.iteration += 1;
        Ok((log, eval))
    }

    /// Saves the policy that the next iteration executes (`iter_NNN_policy.json`) and the
    /// critic (`iter_NNN_critic.json`) into `dir`.
    pub fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        std::fs::create_dir_all(dir)?;
        let i = self.iteration;
        let pol = dir.join(format!("iter_{i:03}_policy.json"));
        let file = self.ppo.actor_critic().policy_file(&self.cfg.ppo.pi_hidden);
        std::fs::write(&pol, serde_json::to_vec(&file)?)?;
        let critic = dir.join(format!("iter_{i:03}_critic.json"));
        self.disc.save(&critic)?;
        Ok((pol, critic))
    }
}

/// Runs `cfg.iterations` iterations on `demos`, calling `progress` after each (with the PPO
/// statistics of that iteration), writing `gaifo_log.csv` (LQR+GAIfO's columns,
/// `algorithm = gaifo-ppo`) and per-iteration checkpoints into `out` when it is given.
pub fn train(
    cfg: &GaifoPpoConfig,
    demos: Demos,
    out: Option<&Path>,
    mut progress: impl FnMut(&GaifoLog, &UpdateStats),
) -> anyhow::Result<Vec<GaifoLog>> {
    let mut run = GaifoPpo::new(cfg.clone(), demos)?;
    run_iterations(
        &mut run,
        cfg.iterations,
        cfg.seed,
        "gaifo-ppo",
        out,
        |l, r| progress(l, &r.last_update),
    )
}

impl Imitation for GaifoPpo {
    fn iterate(&mut self) -> Result<(GaifoLog, Episode), LearnerError> {
        GaifoPpo::iterate(self)
    }
    fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        GaifoPpo::checkpoint(self, dir)
    }
}

fn print_line(l: &GaifoLog, u: &UpdateStats) {
    eprintln!(
        "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>9.4} {:>8.4} {:>9.2e} {:>6.3} {:>7.3} {:>9.3e} {:>7.1} {:>7.1}",
        l.iteration,
        l.task_cost,
        l.performance,
        l.final_distance,
        l.critic_loss,
        l.wasserstein,
        l.kl,
        u.clip_fraction,
        u.mean_std,
        u.value_loss,
        1e3 * (l.t_critic + l.t_cost + l.t_lqr),
        1e3 * l.t_execute
    );
}

/// `learner train --algo gaifo-ppo` with `pcfg` (its `--config` layered over
/// [`GaifoPpoConfig::default`], i.e. LQR+GAIfO's shared settings, then the command line).
pub fn run_cli(
    args: &crate::train_cli::TrainArgs,
    demos: Demos,
    pcfg: &GaifoPpoConfig,
) -> anyhow::Result<()> {
    let pcfg = pcfg.clone();
    let out = args.out_dir();
    eprintln!(
        "GAIfO (PPO) on {} demonstrations of T = {} (goal {:?} m), seed {}, -> {}",
        demos.count,
        demos.horizon,
        demos.goal,
        pcfg.seed,
        out.display()
    );
    eprintln!(
        "{:>4} {:>9} {:>7} {:>8} {:>9} {:>8} {:>9} {:>6} {:>7} {:>9} {:>7} {:>7}",
        "iter",
        "task_cost",
        "perf",
        "final_m",
        "critic",
        "W1_est",
        "approx_kl",
        "clip",
        "std",
        "v_loss",
        "lrn_ms",
        "sim_ms"
    );
    let logs = train(&pcfg, demos, Some(&out), print_line)?;
    crate::train_cli::report(&logs, "gaifo-ppo", pcfg.seed, &out, args.json);
    Ok(())
}
