//! The naive baseline a user tries first: no learning, the demonstrations' mean joint path sent
//! as the commands (docs/design.md §7.3). At step t the command is the mean over the
//! demonstrations of their joint angles at t + 1 (goal joint angles at the control rate: where
//! the demonstrations are one period later; the last step holds the last mean angles), as a
//! gain table with K = 0, so that the real-time controller runs it as it runs every learner's
//! table: a_t = q̄_{t+1} + L ε with L = √init_var I in the noisy episodes.
//!
//! It is a learner of the one interface ([`Learn`], [`LinGaussLearn`]) so that it runs, is
//! served, logged and replayed as the others are; its policy never changes, so every iteration
//! evaluates the same table, and its figure in a comparison is one number at every episode
//! count (the first iteration's noise-free episode; by default it runs one iteration).

use gps::policy::lin_gauss::LinGaussPolicy;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};

use crate::demos::Demos;
use crate::iteration_log::GaifoLog;
use crate::learn::{execute_table, Learn, LinGaussLearn};
use crate::rollout::{Arms, Episode};
use crate::settings::MAX_COUNT;
use crate::ImitationError;

/// Settings of the naive baseline (`learner train --algo replay-mean`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReplayMeanConfig {
    /// The simulated arm of in-process runs.
    pub sim: SimConfig,
    /// Noisy episodes per iteration N (they teach nothing; kept so that the episode plan is
    /// every learner's: 5).
    pub samples: usize,
    /// Iterations (each the same evaluation). Ours: 1.
    pub iterations: usize,
    /// Exploration variance of the noisy episodes, rad² (LQR+GAIfO's initial 0.05).
    pub init_var: f64,
    /// Seed of the noisy episodes' noise.
    pub seed: u64,
}

impl Default for ReplayMeanConfig {
    fn default() -> Self {
        Self {
            sim: SimConfig::default(),
            samples: 5,
            iterations: 1,
            init_var: 0.05,
            seed: 0,
        }
    }
}

impl ReplayMeanConfig {
    /// Refuses settings that cannot work, naming the setting and its range.
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_counts(
            &[
                ("samples", self.samples, 1),
                ("iterations", self.iterations, 1),
            ],
            MAX_COUNT,
        )
        .and_then(|()| {
            crate::error::check_reals(&[(
                "init_var",
                self.init_var,
                self.init_var.is_finite() && self.init_var > 0.0 && self.init_var <= 10.0,
                "finite, > 0 and <= 10 rad²",
            )])
        })
        .map_err(ImitationError::Config)?;
        self.sim
            .validate()
            .map_err(|e| ImitationError::Config(e.to_string()))
    }
}

/// The demonstrations' mean joint path as a controller (module docs): K_t = 0, k_t the mean
/// joint angles at t + 1 (at T − 1 at the last step), Σ_t = `init_var` I. Joint angles are the
/// first dU = `start_q.len()` state coordinates; dX from the demonstrations.
pub fn mean_path_controller(
    demos: &Demos,
    init_var: f64,
) -> Result<LinGaussPolicy, ImitationError> {
    let (count, t_len, du) = (demos.count, demos.horizon, demos.start_q.len());
    if count == 0 || t_len == 0 || demos.states.len() % (count * t_len) != 0 {
        return Err(ImitationError::Episodes(format!(
            "{count} demonstrations of T = {t_len} with {} state values: no mean path",
            demos.states.len()
        )));
    }
    let dx = demos.states.len() / (count * t_len);
    let mut pol = LinGaussPolicy::zeros(t_len, dx, du);
    let sd = init_var.sqrt();
    for t in 0..t_len {
        let next = (t + 1).min(t_len - 1);
        let k = pol.k.slice_mut(t);
        for j in 0..du {
            k[j] = (0..count)
                .map(|d| demos.states[(d * t_len + next) * dx + j])
                .sum::<f64>()
                / count as f64;
        }
        for j in 0..du {
            pol.pol_covar.slice_mut(t)[j * du + j] = init_var;
            pol.chol_pol_covar.slice_mut(t)[j * du + j] = sd;
            pol.inv_pol_covar.slice_mut(t)[j * du + j] = 1.0 / init_var;
        }
    }
    Ok(pol)
}

