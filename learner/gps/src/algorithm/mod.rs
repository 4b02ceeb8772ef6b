//! Algorithm-level pieces of GPS `Algorithm` / `AlgorithmTrajOpt`
//! (python/gps/algorithm/algorithm.py, algorithm_traj_opt.py): cost averaging, the
//! initial-state fit, step-size adaptation, and one full learner update.

pub mod eval_cost;
pub mod init_state;
pub mod step_adjust;
pub mod update;

/// GPS `ALG` hyperparameters used by the learner (algorithm/config.py).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AlgorithmConfig {
    /// Base KL step per time step ε/T (default 0.2).
    pub kl_step: f64,
    /// Lower bound of the step multiplier (default 0.01).
    pub min_step_mult: f64,
    /// Upper bound of the step multiplier (default 10.0).
    pub max_step_mult: f64,
    /// Floor on the per-coordinate variance of x_0 (default 1e-6).
    pub initial_state_var: f64,
    /// Initial dual variable η (GPS `IterationData.eta`, default 1.0).
    pub eta_initial: f64,
}

impl AlgorithmConfig {
    /// Checks every setting's range (a NaN or negative KL step would freeze learning).
    pub fn validate(&self) -> Result<(), crate::GpsError> {
        use crate::error::check;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        check(
            pos(self.kl_step),
            "algorithm.kl_step",
            self.kl_step,
            "finite and > 0",
        )?;
        check(
            pos(self.min_step_mult)
                && pos(self.max_step_mult)
                && self.min_step_mult <= self.max_step_mult,
            "algorithm.min_step_mult/max_step_mult",
            (self.min_step_mult, self.max_step_mult),
            "finite, > 0, min <= max",
        )?;
        check(
            self.initial_state_var.is_finite() && self.initial_state_var >= 0.0,
            "algorithm.initial_state_var",
            self.initial_state_var,
            "finite and >= 0",
        )?;
        check(
            pos(self.eta_initial),
            "algorithm.eta_initial",
            self.eta_initial,
            "finite and > 0",
        )
    }
}

impl Default for AlgorithmConfig {
    fn default() -> Self {
        // GPS algorithm/config.py ALG and algorithm_utils.py IterationData.
        Self {
            kl_step: 0.2,
            min_step_mult: 0.01,
            max_step_mult: 10.0,
            initial_state_var: 1e-6,
            eta_initial: 1.0,
        }
    }
}
