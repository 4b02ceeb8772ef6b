//! Demonstrations on disk: state-only trajectories of the expert (and, separately, its
//! actions for diagnostics), as `.npz` readable by numpy:
//!
//! | array | shape | meaning |
//! |---|---|---|
//! | `states` | (D, T, dX) f64 | s_t of each demonstration (layout: `state_names`) |
//! | `actions_diagnostic` | (D, T, dU) f64 | actions the expert took; never used for imitation |
//! | `goal` | (3,) f64 | goal point of the tool centre point (m, base frame) |
//! | `start_q` | (n,) f64 | start pose (rad), one angle per active joint (3 or 6) |
//! | `goal_pose` | (6,) f64 | a pose task's goal, UR's p[x, y, z, rx, ry, rz] (absent: a point goal) |
//! | `tool_points` | (3, 3) f64 | a pose task's tool points (m, flange frame; with `goal_pose`) |
//! | `dt` | () f64 | control period (s) |
//! | `seed` | () u64 | seed of the run that recorded them |
//! | `cost_random`, `cost_expert` | () f64 | mean task cost of the random policy / of these demos |
//! | `state_names`, `action_names` | (dX,), (dU,) str | layout |
//! | `model` | (1,) str | the arm model they were made on (`"ur5e"`; absent: `"ur5"`) |
//! | `schema_version` | () i64 | [`SCHEMA_VERSION`] |
//!
//! The task's layout (`ur5_shared::StateLayout`: joints from `start_q`, tool points from
//! `goal_pose`) fixes dX and dU; a file whose arrays or names disagree with it is refused,
//! naming both. Loading checks every shape, the dimensions and layout, and that every number is
//! finite, and says exactly what is wrong.

use std::path::Path;

use imitation::demos::Demos;

use super::npz::{NpzError, NpzFile, NpzWriter};
use super::task_arrays::{read_task, write_layout_names, write_task};
use super::IoError;
use crate::error::ensure;

