//! TD3 (Fujimoto, van Hoof, Meger 2018, Algorithm 1) on the project's tanh MLPs: a
//! deterministic actor μ, twin critics Q_1, Q_2, their target copies, clipped double-Q
//! targets with target-policy smoothing, delayed actor updates and Polyak-averaged targets.
//!
//! Inputs. The actor is the policy-table MLP ([`GlobalPolicy`]: one tanh head per joint on
//! `u = (s − m) ⊘ r`, linear output μ(u), rad offsets in goal-angle mode); its σ is TD3's
//! exploration noise and is never trained. Actions enter the critics normalised by the per-step
//! bound b (rad: the clamp's `v_max · dt`; N·m: the effort limit): `â = Δ ⊘ b`. A critic is a
//! scalar tanh MLP ([`Mlp`]) on `[u(s); â; z]`, z = 1 for DAC's absorbing state (then
//! u = 0, â = 0) and 0 otherwise (Kostrikov et al. 2019, §4.2).
//!
//! One gradient step on a minibatch `{(s_i, â_i, s'_i, kind_i, r_i)}` of m rows:
//!
//! ```text
//! ã_i = clip(μ'(s'_i) ⊘ b + clip(σ̃ ε_i, −c, c), −1, 1),  ε_i ~ N(0, I)      (target smoothing)
//! y_i = r_i + γ min_k Q'_k(u(s'_i), ã_i, 0)       step rows
//! y_i = r_i + γ min_k Q'_k(0, 0, 1)               rows into, and of, the absorbing state
//! L_Q = (1/m) Σ_i Σ_k (Q_k(x_i) − y_i)²,  x_i = [u(s_i); â_i; z_i]  (z_i = 1 for absorbing rows)
//! every d-th step:
//! L_π = (1/m) Σ_i [−Q_1(u(s_i), μ(s_i) ⊘ b, 0) + β Σ_j ½ max(0, |μ_j(s_i)/b_j| − 1)²]
//! θ' ← τ θ + (1 − τ) θ'    for μ', Q'_1, Q'_2
//! ```
//!
//! The last term of L_π (β = `bound_penalty`) keeps μ inside the bound the arm's clamp
//! enforces anyway; TD3 squashes its actor with tanh instead, which the policy table's linear
//! output cannot express. Gradients: `∂L_Q/∂θ_k = (2/m) Σ (Q_k − y) ∂Q_k/∂θ_k` and
//! `∂L_π/∂θ_μj = (1/m) Σ (−∂Q_1/∂â_j + β h_j) / b_j · ∂μ_j/∂θ_μj` (h_j the penalty's slope),
//! both by the MLP's backward pass; checked against central differences in the tests.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use ur5_shared::joints::Joints;
use ur5_shared::StateLayout;

use crate::discriminator::mlp::{Mlp, MlpWorkspace};
use crate::discriminator::{Adam, AdamConfig, Normalizer};
use crate::mlp_policy::global::{GlobalPolicy, GlobalPolicyWorkspace};

/// TD3's settings; defaults from Fujimoto et al. (2018, Table 3 and §6.1) unless noted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Td3Config {
    /// Hidden widths of each actor head (tanh). TD3: 400-300 ReLU; ours the policy table's
    /// heads (at most 4 layers of 256; docs/design.md §3.11).
    pub pi_hidden: Vec<usize>,
    /// Hidden widths of each critic (tanh). TD3: 400-300 ReLU.
    pub q_hidden: Vec<usize>,
    /// Discount γ. TD3: 0.99; ours 0.95, from the search on the default task (with the
    /// time-invariant actor and T = 100 steps of 0.1 s, a horizon of about 2 s).
    pub gamma: f64,
    /// Polyak rate τ of the targets. TD3: 0.005.
    pub tau: f64,
    /// Critic steps per actor (and target) step d. TD3: 2.
    pub policy_delay: usize,
    /// Target-policy smoothing σ̃, in units of the action bound. TD3: 0.2.
    pub target_noise: f64,
    /// Its clip c, in units of the action bound. TD3: 0.5.
    pub target_noise_clip: f64,
    /// Minibatch m. TD3: 100.
    pub batch_size: usize,
    /// Adam of the actor. TD3: lr 1e-3, PyTorch's β = (0.9, 0.999), ε = 1e-8.
    pub actor_adam: AdamConfig,
    /// Adam of each critic. TD3: as the actor's.
    pub critic_adam: AdamConfig,
    /// β of the bound penalty in L_π (module docs); ours.
    pub bound_penalty: f64,
}

