//! The GAIfO baseline (Torabi, Warnell, Stone 2018; the baseline of Torabi et al. 2019):
//! a Gaussian MLP policy trained by PPO (Schulman et al. 2017) on the reward
//! `r_t = −D(s_t, s_{t+1})` from the same WGAN-GP critic as LQR+GAIfO, with 5 episodes per
//! iteration like LQR+GAIfO (docs/design.md §1.5).
//!
//! - [`policy`] ([`crate::mlp_policy`], below this module because MDGPS's global policy is the
//!   same): π(Δ|s) = N(μ(s), diag σ²), μ from tanh MLPs of the task's dX-dim state (one per
//!   joint), log σ learned and state-independent; V(s) the same MLP. Both reuse [`crate::discriminator::mlp::Mlp`].
//! - [`rollout`]: episodes of that policy through `shared::safety::clamp_action`; the action
//!   is an offset from the current joint angles.
//! - [`gae`], [`loss`]: advantages and the clipped-surrogate loss with its exact gradient.
//! - [`Ppo::update`]: the optimisation of one iteration (epochs × minibatches of Adam).
//! - [`gaifo_ppo`]: the imitation loop (execute → critic → reward → PPO) and its CSV, whose
//!   columns are LQR+GAIfO's.

pub mod gae;
pub mod gaifo_ppo;
pub mod loss;
pub mod rollout;

pub use crate::mlp_policy as policy;

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::ActionMode;
use ur5_shared::StateLayout;

use crate::discriminator::{Adam, AdamConfig};
use crate::rollout::Episode;
pub use gae::gae;
pub use loss::{clip_grad_norm, ppo_loss_gradient, LossParts, Rollouts};
pub use policy::{ActorCritic, ActorCriticWorkspace, GaussianMlpPolicy, PolicyWorkspace};
use rollout::offset;

/// PPO's settings. Defaults are those of stable-baselines3 `PPO` (v2) with `MlpPolicy`, which
/// follow OpenAI baselines `ppo2` and Schulman et al. (2017), except the number of samples per
/// update (ours: the 5 episodes of an iteration, as the paper's baseline) and the initial
/// exploration (ours: LQR+GAIfO's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PpoConfig {
    /// Hidden widths of each mean head (tanh). SB3 `MlpPolicy`: `[64, 64]` tanh.
    pub pi_hidden: Vec<usize>,
    /// Hidden widths of the value net (tanh). SB3: `[64, 64]`.
    pub v_hidden: Vec<usize>,
    /// Initial σ of every action dimension (rad): LQR+GAIfO's √0.05 ≈ 0.224, not SB3's 1
    /// (docs/design.md §5 D14).
    pub init_std: f64,
    /// Scale of the mean heads' initial output layer; 0 so the initial policy holds the start
    /// pose (SB3: 0.01; docs/design.md §5 D12).
    pub init_out_scale: f64,
    /// Clip range ε. Schulman et al. 2017 / SB3: 0.2.
    pub clip_range: f64,
    /// Discount γ. SB3: 0.99.
    pub gamma: f64,
    /// GAE λ. SB3: 0.95.
    pub gae_lambda: f64,
    /// Adam (one optimiser over all parameters). SB3: lr 3e-4, PyTorch's β = (0.9, 0.999) and
    /// ε = 1e-5 (SB3's `ActorCriticPolicy` sets it for Adam).
    pub adam: AdamConfig,
    /// Epochs over the iteration's data. SB3: 10.
    pub epochs: usize,
    /// Minibatch size (the last minibatch of an epoch may be smaller, as in SB3). SB3: 64.
    pub minibatch: usize,
    /// Value loss coefficient c_V. SB3: 0.5 (on `mean (V − R)²`).
    pub vf_coef: f64,
    /// Entropy coefficient c_H. SB3: 0.0.
    pub ent_coef: f64,
    /// Normalise advantages per minibatch. SB3: true.
    pub normalize_advantage: bool,
    /// Clip the global gradient norm to this. SB3: 0.5.
    pub max_grad_norm: f64,
    /// Scale rewards by a running std of the discounted return and clip to ±10
    /// (`VecNormalize`); on: −D has no fixed scale (docs/design.md §5 D13).
    pub normalize_reward: bool,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            pi_hidden: vec![64, 64],
            v_hidden: vec![64, 64],
            init_std: 0.05f64.sqrt(),
            init_out_scale: 0.0,
            clip_range: 0.2,
            gamma: 0.99,
            gae_lambda: 0.95,
            adam: AdamConfig {
                lr: 3e-4,
                beta1: 0.9,
                beta2: 0.999,
                eps: 1e-5,
            },
            epochs: 10,
            minibatch: 64,
            vf_coef: 0.5,
            ent_coef: 0.0,
            normalize_advantage: true,
            max_grad_norm: 0.5,
            normalize_reward: true,
        }
    }
}

