//! The task: which joints move, where from, and the goal, a point or a pose
//! (docs/design.md §2.5); its state layout follows from it.

use serde::{Deserialize, Serialize};

use super::{check_dt, ConfigError};
use crate::joints::Joints;
use crate::layout::{StateLayout, N_JOINTS};
use crate::model::UrModel;

/// The task (docs/design.md §2.5, the paper's §5 set-up): which joints move, where from, and
/// the goal, a point or a pose. Its state layout ([`TaskConfig::layout`]) follows from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TaskConfig {
    /// Control period (s). Paper §5: a new action every 0.1 s.
    pub dt: f64,
    /// Episode length T (steps). Paper §5: 100 steps (10 s).
    pub horizon: usize,
    /// Active joints: 3 (shoulder pan, shoulder lift, elbow; the wrist locked at
    /// `sim.wrist_q`: the paper's set-up, the default) or 6 (the whole arm). Left out when
    /// serialised at 3, so a three-joint task serialises (and hashes) as before.
    #[serde(skip_serializing_if = "is_three")]
    pub joints: usize,
    /// Start pose q0 (rad), one angle per active joint: the retracted pose every episode starts
    /// from (paper §5: "the arm starts in the same retracted pose"; the exact angles are ours:
    /// upper arm raised, elbow folded; with six joints the wrist's home posture follows).
    pub start_q: Joints,
    /// Goal point of the tool centre point (m, arm base frame). Ours: a point in front of the
    /// arm at table height, reachable without passing a joint limit. With a pose goal, the
    /// pose's position (a file that gives `goal_pose` alone gets it from there).
    pub goal: [f64; 3],
    /// A pose goal instead of a point: UR's pose p[x, y, z, rx, ry, rz] of the tool (m; rotation
    /// vector, rad; base frame; what the teach pendant shows). Needs `joints = 6`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goal_pose: Option<[f64; 6]>,
    /// The three tool points of a pose goal (m, flange frame, relative to the tool centre
    /// point; not on one line): the state carries each one's position minus its target
    /// (`crate::pose`). Ours: the TCP and two points 10 cm from it along the flange's x and y
    /// axes, so 1° of orientation error moves them 1.7 mm.
    #[serde(skip_serializing_if = "is_default_tool_points")]
    pub tool_points: [[f64; 3]; 3],
}

/// Default tool points of a pose goal ([`TaskConfig::tool_points`]).
pub const DEFAULT_TOOL_POINTS: [[f64; 3]; 3] = [[0.0; 3], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]];

fn is_three(n: &usize) -> bool {
    *n == 3
}

fn is_default_tool_points(p: &[[f64; 3]; 3]) -> bool {
    *p == DEFAULT_TOOL_POINTS
}

impl Default for TaskConfig {
    fn default() -> Self {
        Self {
            dt: 0.1,
            horizon: 100,
            joints: 3,
            start_q: Joints::from([0.0, -2.0, 2.4]),
            goal: [-0.45, -0.25, 0.25],
            goal_pose: None,
            tool_points: DEFAULT_TOOL_POINTS,
        }
    }
}