impl Default for Td3Config {
    fn default() -> Self {
        let adam = AdamConfig {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        };
        Self {
            pi_hidden: vec![64, 64],
            q_hidden: vec![64, 64],
            gamma: 0.95,
            tau: 0.005,
            policy_delay: 2,
            target_noise: 0.2,
            target_noise_clip: 0.5,
            batch_size: 100,
            actor_adam: adam,
            critic_adam: adam,
            bound_penalty: 1.0,
        }
    }
}

impl Td3Config {
    /// Checks the ranges, naming the setting.
    pub fn validate(&self) -> Result<(), String> {
        use crate::discriminator::DiscriminatorConfig as D;
        D::check_widths("pi_hidden", &self.pi_hidden)?;
        D::check_widths("q_hidden", &self.q_hidden)?;
        crate::error::check_reals(&[
            (
                "gamma",
                self.gamma,
                (0.0..1.0).contains(&self.gamma),
                "in [0, 1)",
            ),
            (
                "tau",
                self.tau,
                self.tau > 0.0 && self.tau <= 1.0,
                "in (0, 1]",
            ),
            (
                "target_noise",
                self.target_noise,
                self.target_noise >= 0.0 && self.target_noise <= 10.0,
                "in [0, 10]",
            ),
            (
                "target_noise_clip",
                self.target_noise_clip,
                self.target_noise_clip >= 0.0 && self.target_noise_clip <= 10.0,
                "in [0, 10]",
            ),
            (
                "bound_penalty",
                self.bound_penalty,
                self.bound_penalty >= 0.0 && self.bound_penalty.is_finite(),
                "finite and >= 0",
            ),
        ])?;
        crate::error::check_counts(
            &[
                ("policy_delay", self.policy_delay, 1),
                ("batch_size", self.batch_size, 1),
            ],
            D::MAX_COUNT,
        )?;
        self.actor_adam
            .validate()
            .map_err(|e| format!("actor_adam: {e}"))?;
        self.critic_adam
            .validate()
            .map_err(|e| format!("critic_adam: {e}"))
    }
}

/// A minibatch in the critics' input space, m rows.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Minibatch {
    /// States s_i, (m, dX).
    pub s: Vec<f64>,
    /// Normalised actions â_i, (m, dU).
    pub a: Vec<f64>,
    /// Next states s'_i, (m, dX).
    pub s_next: Vec<f64>,
    /// Whether s_i is the absorbing state (z_i = 1).
    pub absorbing: Vec<bool>,
    /// Whether the target bootstraps from the absorbing state (rows into it and of it).
    pub next_absorbing: Vec<bool>,
    /// Rewards r_i.
    pub r: Vec<f64>,
}

impl Minibatch {
    /// Rows.
    pub fn len(&self) -> usize {
        self.r.len()
    }

    /// Whether it has no row.
    pub fn is_empty(&self) -> bool {
        self.r.is_empty()
    }

    /// Drops every row, keeping the memory.
    pub fn clear(&mut self) {
        self.s.clear();
        self.a.clear();
        self.s_next.clear();
        self.absorbing.clear();
        self.next_absorbing.clear();
        self.r.clear();
    }

    /// State of row i (dX: the rows' width).
    fn state(&self, i: usize) -> &[f64] {
        let dx = self.s.len() / self.len();
        &self.s[i * dx..(i + 1) * dx]
    }

    /// Next state of row i (dX).
    fn next_state(&self, i: usize) -> &[f64] {
        let dx = self.s_next.len() / self.len();
        &self.s_next[i * dx..(i + 1) * dx]
    }

