//! Off-policy GAIfO: the WGAN-GP critic D(s, s') of the other imitation learners as the reward
//! of TD3 (Fujimoto et al. 2018) with a replay buffer, in the manner of Discriminator-Actor-
//! Critic (DAC, Kostrikov et al. 2019) but from observations only (docs/design.md §1.8).
//!
//! One iteration, in LQR+GAIfO's order so that the learners compare step for step:
//!
//! 1. execute the actor N times with exploration noise and once without (its mean), the same
//!    episode loop and noise streams as every learner ([`Learn::execute`]);
//! 2. (no dynamics model) add the N episodes' transitions to the replay buffer ([`replay`]);
//! 3. update the critic on expert vs this iteration's transitions, exactly as LQR+GAIfO and
//!    GAIfO (PPO) do ([`Critic::update`]);
//! 4. (the reward) `r = −c (D(s, s') − D̄_E) / σ_D` (c = `reward_scale`) of every sampled row,
//!    recomputed from the critic of the moment for each minibatch, as DAC recomputes its
//!    reward; D̄_E is the critic's mean on the expert transitions and σ_D its standard deviation
//!    on expert ∪ this iteration's transitions, both taken after the critic's update;
//! 5. (no expansion);
//! 6. `updates_per_episode × N` TD3 gradient steps on minibatches from the buffer ([`td3`]).
//!
//! Why TD3 and not SAC: TD3's behaviour policy, a deterministic MLP plus Gaussian noise of fixed
//! σ, is exactly the policy-table law the real-time controller already runs
//! (a = q + μ(u) + σ ⊙ ε, `ur5_shared::policy`), so the actor is published as a policy table
//! and its noisy episodes run on the arm bit for bit as in process; SAC's tanh-squashed Gaussian
//! with a state-dependent σ would need a new controller law, and its entropy temperature is one
//! more quantity tuned online. TD3 is also deterministic given its noise draws, and simpler to
//! test against hand-computed values.
//!
//! Why `−D`: the critic is a Wasserstein critic, not a classifier; its value is an unbounded
//! score, low on expert transitions, so DAC's `log D − log(1 − D)` and GAIL's `−log(1 − D)`
//! (which need D ∈ (0, 1)) do not apply. `−D` is the reward GAIfO (PPO) takes from the same
//! critic, so the two baselines differ in the policy learner only. Why centred and scaled: a
//! Wasserstein critic is defined up to an additive constant, which drifts from update to
//! update, and PPO's advantages are blind to it while TD3's bootstrapped values are not (a
//! shift c moves every Q by c / (1 − γ)); centred on the expert, the reward is about 0 where the
//! expert goes and negative elsewhere, in units of the critic's spread (measured: without it the
//! TD targets chase the drift and the arm runs away; docs/design.md §1.8).
//!
//! Absorbing states (DAC §4.2): the reaching tasks' episodes end at the time limit T only, and
//! DAC treats a time limit as no termination: the last transition bootstraps from Q'(s_T,
//! π'(s_T)) like any other ([`replay::RowKind::Step`]). An episode that terminates
//! ([`EpisodeEnd::Terminated`]) ends in the absorbing state instead: its last transition
//! bootstraps from Q'(s_a, 0), and the buffer gets the absorbing state's own transition, whose
//! reward is that of the terminal state held still, the pair (s_T, s_T).

pub mod replay;
mod resume;
pub mod td3;

use std::time::Instant;

use faer::Mat;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{ActionMode, ArmLimits, SimConfig, TaskConfig};
use ur5_shared::joints::Joints;

use crate::critic::{episode_transitions, expert_transitions, Critic};
use crate::demos::Demos;
use crate::discriminator::{Discriminator, DiscriminatorConfig, Normalizer};
use crate::iteration_log::GaifoLog;
use crate::learn::Learn;
use crate::mlp_policy::action_base;
use crate::mlp_policy::global::GlobalPolicy;
use crate::rollout::{execute, Arms, Episode};
use crate::settings::{CriticSettings, GaifoConfig, MAX_COUNT};
use crate::ImitationError;
use replay::{ReplayBuffer, RowKind};
use td3::{Minibatch, Td3, Td3Config};

