//! Configuration of the task and the simulated arm (serde; TOML files).
//!
//! Every default cites where its number comes from. Unknown keys are rejected so that a typo in
//! a TOML file is an error rather than a silently ignored setting.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use crate::joints::Joints;
use crate::layout::N_JOINTS;

mod task;
use crate::model::UrModel;
pub use task::{TaskConfig, DEFAULT_TOOL_POINTS};

/// Errors reading a configuration file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Io {
        /// File that was asked for.
        path: PathBuf,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The TOML did not parse or did not match the schema.
    #[error("invalid config {origin}: {source}")]
    Parse {
        /// File name, or `<string>`.
        origin: String,
        /// What toml said (line, column, offending key).
        source: toml::de::Error,
    },
    /// A value parsed but is out of its valid range.
    #[error("invalid config value `{key}`: {why}")]
    Invalid {
        /// Dotted key of the offending value.
        key: &'static str,
        /// What is wrong and what is allowed.
        why: String,
    },
}

/// Reads a TOML file into any configuration type, layered over `T::default()` (see
/// [`from_toml_str`]).
pub fn from_toml_file<T: Serialize + DeserializeOwned + Default>(
    path: &Path,
) -> Result<T, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_owned(),
        source,
    })?;
    layered(&text, &path.display().to_string(), T::default())
}

/// Reads a TOML file into a configuration, layered over `base` instead of `T::default()`
/// (for commands whose defaults depend on a choice, e.g. one experiment of several).
pub fn from_toml_file_over<T: Serialize + DeserializeOwned>(
    path: &Path,
    base: T,
) -> Result<T, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
        path: path.to_owned(),
        source,
    })?;
    layered(&text, &path.display().to_string(), base)
}

/// Parses a TOML string into any configuration type, layered over `T::default()`: a key the
/// text leaves out keeps its default at every depth, so `[discriminator]\nn_critic = 30` changes
/// that one value and keeps the rest of the parent's `discriminator` defaults (a plain
/// `toml::from_str` would rebuild the whole table from the field type's own defaults). Tables
/// merge key by key; any other value (numbers, strings, arrays) replaces the default.
/// Unknown keys are still errors.
///
/// The arm model's defaults: a text that names an arm model other than the defaults' (`[sim]
/// model = "ur5e"`, or `model = ...` at the top of a bare [`SimConfig`]) gets that model's
/// defaults for the model-dependent keys it leaves out: [`SimConfig::MODEL_KEYS`] of `[sim]`
/// from [`SimConfig::for_model`] and [`TaskConfig::MODEL_KEYS`] of `[task]` from
/// [`TaskConfig::for_model`] (docs/ur.md, "Arm models"). The task's keys that default from
/// others follow them too (a six-joint `[task]` without `start_q`, a `goal_pose` without `goal`;
/// docs/design.md §2.5). Both hold at every depth: a table with a `[sim]` or `[task]` of its
/// own (an experiment's `[expert]` and `[lqr_gaifo]`) is layered as a configuration of its own.
pub fn from_toml_str<T: Serialize + DeserializeOwned + Default>(
    text: &str,
) -> Result<T, ConfigError> {
    layered(text, "<string>", T::default())
}

fn layered<T: Serialize + DeserializeOwned>(
    text: &str,
    origin: &str,
    base: T,
) -> Result<T, ConfigError> {
    let parse = |source| ConfigError::Parse {
        origin: origin.to_string(),
        source,
    };
    let file: toml::Table = toml::from_str(text).map_err(parse)?;
    let mut merged = match toml::Value::try_from(base) {
        Ok(toml::Value::Table(t)) => t,
        // A configuration that does not serialise to a table: the file alone.
        _ => return toml::from_str(text).map_err(parse),
    };
    // The top level, then every table that holds a `[sim]` or `[task]` of its own (an
    // experiment's `[expert]`, `[lqr_gaifo]`, MDGPS's `[lqr_gaifo]`): each gets the model's and
    // the task's defaults from what the file gives in it, as a configuration of its own would.
    let mut scopes = vec![Vec::new()];
    nested_scopes(&merged, &mut Vec::new(), &mut scopes);
    let empty = toml::Table::new();
    let mut task_given = Vec::with_capacity(scopes.len());
    for path in &scopes {
        let f = table_at(&file, path).unwrap_or(&empty);
        let b = table_at_mut(&mut merged, path).expect("a scope of the base");
        model_defaults(b, f)?;
        task_given.push(task_keys_given(b, f));
    }
    merge_table(&mut merged, file);
    for (path, given) in scopes.iter().zip(task_given) {
        if let Some(t) = table_at_mut(&mut merged, path) {
            task_defaults(t, given);
        }
    }
    T::deserialize(toml::Value::Table(merged)).map_err(parse)
}