/// Demonstrations that could not have come from the configured arm ([`check_against_arm`]);
/// each error names the array, the demonstration, the step and the value, and says what to do.
#[derive(Debug, thiserror::Error)]
pub enum DemosError {
    /// The demonstrations' task (joints, goal, tool points) is not a valid one.
    #[error("the demonstrations' task: {0}")]
    Task(String),
    /// Demonstrations made on another arm model than the config's.
    #[error(
        "demonstrations {} were made on a {made_on}, the config's arm is a {config}: set \
         `model = \"{made_on}\"` in the config's [sim] table (or give demonstrations made on a \
         {config})",
        path.display()
    )]
    OtherModel {
        /// The demonstrations.
        path: std::path::PathBuf,
        /// The arm they were made on.
        made_on: ur5_shared::UrModel,
        /// The config's arm.
        config: ur5_shared::UrModel,
    },
    /// A control period the arm cannot run.
    #[error("dt: {0}")]
    Dt(String),
    /// Normalisation costs that do not measure imitation.
    #[error(
        "cost_expert = {expert} and cost_random = {random}: both must be finite and the \
         expert's below the random policy's, or normalised performance (C_random − C) / \
         (C_random − C_expert) does not measure imitation (it would exceed 1 for a policy worse \
         than the expert)"
    )]
    Costs {
        /// The expert's cost.
        expert: f64,
        /// The random policy's cost.
        random: f64,
    },
    /// A state value that is NaN or infinite.
    #[error(
        "states[{demo}, {step}]: {name} = {value}: every state value must be finite \
         (demonstration {demo}, step {step})"
    )]
    StateNotFinite {
        /// Demonstration.
        demo: usize,
        /// Step.
        step: usize,
        /// The state's name.
        name: String,
        /// The value.
        value: f64,
    },
    /// An action value that is NaN or infinite.
    #[error("actions[{demo}, {step}, {joint}] = {value}: every action value must be finite")]
    ActionNotFinite {
        /// Demonstration.
        demo: usize,
        /// Step.
        step: usize,
        /// Joint.
        joint: usize,
        /// The value.
        value: f64,
    },
    /// A joint angle outside the arm's limits.
    #[error("{at}: joint {joint} at {q} rad, outside the arm's limits [{lower}, {upper}]")]
    JointLimit {
        /// `states[i, t]`.
        at: String,
        /// Joint.
        joint: usize,
        /// Its angle (rad).
        q: f64,
        /// Lower limit (rad).
        lower: f64,
        /// Upper limit (rad).
        upper: f64,
    },
    /// A joint speed the arm cannot reach.
    #[error(
        "{at}: joint {joint} at {qd} rad/s, more than {SPEED_LIMIT_FACTOR} × the arm's speed \
         limit {limit} rad/s"
    )]
    JointSpeed {
        /// `states[i, t]`.
        at: String,
        /// Joint.
        joint: usize,
        /// Its speed (rad/s).
        qd: f64,
        /// The arm's limit (rad/s).
        limit: f64,
    },
    /// A demonstration that does not start at `start_q`.
    #[error("{at}: joint {joint} starts at {q} rad, start_q says {start} (tolerance {tol})")]
    Start {
        /// `states[i, 0]`.
        at: String,
        /// Joint.
        joint: usize,
        /// Its first angle (rad).
        q: f64,
        /// `start_q` (rad).
        start: f64,
        /// Tolerance (rad).
        tol: f64,
    },
    /// End-effector points away from the arm's forward kinematics.
    #[error(
        "{at}: the end effector is {err:.4} m from where the arm's forward kinematics puts it at \
         these joint angles (tolerance {tol} m): recorded on another arm or edited; record \
         demonstrations with `learner expert` on this arm"
    )]
    Kinematics {
        /// `states[i, t]`.
        at: String,
        /// Distance (m).
        err: f64,
        /// Tolerance (m).
        tol: f64,
    },
    /// A control period the joint velocities contradict.
    #[error(
        "dt = {dt} s ({} fps) disagrees with the joint velocities: the joints move {moved:.4} rad \
         in all, the velocities × dt say {said:.4} rad (ratio {ratio:.3}, expected {} to {}); is \
         the dataset's fps (or time column) right?",
        1.0 / dt,
        PERIOD_CONSISTENCY.0,
        PERIOD_CONSISTENCY.1
    )]
    Period {
        /// The period (s).
        dt: f64,
        /// How far the joints move (rad).
        moved: f64,
        /// How far the velocities say (rad).
        said: f64,
        /// `moved / said`.
        ratio: f64,
    },
    /// The arm the demonstrations are checked on (its goal, its construction).
    #[error(transparent)]
    Sim(#[from] hil_sim::SimError),
}

/// Version of this file layout.
pub const SCHEMA_VERSION: i64 = 1;

/// Writes `demos` to `path` (atomically).
pub fn save(demos: &Demos, path: &Path) -> Result<(), NpzError> {
    let d = demos;
    let layout = d.layout();
    let (n, t) = (d.count as u64, d.horizon as u64);
    let (dx, du) = (layout.dx() as u64, layout.du() as u64);
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    w.f64("states", &[n, t, dx], &d.states)?;
    w.f64("actions_diagnostic", &[n, t, du], &d.actions)?;
    write_task(
        &mut w,
        &d.goal,
        &d.start_q,
        d.goal_pose.as_ref(),
        &d.tool_points,
    )?;
    w.f64("dt", &[], &[d.dt])?;
    w.u64("seed", &[], &[d.seed])?;
    w.f64("cost_random", &[], &[d.cost_random])?;
    w.f64("cost_expert", &[], &[d.cost_expert])?;
    write_layout_names(&mut w, &layout)?;
    w.string("model", d.model.name())?;
    w.finish()?;
    Ok(())
}

