//! The Gaussian MLP policy π(Δ|s) = N(μ(s), diag(σ²)) with a state-independent learned log σ,
//! and the value function V(s) beside it, all built from the one tanh MLP of
//! [`crate::discriminator::mlp`]. Below the learners that use it: GAIfO (PPO)'s actor and
//! value function, and, on normalised states, the [`global`] policy of MDGPS, BCO and GAIfO
//! (TD3), with its supervised fit ([`opt`]: MDGPS's S-step, BCO's cloning).
//!
//! The dimensions are the task's, at run time: the state has dX entries and the action dU
//! (`ur5_shared::layout::StateLayout`), taken when a policy is built.
//!
//! That MLP has a scalar output, so the mean is dU of them, one per joint (`μ_j(s)`, no
//! shared trunk). Stable-baselines3's `MlpPolicy` shares nothing between policy and value
//! either, but its action head is one dU-output layer on a shared 64-64 trunk; ours has dU
//! 64-64 trunks (dU× the compute, same function class per output). We keep it so there is one
//! MLP implementation in the project.
//!
//! Parameters, flat (for the optimiser and the gradient checks):
//! `θ = [θ_μ0 | … | θ_μ(dU−1) | log σ (dU) | θ_V]`, each `θ_…` in the MLP's own layout; the
//! heads are drawn in that order, so a three-joint policy draws exactly as before the
//! dimensions were a run-time value.

pub mod global;
pub mod opt;

use rand::Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::config::ActionMode;
use ur5_shared::joints::Joints;

use crate::discriminator::mlp::{Mlp, MlpWorkspace};

/// `½ ln 2π`.
pub const HALF_LN_2PI: f64 = 0.918_938_533_204_672_8;

/// What the policy's offset is added to for `du` active joints: the joint angles `s[0..du]`
/// in goal-angle mode (every layout starts with them, `StateLayout::q`), 0 in torque mode.
pub fn action_base(mode: ActionMode, du: usize, s: &[f64]) -> Joints {
    match mode {
        ActionMode::GoalAngles => Joints::from_slice(&s[..du]),
        ActionMode::Torque => Joints::splat(du, 0.0),
    }
}

/// Gaussian MLP policy over the action offset Δ ∈ R^dU (rad in goal-angle mode, added to
/// [`action_base`]) on states of dX entries.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianMlpPolicy {
    heads: Vec<Mlp>,
    log_std: Joints,
}

/// Scratch space of a [`GaussianMlpPolicy`]: one MLP workspace per mean head.
#[derive(Clone, Debug)]
pub struct PolicyWorkspace {
    heads: Vec<MlpWorkspace>,
}

/// Layer sizes `[dx, hidden..., 1]`.
pub fn net_sizes(dx: usize, hidden: &[usize]) -> Vec<usize> {
    let mut s = vec![dx];
    s.extend_from_slice(hidden);
    s.push(1);
    s
}

impl GaussianMlpPolicy {
    /// Glorot-uniform weights (the MLP's initialisation) with the output layer scaled by
    /// `out_scale`, so that the initial mean offset is ≈ 0 (SB3 / OpenAI baselines scale the
    /// action layer by 0.01 with their orthogonal initialisation for the same reason); log σ
    /// = `log_std` for every joint. `dx`, `du`: the task's state and action dimensions.
    pub fn new(
        dx: usize,
        du: usize,
        hidden: &[usize],
        log_std: f64,
        out_scale: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let sizes = net_sizes(dx, hidden);
        let heads = (0..du)
            .map(|_| {
                let mut net = Mlp::glorot(&sizes, rng);
                let r = net.weight_range(net.layers() - 1);
                for w in &mut net.params_mut()[r] {
                    *w *= out_scale;
                }
                net
            })
            .collect();
        Self {
            heads,
            log_std: Joints::splat(du, log_std),
        }
    }

    /// Rebuilds a policy on states of `dx` entries from its hidden widths, per-head parameters
    /// (one head per joint) and log σ (one per joint; checkpoints).
    pub fn from_parts(dx: usize, hidden: &[usize], heads: Vec<Vec<f64>>, log_std: Joints) -> Self {
        let sizes = net_sizes(dx, hidden);
        assert_eq!(
            heads.len(),
            log_std.len(),
            "one head and one log σ per joint"
        );
        Self {
            heads: heads
                .into_iter()
                .map(|p| Mlp::from_params(&sizes, p))
                .collect(),
            log_std,
        }
    }

    /// Scratch space for this policy's size.
    pub fn workspace(&self) -> PolicyWorkspace {
        PolicyWorkspace {
            heads: self
                .heads
                .iter()
                .map(|h| MlpWorkspace::new(h.sizes()))
                .collect(),
        }
    }

    /// State dimension dX (the heads' input).
    pub fn dx(&self) -> usize {
        self.heads[0].sizes()[0]
    }

