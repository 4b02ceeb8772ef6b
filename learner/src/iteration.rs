//! The pieces of one iteration that the expert (true task cost) and LQR+GAIfO (composite
//! cost) share, in Algorithm 1's order: [`execute`] is line 1; the caller fits the dynamics
//! (line 2) and computes its cost derivatives (lines 3–4); [`improve`] is lines 5–6.

use hil_sim::Ur5Sim;
use ur5_shared::config::TaskConfig;
use ur5_shared::layout::{DU, DX};
use ur5_shared::noise::Noise;

use crate::algorithm::eval_cost::{eval_cost, CostDerivs};
use crate::algorithm::update::Learner;
use crate::expert::to_gain_table;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::rollout::{run_episode, Episode};
use crate::LearnerError;

/// The simulator's error as a learner error.
pub fn sim_err(e: hil_sim::SimError) -> LearnerError {
    LearnerError::Shape(format!("simulator: {e}"))
}

/// Algorithm 1 line 1: executes `pol` (as gain table `version`) `n` times with exploration
/// noise — episode k draws `Noise::new(seed, version, k)`, as the RT loop does — and once
/// without noise for evaluation.
pub fn execute(
    sim: &mut Ur5Sim,
    task: &TaskConfig,
    pol: &LinGaussPolicy,
    version: u64,
    seed: u64,
    n: usize,
) -> Result<(Vec<Episode>, Episode), LearnerError> {
    let table = to_gain_table(pol, version);
    let mut episodes = Vec::with_capacity(n);
    for k in 0..n {
        let mut noise = Noise::new(seed, version, k as u64);
        episodes.push(run_episode(sim, task, &table, Some(&mut noise)).map_err(sim_err)?);
    }
    let eval = run_episode(sim, task, &table, None).map_err(sim_err)?;
    Ok((episodes, eval))
}

/// Stacks episodes into GPS sample arrays `x (N,T,dX)`, `u (N,T,dU)`.
pub fn stack(episodes: &[Episode]) -> (Vec<f64>, Vec<f64>) {
    let x = episodes.iter().flat_map(|e| e.x.iter().copied()).collect();
    let u = episodes.iter().flat_map(|e| e.u.iter().copied()).collect();
    (x, u)
}

/// What the LQR step did.
#[derive(Clone, Copy, Debug)]
pub struct StepReport {
    /// KL(new ‖ old) of the step (total over T).
    pub kl: f64,
    /// Dual variable η after the search.
    pub eta: f64,
    /// Step multiplier used.
    pub step_mult: f64,
}

/// Algorithm 1 lines 5–6: averages the per-sample cost expansion `derivs` into the quadratic
/// model (GPS `_eval_cost`), adapts the KL step from the previous step's predicted vs actual
/// improvement (from the second iteration on, when `adapt_step`), and takes the KL-bounded LQR
/// step from `pol` into `new_pol`. `learner.update_dynamics` must have run on the same samples.
#[allow(clippy::too_many_arguments)]
pub fn improve(
    learner: &mut Learner,
    x: &[f64],
    u: &[f64],
    n: usize,
    derivs: &CostDerivs,
    prev_pol: Option<&LinGaussPolicy>,
    pol: &LinGaussPolicy,
    new_pol: &mut LinGaussPolicy,
    adapt_step: bool,
) -> Result<StepReport, LearnerError> {
    let t_len = pol.t;
    eval_cost(
        x,
        u,
        derivs,
        n,
        t_len,
        DX,
        DU,
        &mut learner.info.cc,
        &mut learner.info.cv,
        &mut learner.info.cm,
    );
    if let (Some(prev), true) = (prev_pol, adapt_step) {
        learner.update_step_size(prev, pol)?;
    }
    let step_mult = learner.step_mult;
    let res = learner.update_trajectories(pol, new_pol)?;
    let kl = res.trace.last().map(|s| s.kl).unwrap_or(f64::NAN);
    Ok(StepReport {
        kl,
        eta: res.eta,
        step_mult,
    })
}