impl TaskConfig {
    /// The keys whose defaults depend on the arm model (see [`from_toml_str`]).
    pub const MODEL_KEYS: [&'static str; 2] = ["start_q", "goal"];

    /// The default task on `model`: its start pose and goal ([`UrModel::default_start_q`],
    /// [`UrModel::default_goal`]); `for_model(UrModel::Ur5) == TaskConfig::default()`.
    pub fn for_model(model: UrModel) -> Self {
        Self {
            start_q: Joints::from(model.default_start_q()),
            goal: model.default_goal(),
            ..Self::default()
        }
    }

    /// The whole arm of `model` reaching the pose `goal_pose` (UR's p[x, y, z, rx, ry, rz])
    /// from its default start with the wrist in its home posture.
    pub fn pose_for_model(model: UrModel, goal_pose: [f64; 6]) -> Self {
        let start = Joints::from(model.default_start_q());
        Self {
            joints: 6,
            start_q: start
                .extended(&model.default_wrist_q())
                .expect("3 + 3 joints"),
            goal: [goal_pose[0], goal_pose[1], goal_pose[2]],
            goal_pose: Some(goal_pose),
            ..Self::default()
        }
    }

    /// The start angles of the three arm joints (shoulder pan, shoulder lift, elbow), for arms
    /// that take those and keep the wrist where it is.
    pub fn start_arm_joints(&self) -> [f64; N_JOINTS] {
        [self.start_q[0], self.start_q[1], self.start_q[2]]
    }

    /// The start angles of all six joints (rad): the task's own when it moves six, else its
    /// three arm joints and the wrist at `wrist_q` (a locked wrist's angles).
    pub fn start_six(&self, wrist_q: &[f64; 3]) -> [f64; 6] {
        if self.start_q.len() >= 6 {
            core::array::from_fn(|j| self.start_q[j])
        } else {
            let q = self.start_arm_joints();
            [q[0], q[1], q[2], wrist_q[0], wrist_q[1], wrist_q[2]]
        }
    }

    /// The state layout of this task: its active joints and one tool point for a point goal,
    /// three for a pose goal.
    pub fn layout(&self) -> StateLayout {
        StateLayout::of_task(self.joints, self.goal_pose.is_some()).expect("validated task")
    }

    /// The tool points' offsets from the tool centre point (m, flange frame), one per point
    /// of [`TaskConfig::layout`]: the TCP alone for a point goal.
    pub fn tool_offsets(&self) -> &[[f64; 3]] {
        if self.goal_pose.is_some() {
            &self.tool_points
        } else {
            &self.tool_points[..1]
        }
    }

    /// The tool points' targets (m, base frame), one per point of [`TaskConfig::layout`]:
    /// the goal point, or the goal pose applied to each tool point's offset.
    pub fn targets(&self) -> Vec<[f64; 3]> {
        match &self.goal_pose {
            None => vec![self.goal],
            Some(p) => {
                let mut out = vec![[0.0; 3]; 3];
                crate::pose::tool_points(&crate::pose::isometry(p), &self.tool_points, &mut out);
                out
            }
        }
    }

    /// Checks ranges; the message names the key and the allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_dt(self.dt).map_err(|why| ConfigError::Invalid {
            key: "task.dt",
            why,
        })?;
        if self.horizon == 0 || self.horizon > crate::layout::MAX_HORIZON {
            return Err(ConfigError::Invalid {
                key: "task.horizon",
                why: format!(
                    "{} must be in 1..={}",
                    self.horizon,
                    crate::layout::MAX_HORIZON
                ),
            });
        }
        if self.joints != 3 && self.joints != 6 {
            return Err(ConfigError::Invalid {
                key: "task.joints",
                why: format!(
                    "{} must be 3 (the wrist locked at sim.wrist_q) or 6 (the whole arm)",
                    self.joints
                ),
            });
        }
        if self.start_q.len() != self.joints {
            return Err(ConfigError::Invalid {
                key: "task.start_q",
                why: format!(
                    "{} angles for task.joints = {}: give one per active joint",
                    self.start_q.len(),
                    self.joints
                ),
            });
        }
        if self
            .start_q
            .iter()
            .chain(self.goal.iter())
            .chain(self.goal_pose.iter().flatten())
            .chain(self.tool_points.iter().flatten())
            .any(|v| !v.is_finite())
        {
            return Err(ConfigError::Invalid {
                key: "task.start_q/goal/goal_pose/tool_points",
                why: "must be finite".into(),
            });
        }
        if let Some(p) = &self.goal_pose {
            if self.joints != 6 {
                return Err(ConfigError::Invalid {
                    key: "task.goal_pose",
                    why: format!(
                        "a pose goal needs the wrist: task.joints = 6 (it is {})",
                        self.joints
                    ),
                });
            }
            if self.goal != [p[0], p[1], p[2]] {
                return Err(ConfigError::Invalid {
                    key: "task.goal",
                    why: format!(
                        "{:?} differs from goal_pose's position {:?}: give one of them",
                        self.goal,
                        [p[0], p[1], p[2]]
                    ),
                });
            }
            let offsets = &self.tool_points;
            let (a, b) = (sub(&offsets[1], &offsets[0]), sub(&offsets[2], &offsets[0]));
            let c = [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ];
            if (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() < 1e-4 {
                return Err(ConfigError::Invalid {
                    key: "task.tool_points",
                    why: format!(
                        "{offsets:?} lie (nearly) on one line: three points fix a pose only if \
                         they span a triangle of at least 1e-4 m² (twice its area)"
                    ),
                });
            }
        }
        Ok(())
    }
}

fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
