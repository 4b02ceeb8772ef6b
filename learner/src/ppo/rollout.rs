//! Episodes of the Gaussian MLP policy on the simulated arm, next to
//! [`crate::rollout::run_episode`] for the gain tables and with its conventions: the same
//! [`Episode`] record, ε from [`Noise`] seeded `(run seed, version, k)` for the k-th noisy
//! episode of policy version `version`, and every action through
//! [`ur5_shared::safety::clamp_action`] before it reaches the arm.
//!
//! Action: in goal-angle mode (the paper's set-up) the policy gives an *offset* from the
//! current joint angles, `a = q + μ(s) + σ ⊙ ε` (rad), so that the initial policy (μ ≈ 0)
//! holds the arm, as the LQR's initial controller does, and the clamp's per-step window
//! `q ± v_max·dt` is centred on the policy's zero. In torque mode the output is the torque
//! itself (N·m). `Episode::u_policy` holds `a` before the clamp; PPO's log-probabilities use the
//! unclamped offset `Δ = a − q` (as SB3 stores the unclipped action), [`offset`].

use hil_sim::{SimError, Ur5Sim};
use ur5_shared::config::{ActionMode, TaskConfig};
use ur5_shared::layout::{DU, DX};
use ur5_shared::noise::Noise;
use ur5_shared::safety::clamp_action;
use ur5_shared::NO_NOISE;

use super::policy::{GaussianMlpPolicy, PolicyWorkspace};
use crate::iteration::sim_err;
use crate::rollout::Episode;
use crate::LearnerError;

/// What the policy's offset is added to: the joint angles `s[0..DU]` in goal-angle mode, 0 in
/// torque mode.
pub fn action_base(mode: ActionMode, s: &[f64; DX]) -> [f64; DU] {
    match mode {
        ActionMode::GoalAngles => std::array::from_fn(|j| s[ur5_shared::layout::Q.start + j]),
        ActionMode::Torque => [0.0; DU],
    }
}

/// The unclamped offset Δ_t = u_policy_t − base(s_t) of step `t` of `ep`.
pub fn offset(mode: ActionMode, ep: &Episode, t: usize) -> [f64; DU] {
    let base = action_base(mode, &ep.state(t));
    std::array::from_fn(|j| ep.u_policy[t * DU + j] - base[j])
}

/// One episode of `task.horizon` steps of `pol` from `task.start_q`: ε ~ N(0, I) from `noise`
/// when given, the mean action otherwise.
pub fn run_mlp_episode(
    sim: &mut Ur5Sim,
    task: &TaskConfig,
    pol: &GaussianMlpPolicy,
    ws: &mut PolicyWorkspace,
    mut noise: Option<&mut Noise>,
) -> Result<Episode, SimError> {
    let horizon = task.horizon;
    let limits = sim.limits();
    let mode = sim.config().mode;
    let std: [f64; DU] = std::array::from_fn(|j| pol.log_std()[j].exp());
    let mut obs = sim.reset(task.start_q, task.goal)?;
    let mut ep = Episode {
        x: Vec::with_capacity(horizon * DX),
        u: Vec::with_capacity(horizon * DU),
        u_policy: Vec::with_capacity(horizon * DU),
        eps: Vec::with_capacity(horizon * DU),
        noisy: noise.is_some(),
    };
    for _ in 0..horizon {
        let s = obs.state(&task.goal);
        let eps = match noise.as_deref_mut() {
            Some(n) => n.next(),
            None => NO_NOISE,
        };
        let mu = pol.mean(&s, ws);
        let base = action_base(mode, &s);
        let mut a: [f64; DU] = std::array::from_fn(|j| base[j] + (mu[j] + std[j] * eps[j]));
        ep.u_policy.extend_from_slice(&a);
        clamp_action(mode, &limits, task.dt, &obs.q, &mut a);
        ep.x.extend_from_slice(&s);
        ep.u.extend_from_slice(&a);
        ep.eps.extend_from_slice(&eps);
        obs = sim.step(a);
    }
    Ok(ep)
}

/// Algorithm 1 line 1 for the MLP policy, like [`crate::iteration::execute`]: `n` noisy
/// episodes (episode k draws `Noise::new(seed, version, k)`) and one noise-free evaluation
/// episode (the policy mean).
pub fn execute_mlp(
    sim: &mut Ur5Sim,
    task: &TaskConfig,
    pol: &GaussianMlpPolicy,
    ws: &mut PolicyWorkspace,
    version: u64,
    seed: u64,
    n: usize,
) -> Result<(Vec<Episode>, Episode), LearnerError> {
    let mut episodes = Vec::with_capacity(n);
    for k in 0..n {
        let mut noise = Noise::new(seed, version, k as u64);
        episodes.push(run_mlp_episode(sim, task, pol, ws, Some(&mut noise)).map_err(sim_err)?);
    }
    let eval = run_mlp_episode(sim, task, pol, ws, None).map_err(sim_err)?;
    Ok((episodes, eval))
}