/// The paths (below `t`, which is at `path`) of every table that has a `sim` or `task` table
/// of its own, parents before children.
fn nested_scopes(t: &toml::Table, path: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    for (k, v) in t {
        let toml::Value::Table(sub) = v else { continue };
        if k == "sim" || k == "task" {
            continue;
        }
        path.push(k.clone());
        if ["sim", "task"]
            .iter()
            .any(|s| sub.get(*s).is_some_and(|v| v.is_table()))
        {
            out.push(path.clone());
        }
        nested_scopes(sub, path, out);
        path.pop();
    }
}

/// The table at `path` below `t` (`t` itself for an empty path).
fn table_at<'a>(t: &'a toml::Table, path: &[String]) -> Option<&'a toml::Table> {
    path.iter()
        .try_fold(t, |t, k| t.get(k).and_then(|v| v.as_table()))
}

/// [`table_at`], mutable.
fn table_at_mut<'a>(t: &'a mut toml::Table, path: &[String]) -> Option<&'a mut toml::Table> {
    path.iter()
        .try_fold(t, |t, k| t.get_mut(k).and_then(|v| v.as_table_mut()))
}

/// Lays the model-dependent defaults of the model `file` names over `base` (see
/// [`from_toml_str`]); nothing when the file names no model or the defaults' own.
fn model_defaults(base: &mut toml::Table, file: &toml::Table) -> Result<(), ConfigError> {
    let in_sim = file
        .get("sim")
        .and_then(|v| v.as_table())
        .and_then(|t| t.get("model"))
        .cloned();
    // A file with a [sim] table over a base with one, or a bare SimConfig (keys at the top).
    let (named, nested) = match in_sim {
        Some(m) if base.get("sim").is_some_and(|v| v.is_table()) => (m, true),
        Some(_) => return Ok(()),
        None => match file.get("model") {
            Some(m) if base.contains_key("ee_link") => (m.clone(), false),
            _ => return Ok(()),
        },
    };
    let model = UrModel::deserialize(named.clone()).map_err(|e| ConfigError::Invalid {
        key: "sim.model",
        why: format!("{named}: {e}"),
    })?;
    let sim_table: &mut toml::Table = if nested {
        base.get_mut("sim")
            .and_then(|v| v.as_table_mut())
            .expect("checked above")
    } else {
        &mut *base
    };
    let current = sim_table
        .get("model")
        .cloned()
        .map(UrModel::deserialize)
        .transpose()
        .map_err(|e| ConfigError::Invalid {
            key: "sim.model",
            why: e.to_string(),
        })?
        .unwrap_or_default();
    if current == model {
        return Ok(());
    }
    let table = |v: toml::Value| match v {
        toml::Value::Table(t) => t,
        _ => unreachable!("a config struct serialises to a table"),
    };
    let sim = table(toml::Value::try_from(SimConfig::for_model(model)).expect("serialisable"));
    for key in SimConfig::MODEL_KEYS {
        let (parent, leaf) = key
            .split_once('.')
            .map_or((None, key), |(p, l)| (Some(p), l));
        // A key the model's defaults leave out when serialised (`model` of the UR5) is left
        // out of the base too, so it takes its default.
        let value = match parent {
            Some(p) => sim
                .get(p)
                .and_then(|t| t.as_table())
                .and_then(|t| t.get(leaf))
                .cloned(),
            None => sim.get(leaf).cloned(),
        };
        let into = match parent {
            Some(p) => match sim_table.get_mut(p) {
                Some(toml::Value::Table(t)) => t,
                _ => continue,
            },
            None => &mut *sim_table,
        };
        match value {
            Some(v) => into.insert(leaf.to_string(), v),
            None => into.remove(leaf),
        };
    }
    if nested {
        if let Some(toml::Value::Table(task_table)) = base.get_mut("task") {
            let task =
                table(toml::Value::try_from(TaskConfig::for_model(model)).expect("serialisable"));
            for key in TaskConfig::MODEL_KEYS {
                task_table.insert(key.to_string(), task[key].clone());
            }
        }
    }
    Ok(())
}

/// Which of the task's keys that others default from the file gives: (`joints`, `start_q`,
/// `goal`, `goal_pose`), for [`task_defaults`]; `None` if the configuration has no task.
fn task_keys_given(base: &toml::Table, file: &toml::Table) -> Option<[bool; 4]> {
    let task = if base.get("task").is_some_and(|v| v.is_table()) {
        file.get("task").and_then(|v| v.as_table())
    } else if base.contains_key("horizon") && base.contains_key("start_q") {
        Some(file)
    } else {
        return None;
    };
    let has = |k: &str| task.is_some_and(|t| t.contains_key(k));
    Some([has("joints"), has("start_q"), has("goal"), has("goal_pose")])
}