    /// Normalised action of row i (dU).
    fn action(&self, i: usize) -> &[f64] {
        let du = self.a.len() / self.len();
        &self.a[i * du..(i + 1) * du]
    }
}

/// What one [`Td3::step`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// L_Q before the step.
    pub critic_loss: f64,
    /// L_π before the actor step (NaN on steps without one).
    pub actor_loss: f64,
    /// Mean TD target.
    pub mean_target: f64,
}

/// TD3's state: actor, twin critics, their targets, the optimisers, the smoothing-noise RNG
/// and scratch memory.
pub struct Td3 {
    pub(crate) cfg: Td3Config,
    /// Per-joint action bound b (dU).
    pub(crate) bound: Joints,
    pub(crate) actor: GlobalPolicy,
    pub(crate) actor_target: GlobalPolicy,
    pub(crate) q: [Mlp; 2],
    pub(crate) q_target: [Mlp; 2],
    pub(crate) adam_actor: Adam,
    pub(crate) adam_q: [Adam; 2],
    /// Critic steps taken (the policy delay counts them).
    pub(crate) steps: u64,
    pws: GlobalPolicyWorkspace,
    qws: MlpWorkspace,
    y: Vec<f64>,
    theta: Vec<f64>,
    grad: Vec<f64>,
}

/// Layer sizes of a critic: `[dX + dU + 1, hidden…, 1]`.
pub fn q_sizes(dx: usize, du: usize, hidden: &[usize]) -> Vec<usize> {
    let mut s = vec![dx + du + 1];
    s.extend_from_slice(hidden);
    s.push(1);
    s
}

impl Td3 {
    /// Fresh nets drawn from `rng`: the actor holds the arm (zero output layer, μ = 0) with
    /// exploration σ = `exploration_std` and input normalisation `norm`; Glorot critics; the
    /// targets copies of them, for the task of `layout`. `bound`: the per-joint action bound
    /// b (> 0, dU).
    pub fn new(
        cfg: Td3Config,
        layout: StateLayout,
        bound: Joints,
        norm: Normalizer,
        exploration_std: f64,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        assert_eq!(bound.len(), layout.du(), "one action bound per joint");
        let mut actor = GlobalPolicy::new(layout, &cfg.pi_hidden, exploration_std, rng);
        actor.set_normalizer(norm);
        let sizes = q_sizes(layout.dx(), layout.du(), &cfg.q_hidden);
        let q = [Mlp::glorot(&sizes, rng), Mlp::glorot(&sizes, rng)];
        let n_actor = actor.net().n_params();
        let n_q = q[0].params().len();
        Self {
            adam_actor: Adam::new(cfg.actor_adam, n_actor),
            adam_q: [
                Adam::new(cfg.critic_adam, n_q),
                Adam::new(cfg.critic_adam, n_q),
            ],
            pws: actor.workspace(),
            qws: MlpWorkspace::new(&sizes),
            actor_target: actor.clone(),
            q_target: q.clone(),
            y: Vec::new(),
            theta: Vec::new(),
            grad: Vec::new(),
            steps: 0,
            cfg,
            bound,
            actor,
            q,
        }
    }

    /// The actor (the policy executed, with its exploration σ).
    pub fn actor(&self) -> &GlobalPolicy {
        &self.actor
    }

    /// The settings.
    pub fn config(&self) -> &Td3Config {
        &self.cfg
    }

    /// The critics Q_1, Q_2.
    pub fn critics(&self) -> &[Mlp; 2] {
        &self.q
    }