/// Reads and checks demonstrations.
pub fn load(path: &Path) -> Result<Demos, NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let bad = |name: &str, why: String| f.bad(name, why);
    let task = read_task(&f)?;
    let layout = task.layout;
    let (dx_want, du_want) = (layout.dx() as u64, layout.du() as u64);
    let names = f.strings("state_names")?;
    if names != layout.state_names() {
        return Err(bad(
            "state_names",
            format!(
                "{names:?} is not the state layout of a task with {layout} ({:?})",
                layout.state_names()
            ),
        ));
    }
    let (shape, states) = f.f64("states")?;
    let [d, t, dx] = shape[..] else {
        return Err(bad(
            "states",
            format!("shape {shape:?}, expected (D, T, {dx_want})"),
        ));
    };
    if dx != dx_want {
        return Err(bad(
            "states",
            format!("state dimension {dx}, but the file's task ({layout}) has dX = {dx_want}"),
        ));
    }
    if d == 0 || t < 2 {
        return Err(bad(
            "states",
            format!("{d} demonstrations of {t} steps: need at least 1 of at least 2 steps"),
        ));
    }
    let actions = f.f64_shaped("actions_diagnostic", &[d, t, du_want])?;
    let scalar = |name: &str| -> Result<f64, NpzError> { Ok(f.f64_shaped(name, &[])?[0]) };
    // Files written before demonstrations carried a model were all made on the UR5.
    let model = if f.names().iter().any(|n| n == "model") {
        let name = f.string("model")?;
        name.parse::<ur5_shared::UrModel>()
            .map_err(|e| bad("model", e.to_string()))?
    } else {
        ur5_shared::UrModel::Ur5
    };
    let demos = Demos {
        model,
        count: d as usize,
        horizon: t as usize,
        goal: task.goal,
        goal_pose: task.goal_pose,
        tool_points: task.tool_points,
        start_q: task.start_q,
        dt: scalar("dt")?,
        seed: f.u64_scalar("seed")?,
        cost_random: scalar("cost_random")?,
        cost_expert: scalar("cost_expert")?,
        states,
        actions,
    };
    for (name, values) in [
        ("states", &demos.states),
        ("actions_diagnostic", &demos.actions),
    ] {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(bad(
                name,
                format!("non-finite value {} at flat index {i}", values[i]),
            ));
        }
    }
    if !(demos.dt > 0.0 && demos.dt.is_finite()) {
        return Err(bad("dt", format!("{} s must be finite and > 0", demos.dt)));
    }
    if demos
        .goal
        .iter()
        .chain(demos.start_q.iter())
        .chain(demos.goal_pose.iter().flatten())
        .chain(demos.tool_points.iter().flatten())
        .any(|v| !v.is_finite())
    {
        return Err(bad(
            "goal",
            "goal, start_q, goal_pose and tool_points must be finite".into(),
        ));
    }
    Ok(demos)
}

/// The arm model the demonstrations in `path` name: a `.npz`'s `model` (a file without it
/// was made on the UR5), a LeRobot dataset's [`super::lerobot::MODEL_KEY`]; `None` for a CSV
/// file and a dataset that names none.
pub fn model_of(path: &Path) -> Result<Option<ur5_shared::UrModel>, IoError> {
    let at = |e: IoError| e.at("loading demonstrations", path);
    if path.is_dir() && super::lerobot::is_dataset(path) {
        return super::lerobot::model_of(path).map_err(|e| at(e.into()));
    }
    if super::foreign::is_foreign(path) {
        return Ok(None);
    }
    Ok(Some(load(path).map_err(|e| at(e.into()))?.model))
}

/// Loads the demonstrations in `path` in any format `--demos` takes (`.npz`, LeRobot dataset
/// folder or CSV: [`super::foreign::load_foreign`]; else [`load`]) and checks them against
/// the arm of `sim` ([`check_against_arm`]), each error naming the file: what every run that
/// imitates a file calls.
pub fn load_checked(path: &Path, sim: &ur5_shared::config::SimConfig) -> Result<Demos, IoError> {
    let demos = if super::foreign::is_foreign(path) {
        super::foreign::load_foreign(path, sim)
    } else {
        load(path).map_err(IoError::from)
    }
    .map_err(|e| e.at("loading demonstrations", path))?;
    ensure!(
        demos.model == sim.model,
        DemosError::OtherModel {
            path: path.to_owned(),
            made_on: demos.model,
            config: sim.model
        }
    );
    check_against_arm(&demos, sim).map_err(|e| IoError::from(e).at("demonstrations", path))?;
    Ok(demos)
}