/// The task's defaults that follow from other keys (docs/design.md §2.5): a six-joint task
/// whose file leaves out `start_q` starts from the three-joint start pose with the wrist where
/// `sim.wrist_q` (a controller's file: `arm.ur.wrist_q`) puts it (its default: UR's home
/// posture); a file that gives `goal_pose`
/// without `goal` gets the pose's position as the goal point.
fn task_defaults(merged: &mut toml::Table, given: Option<[bool; 4]>) {
    let Some([joints, start_q, goal, goal_pose]) = given else {
        return;
    };
    let wrist: Vec<toml::Value> = merged
        .get("sim")
        .and_then(|s| s.get("wrist_q"))
        .or_else(|| {
            merged
                .get("arm")
                .and_then(|a| a.get("ur"))
                .and_then(|u| u.get("wrist_q"))
        })
        .and_then(|w| w.as_array())
        .cloned()
        .unwrap_or_else(|| {
            UrModel::Ur5
                .default_wrist_q()
                .iter()
                .map(|v| toml::Value::Float(*v))
                .collect()
        });
    let task = if merged.get("task").is_some_and(|v| v.is_table()) {
        merged
            .get_mut("task")
            .and_then(|v| v.as_table_mut())
            .expect("checked")
    } else {
        merged
    };
    let six = task.get("joints").and_then(|v| v.as_integer()) == Some(6);
    if joints && six && !start_q {
        if let Some(toml::Value::Array(q)) = task.get_mut("start_q") {
            if q.len() == 3 {
                q.extend(wrist);
            }
        }
    }
    if goal_pose && !goal {
        if let Some(toml::Value::Array(p)) = task.get("goal_pose") {
            let position: Vec<toml::Value> = p.iter().take(3).cloned().collect();
            task.insert("goal".into(), toml::Value::Array(position));
        }
    }
}

/// `base` with `over` laid on top: tables recursively, everything else replaced.
fn merge_table(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_table(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Parses "x,y,z" (three finite numbers, comma-separated) for command lines.
pub fn parse_triple(s: &str) -> Result<[f64; 3], String> {
    parse_numbers(s)
}

/// Parses UR's pose "x,y,z,rx,ry,rz" (six finite numbers, comma-separated: the position in m
/// and the rotation vector in rad, base frame; what the teach pendant shows) for command lines.
pub fn parse_pose(s: &str) -> Result<[f64; 6], String> {
    parse_numbers(s)
        .map_err(|e| format!("{e} (a pose is x,y,z,rx,ry,rz: m, then a rotation vector in rad)"))
}

/// Parses `N` finite comma-separated numbers.
fn parse_numbers<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| format!("`{x}`: {e}")))
        .collect::<Result<_, _>>()?;
    let a: [f64; N] = v
        .try_into()
        .map_err(|v: Vec<f64>| format!("expected {N} comma-separated numbers, got {}", v.len()))?;
    if a.iter().any(|x| !x.is_finite()) {
        return Err("values must be finite".into());
    }
    Ok(a)
}

/// Control rates (Hz) the project supports, the controller's loop and the learner alike:
/// 10 Hz (the paper's 0.1 s period) to 1 kHz (the simulated arm's physics step). A period
/// outside them is an input error (a time column in ms, an `fps` of 1e-300), refused before it
/// can ask for hours of simulation or a loop that cannot keep up.
pub const RATE_RANGE_HZ: (f64, f64) = (10.0, 1000.0);

/// Checks a control period `dt` (s) against [`RATE_RANGE_HZ`] (dt 0.001 to 0.1 s, with a
/// relative tolerance of 1e-9 for periods written as 1 / rate); the message gives the rate.
pub fn check_dt(dt: f64) -> Result<(), String> {
    let rate = 1.0 / dt;
    if dt.is_finite()
        && dt > 0.0
        && rate >= RATE_RANGE_HZ.0 * (1.0 - 1e-9)
        && rate <= RATE_RANGE_HZ.1 * (1.0 + 1e-9)
    {
        Ok(())
    } else {
        // Shortest decimals for ordinary values, exponents for absurd ones (1e300, not 301 digits).
        let show = |x: f64| {
            if x != 0.0 && (x.abs() >= 1e6 || x.abs() < 1e-6) {
                format!("{x:e}")
            } else {
                format!("{x}")
            }
        };
        Err(format!(
            "{} s is a control rate of {} Hz; supported are 10 Hz to 1 kHz (dt 0.001 to 0.1 s)",
            show(dt),
            show(rate)
        ))
    }
}

