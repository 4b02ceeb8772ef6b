//! Demonstrations in the formats `--demos` takes beside our `.npz` (docs/design.md §4.12): a
//! LeRobot v3.0 dataset folder ([`super::lerobot`]), a CSV file of states ([`read_csv`]) or of
//! tool paths ([`super::tool_path`]), and the way
//! back: demonstrations or recorded episodes as
//! [`Trajectories`] for `learner dataset export`.
//!
//! What a state-only source does not say is derived on the arm: the start pose from the first
//! frame of the first trajectory, the goal as the arm's forward kinematics of that frame's
//! joint angles minus its `ee − goal` entries (for a pose task the three tool points' targets
//! so, and the goal pose the one that puts the default tool points on them), C_expert as the trajectories' mean task cost,
//! C_random by running the expert's random initial controller on the task
//! ([`imitation::expert::random_policy_cost`], `learner expert`'s default settings, seed
//! [`DERIVED_SEED`] unless the source notes its own). Costs a source notes (`ur5_task` of a
//! dataset we exported) are checked against the recomputed ones, never trusted: normalised
//! performance divides by their difference.
//!
//! A UR arm's recording of six joint positions ([`super::lerobot::import_joint_positions`])
//! becomes states of the whole arm and a pose ([`from_joint_positions`]): velocities from the
//! positions and the frame rate, tool points by forward kinematics, the goal pose the mean of
//! the episodes' last tool poses (a taught reach ends where the tool should be).

use std::path::{Path, PathBuf};

use super::IoError;
use crate::error::ensure;
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::StateLayout;

use imitation::demos::Demos;

use super::lerobot::{TaskMeta, Trajectories};

/// Seed of the random controller's episodes that measure C_random of a source that does not
/// note it (and the `seed` of its demonstrations).
pub const DERIVED_SEED: u64 = 0;

/// The first columns of a demonstrations CSV file; the dX state columns follow, named as
/// `ur5_shared::StateLayout::state_names` names them for the task's layout.
pub const CSV_INDEX_COLUMNS: [&str; 2] = ["episode", "time_s"];

/// The layouts a demonstrations CSV file may hold, told apart by their state names: three
/// joints and a point (12 columns), six joints and a point (18), six joints and a pose (30).
fn csv_layouts() -> [StateLayout; 3] {
    [
        StateLayout::REACH3,
        StateLayout::of_task(6, false).expect("6 joints, a point"),
        StateLayout::POSE6,
    ]
}

/// The header of a demonstrations CSV file of `layout`.
fn csv_header(layout: &StateLayout) -> Vec<String> {
    CSV_INDEX_COLUMNS
        .iter()
        .map(|c| c.to_string())
        .chain(layout.state_names())
        .collect()
}