/// Demonstrations (loaded from `path`) against the layout of the run that uses them (its
/// task's): a file of other dimensions is refused, naming the file's dX, dU and the run's.
pub fn check_run_layout(
    demos: &Demos,
    run: &ur5_shared::StateLayout,
    path: &Path,
) -> Result<(), IoError> {
    let l = demos.layout();
    run.check_dims("the demonstrations file", l.dx(), l.du())
        .map_err(|e| IoError::from(e).at("loading demonstrations", path))
}

/// The demonstrations of every goal of a multi-goal learner (MDGPS): the `.npz` files of the
/// folder `folder` in name order, each loaded and checked as [`load_checked`] does.
pub fn load_goals(
    folder: &Path,
    sim: &ur5_shared::config::SimConfig,
) -> Result<Vec<Demos>, IoError> {
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(folder)
        .map_err(IoError::file("reading", folder))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "npz"))
        .collect();
    files.sort();
    ensure!(
        !files.is_empty(),
        IoError::content(folder, "no .npz demonstrations (one file per goal)")
    );
    files.iter().map(|f| load_checked(f, sim)).collect()
}

/// Largest difference (rad) between a demonstration's first joint angles and `start_q`, and
/// (m) between a demonstrated end-effector point and the arm's forward kinematics at the
/// demonstrated joint angles. Ours: 0.01, ten times the perturbed arm's sensor noise (1e-3).
pub const CONSISTENCY_TOLERANCE: f64 = 0.01;

/// Largest joint speed (rad/s) a demonstration may show, as a multiple of the arm's limit
/// (the servo may overshoot it briefly). Ours: 2.
pub const SPEED_LIMIT_FACTOR: f64 = 2.0;

/// Checks that `demos` could have come from the arm of `sim` (docs/design.md
/// §4.2): normalisation costs finite and different; the goal within the
/// arm's reach; every joint angle within the arm's limits; every joint speed within
/// [`SPEED_LIMIT_FACTOR`] × its limit; each demonstration starting at `start_q`; and every
/// end-effector point (`ee − goal` + goal) within [`CONSISTENCY_TOLERANCE`] of the arm's
/// forward kinematics at the demonstrated joint angles. Each error names the array, the
/// demonstration, the step and the value.
pub fn check_against_arm(d: &Demos, sim: &ur5_shared::config::SimConfig) -> Result<(), DemosError> {
    let layout = d.layout();
    let (n, p) = (layout.joints(), layout.tool_points());
    ur5_shared::config::check_dt(d.dt).map_err(DemosError::Dt)?;
    ensure!(
        d.cost_random.is_finite() && d.cost_expert.is_finite() && d.cost_expert < d.cost_random,
        DemosError::Costs {
            expert: d.cost_expert,
            random: d.cost_random
        }
    );
    check_finite(d)?;
    check_period(d)?;
    let task = d.task().map_err(|e| DemosError::Task(e.to_string()))?;
    let (offsets, targets) = (task.tool_offsets(), task.targets());
    let mut arm = hil_sim::Ur5Sim::with_joints(sim.clone(), d.dt, n)?;
    arm.check_goal(d.goal)?;
    let limits = arm.limits();
    let tol = CONSISTENCY_TOLERANCE;
    let mut fk = [[0.0; 3]; ur5_shared::layout::MAX_TOOL_POINTS];
    let zeros = [0.0; ur5_shared::layout::MAX_JOINTS];
    for i in 0..d.count {
        for t in 0..d.horizon {
            let s = d.state(i, t);
            let at = format!("states[{i}, {t}]");
            let (q, qd) = (&s[layout.q()], &s[layout.qd()]);
            for j in 0..n {
                ensure!(
                    q[j] >= limits.lower[j] - tol && q[j] <= limits.upper[j] + tol,
                    DemosError::JointLimit {
                        at: at.clone(),
                        joint: j,
                        q: q[j],
                        lower: limits.lower[j],
                        upper: limits.upper[j]
                    }
                );
                ensure!(
                    qd[j].abs() <= SPEED_LIMIT_FACTOR * limits.velocity[j],
                    DemosError::JointSpeed {
                        at: at.clone(),
                        joint: j,
                        qd: qd[j],
                        limit: limits.velocity[j]
                    }
                );
                if t == 0 {
                    ensure!(
                        (q[j] - d.start_q[j]).abs() <= tol,
                        DemosError::Start {
                            at: at.clone(),
                            joint: j,
                            q: q[j],
                            start: d.start_q[j],
                            tol
                        }
                    );
                }
            }
            arm.set_joint_state_all(q, &zeros[..n]);
            arm.true_points(offsets, &mut fk[..p]);
            let mut err = 0.0f64;
            for (k, target) in targets.iter().enumerate() {
                let e = &s[layout.point(k)];
                let d2 = (0..3)
                    .map(|c| (e[c] + target[c] - fk[k][c]).powi(2))
                    .sum::<f64>();
                err = err.max(d2.sqrt());
            }
            ensure!(err <= tol, DemosError::Kinematics { at, err, tol });
        }
    }
    Ok(())
}

