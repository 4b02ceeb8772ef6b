//! The PPO loss on a minibatch and its exact gradient (Schulman et al. 2017, eq. 9, in the
//! form stable-baselines3's `PPO.train` minimises):
//!
//! ```text
//! L(θ) = −mean_i min(ρ_i Â_i, clip(ρ_i, 1 − ε, 1 + ε) Â_i)      ρ_i = exp(log π_θ(Δ_i|s_i) − log π_old)
//!        + c_V mean_i (V_θ(s_i) − R_i)²                          (no value clipping, SB3's default)
//!        − c_H H(π_θ)                                            (H = Σ_j log σ_j + ½(1 + ln 2π))
//! ```
//!
//! Â normalised over the minibatch (mean 0, unbiased std 1, + 1e-8), as SB3 does.
//!
//! Gradient: where the unclipped term is the minimum, `∂/∂ log π = −ρ Â / m`, else 0 (the
//! clipped term is constant in θ); `∂ log π/∂μ_j = (Δ_j − μ_j)/σ_j²`,
//! `∂ log π/∂ log σ_j = ((Δ_j − μ_j)/σ_j)² − 1`, `∂H/∂ log σ_j = 1`, and `∂μ_j/∂θ`, `∂V/∂θ` by
//! the MLP's backward pass.

use ur5_shared::joints::Joints;

use super::PpoConfig;
use crate::mlp_policy::{ActorCritic, ActorCriticWorkspace};

/// PPO's training data of one iteration: one row per transition.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rollouts {
    /// States s_i, (n, dX).
    pub states: Vec<f64>,
    /// Sampled action offsets Δ_i (before the clamp), (n, dU).
    pub deltas: Vec<f64>,
    /// log π_old(Δ_i|s_i) under the policy that sampled them.
    pub logp_old: Vec<f64>,
    /// GAE advantages Â_i (not normalised).
    pub advantages: Vec<f64>,
    /// Value targets R_i = Â_i + V_old(s_i).
    pub returns: Vec<f64>,
}

impl Rollouts {
    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.logp_old.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.logp_old.is_empty()
    }

    /// Drops every row, keeping the memory.
    pub fn clear(&mut self) {
        self.states.clear();
        self.deltas.clear();
        self.logp_old.clear();
        self.advantages.clear();
        self.returns.clear();
    }

    /// State of row i (dX: the rows' width).
    pub fn state(&self, i: usize) -> &[f64] {
        let dx = self.states.len() / self.len();
        &self.states[i * dx..(i + 1) * dx]
    }

    /// Offset of row i (dU).
    pub fn delta(&self, i: usize) -> &[f64] {
        let du = self.deltas.len() / self.len();
        &self.deltas[i * du..(i + 1) * du]
    }
}

/// The loss's parts on one minibatch (at the parameters before the step).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossParts {
    /// The total `L`.
    pub loss: f64,
    /// Clipped surrogate term `−mean min(…)`.
    pub policy_loss: f64,
    /// `mean (V − R)²` (before `c_V`).
    pub value_loss: f64,
    /// Entropy `H(π)` (before `c_H`).
    pub entropy: f64,
    /// SB3's estimate of KL(old ‖ new): `mean((ρ − 1) − log ρ)`.
    pub approx_kl: f64,
    /// Share of the minibatch with `|ρ − 1| > ε`.
    pub clip_fraction: f64,
}

/// `L` on rows `idx` of `data`, and its gradient w.r.t. the flat parameters of `ac` into
/// `grad` (overwritten, length `ac.n_params()`). `adv` is scratch (resized to `idx.len()`).
pub fn ppo_loss_gradient(
    ac: &ActorCritic,
    ws: &mut ActorCriticWorkspace,
    cfg: &PpoConfig,
    data: &Rollouts,
    idx: &[usize],
    adv: &mut Vec<f64>,
    grad: &mut [f64],
) -> LossParts {
    assert_eq!(grad.len(), ac.n_params());
    grad.fill(0.0);
    let m = idx.len();
    assert!(m > 0, "empty minibatch");
    let mf = m as f64;
    adv.clear();
    adv.extend(idx.iter().map(|&i| data.advantages[i]));
    if cfg.normalize_advantage && m > 1 {
        let mean = adv.iter().sum::<f64>() / mf;
        let var = adv.iter().map(|a| (a - mean) * (a - mean)).sum::<f64>() / (mf - 1.0);
        let sd = var.sqrt() + 1e-8;
        for a in adv.iter_mut() {
            *a = (*a - mean) / sd;
        }
    }
    let np = ac.n_policy_params();
    let du = ac.policy.du();
    let n_heads = np - du;
    let mut inv_std = *ac.policy.log_std();
    for v in inv_std.iter_mut() {
        *v = (-*v).exp();
    }
    let (lo, hi) = (1.0 - cfg.clip_range, 1.0 + cfg.clip_range);
    let mut out = LossParts::default();
    for (&i, &a) in idx.iter().zip(adv.iter()) {
        let s = data.state(i);
        let delta = data.delta(i);
        let mu = ac.policy.mean(s, &mut ws.policy);
        let logp = ac.policy.log_prob_given_mean(&mu, delta);
        let log_ratio = logp - data.logp_old[i];
        let ratio = log_ratio.exp();
        let surr1 = ratio * a;
        let surr2 = ratio.clamp(lo, hi) * a;
        out.policy_loss -= surr1.min(surr2) / mf;
        out.approx_kl += ((ratio - 1.0) - log_ratio) / mf;
        if (ratio - 1.0).abs() > cfg.clip_range {
            out.clip_fraction += 1.0 / mf;
        }
        if surr1 <= surr2 {
            let g_logp = -ratio * a / mf;
            let mut c_mu = Joints::splat(du, 0.0);
            for j in 0..du {
                let z = (delta[j] - mu[j]) * inv_std[j];
                c_mu[j] = g_logp * z * inv_std[j];
                grad[n_heads + j] += g_logp * (z * z - 1.0);
            }
            ac.policy
                .accumulate_mean_grad(&mut ws.policy, &c_mu, &mut grad[..np]);
        }
        let v = ac.value(s, ws);
        let err = v - data.returns[i];
        out.value_loss += err * err / mf;
        ac.accumulate_value_grad(ws, cfg.vf_coef * 2.0 * err / mf, &mut grad[np..]);
    }
    out.entropy = ac.policy.entropy();
    for g in &mut grad[n_heads..np] {
        *g -= cfg.ent_coef;
    }
    out.loss = out.policy_loss + cfg.vf_coef * out.value_loss - cfg.ent_coef * out.entropy;
    out
}

/// Scales `grad` to Euclidean norm at most `max_norm` (PyTorch `clip_grad_norm_`: factor
/// `max_norm / (‖g‖ + 1e-6)` when below 1). Returns ‖g‖ before clipping.
pub fn clip_grad_norm(grad: &mut [f64], max_norm: f64) -> f64 {
    let norm = grad.iter().map(|g| g * g).sum::<f64>().sqrt();
    let c = max_norm / (norm + 1e-6);
    if c < 1.0 {
        for g in grad.iter_mut() {
            *g *= c;
        }
    }
    norm
}
