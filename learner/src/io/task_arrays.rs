//! The task's arrays that demonstrations and episode files both carry (`super::demos`,
//! `super::episode`): the goal point, the start pose (its length the task's joints), and a pose
//! task's goal pose and tool points; from them the file's state layout. Also the layout's
//! names, which policy files carry too (`super::policy`).

use ur5_shared::joints::Joints;
use ur5_shared::layout::StateLayout;

use super::npz::{NpzError, NpzFile, NpzWriter};

/// The task's arrays of a demonstrations or episode file: the goal point, the start pose
/// (its length the task's joints), and a pose task's goal pose and tool points.
pub struct TaskArrays {
    pub goal: [f64; 3],
    pub start_q: Joints,
    pub goal_pose: Option<[f64; 6]>,
    pub tool_points: [[f64; 3]; 3],
    /// The layout they make (the file's arrays are checked against it).
    pub layout: StateLayout,
}

/// Writes the task's arrays (`goal` (3,), `start_q` (n,), and for a pose task `goal_pose`
/// (6,) and `tool_points` (3, 3)).
pub fn write_task(
    w: &mut NpzWriter,
    goal: &[f64; 3],
    start_q: &Joints,
    goal_pose: Option<&[f64; 6]>,
    tool_points: &[[f64; 3]; 3],
) -> Result<(), NpzError> {
    w.f64("goal", &[3], goal)?;
    w.f64("start_q", &[start_q.len() as u64], start_q)?;
    if let Some(p) = goal_pose {
        w.f64("goal_pose", &[6], p)?;
        w.f64("tool_points", &[3, 3], tool_points.as_flattened())?;
    }
    Ok(())
}

/// Writes the names of `layout`'s state and action entries (`state_names` (dX,), `action_names`
/// (dU,)), as demonstrations, episode and policy files carry them.
pub fn write_layout_names(w: &mut NpzWriter, layout: &StateLayout) -> Result<(), NpzError> {
    for (key, names) in [
        ("state_names", layout.state_names()),
        ("action_names", layout.action_names()),
    ] {
        w.strings(key, &names.iter().map(String::as_str).collect::<Vec<_>>())?;
    }
    Ok(())
}

/// Reads the arrays [`write_task`] writes; files from before pose tasks have a point goal.
pub fn read_task(f: &NpzFile) -> Result<TaskArrays, NpzError> {
    let (q_shape, start_q) = f.f64("start_q")?;
    let start_q = match q_shape[..] {
        [n] if n as usize == start_q.len() => {
            Joints::try_from_slice(&start_q).map_err(|e| f.bad("start_q", e.to_string()))?
        }
        _ => return Err(f.bad("start_q", format!("shape {q_shape:?}, expected (joints,)"))),
    };
    let has = |name: &str| f.names().iter().any(|n| n == name);
    let goal_pose: Option<[f64; 6]> = if has("goal_pose") {
        Some(f.f64_shaped("goal_pose", &[6])?.try_into().expect("6"))
    } else {
        None
    };
    let tool_points = if has("tool_points") {
        let v = f.f64_shaped("tool_points", &[3, 3])?;
        [0, 1, 2].map(|i| [v[3 * i], v[3 * i + 1], v[3 * i + 2]])
    } else {
        ur5_shared::config::DEFAULT_TOOL_POINTS
    };
    let layout = StateLayout::of_task(start_q.len(), goal_pose.is_some())
        .map_err(|e| f.bad("start_q", e.to_string()))?;
    Ok(TaskArrays {
        goal: f.f64_shaped("goal", &[3])?.try_into().expect("3"),
        start_q,
        goal_pose,
        tool_points,
        layout,
    })
}