/// Real-time speed-ups (`time_compression`) the simulated arms and the controller accept:
/// 1 (real time) to 1000 (a 2 ms arm cycle every 2 µs of wall time; beyond it the deadlines
/// are below what the OS can keep, and 1e308 would be a busy loop).
pub const TIME_COMPRESSION_RANGE: (f64, f64) = (1.0, 1000.0);

/// Checks `time_compression` against [`TIME_COMPRESSION_RANGE`].
pub fn check_time_compression(c: f64) -> Result<(), String> {
    if c.is_finite() && c >= TIME_COMPRESSION_RANGE.0 && c <= TIME_COMPRESSION_RANGE.1 {
        Ok(())
    } else {
        Err(format!(
            "{c} must be in {} to {} (real time to 1000 times faster)",
            TIME_COMPRESSION_RANGE.0, TIME_COMPRESSION_RANGE.1
        ))
    }
}

/// What an action means to the simulated arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ActionMode {
    /// Goal joint angles (rad) tracked by the arm's own joint servo, as a UR5 executes `servoj`
    /// (the paper's set-up, docs/design.md §2.3).
    #[default]
    GoalAngles,
    /// Joint torques (N·m), clamped to the effort limits; gravity is not compensated.
    Torque,
}

/// Limits of the active joints that every action is clamped to (see `crate::safety`), one
/// value per active joint (3 or 6; docs/design.md §2.4). Defaults: UR5 (CB3) data sheet, as
/// written in hil-sim's bundled URDF, for the three arm joints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArmLimits {
    /// Lower joint limits (rad): ±2π for pan and lift, ±π for the elbow.
    pub lower: Joints,
    /// Upper joint limits (rad).
    pub upper: Joints,
    /// Joint velocity limits (rad/s): π rad/s (180°/s).
    pub velocity: Joints,
    /// Joint effort limits (N·m): 150 N·m for the three large joints.
    pub effort: Joints,
}

impl Default for ArmLimits {
    fn default() -> Self {
        use std::f64::consts::PI;
        Self {
            lower: Joints::from([-2.0 * PI, -2.0 * PI, -PI]),
            upper: Joints::from([2.0 * PI, 2.0 * PI, PI]),
            velocity: Joints::splat(N_JOINTS, PI),
            effort: Joints::splat(N_JOINTS, 150.0),
        }
    }
}

impl ArmLimits {
    /// Limits of the three arm joints (shoulder pan, shoulder lift, elbow) of `model`
    /// ([`UrModel::joint_limits`]); `for_model(UrModel::Ur5) == ArmLimits::default()`.
    pub fn for_model(model: UrModel) -> Self {
        Self::for_model_joints(model, N_JOINTS)
    }

    /// Limits of the first `joints` joints of `model` (3: the arm joints; 6: the whole arm).
    pub fn for_model_joints(model: UrModel, joints: usize) -> Self {
        let l = model.joint_limits();
        let first = |v: [f64; 6]| Joints::from_slice(&v[..joints]);
        Self {
            lower: first(l.lower),
            upper: first(l.upper),
            velocity: first(l.velocity),
            effort: first(l.effort),
        }
    }

    /// Number of joints the limits are for.
    pub fn joints(&self) -> usize {
        self.lower.len()
    }

    /// Checks lengths, ordering and signs.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let n = self.lower.len();
        if [self.upper.len(), self.velocity.len(), self.effort.len()] != [n; 3] {
            return Err(ConfigError::Invalid {
                key: "limits",
                why: format!(
                    "lower, upper, velocity and effort have {n}, {}, {} and {} values: give one \
                     per active joint in each",
                    self.upper.len(),
                    self.velocity.len(),
                    self.effort.len()
                ),
            });
        }
        for j in 0..n {
            if !(self.lower[j] < self.upper[j] && self.velocity[j] > 0.0 && self.effort[j] > 0.0) {
                return Err(ConfigError::Invalid {
                    key: "limits",
                    why: format!(
                        "joint {j}: need lower < upper and positive velocity and effort limits"
                    ),
                });
            }
        }
        Ok(())
    }
}