    /// Action dimension dU (one head per joint).
    pub fn du(&self) -> usize {
        self.heads.len()
    }

    /// The mean head of joint `j`.
    pub fn head(&self, j: usize) -> &Mlp {
        &self.heads[j]
    }

    /// Per-joint log σ (dU).
    pub fn log_std(&self) -> &Joints {
        &self.log_std
    }

    /// Sets the per-joint log σ (dU values).
    pub fn set_log_std(&mut self, log_std: Joints) {
        assert_eq!(log_std.len(), self.du(), "one log σ per joint");
        self.log_std = log_std;
    }

    /// Parameters per head (`dU × n_head`) plus dU log σ.
    pub fn n_params(&self) -> usize {
        self.heads.iter().map(|h| h.params().len()).sum::<usize>() + self.du()
    }

    /// The mean μ(s) (dU) at the state `s` (dX). Leaves every head's forward pass in `ws` (for
    /// [`Self::accumulate_mean_grad`]).
    pub fn mean(&self, s: &[f64], ws: &mut PolicyWorkspace) -> Joints {
        let mut mu = Joints::splat(self.du(), 0.0);
        for (j, (h, w)) in self.heads.iter().zip(&mut ws.heads).enumerate() {
            w.u.copy_from_slice(s);
            mu[j] = h.forward(w);
        }
        mu
    }

    /// log π(Δ|s) given the mean μ(s): `Σ_j −½ ((Δ_j − μ_j)/σ_j)² − log σ_j − ½ ln 2π`.
    pub fn log_prob_given_mean(&self, mu: &[f64], delta: &[f64]) -> f64 {
        let mut lp = 0.0;
        for j in 0..self.du() {
            let z = (delta[j] - mu[j]) * (-self.log_std[j]).exp();
            lp += -0.5 * z * z - self.log_std[j] - HALF_LN_2PI;
        }
        lp
    }

    /// Entropy of π(·|s) (the same for every s): `Σ_j log σ_j + ½ (1 + ln 2π)`.
    pub fn entropy(&self) -> f64 {
        self.log_std.iter().map(|l| l + 0.5 + HALF_LN_2PI).sum()
    }

    /// `grad[head j] += c_j ∂μ_j/∂θ_j` after [`Self::mean`] on the same `ws`; `grad` is the
    /// policy part of the flat layout (heads, then log σ).
    pub(crate) fn accumulate_mean_grad(
        &self,
        ws: &mut PolicyWorkspace,
        c: &[f64],
        grad: &mut [f64],
    ) {
        let mut off = 0;
        for (j, (h, w)) in self.heads.iter().zip(&mut ws.heads).enumerate() {
            let n = h.params().len();
            if c[j] != 0.0 {
                h.backward(w, false);
                h.accumulate_param_grad(w, c[j], &mut grad[off..off + n]);
            }
            off += n;
        }
    }

    fn locate(&self, k: usize) -> Option<(usize, usize)> {
        let mut k = k;
        for (j, h) in self.heads.iter().enumerate() {
            let n = h.params().len();
            if k < n {
                return Some((j, k));
            }
            k -= n;
        }
        None
    }

    /// Parameter `k` of the flat layout (heads, then log σ).
    pub fn param(&self, k: usize) -> f64 {
        match self.locate(k) {
            Some((j, i)) => self.heads[j].params()[i],
            None => self.log_std[k - (self.n_params() - self.du())],
        }
    }

    /// Sets parameter `k` of the flat layout.
    pub fn set_param(&mut self, k: usize, v: f64) {
        match self.locate(k) {
            Some((j, i)) => self.heads[j].params_mut()[i] = v,
            None => {
                let i = k - (self.n_params() - self.du());
                self.log_std[i] = v;
            }
        }
    }

    /// `jac[j·dX..(j+1)·dX] = ∂μ_j/∂s` (row j of the `dU × dX` Jacobian of the mean, row-major)
    /// at `s`; leaves every head's forward and backward pass in `ws`. Exact (the MLP's backward
    /// pass with its input gradient); checked against central differences in `tests/mdgps.rs`.
    pub fn mean_jacobian(&self, s: &[f64], ws: &mut PolicyWorkspace, jac: &mut [f64]) -> Joints {
        let mu = self.mean(s, ws);
        let dx = self.dx();
        assert_eq!(jac.len(), self.du() * dx, "a dU × dX Jacobian");
        for ((h, w), row) in self
            .heads
            .iter()
            .zip(&mut ws.heads)
            .zip(jac.chunks_exact_mut(dx))
        {
            h.backward(w, true);
            row.copy_from_slice(&w.grad_u);
        }
        mu
    }

    /// Copies the flat parameters (heads, then log σ) into `out` (`n_params`).
    pub(crate) fn read_params(&self, out: &mut [f64]) {
        let mut off = 0;
        for h in &self.heads {
            let p = h.params();
            out[off..off + p.len()].copy_from_slice(p);
            off += p.len();
        }
        out[off..off + self.log_std.len()].copy_from_slice(&self.log_std);
    }