/// Settings of an off-policy GAIfO run. Everything it shares with LQR+GAIfO (arm, N,
/// iterations, critic, seed) has LQR+GAIfO's value ([`Self::from_gaifo`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaifoTd3Config {
    /// The simulated arm.
    pub sim: SimConfig,
    /// Noisy episodes per iteration N (LQR+GAIfO's 5).
    pub samples: usize,
    /// Iterations.
    pub iterations: usize,
    /// `Discriminator::train` calls per iteration (LQR+GAIfO's).
    pub critic_updates: usize,
    /// Half-life of the critic's learning rate, iterations; 0 = constant (LQR+GAIfO's).
    pub critic_lr_half_life: f64,
    /// The critic (LQR+GAIfO's).
    pub discriminator: DiscriminatorConfig,
    /// Seed of every random draw (noise, critic, nets, minibatches, smoothing noise).
    pub seed: u64,
    /// Exploration σ of the noisy episodes, in units of the per-step action bound (TD3: 0.1;
    /// ours 0.5, from the search).
    pub exploration_noise: f64,
    /// TD3 gradient steps per noisy episode collected (DAC: one per environment step, i.e. T
    /// per episode; ours 100, from the search).
    pub updates_per_episode: usize,
    /// Rows the replay buffer holds (the oldest are overwritten). Its rows are part of every
    /// checkpoint: 27 f64 each on the reaching task.
    pub buffer_capacity: usize,
    /// c in r = −c (D(s, s') − D̄_E) / σ_D (module docs).
    pub reward_scale: f64,
    /// What the critic D is trained on against the expert each iteration: this iteration's
    /// transitions, as LQR+GAIfO and GAIfO (PPO) train it, or as many rows drawn uniformly from
    /// the replay buffer, as DAC trains its discriminator (the rewards are taken on buffer rows).
    pub critic_data: CriticData,
    /// Where TD3's reward comes from: the critic (GAIfO, the default) or, as a diagnostic
    /// only, the true distance to the goal (then it is reinforcement learning, not imitation:
    /// it tells TD3's own behaviour from the critic's, as GAIfO (PPO)'s `reward` does).
    pub reward: OffPolicyReward,
    /// TD3.
    pub td3: Td3Config,
}

/// The critic's policy-side data ([`GaifoTd3Config::critic_data`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CriticData {
    /// The iteration's N episodes' transitions.
    #[default]
    Iteration,
    /// As many rows drawn uniformly from the replay buffer (after this iteration's are in).
    Buffer,
}

/// TD3's reward ([`GaifoTd3Config::reward`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OffPolicyReward {
    /// `r = −c (D(s, s') − D̄_E) / σ_D`: GAIfO (module docs).
    #[default]
    Critic,
    /// `r = −c |ee(s') − goal|` (m): RL on the task's distance, a diagnostic that sees the
    /// goal; not imitation from observation.
    TaskDistance,
}

impl Default for GaifoTd3Config {
    fn default() -> Self {
        Self::from_gaifo(&GaifoConfig::default())
    }
}

impl GaifoTd3Config {
    /// LQR+GAIfO's arm, N, iterations, critic and seed; TD3's own settings.
    pub fn from_gaifo(g: &GaifoConfig) -> Self {
        Self {
            sim: g.sim.clone(),
            samples: g.samples,
            iterations: g.iterations,
            critic_updates: g.critic_updates,
            critic_lr_half_life: g.critic_lr_half_life,
            discriminator: g.discriminator.clone(),
            seed: g.seed,
            // 0.5 and 100 (TD3: 0.1; 50 before), with γ = 0.95: the search on the default
            // task (docs/results.md, "Off-policy GAIfO (TD3)").
            exploration_noise: 0.5,
            updates_per_episode: 100,
            buffer_capacity: 50_000,
            reward_scale: 1.0,
            critic_data: CriticData::Iteration,
            reward: OffPolicyReward::Critic,
            td3: Td3Config::default(),
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

    /// Refuses settings that cannot work, naming the setting and its range.
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_counts(
            &[
                ("samples", self.samples, 1),
                ("iterations", self.iterations, 1),
                ("updates_per_episode", self.updates_per_episode, 0),
                ("buffer_capacity", self.buffer_capacity, 1),
            ],
            MAX_COUNT,
        )
        .and_then(|()| {
            crate::error::check_reals(&[
                (
                    "exploration_noise",
                    self.exploration_noise,
                    self.exploration_noise > 0.0 && self.exploration_noise <= 10.0,
                    "in (0, 10] (units of the action bound)",
                ),
                (
                    "reward_scale",
                    self.reward_scale,
                    self.reward_scale > 0.0 && self.reward_scale.is_finite(),
                    "finite and > 0",
                ),
            ])
        })
        .and_then(|()| self.td3.validate())
        .map_err(ImitationError::Config)?;
        self.critic().validate()?;
        self.sim
            .validate()
            .map_err(|e| ImitationError::Config(e.to_string()))
    }
}

/// How an episode ended (DAC's distinction, module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EpisodeEnd {
    /// Cut by the time limit: not terminal (every episode of the reaching tasks).
    TimeLimit,
    /// Terminated in its last state: followed by the absorbing state.
    Terminated,
}

