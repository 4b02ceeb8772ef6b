//! The Gaussian MLP policy's episodes: the one episode loop [`crate::rollout::run_episode`]
//! with the policy as a [`Policy`] ([`MlpActor`]), so the same [`Episode`] record, noise
//! seeding and action clamp as the gain tables.
//!
//! Action: in goal-angle mode (the paper's set-up) the policy gives an *offset* from the
//! current joint angles, `a = q + μ(s) + σ ⊙ ε` (rad), so that the initial policy (μ ≈ 0)
//! holds the arm, as the LQR's initial controller does, and the clamp's per-step window
//! `q ± v_max·dt` is centred on the policy's zero. In torque mode the output is the torque
//! itself (N·m). `Episode::u_policy` holds `a` before the clamp; PPO's log-probabilities use the
//! unclamped offset `Δ = a − q` (as SB3 stores the unclipped action), [`offset`].

use ur5_shared::config::{ActionMode, TaskConfig};
use ur5_shared::joints::Joints;

use crate::mlp_policy::action_base;
use crate::mlp_policy::{GaussianMlpPolicy, PolicyWorkspace};
use crate::rollout::{execute, Actors, Arms, Episode, Policy};
use crate::ImitationError;

/// The unclamped offset Δ_t = u_policy_t − base(s_t) of step `t` of `ep` (dU).
pub fn offset(mode: ActionMode, ep: &Episode, t: usize) -> Joints {
    let du = ep.du();
    let mut d = action_base(mode, du, ep.state(t));
    for (j, v) in d.iter_mut().enumerate() {
        *v = ep.u_policy[t * du + j] - *v;
    }
    d
}

/// The Gaussian MLP policy as a [`Policy`] for [`crate::rollout::run_episode`]:
/// `a = base(s) + (μ(s) + σ ⊙ ε)`, with its own scratch memory.
pub struct MlpActor<'a> {
    pol: &'a GaussianMlpPolicy,
    ws: PolicyWorkspace,
    std: Joints,
}

impl<'a> MlpActor<'a> {
    /// `pol` acting with scratch memory `ws`.
    pub fn new(pol: &'a GaussianMlpPolicy, ws: PolicyWorkspace) -> Self {
        let mut std = *pol.log_std();
        for v in std.iter_mut() {
            *v = v.exp();
        }
        Self { pol, ws, std }
    }
}

/// Parallel episodes of the MLP policy: each with its own workspace.
impl Actors for GaussianMlpPolicy {
    fn actor(&self) -> Box<dyn Policy + '_> {
        Box::new(MlpActor::new(self, self.workspace()))
    }
}

impl Policy for MlpActor<'_> {
    fn horizon(&self) -> usize {
        usize::MAX
    }

    /// The MLP policy acts on states of its dX and writes its dU actions.
    fn act(&mut self, _t: usize, s: &[f64], eps: &[f64], mode: ActionMode, a: &mut [f64]) {
        let mu = self.pol.mean(s, &mut self.ws);
        let base = action_base(mode, self.pol.du(), s);
        for j in 0..self.pol.du() {
            a[j] = base[j] + (mu[j] + self.std[j] * eps[j]);
        }
    }
}

/// Step 1 of Algorithm 1 for the MLP policy ([`crate::rollout::execute`]): `n` noisy
/// episodes (episode k draws `Noise::new(seed, version, k)`) and one noise-free evaluation
/// episode (the policy mean), in parallel on arms from `arms`.
pub fn execute_mlp(
    arms: &dyn Arms,
    task: &TaskConfig,
    pol: &GaussianMlpPolicy,
    version: u64,
    seed: u64,
    n: usize,
) -> Result<(Vec<Episode>, Episode), ImitationError> {
    execute(arms, task, pol, version, seed, n)
}