/// Reads a demonstrations CSV file: a header `episode,time_s,<the state names of the task's
/// layout>` (12, 18 or 30 of them: the header gives the layout) and one row per step, the
/// steps of an episode together and in time order, every episode of the same length, times
/// 0, dt, 2 dt, … (dt from the first episode, the same for all).
pub fn read_csv(path: &Path) -> Result<Trajectories, IoError> {
    let mut r = csv::Reader::from_path(path).map_err(IoError::csv("reading", path))?;
    let header: Vec<String> = r
        .headers()
        .map_err(IoError::csv("reading", path))?
        .iter()
        .map(str::to_string)
        .collect();
    let Some(layout) = csv_layouts().into_iter().find(|l| header == csv_header(l)) else {
        return Err(IoError::content(
            path,
            format!(
                "header {header:?} ({} state columns), expected {:?} (3 joints and a point, \
                 dX = 12), or the 18 state names of 6 joints and a point, or the 30 of 6 joints \
                 and a pose ({:?})",
                header.len().saturating_sub(2),
                csv_header(&StateLayout::REACH3),
                StateLayout::POSE6.state_names()
            ),
        ));
    };
    let dx = layout.dx();
    let expected = csv_header(&layout);
    let mut rows: Vec<(u64, f64, Vec<f64>)> = Vec::new();
    for (line, rec) in r.records().enumerate() {
        let rec = rec.map_err(|source| IoError::CsvRow {
            path: path.to_owned(),
            row: line + 2,
            source,
        })?;
        let not_a_number = |k: usize, why: &dyn std::fmt::Display| {
            IoError::content(
                path,
                format!(
                    "row {}, column {}: `{}`: {why}",
                    line + 2,
                    expected[k],
                    &rec[k]
                ),
            )
        };
        let num = |k: usize| -> Result<f64, IoError> {
            rec[k]
                .trim()
                .parse::<f64>()
                .map_err(|e| not_a_number(k, &e))
        };
        let e = rec[0]
            .trim()
            .parse::<u64>()
            .map_err(|e| not_a_number(0, &e))?;
        let s = (0..dx).map(|k| num(2 + k)).collect::<Result<Vec<_>, _>>()?;
        rows.push((e, num(1)?, s));
    }
    let first = rows.first().map(|r| r.0);
    let horizon = rows.iter().take_while(|r| Some(r.0) == first).count();
    ensure!(
        horizon >= 2,
        IoError::content(
            path,
            format!("the first episode has {horizon} rows: need at least 2")
        )
    );
    ensure!(
        rows.len() % horizon == 0,
        IoError::content(
            path,
            format!(
                "{} rows are not whole episodes of {horizon} steps",
                rows.len()
            )
        )
    );
    let dt = rows[1].1 - rows[0].1;
    let mut states = Vec::with_capacity(rows.len() * dx);
    let mut seen = std::collections::BTreeSet::new();
    for (i, (e, time, s)) in rows.iter().enumerate() {
        let (d, t) = (i / horizon, i % horizon);
        // An episode's rows together, each label once: a reused or interleaved label would
        // otherwise join steps of two episodes into one.
        ensure!(
            t != 0 || seen.insert(*e),
            IoError::content(
                path,
                format!(
                    "row {}: episode {e} again, after other episodes: the rows of an episode \
                     must be consecutive and every episode label used once",
                    i + 2
                )
            )
        );
        ensure!(
            *e == rows[d * horizon].0 && (t == 0 || rows[i - 1].0 == *e),
            IoError::content(
                path,
                format!(
                    "row {}: episode {e} where episode {} has {horizon} steps (every episode \
                     must be as long as the first)",
                    i + 2,
                    rows[d * horizon].0
                )
            )
        );
        ensure!(
            (time - t as f64 * dt).abs() <= 1e-6 * dt.max(1.0),
            IoError::content(
                path,
                format!(
                    "row {}: time_s {time}, expected {} (steps of {dt} s)",
                    i + 2,
                    t as f64 * dt
                )
            )
        );
        states.extend_from_slice(s);
    }
    Ok(Trajectories {
        layout,
        count: rows.len() / horizon,
        horizon,
        states,
        actions: None,
        dt,
        task: None,
        model: None,
    })
}

/// Writes `traj`'s states as a demonstrations CSV file ([`read_csv`]'s layout; the header
/// names the states of `traj.layout`).
pub fn write_csv(traj: &Trajectories, path: &Path) -> Result<(), IoError> {
    let mut w = csv::Writer::from_path(path).map_err(IoError::csv("writing", path))?;
    w.write_record(csv_header(&traj.layout))
        .map_err(IoError::csv("writing", path))?;
    for (i, s) in traj.states.chunks(traj.layout.dx()).enumerate() {
        let (d, t) = (i / traj.horizon, i % traj.horizon);
        let mut rec = vec![d.to_string(), format!("{}", t as f64 * traj.dt)];
        rec.extend(s.iter().map(|v| format!("{v:?}")));
        w.write_record(&rec)
            .map_err(IoError::csv("writing", path))?;
    }
    w.flush().map_err(IoError::file("writing", path))?;
    Ok(())
}

/// `demos` as trajectories (for export), noting their task and costs.
pub fn from_demos(demos: &Demos) -> Trajectories {
    Trajectories {
        layout: demos.layout(),
        states: demos.states.clone(),
        actions: Some(demos.actions.clone()),
        count: demos.count,
        horizon: demos.horizon,
        dt: demos.dt,
        task: Some(TaskMeta {
            goal: demos.goal,
            start_q: demos.start_q,
            seed: demos.seed,
            cost_random: Some(demos.cost_random),
            cost_expert: Some(demos.cost_expert),
            goal_pose: demos.goal_pose,
            tool_points: demos.goal_pose.map(|_| demos.tool_points),
        }),
        model: Some(demos.model),
    }
}