/// Every state and action value finite; the error names the demonstration, the step and the
/// state's name ([`StateLayout::state_name`]).
fn check_finite(d: &Demos) -> Result<(), DemosError> {
    let layout = d.layout();
    let (dx, du) = (layout.dx(), layout.du());
    if let Some(k) = d.states.iter().position(|v| !v.is_finite()) {
        let (row, c) = (k / dx, k % dx);
        return Err(DemosError::StateNotFinite {
            demo: row / d.horizon,
            step: row % d.horizon,
            name: layout.state_name(c),
            value: d.states[k],
        });
    }
    if let Some(k) = d.actions.iter().position(|v| !v.is_finite()) {
        let row = k / du;
        return Err(DemosError::ActionNotFinite {
            demo: row / d.horizon,
            step: row % d.horizon,
            joint: k % du,
            value: d.actions[k],
        });
    }
    Ok(())
}

/// Range of Σ|Δq| / (dt Σ|q̇|) over all joints and steps that a demonstration's control period
/// `dt` may give: the joint angles must move about as far per step as their recorded
/// velocities say. Our arm's demonstrations give 1.6 (velocities sampled at the control
/// instants, below the step's mean speed); a period 2 or more times too short (fps 20 for
/// data at 10 Hz: 3.2, fps 1000: 160) or 3 or more times too long is refused. A period off by
/// less (fps 5 for 10 Hz: 0.8) is not told apart from the arm's own dynamics this way.
pub const PERIOD_CONSISTENCY: (f64, f64) = (0.5, 3.0);