impl PpoConfig {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), String> {
        use crate::discriminator::DiscriminatorConfig as D;
        D::check_widths("pi_hidden", &self.pi_hidden)?;
        D::check_widths("v_hidden", &self.v_hidden)?;
        crate::error::check_reals(&[
            (
                "init_std",
                self.init_std,
                self.init_std > 0.0 && self.init_std <= 10.0,
                "in (0, 10] rad",
            ),
            (
                "init_out_scale",
                self.init_out_scale,
                self.init_out_scale.is_finite(),
                "finite",
            ),
            (
                "clip_range",
                self.clip_range,
                self.clip_range > 0.0 && self.clip_range <= 10.0,
                "in (0, 10]",
            ),
            (
                "gamma",
                self.gamma,
                (0.0..=1.0).contains(&self.gamma),
                "in [0, 1]",
            ),
            (
                "gae_lambda",
                self.gae_lambda,
                (0.0..=1.0).contains(&self.gae_lambda),
                "in [0, 1]",
            ),
            (
                "vf_coef",
                self.vf_coef,
                self.vf_coef >= 0.0 && self.vf_coef.is_finite(),
                "finite and >= 0",
            ),
            (
                "ent_coef",
                self.ent_coef,
                self.ent_coef.is_finite(),
                "finite",
            ),
            (
                "max_grad_norm",
                self.max_grad_norm,
                self.max_grad_norm > 0.0 && self.max_grad_norm.is_finite(),
                "finite and > 0",
            ),
        ])?;
        crate::error::check_counts(
            &[("epochs", self.epochs, 1), ("minibatch", self.minibatch, 1)],
            D::MAX_COUNT,
        )?;
        self.adam.validate()
    }
}

/// What one [`Ppo::update`] did (means over its minibatch steps).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Transitions used.
    pub samples: usize,
    /// Adam steps taken.
    pub steps: usize,
    pub policy_loss: f64,
    pub value_loss: f64,
    /// Entropy of π after the update.
    pub entropy: f64,
    /// Mean approximate KL(old ‖ new) over the last epoch's minibatches (SB3's `approx_kl`).
    pub approx_kl: f64,
    pub clip_fraction: f64,
    /// Mean gradient norm before clipping.
    pub grad_norm: f64,
    /// Mean σ after the update.
    pub mean_std: f64,
    /// Mean undiscounted reward per transition of the data.
    pub mean_reward: f64,
}

/// Running mean and variance (Chan et al. parallel update, as baselines' `RunningMeanStd`,
/// initial count 1e-4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunningMeanStd {
    pub mean: f64,
    pub var: f64,
    pub count: f64,
}

impl Default for RunningMeanStd {
    fn default() -> Self {
        Self {
            mean: 0.0,
            var: 1.0,
            count: 1e-4,
        }
    }
}

impl RunningMeanStd {
    /// Adds one sample.
    pub fn update(&mut self, x: f64) {
        let tot = self.count + 1.0;
        let delta = x - self.mean;
        let m2 = self.var * self.count + delta * delta * self.count / tot;
        self.mean += delta / tot;
        self.var = m2 / tot;
        self.count = tot;
    }
}