/// Recorded episodes (`learner serve`'s `.npz` files: `path` is one file or a folder of them,
/// read in name order) as trajectories with their executed actions. They must be of one task.
pub fn from_episodes(path: &Path) -> Result<Trajectories, IoError> {
    let files: Vec<PathBuf> = if path.is_dir() {
        let mut f: Vec<PathBuf> = std::fs::read_dir(path)
            .map_err(IoError::file("reading", path))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "npz"))
            .collect();
        f.sort();
        f
    } else {
        vec![path.to_path_buf()]
    };
    ensure!(
        !files.is_empty(),
        IoError::content(path, "no .npz episode files")
    );
    let mut out: Option<(Trajectories, TaskConfig)> = None;
    for f in &files {
        let (ep, origin) = super::episode::load_episode(f)?;
        let task = super::episode::load_episode_task(f)?;
        match &mut out {
            None => {
                let traj = Trajectories {
                    layout: ep.layout,
                    horizon: ep.horizon(),
                    count: 1,
                    states: ep.x,
                    actions: Some(ep.u),
                    dt: task.dt,
                    task: Some(TaskMeta {
                        goal: task.goal,
                        start_q: task.start_q,
                        seed: origin.seed,
                        cost_random: None,
                        cost_expert: None,
                        goal_pose: task.goal_pose,
                        tool_points: task.goal_pose.map(|_| task.tool_points),
                    }),
                    model: None,
                };
                out = Some((traj, task));
            }
            Some((traj, first)) => {
                first
                    .layout()
                    .check_dims("an episode file", ep.layout.dx(), ep.layout.du())
                    .map_err(|e| IoError::from(e).at("reading", f))?;
                ensure!(
                    task == *first,
                    IoError::content(
                        f,
                        format!("task {task:?} differs from the first episode's {first:?}")
                    )
                );
                traj.states.extend_from_slice(&ep.x);
                traj.actions.as_mut().expect("set").extend_from_slice(&ep.u);
                traj.count += 1;
            }
        }
    }
    Ok(out.expect("at least one file").0)
}

/// Trajectories from any source as demonstrations for the arm of `sim`, the missing task and
/// costs derived (module docs).
pub fn to_demos(traj: Trajectories, sim: &SimConfig) -> Result<Demos, IoError> {
    // A source that names another arm: derived on that arm (`load_checked` then names the
    // difference to the configured one).
    let model = traj.model.unwrap_or(sim.model);
    let noted;
    let sim = if model == sim.model {
        sim
    } else {
        noted = SimConfig::for_model(model);
        &noted
    };
    // Before anything simulates at that period (1e300 s would be 1e303 physics steps).
    ur5_shared::config::check_dt(traj.dt).map_err(IoError::TrajectoryDt)?;
    let layout = traj.layout;
    let (goal, goal_pose, tool_points, start_q, seed) = match &traj.task {
        Some(m) => (
            m.goal,
            m.goal_pose,
            m.tool_points
                .unwrap_or(ur5_shared::config::DEFAULT_TOOL_POINTS),
            m.start_q,
            m.seed,
        ),
        None => {
            let (goal, goal_pose, start_q) = derive_goal(&traj, sim)?;
            let points = ur5_shared::config::DEFAULT_TOOL_POINTS;
            (goal, goal_pose, points, start_q, DERIVED_SEED)
        }
    };
    // The active joints are those of the start pose, the goal a point or a pose.
    let task = TaskConfig {
        dt: traj.dt,
        horizon: traj.horizon,
        joints: start_q.len(),
        start_q,
        goal,
        goal_pose,
        tool_points,
    };
    task.validate().map_err(IoError::TrajectoryTask)?;
    task.layout()
        .check_dims("the trajectories' states", layout.dx(), layout.du())?;
    let known = traj.task.as_ref();
    // Both costs are recomputed from the data; a recorded one is checked against them, not
    // trusted (normalised performance divides by their difference).
    let mut expert = 0.0;
    for ep in traj.states.chunks(traj.horizon * layout.dx()) {
        expert += ur5_shared::cost::task_cost_of_states(&layout, ep)?;
    }
    expert /= traj.count as f64;
    let cost_expert = match known.and_then(|m| m.cost_expert) {
        // The states may have been stored in single precision.
        Some(c) if (c - expert).abs() <= COST_EXPERT_TOLERANCE * expert.abs().max(1e-12) => c,
        Some(c) => {
            return Err(IoError::TaskCost {
                field: "cost_expert",
                recorded: c,
                recomputed: expert,
                of: "the demonstrations' states (their mean task cost)",
            })
        }
        None => expert,
    };
    let random = {
        let cfg = imitation::expert::ExpertConfig {
            task: task.clone(),
            sim: sim.clone(),
            seed,
            ..Default::default()
        };
        let mut arm = crate::arm::SimArm::for_task(sim.clone(), &task)?;
        imitation::expert::random_policy_cost(&cfg, &mut arm)?
    };
    let cost_random = match known.and_then(|m| m.cost_random) {
        Some(c) if c >= random / COST_RANDOM_FACTOR && c <= random * COST_RANDOM_FACTOR => c,
        Some(c) => {
            return Err(IoError::TaskCost {
                field: "cost_random",
                recorded: c,
                recomputed: random,
                of: "the task, arm and seed (the random initial controller's mean cost, default expert settings)",
            })
        }
        None => random,
    };
    let actions = traj
        .actions
        .unwrap_or_else(|| vec![0.0; traj.count * traj.horizon * layout.du()]);
    Ok(Demos {
        states: traj.states,
        actions,
        // Checked against the configured arm by `load_checked`.
        model,
        count: traj.count,
        horizon: traj.horizon,
        goal,
        goal_pose,
        tool_points,
        start_q,
        dt: traj.dt,
        seed,
        cost_random,
        cost_expert,
    })
}