/// The per-step action bound b of each of the task's `joints` active joints: the clamp's
/// `v_max · dt` (rad) in goal-angle mode, the effort limit (N·m) in torque mode
/// (`ur5_shared::safety::clamp_action`).
pub fn action_bound(sim: &SimConfig, joints: usize, dt: f64) -> Joints {
    let limits = ArmLimits::for_model_joints(sim.model, joints);
    let mut b = Joints::splat(joints, 0.0);
    for (j, b) in b.iter_mut().enumerate() {
        *b = match sim.mode {
            ActionMode::GoalAngles => limits.velocity[j] * dt,
            ActionMode::Torque => limits.effort[j],
        };
    }
    b
}

/// Adds the transitions of `ep` to `buffer` (module docs): (s_t, â_t, s_{t+1}) for t < T − 1,
/// â_t the executed offset `u_t − base(s_t)` over `bound`; with [`EpisodeEnd::Terminated`] the
/// last one leads to the absorbing state, which gets its own row (s_{T−1}, 0, s_{T−1}).
pub fn add_episode(
    buffer: &mut ReplayBuffer,
    ep: &Episode,
    mode: ActionMode,
    bound: &[f64],
    end: EpisodeEnd,
) {
    let t_len = ep.horizon();
    let du = ep.du();
    for t in 0..t_len.saturating_sub(1) {
        let s = ep.state(t);
        let mut a = action_base(mode, du, s);
        for (j, a) in a.iter_mut().enumerate() {
            *a = (ep.u[t * du + j] - *a) / bound[j];
        }
        let kind = match end {
            EpisodeEnd::Terminated if t + 2 == t_len => RowKind::ToAbsorbing,
            _ => RowKind::Step,
        };
        buffer.push(s, &a, ep.state(t + 1), kind);
    }
    if end == EpisodeEnd::Terminated && t_len >= 1 {
        let last = ep.state(t_len - 1);
        buffer.push(last, &Joints::splat(du, 0.0), last, RowKind::Absorbing);
    }
}

/// What the TD3 steps of one iteration did (means over them).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Gradient steps taken.
    pub steps: usize,
    /// Mean L_Q.
    pub critic_loss: f64,
    /// Mean L_π over the steps that had an actor step.
    pub actor_loss: f64,
    /// Mean TD target.
    pub mean_target: f64,
    /// Mean reward of the sampled rows.
    pub mean_reward: f64,
    /// Rows in the replay buffer.
    pub buffer_rows: usize,
}

/// The state of an off-policy GAIfO run.
pub struct GaifoTd3 {
    cfg: GaifoTd3Config,
    task: TaskConfig,
    demos: Demos,
    critic: Critic,
    td3: Td3,
    buffer: ReplayBuffer,
    /// Minibatch rows and smoothing noise.
    rng: ChaCha8Rng,
    bound: Joints,
    iteration: usize,
    idx: Vec<usize>,
    batch: Minibatch,
    /// (D̄_E, σ_D) of the iteration's reward (module docs); recomputed after every critic
    /// update, so not part of the checkpoint.
    reward_ref: (f64, f64),
    /// Statistics of the last iteration's TD3 steps.
    pub last_update: UpdateStats,
}

/// The demonstrations' states, one per row (`count · T` × dX).
fn demo_states(demos: &Demos) -> Mat<f64> {
    let dx = demos.layout().dx();
    Mat::from_fn(demos.count * demos.horizon, dx, |r, c| {
        demos.states[r * dx + c]
    })
}