/// The naive baseline's run.
pub struct ReplayMean {
    cfg: ReplayMeanConfig,
    task: TaskConfig,
    demos: Demos,
    policy: LinGaussPolicy,
    iteration: usize,
}

impl ReplayMean {
    /// The mean path of `demos` on their task.
    pub fn new(cfg: ReplayMeanConfig, demos: Demos) -> Result<Self, ImitationError> {
        cfg.validate()?;
        let task = demos.task()?;
        let policy = mean_path_controller(&demos, cfg.init_var)?;
        Ok(Self {
            cfg,
            task,
            demos,
            policy,
            iteration: 0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &ReplayMeanConfig {
        &self.cfg
    }

    /// Continues a run after `iteration` iterations (its policy never changes, so this is its
    /// whole state).
    pub fn resumed_at(mut self, iteration: usize) -> Self {
        self.iteration = iteration;
        self
    }
}

impl Learn for ReplayMean {
    type Log = GaifoLog;
    const ALGO: &'static str = "replay-mean";

    crate::learn::run_accessors!();
    fn execute(&mut self, arms: &dyn Arms) -> Result<(Vec<Episode>, Vec<Episode>), ImitationError> {
        execute_table(self, arms)
    }

    /// Nothing to learn: the evaluation of the noise-free episode, every learner column NaN
    /// and the learner's times 0.
    fn learn_goals(
        &mut self,
        _noisy: &[Episode],
        evals: &[Episode],
        t_execute: f64,
    ) -> Result<GaifoLog, ImitationError> {
        let eval = crate::learn::single_eval(evals)?;
        let none = crate::discriminator::TrainStats {
            critic_loss: f64::NAN,
            gradient_penalty: f64::NAN,
            wasserstein: f64::NAN,
        };
        let log = GaifoLog {
            t_execute,
            ..GaifoLog::evaluated(self.iteration, eval, &self.demos, &none)
        };
        self.iteration += 1;
        Ok(log)
    }

    fn eval_cost(log: &GaifoLog) -> f64 {
        log.task_cost
    }
}

impl LinGaussLearn for ReplayMean {
    fn policy(&self) -> &LinGaussPolicy {
        &self.policy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The commands are the mean of the demonstrations' next joint angles, K = 0.
    #[test]
    fn the_controller_commands_the_mean_next_joint_angles() {
        let (count, t_len, dx) = (2, 4, 12);
        let mut states = vec![0.0; count * t_len * dx];
        for d in 0..count {
            for t in 0..t_len {
                for i in 0..dx {
                    states[(d * t_len + t) * dx + i] = (d * 100 + t * 10 + i) as f64;
                }
            }
        }
        let demos = Demos {
            states,
            actions: vec![],
            model: Default::default(),
            count,
            horizon: t_len,
            goal: [-0.4, -0.3, 0.3],
            goal_pose: None,
            tool_points: ur5_shared::config::DEFAULT_TOOL_POINTS,
            start_q: [0.0; 3].into(),
            dt: 0.1,
            seed: 0,
            cost_random: 1.0,
            cost_expert: 0.0,
        };
        let pol = mean_path_controller(&demos, 0.04).unwrap();
        for t in 0..t_len {
            let next = (t + 1).min(t_len - 1) as f64;
            for j in 0..3 {
                // Mean of (next·10 + j) and (100 + next·10 + j).
                assert_eq!(pol.k.slice(t)[j], 50.0 + next * 10.0 + j as f64);
                assert!((pol.chol_pol_covar.slice(t)[j * 3 + j] - 0.2).abs() < 1e-15);
            }
            assert!(pol.gain.slice(t).iter().all(|g| *g == 0.0));
        }
        let mut bad = demos.clone();
        bad.states.pop();
        assert!(mean_path_controller(&bad, 0.04).is_err());
    }
}
