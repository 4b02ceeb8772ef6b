//! The MDGPS global policy on disk (`policy.npz`, docs/design.md §4.10), readable by numpy:
//!
//! | array | shape | meaning |
//! |---|---|---|
//! | `params` | (P,) f64 | the flat parameter vector θ (layout in `imitation::mlp_policy::global`: input mean and scale, dU mean heads, log σ) |
//! | `hidden` | (H,) i64 | hidden widths of each mean head; P = `flat_len(dX, dU, hidden)` |
//! | `action_mode` | str | `goal_angles` (a = q + μ + σ ε, rad) or `torque` (a = μ + σ ε, N·m) |
//! | `start_q` | (dU,) f64 | start pose the policy was trained from (rad), one angle per active joint |
//! | `dt` | () f64 | control period (s) |
//! | `horizon` | () u64 | T of the training episodes (the policy itself is time-invariant) |
//! | `seed`, `iterations` | () u64 | the training run's seed and MDGPS iterations |
//! | `model` | str | the arm it was trained on (`ur5e`, …; absent in files written before: the UR5) |
//! | `state_names`, `action_names` | (dX,), (dU,) str | the task's layout (`StateLayout::state_names`): 12 and 3 names for three joints and a point, 30 and 6 for six joints and a pose |
//! | `schema_version` | () i64 | [`SCHEMA_VERSION`] |
//!
//! Loading finds the layout from the names (files of the three-joint task load as before),
//! checks the schema, every shape (P against `hidden` and the layout's dX, dU), finiteness,
//! the input scale's sign and the controller's bounds (`PolicyBounds`: |weight| ≤ 1e4, …),
//! naming the file and array at fault. A policy used for a task of another layout is refused
//! naming both ([`PolicyFile::check_layout`]).

use std::path::Path;

use imitation::mlp_policy::global::{flat_len, GlobalPolicy};
use ur5_shared::config::ActionMode;
use ur5_shared::joints::Joints;
use ur5_shared::layout::DimensionMismatch;
use ur5_shared::{PolicyBounds, StateLayout, UrModel};

use super::npz::{NpzError, NpzFile, NpzWriter};

/// Version of this file layout.
pub const SCHEMA_VERSION: i64 = 1;

/// Widest hidden layer a file may ask for (far above any use; a corrupt width cannot ask for
/// gigabytes).
pub const MAX_WIDTH: usize = 4096;

/// A saved policy and what it was trained for.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyFile {
    /// The policy.
    pub policy: GlobalPolicy,
    /// What its output is.
    pub mode: ActionMode,
    /// Start pose of the training episodes (rad), one angle per active joint of the policy's
    /// layout.
    pub start_q: Joints,
    /// Control period (s).
    pub dt: f64,
    /// Steps of the training episodes.
    pub horizon: usize,
    /// Seed of the training run.
    pub seed: u64,
    /// MDGPS iterations it was trained for.
    pub iterations: u64,
    /// The arm it was trained on: its kinematics and limits are the policy's world.
    pub model: UrModel,
}

impl PolicyFile {
    /// The layout of the task the policy acts on (its dX inputs, dU outputs).
    pub fn layout(&self) -> StateLayout {
        self.policy.layout()
    }

    /// `Ok` if the policy acts on states and actions of `task`'s layout; otherwise the
    /// mismatch, naming both.
    pub fn check_layout(&self, task: &StateLayout) -> Result<(), DimensionMismatch> {
        let l = self.layout();
        task.check_dims("the policy file", l.dx(), l.du())
    }
}

fn mode_name(mode: ActionMode) -> &'static str {
    match mode {
        ActionMode::GoalAngles => "goal_angles",
        ActionMode::Torque => "torque",
    }
}

/// Writes `p` to `path` (atomically).
pub fn save_policy(p: &PolicyFile, path: &Path) -> Result<(), NpzError> {
    let layout = p.layout();
    assert_eq!(
        p.start_q.len(),
        layout.du(),
        "a start pose of the policy's joints"
    );
    let flat = p.policy.flat();
    let hidden: Vec<i64> = p.policy.hidden().iter().map(|&h| h as i64).collect();
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    w.f64("params", &[flat.len() as u64], &flat)?;
    w.i64("hidden", &[hidden.len() as u64], &hidden)?;
    w.string("action_mode", mode_name(p.mode))?;
    w.f64("start_q", &[p.start_q.len() as u64], &p.start_q)?;
    w.f64("dt", &[], &[p.dt])?;
    w.u64("horizon", &[], &[p.horizon as u64])?;
    w.u64("seed", &[], &[p.seed])?;
    w.u64("iterations", &[], &[p.iterations])?;
    w.string("model", p.model.name())?;
    super::task_arrays::write_layout_names(&mut w, &layout)?;
    w.finish()?;
    Ok(())
}