    /// Critic steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Writes the critics' input `[u(s); â; z]` into `ws.u` (u = 0, â = 0 for the absorbing
    /// state).
    fn set_q_input(
        actor: &GlobalPolicy,
        pws: &mut GlobalPolicyWorkspace,
        ws: &mut MlpWorkspace,
        s: Option<&[f64]>,
        a: &[f64],
    ) {
        let (dx, du) = (actor.layout().dx(), actor.layout().du());
        match s {
            Some(s) => {
                actor.normalise(s, pws);
                ws.u[..dx].copy_from_slice(&pws.u);
                ws.u[dx..dx + du].copy_from_slice(a);
                ws.u[dx + du] = 0.0;
            }
            None => {
                ws.u[..dx + du].fill(0.0);
                ws.u[dx + du] = 1.0;
            }
        }
    }

    /// Q_k (k = 0, 1; `target`: Q'_k) at state `s` (`None`: the absorbing state) and
    /// normalised action `a`.
    pub fn q_value(&mut self, k: usize, target: bool, s: Option<&[f64]>, a: &[f64]) -> f64 {
        Self::set_q_input(&self.actor, &mut self.pws, &mut self.qws, s, a);
        let net = if target {
            &self.q_target[k]
        } else {
            &self.q[k]
        };
        net.forward(&mut self.qws)
    }

    /// μ(s) ⊘ b of the actor (`target`: of μ'), dU.
    pub fn normalised_action(&mut self, target: bool, s: &[f64]) -> Joints {
        let pol = if target {
            &self.actor_target
        } else {
            &self.actor
        };
        let mut mu = pol.offset(s, &mut self.pws);
        for (m, b) in mu.iter_mut().zip(self.bound.iter()) {
            *m /= b;
        }
        mu
    }

    /// The TD targets y_i of `batch` into `y` (module docs), with the smoothing noise
    /// `eps` ((m, dU) standard-normal draws; unused on absorbing targets).
    pub fn targets(&mut self, batch: &Minibatch, eps: &[f64], y: &mut Vec<f64>) {
        let (sigma, c, gamma) = (
            self.cfg.target_noise,
            self.cfg.target_noise_clip,
            self.cfg.gamma,
        );
        y.clear();
        let du = self.bound.len();
        for i in 0..batch.len() {
            let (s, a) = if batch.next_absorbing[i] {
                (None, Joints::splat(du, 0.0))
            } else {
                let s = batch.next_state(i);
                let mut a = self.normalised_action(true, s);
                for (j, a) in a.iter_mut().enumerate() {
                    *a = (*a + (sigma * eps[i * du + j]).clamp(-c, c)).clamp(-1.0, 1.0);
                }
                (Some(s), a)
            };
            let q1 = self.q_value(0, true, s, &a);
            let q2 = self.q_value(1, true, s, &a);
            y.push(batch.r[i] + gamma * q1.min(q2));
        }
    }

    /// L_Q of critic `k` on `batch` against targets `y` (its share of the module docs' sum),
    /// and its gradient into `grad` (overwritten, Q_k's parameter layout).
    pub fn critic_loss_gradient(
        &mut self,
        k: usize,
        batch: &Minibatch,
        y: &[f64],
        grad: &mut Vec<f64>,
    ) -> f64 {
        let m = batch.len() as f64;
        grad.clear();
        grad.resize(self.q[k].params().len(), 0.0);
        let mut loss = 0.0;
        for i in 0..batch.len() {
            let s = (!batch.absorbing[i]).then(|| batch.state(i));
            let q = self.q_value(k, false, s, batch.action(i));
            let e = q - y[i];
            loss += e * e / m;
            self.q[k].backward(&mut self.qws, false);
            self.q[k].accumulate_param_grad(&self.qws, 2.0 * e / m, grad);
        }
        loss
    }