/// Gains of the simulated arm's joint servo (runs at the physics rate).
///
/// Law per active joint j: v_des = clamp(ω_p (q_goal − q), ±v_max);
/// τ = τ_g(q) + k_v,j (v_des − q̇), clamped to ±effort_j; τ_g is the gravity torque of the nominal
/// model (the arm's controller knows its own nominal masses, as a real UR5's does).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoConfig {
    /// Position-loop bandwidth ω_p (1/s). Ours: 10/s gives a 0.1 s time constant, so a goal one
    /// control period ahead is mostly reached by the time the next goal arrives.
    pub position_gain: f64,
    /// Velocity-loop gain k_v per joint (N·m·s/rad). Ours: about 50× the largest joint inertia
    /// (≈ 3, 3, 0.6 kg·m² at full reach), a velocity loop ≈ 5× faster than the position loop
    /// and still far inside the explicit-integration stability limit at 1 ms.
    pub velocity_gain: [f64; N_JOINTS],
    /// Joint velocity limit v_max (rad/s) used by the servo. UR5 data sheet: π rad/s (180°/s).
    pub max_velocity: f64,
}

impl ServoConfig {
    /// The servo for `model`: the UR5's position gain; velocity gains scaled from the UR5's by
    /// the ratio of a rough joint inertia at full reach (links as point masses at their
    /// centres: upper arm at |a2|/2, forearm at |a2| + |a3|/2, the wrists at |a2| + |a3| from
    /// the shoulder; forearm and wrists about the elbow), so every model's velocity loop has
    /// the UR5's bandwidth; rounded to two digits (masses: ROS 2 `ur_description`
    /// `physical_parameters.yaml`). `max_velocity`: the slowest active joint's limit.
    pub fn for_model(model: UrModel) -> Self {
        let velocity_gain = match model {
            UrModel::Ur5 => [150.0, 150.0, 30.0],
            UrModel::Ur3 => [30.0, 30.0, 6.3],
            UrModel::Ur10 => [530.0, 530.0, 110.0],
            UrModel::Ur3e => [31.0, 31.0, 6.3],
            UrModel::Ur5e | UrModel::Ur7e => [170.0, 170.0, 35.0],
            UrModel::Ur10e | UrModel::Ur12e => [550.0, 550.0, 110.0],
            UrModel::Ur16e => [300.0, 300.0, 49.0],
            UrModel::Ur15 => [680.0, 680.0, 110.0],
            UrModel::Ur18 => [320.0, 320.0, 46.0],
            UrModel::Ur20 => [1700.0, 1700.0, 290.0],
            UrModel::Ur30 => [880.0, 880.0, 140.0],
        };
        let v = ArmLimits::for_model(model).velocity;
        Self {
            velocity_gain,
            max_velocity: v[0].min(v[1]).min(v[2]),
            ..Self::default()
        }
    }
}

impl Default for ServoConfig {
    fn default() -> Self {
        Self {
            position_gain: 10.0,
            velocity_gain: [150.0, 150.0, 30.0],
            max_velocity: std::f64::consts::PI,
        }
    }
}

/// Perturbations that turn the nominal simulated arm into a stand-in "physical arm"
/// (docs/design.md §2.7, the paper's hardware experiment). All off by default; all noise is drawn from
/// one RNG seeded with `seed`, so a run replays bit for bit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Perturbation {
    /// Scale applied to every moving link's mass and inertia (1 = nominal).
    pub mass_scale: f64,
    /// Viscous joint damping per active joint (N·m·s/rad).
    pub joint_damping: [f64; N_JOINTS],
    /// Dry (Coulomb) joint friction per active joint: the largest torque friction can produce (N·m).
    pub joint_friction: [f64; N_JOINTS],
    /// Standard deviation of Gaussian noise added to every applied joint torque (N·m), drawn
    /// once per physics step.
    pub actuator_noise_std: f64,
    /// Standard deviation of Gaussian noise on the measured joint angles (rad).
    pub sensor_noise_q_std: f64,
    /// Standard deviation of Gaussian noise on measured joint velocities (rad/s).
    pub sensor_noise_qd_std: f64,
    /// Standard deviation of Gaussian noise on the measured end-effector position (m) and
    /// velocity (m/s).
    pub sensor_noise_ee_std: f64,
    /// Actions applied this many control periods late (0 or 1: one-step latency).
    pub latency_steps: usize,
    /// Seed of the perturbation RNG.
    pub seed: u64,
}

impl Default for Perturbation {
    fn default() -> Self {
        Self {
            mass_scale: 1.0,
            joint_damping: [0.0; N_JOINTS],
            joint_friction: [0.0; N_JOINTS],
            actuator_noise_std: 0.0,
            sensor_noise_q_std: 0.0,
            sensor_noise_qd_std: 0.0,
            sensor_noise_ee_std: 0.0,
            latency_steps: 0,
            seed: 0,
        }
    }
}