/// (D̄_E, σ_D): the mean of `disc` on the `expert` transitions and its population standard
/// deviation on expert ∪ `controller` (rows of [s; s']); σ_D = 1 where it is not positive.
pub fn reward_reference(
    disc: &Discriminator,
    expert: &Mat<f64>,
    controller: &Mat<f64>,
) -> (f64, f64) {
    let mut ws = disc.workspace();
    let mut x = vec![0.0; expert.ncols()];
    let mut values = |m: &Mat<f64>| -> Vec<f64> {
        (0..m.nrows())
            .map(|r| {
                for (c, v) in x.iter_mut().enumerate() {
                    *v = m[(r, c)];
                }
                disc.value(&x, &mut ws)
            })
            .collect()
    };
    let (e, c) = (values(expert), values(controller));
    let d_e = e.iter().sum::<f64>() / e.len().max(1) as f64;
    let n = (e.len() + c.len()).max(1) as f64;
    let mean = e.iter().chain(&c).sum::<f64>() / n;
    let var = e
        .iter()
        .chain(&c)
        .map(|v| (v - mean) * (v - mean))
        .sum::<f64>()
        / n;
    let sd = var.sqrt();
    (d_e, if sd > 0.0 && sd.is_finite() { sd } else { 1.0 })
}

impl GaifoTd3 {
    /// Sets up a run imitating `demos` (the task is theirs): the actor's and critics' input
    /// normalisation fitted on the demonstrations' states, the nets drawn from the run seed;
    /// the dimensions are the task's layout.
    pub fn new(cfg: GaifoTd3Config, demos: Demos) -> Result<Self, ImitationError> {
        cfg.validate()?;
        let task = demos.task()?;
        let layout = task.layout();
        let critic = Critic::from_settings(expert_transitions(&demos), cfg.critic(), cfg.seed)?;
        let norm = Normalizer::from_data(demo_states(&demos).as_ref())?;
        let bound = action_bound(&cfg.sim, layout.du(), task.dt);
        let mut rng = td3::td3_rng(cfg.seed);
        let mut td3 = Td3::new(cfg.td3.clone(), layout, bound, norm, 1.0, &mut rng);
        let mut log_std = bound;
        for l in log_std.iter_mut() {
            *l = (cfg.exploration_noise * *l).ln();
        }
        td3.actor.net_mut().set_log_std(log_std);
        td3.actor_target = td3.actor.clone();
        Ok(Self {
            buffer: ReplayBuffer::new(layout.dx(), layout.du(), cfg.buffer_capacity),
            iteration: 0,
            idx: Vec::new(),
            batch: Minibatch::default(),
            reward_ref: (0.0, 1.0),
            last_update: UpdateStats::default(),
            cfg,
            task,
            demos,
            critic,
            td3,
            rng,
            bound,
        })
    }

    /// TD3 (actor, critics, targets).
    pub fn td3(&self) -> &Td3 {
        &self.td3
    }

    /// The policy executed next (mean and exploration σ).
    pub fn policy(&self) -> &GlobalPolicy {
        self.td3.actor()
    }

    /// The replay buffer.
    pub fn buffer(&self) -> &ReplayBuffer {
        &self.buffer
    }

    /// The critic D(s, s').
    pub fn discriminator(&self) -> &Discriminator {
        self.critic.discriminator()
    }

    /// The critic and its schedule.
    pub fn critic(&self) -> &Critic {
        &self.critic
    }

    /// The settings of the run.
    pub fn config(&self) -> &GaifoTd3Config {
        &self.cfg
    }

    /// The per-joint action bound b (dU).
    pub fn bound(&self) -> &[f64] {
        &self.bound
    }

