//! Demonstrations: state-only trajectories of an expert (and, for diagnostics only, its
//! actions). On disk they are `.npz` (the `learner` application's `io::demos`, layout in
//! docs/design.md §4).

use ur5_shared::config::TaskConfig;
use ur5_shared::joints::Joints;
use ur5_shared::layout::StateLayout;
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
    /// Goal point of the tool centre point (m).
    pub goal: [f64; 3],
    /// Goal pose (UR's p[x, y, z, rx, ry, rz]) of a pose task, `None` for a point goal.
    pub goal_pose: Option<[f64; 6]>,
    /// The pose task's tool points (m, flange frame; `TaskConfig::tool_points`).
    pub tool_points: [[f64; 3]; 3],
    /// Start pose (rad), one angle per active joint.
    pub start_q: Joints,
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
    /// The layout of the demonstrations' states: their task's
    /// ([`TaskConfig::layout`]).
    pub fn layout(&self) -> StateLayout {
        StateLayout::of_task(self.start_q.len(), self.goal_pose.is_some())
            .expect("validated demonstrations")
    }

    /// State t of demonstration d (dX).
    pub fn state(&self, d: usize, t: usize) -> &[f64] {
        let dx = self.layout().dx();
        let i = (d * self.horizon + t) * dx;
        &self.states[i..i + dx]
    }

    /// State t of demonstration d of a three-joint point task (dX = 12) as an array, for
    /// code written for that task only (the precision probe example); panics on another
    /// layout.
    pub fn reach3_state(&self, d: usize, t: usize) -> [f64; ur5_shared::layout::DX] {
        self.state(d, t)
            .try_into()
            .expect("a three-joint task's state")
    }

    /// The task the demonstrations were recorded on (joints, goal, start pose, T, dt),
    /// checked.
    pub fn task(&self) -> Result<TaskConfig, ImitationError> {
        let task = TaskConfig {
            dt: self.dt,
            horizon: self.horizon,
            joints: self.start_q.len(),
            start_q: self.start_q,
            goal: self.goal,
            goal_pose: self.goal_pose,
            tool_points: self.tool_points,
        };
        task.validate().map_err(ImitationError::Task)?;
        Ok(task)
    }
}