/// Reads and checks a policy file.
pub fn load_policy(path: &Path) -> Result<PolicyFile, NpzError> {
    let f = NpzFile::open(path)?;
    // A gain table is the file most often passed by mistake; say so rather than compare
    // schema versions of two different layouts.
    let has = |n: &str| f.names().iter().any(|x| x == n);
    if has("K") && has("s_hat") && !has("params") {
        return Err(f.bad(
            "K",
            "this is a gain table (K, k, s_hat: what `learner train` and `learner serve` \
             write and the controller executes), not a policy file (params, hidden: `learner \
             experiment multi-goal` writes them as policy_seedN.npz)"
                .into(),
        ));
    }
    f.check_schema(SCHEMA_VERSION)?;
    let bad = |name: &str, why: String| f.bad(name, why);
    let (states, actions) = (f.strings("state_names")?, f.strings("action_names")?);
    let layout = StateLayout::from_dims(states.len(), actions.len()).ok_or_else(|| {
        bad(
            "state_names",
            format!(
                "{} state and {} action names: the dimensions of no task (dX = 2n + 6p, dU = n)",
                states.len(),
                actions.len()
            ),
        )
    })?;
    for (name, got, want) in [
        ("state_names", &states, layout.state_names()),
        ("action_names", &actions, layout.action_names()),
    ] {
        if *got != want {
            return Err(bad(
                name,
                format!("{got:?} is not the layout of a task with {layout} ({want:?})"),
            ));
        }
    }
    let (shape, hidden) = f.f64("hidden")?;
    if shape.len() != 1 || hidden.is_empty() {
        return Err(bad(
            "hidden",
            format!("shape {shape:?}, expected (H,) with H >= 1 hidden layers"),
        ));
    }
    if let Some(h) = hidden
        .iter()
        .find(|&&h| !(h >= 1.0 && h <= MAX_WIDTH as f64 && h.fract() == 0.0))
    {
        return Err(bad(
            "hidden",
            format!("width {h}: every width must be an integer in 1..={MAX_WIDTH}"),
        ));
    }
    let hidden: Vec<usize> = hidden.iter().map(|&h| h as usize).collect();
    let params = f.f64_shaped(
        "params",
        &[flat_len(layout.dx(), layout.du(), &hidden) as u64],
    )?;
    let policy = GlobalPolicy::from_flat(layout, &hidden, &params).map_err(|e| bad("params", e))?;
    let mode = match f.string("action_mode")?.as_str() {
        "goal_angles" => ActionMode::GoalAngles,
        "torque" => ActionMode::Torque,
        other => {
            return Err(bad(
                "action_mode",
                format!("`{other}`, expected `goal_angles` or `torque`"),
            ))
        }
    };
    // The bounds the real-time controller holds a policy to: what it would refuse is not
    // evaluated or served either.
    policy
        .to_table(0, mode)
        .and_then(|t| t.validate(&PolicyBounds::default()))
        .map_err(|e| {
            bad(
                "params",
                format!("{e}: not a trained policy's (the controller refuses it)"),
            )
        })?;
    let start_q = Joints::from_slice(&f.f64_shaped("start_q", &[layout.du() as u64])?);
    if start_q.iter().any(|v| !v.is_finite()) {
        return Err(bad("start_q", format!("{start_q:?} is not finite")));
    }
    let dt = f.f64_shaped("dt", &[])?[0];
    if let Err(why) = ur5_shared::config::check_dt(dt) {
        return Err(bad("dt", why));
    }
    let horizon = f.u64_scalar("horizon")?;
    if horizon < 2 {
        return Err(bad("horizon", format!("{horizon}: must be >= 2 steps")));
    }
    // Files written before policies carried a model were all made on the UR5.
    let model = if has("model") {
        let name = f.string("model")?;
        name.parse::<UrModel>()
            .map_err(|e| bad("model", e.to_string()))?
    } else {
        UrModel::Ur5
    };
    Ok(PolicyFile {
        policy,
        mode,
        start_q,
        dt,
        horizon: horizon as usize,
        seed: f.u64_scalar("seed")?,
        iterations: f.u64_scalar("iterations")?,
        model,
    })
}
