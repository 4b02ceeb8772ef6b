//! The per-iteration log row of the single-task imitation learners (LQR+GAIfO and the GAIfO
//! (PPO) baseline): the progress line and the CSV row of `gaifo_log.csv`.

use serde::Serialize;

use crate::demos::Demos;
use crate::discriminator::TrainStats;
use crate::rollout::Episode;

/// Per-iteration log (progress line and CSV row).
#[derive(Clone, Debug, Default, Serialize)]
pub struct GaifoLog {
    /// Iteration (0-based).
    pub iteration: usize,
    /// True task cost C(τ) of the noise-free episode.
    pub task_cost: f64,
    /// Its normalised performance (C_random − C) / (C_random − C_expert).
    pub performance: f64,
    /// Final end-effector distance of the noise-free episode (m).
    pub final_distance: f64,
    /// Mean critic loss of this iteration's critic steps.
    pub critic_loss: f64,
    /// Critic's Wasserstein-1 estimate E_controller[D] − E_expert[D] after the update.
    pub wasserstein: f64,
    /// KL of the LQR step.
    pub kl: f64,
    /// η after the search.
    pub eta: f64,
    /// Step multiplier.
    pub step_mult: f64,
    /// Seconds per phase: executing episodes (simulator).
    pub t_execute: f64,
    /// Dynamics fit (GMM prior + regression).
    pub t_dynamics: f64,
    /// Discriminator update.
    pub t_critic: f64,
    /// Composite cost and its expansion (Hessians).
    pub t_cost: f64,
    /// KL-bounded LQR (cost averaging, step size, η search).
    pub t_lqr: f64,
    /// Thread CPU seconds of the learner phases (dynamics, critic, cost, LQR): the learner
    /// time of one iteration on one core, unaffected by waiting for a core on a busy machine.
    pub cpu_learner: f64,
}

impl GaifoLog {
    /// The log of iteration `iteration` with the evaluation of its noise-free episode `eval`
    /// (task cost, normalised performance against `demos`, final distance) and the critic's
    /// statistics filled in; the step (`kl`, `eta`, `step_mult`) NaN and the times 0, for the
    /// algorithm to set. Shared by LQR+GAIfO and the PPO baseline.
    pub fn evaluated(iteration: usize, eval: &Episode, demos: &Demos, critic: &TrainStats) -> Self {
        let c = eval.task_cost();
        Self {
            iteration,
            task_cost: c,
            performance: ur5_shared::normalised_performance(
                c,
                demos.cost_random,
                demos.cost_expert,
            )
            .unwrap_or(f64::NAN),
            final_distance: eval.final_distance(),
            critic_loss: critic.critic_loss,
            wasserstein: critic.wasserstein,
            kl: f64::NAN,
            eta: f64::NAN,
            step_mult: f64::NAN,
            t_execute: 0.0,
            t_dynamics: 0.0,
            t_critic: 0.0,
            t_cost: 0.0,
            t_lqr: 0.0,
            cpu_learner: 0.0,
        }
    }

    /// Learner time (everything but executing episodes), s.
    pub fn learner_seconds(&self) -> f64 {
        self.t_dynamics + self.t_critic + self.t_cost + self.t_lqr
    }

    /// Column names of [`GaifoLog::progress_line`].
    pub const PROGRESS_HEADER: &'static str = "iter task_cost    perf  final_m    critic   W1_est       kl       eta   mult  lrn_ms  sim_ms";

    /// The progress line of this iteration (`learner train`, `learner serve --algo lqr-gaifo`;
    /// `sim_ms` is [`GaifoLog::t_execute`]).
    pub fn progress_line(&self) -> String {
        format!(
            "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>9.4} {:>8.4} {:>8.3} {:>9.2e} {:>6.2} {:>7.1} {:>7.1}",
            self.iteration,
            self.task_cost,
            self.performance,
            self.final_distance,
            self.critic_loss,
            self.wasserstein,
            self.kl,
            self.eta,
            self.step_mult,
            1e3 * self.learner_seconds(),
            1e3 * self.t_execute
        )
    }
}
