//! The per-iteration log row of the single-task imitation learners (LQR+GAIfO and the GAIfO
//! (PPO) baseline): the progress line and the CSV row of `gaifo_log.csv`.

use serde::Serialize;

use crate::demos::Demos;
use crate::discriminator::TrainStats;
use crate::rollout::Episode;
use crate::tool_path::{mean_path, rmse, spread, tool_paths, PathMeasures, Point};

/// Per-iteration log (progress line and CSV row).
#[derive(Clone, Debug, Serialize)]
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
    /// How far this iteration's noisy episodes end from the demonstrations, with no task cost:
    /// [`demo_gap`] (dimensionless; docs/design.md §5 D36). NaN where the learner does not
    /// compute it (the PPO baseline, the expert). Not a column of `gaifo_log.csv`.
    pub demo_gap: f64,
    /// Per-step RMSE (m) of the noise-free episode's tool path against the demonstrations'
    /// mean path ([`path_rmse`]; docs/design.md §4.15). NaN where not computed. Not a column
    /// of `gaifo_log.csv`.
    pub path_rmse: f64,
    /// Final orientation error of the tool in the noise-free episode (degrees;
    /// `Episode::final_orientation_error`): pose goals only, NaN otherwise. Not a column of
    /// `gaifo_log.csv`.
    pub final_orientation_error_deg: f64,
}

impl Default for GaifoLog {
    /// Zeros, and `demo_gap` NaN (not computed).
    fn default() -> Self {
        Self {
            iteration: 0,
            task_cost: 0.0,
            performance: 0.0,
            final_distance: 0.0,
            critic_loss: 0.0,
            wasserstein: 0.0,
            kl: 0.0,
            eta: 0.0,
            step_mult: 0.0,
            t_execute: 0.0,
            t_dynamics: 0.0,
            t_critic: 0.0,
            t_cost: 0.0,
            t_lqr: 0.0,
            cpu_learner: 0.0,
            demo_gap: f64::NAN,
            path_rmse: f64::NAN,
            final_orientation_error_deg: f64::NAN,
        }
    }
}

/// The target of the first tool point (the tool centre point) of the demonstrations' task.
fn tcp_target(demos: &Demos) -> Point {
    demos
        .task()
        .ok()
        .and_then(|t| t.targets().first().copied())
        .unwrap_or(demos.goal)
}

/// The demonstrations' tool paths (of their first tool point, the tool centre point).
fn demo_paths(demos: &Demos) -> Vec<Vec<Point>> {
    tool_paths(
        &demos.states,
        &demos.layout(),
        demos.horizon,
        &tcp_target(demos),
    )
}

/// Per-step RMSE (m) of `eval`'s tool path against the mean path of `demos` (docs/design.md
/// §4.15), or NaN if either has no samples.
pub fn path_rmse(eval: &Episode, demos: &Demos) -> f64 {
    let paths = demo_paths(demos);
    let refs: Vec<&[Point]> = paths.iter().map(Vec::as_slice).collect();
    let Ok(mean) = mean_path(&refs) else {
        return f64::NAN;
    };
    let ep = tool_paths(&eval.x, &eval.layout, eval.horizon(), &tcp_target(demos));
    rmse(&ep[0], &mean).unwrap_or(f64::NAN)
}

/// The demonstrations' own spread in the path measures (each against the mean of the others;
/// docs/design.md §4.15), or `None` for fewer than two demonstrations.
pub fn demo_spread(demos: &Demos) -> Option<PathMeasures> {
    let paths = demo_paths(demos);
    let refs: Vec<&[Point]> = paths.iter().map(Vec::as_slice).collect();
    spread(&refs).ok()
}