    /// L_π on the states of `batch` that are not absorbing (module docs), and its gradient
    /// into `grad` (overwritten, the actor's flat layout: heads, then log σ, whose entries stay
    /// 0: σ is not trained).
    pub fn actor_loss_gradient(&mut self, batch: &Minibatch, grad: &mut Vec<f64>) -> f64 {
        grad.clear();
        grad.resize(self.actor.net().n_params(), 0.0);
        let rows: Vec<usize> = (0..batch.len()).filter(|&i| !batch.absorbing[i]).collect();
        if rows.is_empty() {
            return 0.0;
        }
        let m = rows.len() as f64;
        let beta = self.cfg.bound_penalty;
        let (dx, du) = (self.actor.layout().dx(), self.actor.layout().du());
        let mut loss = 0.0;
        for &i in &rows {
            let s = batch.state(i);
            self.actor.normalise(s, &mut self.pws);
            let mut a = self.actor.net().mean(&self.pws.u, &mut self.pws.net);
            for (a, b) in a.iter_mut().zip(self.bound.iter()) {
                *a /= b;
            }
            Self::set_q_input(&self.actor, &mut self.pws, &mut self.qws, Some(s), &a);
            let q = self.q[0].forward(&mut self.qws);
            self.q[0].backward(&mut self.qws, true);
            let mut c = Joints::splat(du, 0.0);
            loss -= q / m;
            for j in 0..du {
                let over = a[j].abs() - 1.0;
                let (pen, slope) = if over > 0.0 {
                    (0.5 * over * over, over * a[j].signum())
                } else {
                    (0.0, 0.0)
                };
                loss += beta * pen / m;
                c[j] = (-self.qws.grad_u[dx + j] + beta * slope) / (m * self.bound[j]);
            }
            // The mean heads' forward passes of `s` are still in `pws.net` (the critic's input
            // only read the normalisation).
            self.actor
                .net()
                .accumulate_mean_grad(&mut self.pws.net, &c, grad);
        }
        loss
    }

    /// One TD3 gradient step on `batch` (module docs), drawing the smoothing noise from `rng`
    /// ((m, dU) standard normals, row by row).
    pub fn step(&mut self, batch: &Minibatch, rng: &mut ChaCha8Rng) -> StepStats {
        let eps: Vec<f64> = (0..batch.len() * self.bound.len())
            .map(|_| StandardNormal.sample(rng))
            .collect();
        let mut y = std::mem::take(&mut self.y);
        self.targets(batch, &eps, &mut y);
        let mut st = StepStats {
            mean_target: y.iter().sum::<f64>() / y.len().max(1) as f64,
            actor_loss: f64::NAN,
            ..StepStats::default()
        };
        let mut grad = std::mem::take(&mut self.grad);
        for k in 0..2 {
            st.critic_loss += self.critic_loss_gradient(k, batch, &y, &mut grad);
            self.adam_q[k].step(self.q[k].params_mut(), &grad);
        }
        self.y = y;
        self.steps += 1;
        if self.steps % self.cfg.policy_delay as u64 == 0 {
            st.actor_loss = self.actor_loss_gradient(batch, &mut grad);
            let mut theta = std::mem::take(&mut self.theta);
            theta.resize(grad.len(), 0.0);
            self.actor.net().read_params(&mut theta);
            self.adam_actor.step(&mut theta, &grad);
            self.actor.net_mut().write_params(&theta);
            self.theta = theta;
            self.polyak();
        }
        self.grad = grad;
        st
    }

    /// θ' ← τ θ + (1 − τ) θ' for the actor's heads and both critics.
    fn polyak(&mut self) {
        let tau = self.cfg.tau;
        let mix = |target: &mut [f64], online: &[f64]| {
            for (t, o) in target.iter_mut().zip(online) {
                *t = tau * o + (1.0 - tau) * *t;
            }
        };
        for k in 0..2 {
            let online = self.q[k].params().to_vec();
            mix(self.q_target[k].params_mut(), &online);
        }
        let n = self.actor.net().n_params();
        let (mut online, mut target) = (vec![0.0; n], vec![0.0; n]);
        self.actor.net().read_params(&mut online);
        self.actor_target.net().read_params(&mut target);
        mix(&mut target, &online);
        self.actor_target.net_mut().write_params(&target);
    }
}

/// Standard-normal draws as [`Td3::step`] takes them (for tests that redo a step by hand).
pub fn smoothing_noise(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| StandardNormal.sample(rng)).collect()
}

/// A ChaCha8 stream for TD3's draws from the run seed.
pub fn td3_rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ 0x5444_3300) // "TD3"
}