/// The goal (point, and pose for a pose task) and start pose of trajectories that do not note
/// their task (module docs): from the first frame, the tool points by the arm's forward
/// kinematics minus the state's point-minus-target entries; a pose from the three targets and
/// the default tool points.
fn derive_goal(
    traj: &Trajectories,
    sim: &SimConfig,
) -> Result<([f64; 3], Option<[f64; 6]>, ur5_shared::joints::Joints), IoError> {
    let layout = traj.layout;
    let (n, p) = (layout.joints(), layout.tool_points());
    let s0 = &traj.states[..layout.dx()];
    let q = &s0[layout.q()];
    let mut arm = hil_sim::Ur5Sim::with_joints(sim.clone(), traj.dt, n)?;
    arm.set_joint_state_all(q, &vec![0.0; n]);
    let offsets = ur5_shared::config::DEFAULT_TOOL_POINTS;
    let mut fk = [[0.0; 3]; 3];
    arm.true_points(&offsets[..p], &mut fk[..p]);
    let mut targets = [[0.0; 3]; 3];
    for (i, t) in targets.iter_mut().enumerate().take(p) {
        let e = &s0[layout.point(i)];
        *t = [fk[i][0] - e[0], fk[i][1] - e[1], fk[i][2] - e[2]];
    }
    let start_q = ur5_shared::joints::Joints::from_slice(q);
    if p == 1 {
        return Ok((targets[0], None, start_q));
    }
    let pose = ur5_shared::pose::pose_of_points(&offsets, &targets).ok_or_else(|| {
        IoError::TrajectoryTask(ur5_shared::config::ConfigError::Invalid {
            key: "task.goal_pose",
            why: format!(
                "the first frame's three tool point targets {targets:?} lie on one line: no \
                 pose puts the tool points there"
            ),
        })
    })?;
    let goal_pose = ur5_shared::pose::ur_pose(&pose);
    Ok((
        [goal_pose[0], goal_pose[1], goal_pose[2]],
        Some(goal_pose),
        start_q,
    ))
}

/// The mean of the tool poses (`kin`'s tool centre point) at the joint angles `qs` (rad), as
/// UR's p[x, y, z, rx, ry, rz] ([`ur5_shared::pose::mean_pose`]): the goal pose of motions that
/// end at those angles.
pub fn mean_tool_pose(
    kin: &ur5_shared::kinematics::UrKinematics,
    qs: impl Iterator<Item = ur5_shared::kinematics::Joints6>,
) -> [f64; 6] {
    let ends: Vec<_> = qs.map(|q| kin.tool_pose(&q)).collect();
    ur5_shared::pose::ur_pose(&ur5_shared::pose::mean_pose(&ends))
}