/// The mean over `episodes` of the distance between each one's final state s_{T−1} and the
/// demonstrations' mean final state, every coordinate i divided by σ_i, the standard deviation
/// of coordinate i over all demonstrated states (all demonstrations and steps; σ_i = 1 where
/// it is below 1e-6). Uses the states only, as imitation from observation may: a controller
/// whose episodes come to rest where the demonstrations do scores near 0. Shapes: states of
/// the demonstrations' dX (docs/design.md §2).
pub fn demo_gap(episodes: &[Episode], demos: &Demos) -> f64 {
    let (n, t_last) = (demos.count * demos.horizon, demos.horizon - 1);
    let dx = demos.layout().dx();
    let mut mean = vec![0.0; dx];
    let mut end = vec![0.0; dx];
    for d in 0..demos.count {
        for t in 0..demos.horizon {
            let s = demos.state(d, t);
            for i in 0..dx {
                mean[i] += s[i] / n as f64;
                if t == t_last {
                    end[i] += s[i] / demos.count as f64;
                }
            }
        }
    }
    let mut var = vec![0.0; dx];
    for d in 0..demos.count {
        for t in 0..demos.horizon {
            let s = demos.state(d, t);
            for i in 0..dx {
                var[i] += (s[i] - mean[i]) * (s[i] - mean[i]) / n as f64;
            }
        }
    }
    let sigma: Vec<f64> = var
        .iter()
        .map(|v| if v.sqrt() < 1e-6 { 1.0 } else { v.sqrt() })
        .collect();
    let gaps = episodes.iter().map(|e| {
        let s = e.state(e.horizon() - 1);
        (0..dx)
            .map(|i| ((s[i] - end[i]) / sigma[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    });
    gaps.sum::<f64>() / episodes.len() as f64
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
            path_rmse: path_rmse(eval, demos),
            final_orientation_error_deg: demos
                .task()
                .ok()
                .and_then(|t| eval.final_orientation_error(&t.targets()))
                .map_or(f64::NAN, f64::to_degrees),
            ..Self::default()
        }
    }

    /// Learner time (everything but executing episodes), s.
    pub fn learner_seconds(&self) -> f64 {
        self.t_dynamics + self.t_critic + self.t_cost + self.t_lqr
    }

    /// Column names of [`GaifoLog::progress_line`].
    pub const PROGRESS_HEADER: &'static str = "iter task_cost    perf  final_m   path_m    critic   W1_est       kl       eta   mult  lrn_ms  sim_ms";

    /// The progress line of this iteration (`learner train`, `learner serve --algo lqr-gaifo`;
    /// `path_m` is [`GaifoLog::path_rmse`], `sim_ms` [`GaifoLog::t_execute`]).
    pub fn progress_line(&self) -> String {
        format!(
            "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>8.4} {:>9.4} {:>8.4} {:>8.3} {:>9.2e} {:>6.2} {:>7.1} {:>7.1}",
            self.iteration,
            self.task_cost,
            self.performance,
            self.final_distance,
            self.path_rmse,
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

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::layout::DX;

    /// Two demonstrations of T = 2: coordinate i takes the values 0, 2 (first) and 0, 0
    /// (second) so its spread over the four states is σ = √0.75 and the mean final state 1.
    fn demos() -> Demos {
        let mut states = vec![0.0; 2 * 2 * DX];
        for i in 0..DX {
            states[DX + i] = 2.0;
        }
        Demos {
            states,
            actions: vec![0.0; 2 * 2 * 3],
            model: Default::default(),
            count: 2,
            horizon: 2,
            goal: [0.0; 3],
            goal_pose: None,
            tool_points: ur5_shared::config::DEFAULT_TOOL_POINTS,
            start_q: [0.0; 3].into(),
            dt: 0.05,
            seed: 0,
            cost_random: 1.0,
            cost_expert: 0.0,
        }
    }

    fn ending_at(s_last: [f64; DX]) -> Episode {
        let mut x = vec![0.0; 2 * DX];
        x[DX..].copy_from_slice(&s_last);
        Episode {
            layout: ur5_shared::StateLayout::REACH3,
            x,
            u: vec![0.0; 6],
            u_policy: vec![0.0; 6],
            eps: vec![0.0; 6],
            noisy: true,
        }
    }

    #[test]
    fn demo_gap_is_the_mean_normalised_distance_to_the_demonstrations_end() {
        let d = demos();
        let sigma = 0.75f64.sqrt();
        assert_eq!(demo_gap(&[ending_at([1.0; DX])], &d), 0.0);
        // One coordinate off by one σ: gap 1; a second episode off by 3σ in two coordinates.
        let mut a = [1.0; DX];
        a[6] += sigma;
        let mut b = [1.0; DX];
        b[0] -= 3.0 * sigma;
        b[11] += 3.0 * sigma;
        let want = (1.0 + (18.0f64).sqrt()) / 2.0;
        let got = demo_gap(&[ending_at(a), ending_at(b)], &d);
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }
}
