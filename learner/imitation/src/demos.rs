//! Demonstrations: state-only trajectories of an expert (and, for diagnostics only, its
//! actions). On disk they are `.npz` (the `learner` application's `io::demos`, layout in
//! docs/design.md §4).

use ur5_shared::config::TaskConfig;
use ur5_shared::layout::DX;
use ur5_shared::UrModel;

use crate::ImitationError;

/// A set of demonstrations.
#[derive(Clone, Debug, PartialEq)]
pub struct Demos {
    /// States, (D, T, dX) row-major.
    pub states: Vec<f64>,
    /// Actions (diagnostics only; imitation never reads them), (D, T, dU) row-major.
    pub actions: Vec<f64>,
    /// The arm model the demonstrations were made on (docs/ur.md, "Arm models"); files
    /// without one were made on the UR5.
    pub model: UrModel,
    /// Number of demonstrations D.
    pub count: usize,
    /// Horizon T.
    pub horizon: usize,
    /// Goal point (m).
    pub goal: [f64; 3],
    /// Start pose (rad).
    pub start_q: [f64; 3],
    /// Control period (s).
    pub dt: f64,
    /// Seed of the recording run.
    pub seed: u64,
    /// Mean task cost of the random policy (for normalised performance).
    pub cost_random: f64,
    /// Mean task cost of these demonstrations.
    pub cost_expert: f64,
}

impl Demos {
    /// State t of demonstration d.
    pub fn state(&self, d: usize, t: usize) -> [f64; DX] {
        let i = (d * self.horizon + t) * DX;
        self.states[i..i + DX].try_into().expect("dX")
    }

    /// The task the demonstrations were recorded on (goal, start pose, T, dt), checked.
    pub fn task(&self) -> Result<TaskConfig, ImitationError> {
        let task = TaskConfig {
            dt: self.dt,
            horizon: self.horizon,
            start_q: self.start_q,
            goal: self.goal,
        };
        task.validate().map_err(ImitationError::Task)?;
        Ok(task)
    }
}