impl Perturbation {
    /// A moderate perturbed arm for the "simulated vs physical" experiment: +10 % mass, some
    /// damping and friction, small actuator and sensor noise, one-step latency. Our choice of
    /// magnitudes (a few per cent of the nominal torques), not the paper's.
    pub fn physical_stand_in(seed: u64) -> Self {
        Self {
            mass_scale: 1.1,
            joint_damping: [2.0, 2.0, 1.0],
            joint_friction: [1.0, 1.0, 0.5],
            actuator_noise_std: 0.5,
            sensor_noise_q_std: 1e-3,
            sensor_noise_qd_std: 5e-3,
            sensor_noise_ee_std: 1e-3,
            latency_steps: 1,
            seed,
        }
    }

    /// True when every knob is at its nominal value.
    pub fn is_nominal(&self) -> bool {
        let z = Self {
            seed: self.seed,
            ..Self::default()
        };
        *self == z
    }
}

/// The simulated UR arm (hil-sim), also the arm the learner's checks and the `ur` backend's
/// kinematics assume.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// The arm model (`"ur5"`, `"ur5e"`, …; docs/ur.md, "Arm models"). Its bundled URDF is
    /// simulated unless `urdf` names another file; a config file that names a model gets that
    /// model's defaults for the keys it leaves out ([`SimConfig::MODEL_KEYS`], the task's start
    /// pose and goal). Default: the CB-series UR5 of the paper. Left out when serialised if it
    /// is the UR5, so a UR5 configuration serialises (and hashes, in run manifests) as it did
    /// before arms had a model.
    #[serde(skip_serializing_if = "UrModel::is_ur5")]
    pub model: UrModel,
    /// URDF file; `None` uses the model's URDF bundled with hil-sim (`hil-sim/urdf/<model>.urdf`).
    pub urdf: Option<PathBuf>,
    /// Physics step (s), also the servo rate: 1 kHz.
    pub physics_dt: f64,
    /// Solver substeps per physics step (rapier's `num_solver_iterations`); accuracy is first
    /// order in physics_dt / substeps (UR5.md: ≈ 2.5e-3 relative at 1 ms, 2.5e-4 at 0.1 ms).
    pub substeps: usize,
    /// Meaning of actions.
    pub mode: ActionMode,
    /// Angles the three wrist joints are locked at (rad). Ours: the usual UR5 home posture
    /// of the wrist (wrist 1 at −π/2, wrist 2 at π/2).
    pub wrist_q: [f64; 3],
    /// URDF link whose origin (plus `ee_offset`) is the end-effector point.
    pub ee_link: String,
    /// Offset of the end-effector point from `ee_link`'s origin, in that link's frame (m).
    pub ee_offset: [f64; 3],
    /// Joint servo gains (goal-angle mode).
    pub servo: ServoConfig,
    /// Stand-in "physical arm" knobs (all off by default).
    pub perturbation: Perturbation,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            model: UrModel::Ur5,
            urdf: None,
            physics_dt: 1e-3,
            substeps: 1,
            mode: ActionMode::GoalAngles,
            wrist_q: [
                -std::f64::consts::FRAC_PI_2,
                std::f64::consts::FRAC_PI_2,
                0.0,
            ],
            ee_link: "wrist_3_link".into(),
            ee_offset: [0.0; 3],
            servo: ServoConfig::default(),
            perturbation: Perturbation::default(),
        }
    }
}

impl SimConfig {
    /// The keys (dotted below `[sim]`) whose defaults depend on the arm model (see
    /// [`from_toml_str`]).
    pub const MODEL_KEYS: [&'static str; 5] = [
        "model",
        "wrist_q",
        "ee_offset",
        "servo.velocity_gain",
        "servo.max_velocity",
    ];

    /// The simulated `model` with its defaults: wrist lock and end-effector offset
    /// ([`UrModel::default_wrist_q`], [`UrModel::default_ee_offset`]) and servo gains scaled to
    /// its inertia ([`ServoConfig::for_model`]); `for_model(UrModel::Ur5) ==
    /// SimConfig::default()`.
    pub fn for_model(model: UrModel) -> Self {
        Self {
            model,
            wrist_q: model.default_wrist_q(),
            ee_offset: model.default_ee_offset(),
            servo: ServoConfig::for_model(model),
            ..Self::default()
        }
    }