/// Normalises `rewards` in place as `VecNormalize` does, one environment stepping through the
/// episodes in order: `ret ← γ ret + r` (0 at each episode start), update the statistics with
/// `ret`, `r ← clip(r / sqrt(var + 1e-8), ±10)`.
pub fn normalize_rewards(rms: &mut RunningMeanStd, gamma: f64, rewards: &mut [Vec<f64>]) {
    for ep in rewards.iter_mut() {
        let mut ret = 0.0;
        for r in ep.iter_mut() {
            ret = gamma * ret + *r;
            rms.update(ret);
            *r = (*r / (rms.var + 1e-8).sqrt()).clamp(-10.0, 10.0);
        }
    }
}

/// PPO's state: the nets, Adam, the minibatch RNG and all scratch memory.
pub struct Ppo {
    cfg: PpoConfig,
    mode: ActionMode,
    ac: ActorCritic,
    ws: ActorCriticWorkspace,
    adam: Adam,
    rng: ChaCha8Rng,
    theta: Vec<f64>,
    grad: Vec<f64>,
    adv_scratch: Vec<f64>,
    data: Rollouts,
    perm: Vec<usize>,
    values: Vec<f64>,
    adv: Vec<f64>,
    ret_rms: RunningMeanStd,
    scaled: Vec<Vec<f64>>,
}

impl Ppo {
    /// Fresh nets for the task's `layout` (dX inputs, dU mean heads) from `ChaCha8(seed)`,
    /// which then draws the minibatches. `mode` is the arm's action mode (what the offset is
    /// added to, [`policy::action_base`]).
    pub fn new(
        cfg: PpoConfig,
        mode: ActionMode,
        layout: StateLayout,
        seed: u64,
    ) -> Result<Self, String> {
        cfg.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let ac = ActorCritic::new(
            layout.dx(),
            layout.du(),
            &cfg.pi_hidden,
            &cfg.v_hidden,
            cfg.init_std.ln(),
            cfg.init_out_scale,
            &mut rng,
        );
        let n = ac.n_params();
        Ok(Self {
            ws: ac.workspace(),
            adam: Adam::new(cfg.adam, n),
            theta: vec![0.0; n],
            grad: vec![0.0; n],
            adv_scratch: Vec::new(),
            data: Rollouts::default(),
            perm: Vec::new(),
            values: Vec::new(),
            adv: Vec::new(),
            ret_rms: RunningMeanStd::default(),
            scaled: Vec::new(),
            cfg,
            mode,
            ac,
            rng,
        })
    }

    /// The settings.
    pub fn config(&self) -> &PpoConfig {
        &self.cfg
    }

    /// The nets.
    pub fn actor_critic(&self) -> &ActorCritic {
        &self.ac
    }

    /// The policy.
    pub fn policy(&self) -> &GaussianMlpPolicy {
        &self.ac.policy
    }

    /// Scratch space of the policy (for rollouts).
    pub fn policy_workspace(&mut self) -> &mut PolicyWorkspace {
        &mut self.ws.policy
    }

    /// The policy and a workspace for it at once (a rollout needs both).
    pub fn policy_and_workspace(&mut self) -> (&GaussianMlpPolicy, &mut PolicyWorkspace) {
        (&self.ac.policy, &mut self.ws.policy)
    }

    /// The last update's training data.
    pub fn rollouts(&self) -> &Rollouts {
        &self.data
    }