    /// Steps 4 and 6: `steps` TD3 gradient steps, each on a minibatch drawn from the buffer
    /// with rewards from the critic of the moment.
    fn td3_steps(&mut self, steps: usize) -> UpdateStats {
        let mut st = UpdateStats {
            buffer_rows: self.buffer.len(),
            ..UpdateStats::default()
        };
        if self.buffer.is_empty() {
            return st;
        }
        let disc = self.critic.cost_discriminator();
        let mut dws = disc.workspace();
        let layout = self.task.layout();
        let dx = layout.dx();
        let mut x = vec![0.0; 2 * dx];
        let m = self.cfg.td3.batch_size;
        let mut actor_steps = 0usize;
        for _ in 0..steps {
            self.buffer.sample(&mut self.rng, m, &mut self.idx);
            self.batch.clear();
            for &i in &self.idx {
                let row = self.buffer.row(i);
                x[..dx].copy_from_slice(row.s);
                x[dx..].copy_from_slice(row.s_next);
                let r = match self.cfg.reward {
                    OffPolicyReward::Critic => {
                        let (d_e, sd) = self.reward_ref;
                        -self.cfg.reward_scale * (disc.value(&x, &mut dws) - d_e) / sd
                    }
                    OffPolicyReward::TaskDistance => {
                        -self.cfg.reward_scale
                            * ur5_shared::cost::goal_distance(&layout, row.s_next)
                    }
                };
                st.mean_reward += r;
                self.batch.s.extend_from_slice(row.s);
                self.batch.a.extend_from_slice(row.a);
                self.batch.s_next.extend_from_slice(row.s_next);
                self.batch.absorbing.push(row.kind == RowKind::Absorbing);
                self.batch.next_absorbing.push(row.kind != RowKind::Step);
                self.batch.r.push(r);
            }
            let s = self.td3.step(&self.batch, &mut self.rng);
            st.critic_loss += s.critic_loss;
            st.mean_target += s.mean_target;
            if !s.actor_loss.is_nan() {
                st.actor_loss += s.actor_loss;
                actor_steps += 1;
            }
            st.steps += 1;
        }
        let k = st.steps.max(1) as f64;
        st.critic_loss /= k;
        st.mean_target /= k;
        st.mean_reward /= k * m as f64;
        st.actor_loss = if actor_steps > 0 {
            st.actor_loss / actor_steps as f64
        } else {
            f64::NAN
        };
        st
    }
}

impl Learn for GaifoTd3 {
    type Log = GaifoLog;
    const ALGO: &'static str = "gaifo-td3";

    crate::learn::run_accessors!();

    /// Step 1: the actor with exploration noise, and its mean for the evaluation.
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        let (version, seed, n) = (self.version(), self.cfg.seed, self.cfg.samples);
        let actors = self.td3.actor();
        let (noisy, eval) = execute(arms, &self.task, actors, version, seed, n)?;
        Ok((noisy, vec![eval]))
    }

    /// Steps 2–6 of the module docs on the episodes of the current policy.
    fn learn_goals(
        &mut self,
        episodes: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        let eval = crate::learn::single_eval(evals)?;
        if let Some(e) = episodes.iter().position(|e| e.horizon() < 2) {
            return Err(ImitationError::Episodes(format!(
                "episode {e} has {} states; a transition needs 2",
                episodes[e].horizon()
            )));
        }
        let t1 = Instant::now();
        let c1 = crate::cpu::thread_cpu_s();
        // 2. The replay buffer.
        for ep in episodes {
            add_episode(
                &mut self.buffer,
                ep,
                self.cfg.sim.mode,
                &self.bound,
                EpisodeEnd::TimeLimit,
            );
        }
        // 3. The critic on (s, s') of this iteration's episodes vs the expert.
        let controller = match self.cfg.critic_data {
            CriticData::Iteration => episode_transitions(episodes),
            CriticData::Buffer => {
                let n: usize = episodes.iter().map(|e| e.horizon() - 1).sum();
                self.buffer.sample(&mut self.rng, n, &mut self.idx);
                let (buffer, idx) = (&self.buffer, &self.idx);
                let dx = self.task.layout().dx();
                Mat::from_fn(n, 2 * dx, |r, c| {
                    let row = buffer.row(idx[r]);
                    if c < dx {
                        row.s[c]
                    } else {
                        row.s_next[c - dx]
                    }
                })
            }
        };
        let critic = self.critic.update(&controller, self.iteration)?;
        self.reward_ref = reward_reference(
            self.critic.cost_discriminator(),
            self.critic.expert(),
            &controller,
        );
        // 4, 6. TD3 on minibatches of the buffer, rewards from the updated critic.
        let t2 = Instant::now();
        let st = self.td3_steps(self.cfg.updates_per_episode * episodes.len());
        let t3 = Instant::now();
        let cpu_learner = crate::cpu::thread_cpu_s() - c1;
        if !(st.critic_loss.is_finite() && self.td3.actor().flat().iter().all(|v| v.is_finite())) {
            return Err(ImitationError::Config(format!(
                "TD3 diverged at iteration {} (critic loss {}): lower td3.critic_adam.lr or \
                 reward_scale",
                self.iteration, st.critic_loss
            )));
        }
        let log = GaifoLog {
            t_execute,
            t_critic: (t2 - t1).as_secs_f64(),
            t_lqr: (t3 - t2).as_secs_f64(),
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
mod tests;