    /// Checks ranges; the message names the key and the allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |key, why: String| Err(ConfigError::Invalid { key, why });
        if !(self.physics_dt.is_finite() && self.physics_dt > 0.0 && self.physics_dt <= 0.01) {
            return bad(
                "sim.physics_dt",
                format!("{} s must be in (0, 0.01]", self.physics_dt),
            );
        }
        if self.substeps == 0 || self.substeps > 1000 {
            return bad(
                "sim.substeps",
                format!("{} must be in 1..=1000", self.substeps),
            );
        }
        let p = &self.perturbation;
        if !(p.mass_scale.is_finite() && p.mass_scale > 0.0) {
            return bad(
                "sim.perturbation.mass_scale",
                format!("{} must be finite and > 0", p.mass_scale),
            );
        }
        let nonneg = p
            .joint_damping
            .iter()
            .chain(p.joint_friction.iter())
            .chain(
                [
                    p.actuator_noise_std,
                    p.sensor_noise_q_std,
                    p.sensor_noise_qd_std,
                    p.sensor_noise_ee_std,
                ]
                .iter(),
            )
            .all(|v| v.is_finite() && *v >= 0.0);
        if !nonneg {
            return bad(
                "sim.perturbation",
                "damping, friction and noise levels must be finite and >= 0".into(),
            );
        }
        if p.latency_steps > 1 {
            return bad(
                "sim.perturbation.latency_steps",
                format!("{} must be 0 or 1", p.latency_steps),
            );
        }
        let s = &self.servo;
        if !(s.position_gain > 0.0
            && s.max_velocity > 0.0
            && s.velocity_gain.iter().all(|g| *g > 0.0))
        {
            return bad("sim.servo", "gains and max_velocity must be > 0".into());
        }
        if self
            .wrist_q
            .iter()
            .chain(self.ee_offset.iter())
            .any(|v| !v.is_finite())
        {
            return bad("sim.wrist_q/ee_offset", "must be finite".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_round_trip_through_toml() {
        let sim = SimConfig::default();
        sim.validate().unwrap();
        TaskConfig::default().validate().unwrap();
        let text = toml::to_string(&sim).unwrap();
        let back: SimConfig = from_toml_str(&text).unwrap();
        assert_eq!(back, sim);
        assert!(sim.perturbation.is_nominal());
        assert!(!Perturbation::physical_stand_in(1).is_nominal());
    }

    #[derive(Debug, PartialEq, Default, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Inner {
        a: f64,
        b: Vec<usize>,
    }
    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Outer {
        inner: Inner,
        n: u32,
    }
    impl Default for Outer {
        fn default() -> Self {
            Self {
                inner: Inner {
                    a: 1.0,
                    b: vec![32, 32],
                },
                n: 5,
            }
        }
    }

    #[test]
    fn a_partial_table_keeps_the_parents_defaults() {
        let o: Outer = from_toml_str("[inner]\na = 2.0").unwrap();
        assert_eq!(o.inner.b, vec![32, 32], "not Inner::default()'s empty list");
        assert_eq!((o.inner.a, o.n), (2.0, 5));
        let o: Outer = from_toml_str("n = 7\n[inner]\nb = [4]").unwrap();
        assert_eq!(o.inner, Inner { a: 1.0, b: vec![4] });
        assert_eq!(o.n, 7);
        let err = from_toml_str::<Outer>("[inner]\nc = 1").unwrap_err();
        assert!(err.to_string().contains('c'), "{err}");
        assert!(from_toml_str::<Outer>("n = \"x\"").is_err());
        assert!(from_toml_str::<Outer>("n = ").is_err());
    }

    #[test]
    fn the_ur5s_defaults_are_todays_and_a_named_model_brings_its_own() {
        assert_eq!(ArmLimits::for_model(UrModel::Ur5), ArmLimits::default());
        for m in UrModel::ALL {
            ArmLimits::for_model(m).validate().unwrap();
        }
        let s = SimConfig::default();
        assert_eq!(UrModel::Ur5.default_wrist_q(), s.wrist_q);
        assert_eq!(UrModel::Ur5.default_ee_offset(), s.ee_offset);
        assert_eq!(SimConfig::for_model(UrModel::Ur5), SimConfig::default());
        assert_eq!(TaskConfig::for_model(UrModel::Ur5), TaskConfig::default());
        #[derive(Debug, PartialEq, Default, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        struct File {
            task: TaskConfig,
            sim: SimConfig,
        }
        let f: File = from_toml_str("[sim]\nmodel = \"ur5\"").unwrap();
        assert_eq!(f, File::default());
        let f: File = from_toml_str("[sim]\nmodel = \"ur10e\"\n[task]\nhorizon = 50").unwrap();
        assert_eq!(f.sim, SimConfig::for_model(UrModel::Ur10e));
        assert_eq!(f.task.goal, UrModel::Ur10e.default_goal());
        assert_eq!(f.task.horizon, 50);
        // Keys the file gives win over the model's defaults.
        let f: File =
            from_toml_str("[sim]\nmodel = \"ur3e\"\nwrist_q = [0.1, 0.2, 0.3]\n[task]\ngoal = [0.1, 0.2, 0.3]\n[sim.servo]\nposition_gain = 5.0")
                .unwrap();
        assert_eq!(f.sim.wrist_q, [0.1, 0.2, 0.3]);
        assert_eq!(f.task.goal, [0.1, 0.2, 0.3]);
        assert_eq!(f.task.start_q, UrModel::Ur3e.default_start_q());
        assert_eq!(f.sim.servo.position_gain, 5.0);
        assert_eq!(
            f.sim.servo.velocity_gain,
            ServoConfig::for_model(UrModel::Ur3e).velocity_gain
        );
        let s: SimConfig = from_toml_str("model = \"ur20\"").unwrap();
        assert_eq!(s, SimConfig::for_model(UrModel::Ur20));
        // Back to the UR5 over a base of another model.
        let over = layered(
            "[sim]\nmodel = \"ur5\"",
            "<string>",
            File {
                task: TaskConfig::for_model(UrModel::Ur10e),
                sim: SimConfig::for_model(UrModel::Ur10e),
            },
        )
        .unwrap();
        assert_eq!(over, File::default());
        let e = from_toml_str::<File>("[sim]\nmodel = \"ur7\"").unwrap_err();
        assert!(
            e.to_string().contains("ur7") && e.to_string().contains("sim.model"),
            "{e}"
        );
    }