    /// Builds the training data from `episodes` and `rewards` (`rewards[e][t]` for the
    /// transition s_t → s_{t+1}, t < T_e − 1): log π_old of every sampled offset, V(s_t) of
    /// every state, GAE with V(s_{T−1}) bootstrapped at the time limit.
    pub fn collect(&mut self, episodes: &[Episode], rewards: &[Vec<f64>]) {
        assert_eq!(episodes.len(), rewards.len());
        self.data.clear();
        for (ep, r) in episodes.iter().zip(rewards) {
            let t_len = ep.horizon();
            assert_eq!(r.len() + 1, t_len, "one reward per transition");
            self.values.clear();
            for t in 0..t_len {
                self.values.push(self.ac.value(ep.state(t), &mut self.ws));
            }
            self.adv.resize(t_len - 1, 0.0);
            gae(
                r,
                &self.values[..t_len - 1],
                self.values[t_len - 1],
                self.cfg.gamma,
                self.cfg.gae_lambda,
                &mut self.adv,
            );
            for t in 0..t_len - 1 {
                let s = ep.state(t);
                let d = offset(self.mode, ep, t);
                let mu = self.ac.policy.mean(s, &mut self.ws.policy);
                self.data.states.extend_from_slice(s);
                self.data.deltas.extend_from_slice(&d);
                self.data
                    .logp_old
                    .push(self.ac.policy.log_prob_given_mean(&mu, &d));
                self.data.advantages.push(self.adv[t]);
                self.data.returns.push(self.adv[t] + self.values[t]);
            }
        }
    }

    /// One PPO update on `episodes` with per-transition `rewards` ([`Self::collect`]):
    /// `epochs` passes over the data in shuffled minibatches, each one Adam step on the
    /// clipped loss ([`loss`]) with the gradient norm clipped.
    /// With `normalize_reward` the rewards are scaled first ([`normalize_rewards`]).
    pub fn update(&mut self, episodes: &[Episode], rewards: &[Vec<f64>]) -> UpdateStats {
        if self.cfg.normalize_reward {
            let mut scaled = std::mem::take(&mut self.scaled);
            scaled.clear();
            scaled.extend(rewards.iter().cloned());
            normalize_rewards(&mut self.ret_rms, self.cfg.gamma, &mut scaled);
            self.collect(episodes, &scaled);
            self.scaled = scaled;
        } else {
            self.collect(episodes, rewards);
        }
        let n = self.data.len();
        let n_rewards: usize = rewards.iter().map(|r| r.len()).sum();
        let mut st = UpdateStats {
            samples: n,
            mean_reward: rewards.iter().flatten().sum::<f64>() / n_rewards.max(1) as f64,
            ..UpdateStats::default()
        };
        if n == 0 {
            return st;
        }
        self.perm.clear();
        self.perm.extend(0..n);
        let mut last_epoch_batches = 0usize;
        for epoch in 0..self.cfg.epochs {
            self.perm.shuffle(&mut self.rng);
            let last = epoch + 1 == self.cfg.epochs;
            for start in (0..n).step_by(self.cfg.minibatch) {
                let idx = &self.perm[start..(start + self.cfg.minibatch).min(n)];
                let parts = ppo_loss_gradient(
                    &self.ac,
                    &mut self.ws,
                    &self.cfg,
                    &self.data,
                    idx,
                    &mut self.adv_scratch,
                    &mut self.grad,
                );
                st.grad_norm += clip_grad_norm(&mut self.grad, self.cfg.max_grad_norm);
                self.ac.read_params(&mut self.theta);
                self.adam.step(&mut self.theta, &self.grad);
                self.ac.write_params(&self.theta);
                st.steps += 1;
                st.policy_loss += parts.policy_loss;
                st.value_loss += parts.value_loss;
                st.clip_fraction += parts.clip_fraction;
                if last {
                    st.approx_kl += parts.approx_kl;
                    last_epoch_batches += 1;
                }
            }
        }
        let k = st.steps as f64;
        st.policy_loss /= k;
        st.value_loss /= k;
        st.clip_fraction /= k;
        st.grad_norm /= k;
        st.approx_kl /= last_epoch_batches.max(1) as f64;
        st.entropy = self.ac.policy.entropy();
        st.mean_std = self
            .ac
            .policy
            .log_std()
            .iter()
            .map(|l| l.exp())
            .sum::<f64>()
            / self.ac.policy.du() as f64;
        st
    }
}