/// A UR arm's recorded joint positions as trajectories of the whole arm and a pose
/// ([`StateLayout::POSE6`], module docs): joint velocities by central differences of the
/// positions over the frame period (one-sided at an episode's ends), the three default tool
/// points and their velocities by forward kinematics of `sim`'s model and tool point, the goal
/// pose the mean of the episodes' last tool poses, the start pose the first frame's.
pub fn from_joint_positions(rec: &super::lerobot::JointRecording, sim: &SimConfig) -> Trajectories {
    use ur5_shared::kinematics::UrKinematics;
    let model = rec.model.unwrap_or(sim.model);
    let kin = UrKinematics::new(model, sim.ee_offset);
    let (t_len, dt) = (rec.horizon, rec.dt);
    let q = |d: usize, t: usize| -> [f64; 6] {
        let i = (d * t_len + t) * 6;
        rec.positions[i..i + 6].try_into().expect("6 joints")
    };
    let goal_pose = mean_tool_pose(&kin, (0..rec.count).map(|d| q(d, t_len - 1)));
    let start_q = ur5_shared::joints::Joints::from_slice(&q(0, 0));
    let task = TaskConfig {
        dt,
        horizon: t_len,
        joints: 6,
        start_q,
        goal: [goal_pose[0], goal_pose[1], goal_pose[2]],
        goal_pose: Some(goal_pose),
        tool_points: ur5_shared::config::DEFAULT_TOOL_POINTS,
    };
    let layout = StateLayout::POSE6;
    let mut states = vec![0.0; rec.count * t_len * layout.dx()];
    let steps = (0..rec.count * t_len).map(|k| {
        let (d, t) = (k / t_len, k % t_len);
        let (before, after) = (t.saturating_sub(1), (t + 1).min(t_len - 1));
        let (a, b) = (q(d, before), q(d, after));
        let qd: [f64; 6] = core::array::from_fn(|j| (b[j] - a[j]) / ((after - before) as f64 * dt));
        (q(d, t), qd)
    });
    super::tool_path::arm_states(&kin, &task, steps, &mut states);
    Trajectories {
        layout,
        states,
        actions: None,
        count: rec.count,
        horizon: t_len,
        dt,
        task: Some(TaskMeta {
            goal: task.goal,
            start_q,
            seed: DERIVED_SEED,
            cost_random: None,
            cost_expert: None,
            goal_pose: Some(goal_pose),
            tool_points: None,
        }),
        model: rec.model,
    }
}

/// A recorded `cost_expert` may differ from the one recomputed from the states by this
/// fraction (states kept in single precision).
const COST_EXPERT_TOLERANCE: f64 = 1e-3;
/// A recorded `cost_random` is taken if within this factor of the one recomputed with the
/// default expert settings: an expert of another seed or `random_episodes` estimates the same
/// cost differently (the default task, seeds 0–9, 10 or 2 random episodes: 12.20 to 13.44,
/// within 5 % of seed 0's 12.93); beyond the factor the file was altered.
const COST_RANDOM_FACTOR: f64 = 1.5;

/// Whether `path` is demonstrations in a format of this module (a folder: a LeRobot dataset;
/// a `.csv` file) rather than a `.npz`.
pub fn is_foreign(path: &Path) -> bool {
    path.is_dir()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
}

/// The demonstrations in the LeRobot dataset folder or `.csv` file `path` ([`is_foreign`]); a
/// CSV file of tool paths ([`super::tool_path`]) is solved on the arm of `sim` at the default
/// task's control period.
pub fn load_foreign(path: &Path, sim: &SimConfig) -> Result<Demos, IoError> {
    if path.is_dir() {
        ensure!(
            super::lerobot::is_dataset(path),
            IoError::content(
                path,
                "a folder without meta/info.json: not a LeRobot dataset"
            )
        );
        if super::lerobot::state_width(path)? == super::lerobot::JOINT_POSITIONS {
            let rec = super::lerobot::import_joint_positions(path)?;
            // Before anything simulates at that period.
            ur5_shared::config::check_dt(rec.dt).map_err(IoError::TrajectoryDt)?;
            return to_demos(from_joint_positions(&rec, sim), sim);
        }
        return to_demos(super::lerobot::import(path)?, sim);
    }
    if super::tool_path::is_tool_path_csv(path) {
        let dt = TaskConfig::for_model(sim.model).dt;
        return to_demos(super::tool_path::load(path, sim, dt, DERIVED_SEED)?, sim);
    }
    to_demos(read_csv(path)?, sim)
}