    /// A table with a `[sim]` or `[task]` of its own (an experiment's `[expert]`, at any depth)
    /// is layered as a configuration of its own: the model's defaults and the six-joint pose
    /// task's; a file that leaves it alone keeps the defaults.
    #[test]
    fn nested_configurations_get_the_model_and_task_defaults() {
        #[derive(Debug, PartialEq, Default, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        struct Run {
            task: TaskConfig,
            sim: SimConfig,
        }
        #[derive(Debug, PartialEq, Default, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        struct Learner {
            sim: SimConfig,
            n: u32,
        }
        #[derive(Debug, PartialEq, Default, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        struct Deeper {
            inner: Run,
        }
        #[derive(Debug, PartialEq, Default, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        struct Exp {
            expert: Run,
            learner: Learner,
            deeper: Deeper,
        }
        let pose = "goal_pose = [-0.4383, -0.2993, 0.3748, 0.4667, -0.108, -0.8096]\n";
        let top: Run = from_toml_str(&format!(
            "[sim]\nmodel = \"ur5e\"\n[task]\njoints = 6\n{pose}"
        ))
        .unwrap();
        assert_eq!(top.task.start_q.len(), 6);
        assert_eq!(top.task.goal, [-0.4383, -0.2993, 0.3748]);
        let e: Exp = from_toml_str(&format!(
            "[expert.sim]\nmodel = \"ur5e\"\n[expert.task]\njoints = 6\n{pose}\
             [learner]\nn = 2\n[learner.sim]\nmodel = \"ur10e\"\n\
             [deeper.inner.task]\njoints = 6\n"
        ))
        .unwrap();
        assert_eq!(e.expert, top);
        assert_eq!(e.learner.sim, SimConfig::for_model(UrModel::Ur10e));
        assert_eq!(e.learner.n, 2);
        let mut q = UrModel::Ur5.default_start_q().to_vec();
        q.extend(UrModel::Ur5.default_wrist_q());
        assert_eq!(e.deeper.inner.task.start_q.as_slice(), q.as_slice());
        assert_eq!(from_toml_str::<Exp>("").unwrap(), Exp::default());
        let e: Exp = from_toml_str("[learner]\nn = 3\n").unwrap();
        assert_eq!(
            (e.learner.sim, e.expert),
            (SimConfig::default(), Run::default())
        );
    }

    #[test]
    fn unknown_keys_and_bad_values_are_rejected() {
        let err = from_toml_str::<SimConfig>("physics_dtt = 0.001").unwrap_err();
        assert!(err.to_string().contains("physics_dtt"), "{err}");
        let sim: SimConfig = from_toml_str("physics_dt = -1.0").unwrap();
        assert!(sim
            .validate()
            .unwrap_err()
            .to_string()
            .contains("physics_dt"));
        let sim: SimConfig = from_toml_str("[perturbation]\nlatency_steps = 3").unwrap();
        assert!(sim.validate().is_err());
    }
}