    /// Sets the flat parameters (heads, then log σ) from `src` (`n_params`).
    pub(crate) fn write_params(&mut self, src: &[f64]) {
        let mut off = 0;
        for h in &mut self.heads {
            let p = h.params_mut();
            let n = p.len();
            p.copy_from_slice(&src[off..off + n]);
            off += n;
        }
        let du = self.log_std.len();
        self.log_std.copy_from_slice(&src[off..off + du]);
    }
}

/// The policy and the value function V(s) with one flat parameter vector
/// `[policy (heads, log σ) | V]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ActorCritic {
    pub policy: GaussianMlpPolicy,
    pub value: Mlp,
}

/// Scratch space of an [`ActorCritic`].
#[derive(Clone, Debug)]
pub struct ActorCriticWorkspace {
    pub policy: PolicyWorkspace,
    pub(crate) value: MlpWorkspace,
}

/// A checkpoint of the policy (JSON).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PolicyFile {
    /// Format version.
    pub schema_version: u32,
    /// Hidden widths of every mean head.
    pub hidden: Vec<usize>,
    /// How the action is formed from the state and the sampled offset.
    pub action: String,
    /// Per-head flat parameters (layout of `learner::discriminator::mlp`).
    pub heads: Vec<Vec<f64>>,
    /// Per-joint log σ (dU).
    pub log_std: Vec<f64>,
}

impl ActorCritic {
    /// A fresh policy ([`GaussianMlpPolicy::new`]) and a Glorot-initialised value net, for
    /// states of `dx` entries and actions of `du`.
    pub fn new(
        dx: usize,
        du: usize,
        pi_hidden: &[usize],
        v_hidden: &[usize],
        log_std: f64,
        out_scale: f64,
        rng: &mut impl Rng,
    ) -> Self {
        let policy = GaussianMlpPolicy::new(dx, du, pi_hidden, log_std, out_scale, rng);
        let value = Mlp::glorot(&net_sizes(dx, v_hidden), rng);
        Self { policy, value }
    }

    /// Scratch space for these nets.
    pub fn workspace(&self) -> ActorCriticWorkspace {
        ActorCriticWorkspace {
            policy: self.policy.workspace(),
            value: MlpWorkspace::new(self.value.sizes()),
        }
    }

    /// Length of the flat parameter vector.
    pub fn n_params(&self) -> usize {
        self.policy.n_params() + self.value.params().len()
    }

    /// Number of policy parameters (the value net's start in the flat layout).
    pub fn n_policy_params(&self) -> usize {
        self.policy.n_params()
    }

    /// V(s). Leaves the forward pass in `ws` (for the value gradient).
    pub fn value(&self, s: &[f64], ws: &mut ActorCriticWorkspace) -> f64 {
        ws.value.u.copy_from_slice(s);
        self.value.forward(&mut ws.value)
    }

    /// `grad[V part] += c ∂V/∂θ_V` after [`Self::value`] on the same `ws`.
    pub(crate) fn accumulate_value_grad(
        &self,
        ws: &mut ActorCriticWorkspace,
        c: f64,
        grad: &mut [f64],
    ) {
        self.value.backward(&mut ws.value, false);
        self.value.accumulate_param_grad(&ws.value, c, grad);
    }

    /// Parameter `k` of the flat layout.
    pub fn param(&self, k: usize) -> f64 {
        let np = self.policy.n_params();
        if k < np {
            self.policy.param(k)
        } else {
            self.value.params()[k - np]
        }
    }

    /// Sets parameter `k` of the flat layout.
    pub fn set_param(&mut self, k: usize, v: f64) {
        let np = self.policy.n_params();
        if k < np {
            self.policy.set_param(k, v)
        } else {
            self.value.params_mut()[k - np] = v
        }
    }

    /// Copies the flat parameter vector into `out` (`n_params`).
    pub fn read_params(&self, out: &mut [f64]) {
        let np = self.policy.n_params();
        self.policy.read_params(&mut out[..np]);
        out[np..].copy_from_slice(self.value.params());
    }

    /// Sets every parameter from the flat vector `src` (`n_params`).
    pub fn write_params(&mut self, src: &[f64]) {
        let np = self.policy.n_params();
        self.policy.write_params(&src[..np]);
        self.value.params_mut().copy_from_slice(&src[np..]);
    }

    /// The policy as a checkpoint.
    pub fn policy_file(&self, hidden: &[usize]) -> PolicyFile {
        PolicyFile {
            schema_version: 1,
            hidden: hidden.to_vec(),
            action: "goal angles a = q + mean(s) (+ exp(log_std) * eps when exploring), then shared::safety::clamp_action".into(),
            heads: (0..self.policy.du())
                .map(|j| self.policy.head(j).params().to_vec())
                .collect(),
            log_std: self.policy.log_std().to_vec(),
        }
    }
}