/// The control period `dt` consistent with the recorded joint velocities
/// ([`PERIOD_CONSISTENCY`]); skipped for demonstrations that barely move (Σ|q̇| dt < 1e-3
/// rad, nothing to tell from).
fn check_period(d: &Demos) -> Result<(), DemosError> {
    let layout = d.layout();
    let (q, qd) = (layout.q(), layout.qd());
    let (mut moved, mut said) = (0.0, 0.0);
    for i in 0..d.count {
        for t in 0..d.horizon.saturating_sub(1) {
            let (s, next) = (d.state(i, t), d.state(i, t + 1));
            for j in 0..layout.joints() {
                moved += (next[q.start + j] - s[q.start + j]).abs();
                said += s[qd.start + j].abs() * d.dt;
            }
        }
    }
    if said < 1e-3 {
        return Ok(());
    }
    let ratio = moved / said;
    ensure!(
        (PERIOD_CONSISTENCY.0..=PERIOD_CONSISTENCY.1).contains(&ratio),
        DemosError::Period {
            dt: d.dt,
            moved,
            said,
            ratio
        }
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ur5_shared::layout::{ACTION_NAMES, DU, DX, STATE_NAMES};

    fn sample() -> Demos {
        let (d, t) = (2, 5);
        Demos {
            states: (0..d * t * DX).map(|i| i as f64 * 0.01).collect(),
            actions: (0..d * t * DU).map(|i| -(i as f64)).collect(),
            count: d,
            horizon: t,
            model: ur5_shared::UrModel::Ur5,
            goal: [-0.4, -0.2, 0.3],
            goal_pose: None,
            tool_points: ur5_shared::config::DEFAULT_TOOL_POINTS,
            start_q: [0.0, -2.0, 2.4].into(),
            dt: 0.1,
            seed: 11,
            cost_random: 20.0,
            cost_expert: 3.0,
        }
    }

    #[test]
    fn the_model_is_recorded_old_files_mean_the_ur5_and_another_arm_is_refused() {
        use ur5_shared::UrModel;
        let dir = std::env::temp_dir().join(format!("demos-model-{}", std::process::id()));
        let path = dir.join("demos.npz");
        let d = Demos {
            model: UrModel::Ur5e,
            ..sample()
        };
        save(&d, &path).unwrap();
        assert_eq!(load(&path).unwrap().model, UrModel::Ur5e);
        let e = crate::error::line(&load_checked(&path, &Default::default()).unwrap_err());
        assert!(
            e.contains("made on a ur5e") && e.contains("arm is a ur5") && e.contains("[sim]"),
            "{e}"
        );

        // A file written before demonstrations carried a model: every array but `model`.
        let s = sample();
        let (n, t) = (s.count as u64, s.horizon as u64);
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.f64("states", &[n, t, DX as u64], &s.states).unwrap();
        w.f64("actions_diagnostic", &[n, t, DU as u64], &s.actions)
            .unwrap();
        w.f64("goal", &[3], &s.goal).unwrap();
        w.f64("start_q", &[3], &s.start_q).unwrap();
        w.f64("dt", &[], &[s.dt]).unwrap();
        w.u64("seed", &[], &[s.seed]).unwrap();
        w.f64("cost_random", &[], &[s.cost_random]).unwrap();
        w.f64("cost_expert", &[], &[s.cost_expert]).unwrap();
        w.strings("state_names", &STATE_NAMES).unwrap();
        w.strings("action_names", &ACTION_NAMES).unwrap();
        w.finish().unwrap();
        assert_eq!(load(&path).unwrap(), s, "no model: the UR5");

        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.strings("state_names", &STATE_NAMES).unwrap();
        w.f64("states", &[n, t, DX as u64], &s.states).unwrap();
        w.f64("actions_diagnostic", &[n, t, DU as u64], &s.actions)
            .unwrap();
        w.string("model", "ur7").unwrap();
        for name in ["goal", "start_q"] {
            w.f64(name, &[3], &[0.0; 3]).unwrap();
        }
        for name in ["dt", "cost_random", "cost_expert"] {
            w.f64(name, &[], &[1.0]).unwrap();
        }
        w.u64("seed", &[], &[1]).unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("model") && e.contains("ur7"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn round_trip_and_each_bad_file_is_named() {
        let dir = std::env::temp_dir().join(format!("demos-test-{}", std::process::id()));
        let path = dir.join("demos.npz");
        let demos = sample();
        save(&demos, &path).unwrap();
        assert_eq!(load(&path).unwrap(), demos);

        // A pose task's demonstrations (six joints, three tool points) round-trip with their
        // dimensions; named as another task's layout when the states do not fit it.
        let pose = Demos {
            states: (0..2 * 5 * 30).map(|i| i as f64 * 1e-3).collect(),
            actions: vec![0.1; 2 * 5 * 6],
            goal: [-0.4, -0.2, 0.3],
            goal_pose: Some([-0.4, -0.2, 0.3, 3.0, 0.5, -0.2]),
            start_q: [0.0, -2.0, 2.4, -1.5, 1.5, 0.0].into(),
            ..sample()
        };
        save(&pose, &path).unwrap();
        assert_eq!(load(&path).unwrap(), pose);
        let wrong = Demos {
            goal_pose: None,
            ..pose.clone()
        };
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        write_task(
            &mut w,
            &wrong.goal,
            &wrong.start_q,
            None,
            &wrong.tool_points,
        )
        .unwrap();
        let names = ur5_shared::StateLayout::new(6, 1).unwrap().state_names();
        w.strings(
            "state_names",
            &names.iter().map(String::as_str).collect::<Vec<_>>(),
        )
        .unwrap();
        w.f64("states", &[2, 5, 30], &pose.states).unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("state dimension 30") && e.contains("(6 joints, 1 tool point) has dX = 18"),
            "{e}"
        );

        // Non-finite state.
        let mut nan = sample();
        nan.states[17] = f64::NAN;
        save(&nan, &path).unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("states") && e.contains("non-finite") && e.contains("17"),
            "{e}"
        );

        // Wrong state dimension: write a (2, 5, 11) array by hand.
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.f64("start_q", &[3], &[0.0, -2.0, 2.4]).unwrap();
        w.f64("goal", &[3], &[-0.4, -0.2, 0.3]).unwrap();
        w.strings("state_names", &STATE_NAMES).unwrap();
        w.f64("states", &[2, 5, 11], &vec![0.0; 110]).unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("state dimension 11") && e.contains("(3 joints, 1 tool point) has dX = 12"),
            "{e}"
        );

        // Missing array.
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("no array `start_q`"), "{e}");

        // Action array of the wrong size.
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.f64("start_q", &[3], &[0.0, -2.0, 2.4]).unwrap();
        w.f64("goal", &[3], &[-0.4, -0.2, 0.3]).unwrap();
        w.strings("state_names", &STATE_NAMES).unwrap();
        w.f64("states", &[2, 5, 12], &vec![0.0; 120]).unwrap();
        w.f64("actions_diagnostic", &[2, 4, 3], &vec![0.0; 24])
            .unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("actions_diagnostic") && e.contains("expected [2, 5, 3]"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Each kind of impossible demonstration is refused, naming what is wrong.
    #[test]
    fn demonstrations_the_arm_could_not_have_made_are_refused() {
        let cfg = imitation::expert::ExpertConfig {
            task: ur5_shared::config::TaskConfig {
                horizon: 10,
                ..Default::default()
            },
            // After 1 iteration this expert is still worse than the random policy.
            iterations: 3,
            random_episodes: 2,
            demos: 2,
            ..Default::default()
        };
        let run = crate::run::expert(&cfg, |_| {}).unwrap();
        let good = crate::run::demos(&cfg, &run).unwrap();
        check_against_arm(&good, &cfg.sim).unwrap();
        let idx = |i: usize, t: usize, k: usize| (i * good.horizon + t) * DX + k;
        let cases: Vec<(&str, Box<dyn Fn(&mut Demos)>)> = vec![
            (
                "outside the arm's limits",
                Box::new(|d| d.states[idx(1, 4, 2)] = 4.0),
            ),
            (
                "outside the arm's limits",
                Box::new(|d| d.states.iter_mut().for_each(|v| *v *= 1e6)),
            ),
            ("speed limit", Box::new(|d| d.states[idx(0, 3, 4)] = 50.0)),
            ("start_q says", Box::new(|d| d.start_q[1] += 0.1)),
            (
                "forward kinematics",
                Box::new(|d| d.states[idx(1, 7, 6)] += 0.05),
            ),
            (
                "forward kinematics",
                Box::new(|d| d.states[idx(0, 2, 0)] += 0.2),
            ),
            ("reach", Box::new(|d| d.goal[0] += 10.0)),
            ("cost_expert", Box::new(|d| d.cost_expert = d.cost_random)),
            (
                "the expert's below the random policy's",
                Box::new(|d| std::mem::swap(&mut d.cost_expert, &mut d.cost_random)),
            ),
            (
                "states[1, 7]: ee_vel_y = NaN: every state value must be finite",
                Box::new(|d| d.states[idx(1, 7, 10)] = f64::NAN),
            ),
            (
                "actions[0, 2, 1] = inf",
                Box::new(|d| d.actions[(2 * DU) + 1] = f64::INFINITY),
            ),
            (
                "disagrees with the joint velocities",
                Box::new(|d| d.dt = 0.02),
            ),
            ("0.01 Hz", Box::new(|d| d.dt = 100.0)),
        ];
        for (what, edit) in cases {
            let mut d = good.clone();
            edit(&mut d);
            let e = crate::error::line(&check_against_arm(&d, &cfg.sim).unwrap_err());
            assert!(e.contains(what), "{what}: {e}");
        }
    }
}
