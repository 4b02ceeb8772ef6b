//! LeRobot v3.0 datasets (docs/design.md §4.12), out and in, with the `parquet` crate's column
//! API (no arrow). A dataset is a folder:
//!
//! | file | what |
//! |---|---|
//! | `meta/info.json` | `codebase_version` "v3.0", `robot_type` (the arm model, "ur5" if not known), `fps`, totals, paths, `features` (dtype, shape, names); ours also `ur5_task` ([`TaskMeta`]) and `ur_model` ([`MODEL_KEY`]: the arm model, when known) |
//! | `meta/stats.json` | per numeric feature: `min`, `max`, `mean`, `std` (per entry), `count` |
//! | `meta/tasks.parquet` | `task_index` (int64) and `task` (string; pandas reads it as the index) |
//! | `meta/episodes/chunk-000/file-000.parquet` | per episode: `episode_index`, `tasks`, `length`, `data/chunk_index`, `data/file_index`, `dataset_from_index`, `dataset_to_index`, `meta/episodes/chunk_index`, `meta/episodes/file_index` |
//! | `data/chunk-000/file-000.parquet` | per frame: `observation.state` list<float64> [dX], `action` list<float64> [dU] (when recorded), `timestamp` float32 (s), `frame_index`, `episode_index`, `index`, `task_index` int64 |
//!
//! The state's width is the task's dX (`ur5_shared::StateLayout`: 12 for three joints and a
//! point, 18 for six joints and a point, 30 for six joints and a pose), its `names` the
//! layout's; the action's width is dU. States are written as float64 so that an export reads
//! back bit for bit; the reader takes `observation.state` as float64 or float32 lists from
//! every `data/*/*.parquet` file (in name order), groups frames by `episode_index` and orders
//! them by `frame_index`. It reads nothing else from the frames: imitation is state-only.
//!
//! A recording of a UR arm made elsewhere stores the six joint positions (rad) as
//! `observation.state` ([`JOINT_POSITIONS`] wide): [`import_joint_positions`] reads those, and
//! `io::foreign` makes them states of the whole arm.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use parquet::basic::{LogicalType, Repetition, Type as Physical};
use parquet::data_type::{ByteArray, ByteArrayType, DoubleType, FloatType, Int64Type};
use parquet::file::metadata::KeyValue;
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::file::writer::{SerializedColumnWriter, SerializedFileWriter};
use parquet::record::Field;
use parquet::schema::types::Type;
use serde::{Deserialize, Serialize};

use ur5_shared::layout::StateLayout;
use ur5_shared::UrModel;

/// The state feature, the only one the reader needs.
pub const STATE_FEATURE: &str = "observation.state";
/// The action feature (written where actions were recorded).
pub const ACTION_FEATURE: &str = "action";
/// Our key in `meta/info.json` naming the arm model (`"ur5"`, `"ur5e"`, …; its `robot_type`
/// says the same). Datasets exported before it, and those made elsewhere, have none: they are
/// taken to be of the configured arm (the UR5 for `learner dataset check`).
pub const MODEL_KEY: &str = "ur_model";
/// The task of every three-joint dataset we write.
pub const TASK: &str = "reach the goal point with the end effector (UR5, 3 joints)";
/// The task of a dataset of another layout than the three-joint point task's.
fn task_text(layout: &StateLayout) -> String {
    match (layout.joints(), layout.tool_points()) {
        _ if *layout == StateLayout::REACH3 => TASK.into(),
        (n, 1) => format!("reach the goal point with the end effector (UR, {n} joints)"),
        (n, _) => format!("reach the goal pose with the tool (UR, {n} joints)"),
    }
}
/// Width of the `observation.state` of a UR arm's recording made elsewhere: its six joint
/// positions (rad), base to wrist 3.
pub const JOINT_POSITIONS: usize = 6;

/// Errors of reading or writing a dataset; each names the file and, where it applies, the
/// feature.
#[derive(Debug, thiserror::Error)]
pub enum LeRobotError {
    /// File-system error on `path`.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Parquet error on `path`.
    #[error("{path}: {source}")]
    Parquet {
        path: PathBuf,
        source: parquet::errors::ParquetError,
    },
    /// `meta/info.json` unreadable or not a dataset's.
    #[error("{path}: {why}")]
    Info { path: PathBuf, why: String },
    /// A feature is missing or has the wrong type or size.
    #[error("{path}: feature `{feature}`: {why}")]
    Feature {
        path: PathBuf,
        feature: String,
        why: String,
    },
}

/// The task of the arm a dataset was recorded on, as our exports note it in `meta/info.json`
/// (`ur5_task`); a dataset made elsewhere has none and the importer derives it
/// (`io::foreign`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskMeta {
    /// Goal point (m, base frame).
    pub goal: [f64; 3],
    /// Start pose (rad), one angle per active joint (the joint-state formats carry the
    /// three-joint task's).
    pub start_q: ur5_shared::joints::Joints,
    /// Seed of the recording run.
    pub seed: u64,
    /// Mean task cost of the random policy, when known.
    pub cost_random: Option<f64>,
    /// Mean task cost of these trajectories, when known.
    pub cost_expert: Option<f64>,
    /// A pose task's goal pose, UR's p[x, y, z, rx, ry, rz] (m, rad; base frame); absent for
    /// a point goal (and so absent from three-joint datasets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_pose: Option<[f64; 6]>,
    /// A pose task's tool points (m, flange frame, relative to the TCP); absent: the default
    /// ones (`ur5_shared::config::DEFAULT_TOOL_POINTS`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_points: Option<[[f64; 3]; 3]>,
}

/// Equal-length state trajectories (and, where recorded, actions) at one control period: what
/// every demonstration format holds.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectories {
    /// The states' layout (dX, dU and the names): the task's.
    pub layout: StateLayout,
    /// States, (D, T, dX) row-major (names `layout.state_names()`).
    pub states: Vec<f64>,
    /// Actions, (D, T, dU) row-major, when recorded.
    pub actions: Option<Vec<f64>>,
    /// D.
    pub count: usize,
    /// T.
    pub horizon: usize,
    /// Control period (s).
    pub dt: f64,
    /// The task, when the source notes it.
    pub task: Option<TaskMeta>,
    /// The arm model the source notes (a LeRobot dataset's [`MODEL_KEY`], a `.npz`'s
    /// `model`); `None`: not noted, the arm of the run's configuration is assumed.
    pub model: Option<UrModel>,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> LeRobotError + '_ {
    move |source| LeRobotError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn pq_err(path: &Path) -> impl FnOnce(parquet::errors::ParquetError) -> LeRobotError + '_ {
    move |source| LeRobotError::Parquet {
        path: path.to_path_buf(),
        source,
    }
}

/// One column of a table to write.
enum Column {
    /// int64.
    I64(Vec<i64>),
    /// float32.
    F32(Vec<f32>),
    /// string.
    Str(Vec<String>),
    /// list<float64>, every row `width` entries.
    ListF64 { values: Vec<f64>, width: usize },
    /// list<string>, every row `width` entries.
    ListStr { values: Vec<String>, width: usize },
}

impl Column {
    fn schema(&self, name: &str) -> Type {
        let leaf = |name: &str, physical, logical: Option<LogicalType>| {
            Type::primitive_type_builder(name, physical)
                .with_repetition(Repetition::REQUIRED)
                .with_logical_type(logical)
                .build()
                .expect("a valid primitive column")
        };
        let list = |element: Type| {
            let repeated = Type::group_type_builder("list")
                .with_repetition(Repetition::REPEATED)
                .with_fields(vec![Arc::new(element)])
                .build()
                .expect("a valid list group");
            Type::group_type_builder(name)
                .with_repetition(Repetition::REQUIRED)
                .with_logical_type(Some(LogicalType::List))
                .with_fields(vec![Arc::new(repeated)])
                .build()
                .expect("a valid list column")
        };
        match self {
            Column::I64(_) => leaf(name, Physical::INT64, None),
            Column::F32(_) => leaf(name, Physical::FLOAT, None),
            Column::Str(_) => leaf(name, Physical::BYTE_ARRAY, Some(LogicalType::String)),
            Column::ListF64 { .. } => list(leaf("element", Physical::DOUBLE, None)),
            Column::ListStr { .. } => list(leaf(
                "element",
                Physical::BYTE_ARRAY,
                Some(LogicalType::String),
            )),
        }
    }

    fn write(&self, w: &mut SerializedColumnWriter<'_>) -> parquet::errors::Result<()> {
        let levels = |n: usize, width: usize| -> (Vec<i16>, Vec<i16>) {
            let rep = (0..n).map(|i| i16::from(i % width != 0)).collect();
            (vec![1; n], rep)
        };
        let bytes = |v: &[String]| -> Vec<ByteArray> {
            v.iter().map(|s| ByteArray::from(s.as_str())).collect()
        };
        match self {
            Column::I64(v) => w.typed::<Int64Type>().write_batch(v, None, None)?,
            Column::F32(v) => w.typed::<FloatType>().write_batch(v, None, None)?,
            Column::Str(v) => w
                .typed::<ByteArrayType>()
                .write_batch(&bytes(v), None, None)?,
            Column::ListF64 { values, width } => {
                let (def, rep) = levels(values.len(), *width);
                w.typed::<DoubleType>()
                    .write_batch(values, Some(&def), Some(&rep))?
            }
            Column::ListStr { values, width } => {
                let (def, rep) = levels(values.len(), *width);
                w.typed::<ByteArrayType>()
                    .write_batch(&bytes(values), Some(&def), Some(&rep))?
            }
        };
        Ok(())
    }
}

/// Writes one row group of `columns` (all of the same number of rows) to `path`, with the
/// file key-value metadata `kv`.
fn write_table(
    path: &Path,
    columns: &[(&str, Column)],
    kv: Vec<KeyValue>,
) -> Result<(), LeRobotError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    }
    let schema = Type::group_type_builder("schema")
        .with_fields(columns.iter().map(|(n, c)| Arc::new(c.schema(n))).collect())
        .build()
        .map_err(pq_err(path))?;
    let props = parquet::file::properties::WriterProperties::builder()
        .set_key_value_metadata(Some(kv))
        .build();
    let file = File::create(path).map_err(io_err(path))?;
    let mut w =
        SerializedFileWriter::new(file, Arc::new(schema), Arc::new(props)).map_err(pq_err(path))?;
    let mut rg = w.next_row_group().map_err(pq_err(path))?;
    for (_, c) in columns {
        let mut col = rg
            .next_column()
            .map_err(pq_err(path))?
            .expect("one writer per schema column");
        c.write(&mut col).map_err(pq_err(path))?;
        col.close().map_err(pq_err(path))?;
    }
    rg.close().map_err(pq_err(path))?;
    w.close().map_err(pq_err(path))?;
    Ok(())
}

/// min, max, mean, std (population) per entry of `rows` (each `width` wide), and the count.
fn stats(values: &[f64], width: usize) -> serde_json::Value {
    let n = values.len() / width;
    let col = |k: usize| values.iter().skip(k).step_by(width).copied();
    let mean: Vec<f64> = (0..width).map(|k| col(k).sum::<f64>() / n as f64).collect();
    let std: Vec<f64> = (0..width)
        .map(|k| (col(k).map(|v| (v - mean[k]).powi(2)).sum::<f64>() / n as f64).sqrt())
        .collect();
    let min: Vec<f64> = (0..width)
        .map(|k| col(k).fold(f64::INFINITY, f64::min))
        .collect();
    let max: Vec<f64> = (0..width)
        .map(|k| col(k).fold(f64::NEG_INFINITY, f64::max))
        .collect();
    serde_json::json!({"min": min, "max": max, "mean": mean, "std": std, "count": [n]})
}

/// Writes `traj` as a LeRobot v3.0 dataset into `dir` (created; files of the same names
/// replaced). `fps` is 1 / dt, which must be a whole number.
pub fn export(traj: &Trajectories, dir: &Path) -> Result<(), LeRobotError> {
    let info_path = dir.join("meta/info.json");
    let fps = (1.0 / traj.dt).round();
    if !(fps >= 1.0 && (fps * traj.dt - 1.0).abs() < 1e-9) {
        return Err(LeRobotError::Info {
            path: info_path,
            why: format!("dt = {} s is not 1 / fps for a whole fps", traj.dt),
        });
    }
    let (d, t) = (traj.count, traj.horizon);
    let n = d * t;
    let layout = traj.layout;
    let (dx, du) = (layout.dx(), layout.du());
    let task = task_text(&layout);
    let frame =
        |f: &dyn Fn(usize, usize) -> i64| -> Vec<i64> { (0..n).map(|i| f(i / t, i % t)).collect() };
    let mut data = vec![(
        STATE_FEATURE,
        Column::ListF64 {
            values: traj.states.clone(),
            width: dx,
        },
    )];
    if let Some(a) = &traj.actions {
        data.push((
            ACTION_FEATURE,
            Column::ListF64 {
                values: a.clone(),
                width: du,
            },
        ));
    }
    data.extend([
        (
            "timestamp",
            Column::F32((0..n).map(|i| ((i % t) as f64 * traj.dt) as f32).collect()),
        ),
        ("frame_index", Column::I64(frame(&|_, k| k as i64))),
        ("episode_index", Column::I64(frame(&|e, _| e as i64))),
        ("index", Column::I64((0..n as i64).collect())),
        ("task_index", Column::I64(vec![0; n])),
    ]);
    write_table(&dir.join("data/chunk-000/file-000.parquet"), &data, vec![])?;

    let episodes = [
        ("episode_index", Column::I64((0..d as i64).collect())),
        (
            "tasks",
            Column::ListStr {
                values: vec![task.clone(); d],
                width: 1,
            },
        ),
        ("length", Column::I64(vec![t as i64; d])),
        ("data/chunk_index", Column::I64(vec![0; d])),
        ("data/file_index", Column::I64(vec![0; d])),
        (
            "dataset_from_index",
            Column::I64((0..d).map(|e| (e * t) as i64).collect()),
        ),
        (
            "dataset_to_index",
            Column::I64((0..d).map(|e| ((e + 1) * t) as i64).collect()),
        ),
        ("meta/episodes/chunk_index", Column::I64(vec![0; d])),
        ("meta/episodes/file_index", Column::I64(vec![0; d])),
    ];
    write_table(
        &dir.join("meta/episodes/chunk-000/file-000.parquet"),
        &episodes,
        vec![],
    )?;

    // pandas (and so LeRobot's loader) takes the `task` column as the table's index.
    let pandas = serde_json::json!({
        "index_columns": ["task"], "column_indexes": [], "pandas_version": "2.2.0",
        "creator": {"library": "learner", "version": env!("CARGO_PKG_VERSION")},
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": null}
        ]
    });
    write_table(
        &dir.join("meta/tasks.parquet"),
        &[
            ("task_index", Column::I64(vec![0])),
            ("task", Column::Str(vec![task])),
        ],
        vec![KeyValue::new("pandas".into(), pandas.to_string())],
    )?;

    let scalar = |dtype: &str| serde_json::json!({"dtype": dtype, "shape": [1], "names": null});
    let mut features = serde_json::Map::new();
    features.insert(
        STATE_FEATURE.into(),
        serde_json::json!({"dtype": "float64", "shape": [dx], "names": layout.state_names()}),
    );
    let mut stats_json = serde_json::Map::new();
    stats_json.insert(STATE_FEATURE.into(), stats(&traj.states, dx));
    if let Some(a) = &traj.actions {
        features.insert(
            ACTION_FEATURE.into(),
            serde_json::json!({"dtype": "float64", "shape": [du], "names": layout.action_names()}),
        );
        stats_json.insert(ACTION_FEATURE.into(), stats(a, du));
    }
    features.insert("timestamp".into(), scalar("float32"));
    for k in ["frame_index", "episode_index", "index", "task_index"] {
        features.insert(k.into(), scalar("int64"));
    }
    let mut info = serde_json::json!({
        "codebase_version": "v3.0",
        "robot_type": traj.model.unwrap_or_default().name(),
        "total_episodes": d,
        "total_frames": n,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": fps as u64,
        "splits": {"train": format!("0:{d}")},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": null,
        "features": features,
        "ur5_task": traj.task,
    });
    info[MODEL_KEY] = traj.model.map(UrModel::name).into();
    let write_json = |path: PathBuf, v: &serde_json::Value| -> Result<(), LeRobotError> {
        let text = serde_json::to_string_pretty(v).expect("JSON values serialise");
        std::fs::write(&path, text).map_err(io_err(&path))
    };
    write_json(info_path, &info)?;
    write_json(
        dir.join("meta/stats.json"),
        &serde_json::Value::Object(stats_json),
    )
}

/// Whether `dir` looks like a LeRobot dataset (it has `meta/info.json`).
pub fn is_dataset(dir: &Path) -> bool {
    dir.join("meta/info.json").is_file()
}

/// What `meta/info.json` and the data files of a dataset hold, before the frames are read as
/// states or as joint positions.
struct Raw {
    /// Width of `observation.state`.
    width: usize,
    /// Frames, (D, T, width) row-major.
    values: Vec<f64>,
    count: usize,
    horizon: usize,
    fps: f64,
    task: Option<TaskMeta>,
    model: Option<UrModel>,
}

/// The width of the dataset's `observation.state` as `meta/info.json` declares it (`shape`
/// [width]).
pub fn state_width(dir: &Path) -> Result<usize, LeRobotError> {
    let (info, info_path) = read_info(dir)?;
    declared_width(&info, &info_path)
}

fn read_info(dir: &Path) -> Result<(serde_json::Value, PathBuf), LeRobotError> {
    let info_path = dir.join("meta/info.json");
    let text = std::fs::read_to_string(&info_path).map_err(io_err(&info_path))?;
    let info = serde_json::from_str(&text).map_err(|e| LeRobotError::Info {
        path: info_path.clone(),
        why: format!("not JSON: {e}"),
    })?;
    Ok((info, info_path))
}

fn declared_width(info: &serde_json::Value, info_path: &Path) -> Result<usize, LeRobotError> {
    let feature = |why: String| LeRobotError::Feature {
        path: info_path.to_owned(),
        feature: STATE_FEATURE.into(),
        why,
    };
    let f = &info["features"][STATE_FEATURE];
    if f.is_null() {
        return Err(feature(
            "missing from meta/info.json `features`: state-only imitation needs the state".into(),
        ));
    }
    match f["shape"].as_array().map(|a| a.as_slice()) {
        Some([w]) if w.as_u64().is_some_and(|w| w > 0) => Ok(w.as_u64().expect("checked") as usize),
        _ => Err(feature(format!(
            "shape {}, expected [dX] (the task's state) or [{JOINT_POSITIONS}] (a UR arm's \
             joint positions)",
            f["shape"]
        ))),
    }
}

/// Reads the dataset in `dir` whatever its state's width ([`Raw`]).
fn read_raw(dir: &Path) -> Result<Raw, LeRobotError> {
    let (info, info_path) = read_info(dir)?;
    let bad_info = |why: String| LeRobotError::Info {
        path: info_path.clone(),
        why,
    };
    let fps = info["fps"]
        .as_f64()
        .filter(|f| *f > 0.0)
        .ok_or_else(|| bad_info("no positive `fps`".into()))?;
    let width = declared_width(&info, &info_path)?;
    let model = noted_model(&info).map_err(bad_info)?;
    let task: Option<TaskMeta> = match &info["ur5_task"] {
        serde_json::Value::Null => None,
        v => Some(
            serde_json::from_value(v.clone()).map_err(|e| bad_info(format!("`ur5_task`: {e}")))?,
        ),
    };
    let mut frames: BTreeMap<i64, BTreeMap<i64, Vec<f64>>> = BTreeMap::new();
    for path in data_files(&dir.join("data"))? {
        read_frames(&path, width, &mut frames)?;
    }
    let count = frames.len();
    let horizon = frames.values().next().map_or(0, |e| e.len());
    let at = |why: String| LeRobotError::Feature {
        path: dir.join("data"),
        feature: STATE_FEATURE.into(),
        why,
    };
    if count == 0 || horizon < 2 {
        return Err(at(format!(
            "{count} episodes of {horizon} frames: need at least 1 of at least 2"
        )));
    }
    let mut values = Vec::with_capacity(count * horizon * width);
    for (e, ep) in &frames {
        if ep.len() != horizon {
            return Err(at(format!(
                "episode {e} has {} frames, episode {} has {horizon}: demonstrations must be \
                 of equal length",
                ep.len(),
                frames.keys().next().expect("count >= 1")
            )));
        }
        for (k, (i, s)) in ep.iter().enumerate() {
            if *i != k as i64 {
                return Err(at(format!(
                    "episode {e}: frame_index {i} where {k} belongs"
                )));
            }
            values.extend_from_slice(s);
        }
    }
    Ok(Raw {
        width,
        values,
        count,
        horizon,
        fps,
        task,
        model,
    })
}

/// Reads the state trajectories of the LeRobot v3.0 dataset in `dir`: `fps` and, if noted,
/// `ur5_task` from `meta/info.json`; `observation.state` (dX entries, float64 or float32),
/// `episode_index` and `frame_index` from every `data/*/*.parquet`. The state's width gives
/// the layout ([`StateLayout::of_task_state`]: 12, 18 or 30), which a noted task must share.
/// Errors name the feature that is missing, of another size or type, or of episodes of
/// unequal length.
pub fn import(dir: &Path) -> Result<Trajectories, LeRobotError> {
    let width = state_width(dir)?;
    let info_path = dir.join("meta/info.json");
    let feature = |why: String| LeRobotError::Feature {
        path: info_path.clone(),
        feature: STATE_FEATURE.into(),
        why,
    };
    let Some(layout) = StateLayout::of_task_state(width) else {
        return Err(feature(format!(
            "shape [{width}], expected [12] (3 joints and a point), [18] (6 joints and a point) \
             or [30] (6 joints and a pose){}",
            if width == JOINT_POSITIONS {
                ": a UR arm's joint positions are imported as such by `--demos`"
            } else {
                ""
            }
        )));
    };
    let raw = read_raw(dir)?;
    if let Some(t) = &raw.task {
        let noted = StateLayout::of_task(t.start_q.len(), t.goal_pose.is_some());
        if noted != Ok(layout) {
            return Err(LeRobotError::Info {
                path: info_path,
                why: format!(
                    "`ur5_task` ({} start angles, {}) does not describe states of dX = {} \
                     ({layout})",
                    t.start_q.len(),
                    if t.goal_pose.is_some() {
                        "a goal pose"
                    } else {
                        "a goal point"
                    },
                    layout.dx()
                ),
            });
        }
    }
    Ok(Trajectories {
        layout,
        states: raw.values,
        actions: None,
        count: raw.count,
        horizon: raw.horizon,
        dt: 1.0 / raw.fps,
        task: raw.task,
        model: raw.model,
    })
}

/// A UR arm's recorded joint positions: what a LeRobot dataset of a UR arm made elsewhere
/// stores as its `observation.state`.
#[derive(Clone, Debug, PartialEq)]
pub struct JointRecording {
    /// Joint positions (rad), (D, T, 6) row-major, base to wrist 3.
    pub positions: Vec<f64>,
    /// D.
    pub count: usize,
    /// T.
    pub horizon: usize,
    /// Frame period 1 / fps (s).
    pub dt: f64,
    /// The arm model the dataset notes ([`MODEL_KEY`]).
    pub model: Option<UrModel>,
}

/// Reads the dataset in `dir` whose `observation.state` is a UR arm's [`JOINT_POSITIONS`]
/// joint positions (rad), with the same checks as [`import`].
pub fn import_joint_positions(dir: &Path) -> Result<JointRecording, LeRobotError> {
    let raw = read_raw(dir)?;
    if raw.width != JOINT_POSITIONS {
        return Err(LeRobotError::Feature {
            path: dir.join("meta/info.json"),
            feature: STATE_FEATURE.into(),
            why: format!(
                "shape [{}], expected [{JOINT_POSITIONS}] (a UR arm's joint positions)",
                raw.width
            ),
        });
    }
    Ok(JointRecording {
        positions: raw.values,
        count: raw.count,
        horizon: raw.horizon,
        dt: 1.0 / raw.fps,
        model: raw.model,
    })
}

/// The arm model `meta/info.json` notes under [`MODEL_KEY`] (`None`: no such key, or null).
fn noted_model(info: &serde_json::Value) -> Result<Option<UrModel>, String> {
    match &info[MODEL_KEY] {
        serde_json::Value::Null => Ok(None),
        serde_json::Value::String(name) => name
            .parse()
            .map(Some)
            .map_err(|e| format!("`{MODEL_KEY}`: {e}")),
        v => Err(format!("`{MODEL_KEY}`: {v} is not a model name")),
    }
}

/// The arm model the dataset in `dir` notes ([`MODEL_KEY`]; `None` if it notes none).
pub fn model_of(dir: &Path) -> Result<Option<UrModel>, LeRobotError> {
    let (info, info_path) = read_info(dir)?;
    noted_model(&info).map_err(|why| LeRobotError::Info {
        path: info_path,
        why,
    })
}

/// The `*.parquet` files in the chunk folders of `data` (`chunk-*/file-*.parquet`), in name
/// order.
fn data_files(data: &Path) -> Result<Vec<PathBuf>, LeRobotError> {
    let mut files = Vec::new();
    let chunks = std::fs::read_dir(data).map_err(io_err(data))?;
    for chunk in chunks {
        let chunk = chunk.map_err(io_err(data))?.path();
        if !chunk.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&chunk).map_err(io_err(&chunk))? {
            let f = f.map_err(io_err(&chunk))?.path();
            if f.extension().is_some_and(|e| e == "parquet") {
                files.push(f);
            }
        }
    }
    files.sort();
    Ok(files)
}

/// Adds the frames of the data file `path` to `frames` (episode → frame → state of `width`
/// entries).
fn read_frames(
    path: &Path,
    width: usize,
    frames: &mut BTreeMap<i64, BTreeMap<i64, Vec<f64>>>,
) -> Result<(), LeRobotError> {
    let feature_err = |feature: &str, why: String| LeRobotError::Feature {
        path: path.to_path_buf(),
        feature: feature.into(),
        why,
    };
    let file = File::open(path).map_err(io_err(path))?;
    let reader = SerializedFileReader::new(file).map_err(pq_err(path))?;
    let schema = reader.metadata().file_metadata().schema_descr();
    let wanted = [STATE_FEATURE, "episode_index", "frame_index"];
    let fields: Vec<_> = wanted
        .iter()
        .map(|name| {
            schema
                .root_schema()
                .get_fields()
                .iter()
                .find(|f| f.name() == *name)
                .cloned()
                .ok_or_else(|| feature_err(name, "no such column in the data file".into()))
        })
        .collect::<Result<_, _>>()?;
    let projection = Type::group_type_builder("schema")
        .with_fields(fields)
        .build()
        .map_err(pq_err(path))?;
    let rows = reader
        .get_row_iter(Some(projection))
        .map_err(pq_err(path))?;
    for row in rows {
        let row = row.map_err(pq_err(path))?;
        let (mut state, mut episode, mut frame) = (None, None, None);
        for (name, field) in row.get_column_iter() {
            match (name.as_str(), field) {
                (STATE_FEATURE, Field::ListInternal(list)) => {
                    let v: Vec<f64> = list
                        .elements()
                        .iter()
                        .map(|x| match x {
                            Field::Double(v) => Ok(*v),
                            Field::Float(v) => Ok(f64::from(*v)),
                            other => Err(feature_err(
                                STATE_FEATURE,
                                format!("entries of type {other:?}, expected float64 or float32"),
                            )),
                        })
                        .collect::<Result<_, _>>()?;
                    if v.len() != width {
                        return Err(feature_err(
                            STATE_FEATURE,
                            format!(
                                "a frame with {} entries, expected {width} (meta/info.json's \
                                 shape)",
                                v.len()
                            ),
                        ));
                    }
                    state = Some(v);
                }
                (STATE_FEATURE, other) => {
                    return Err(feature_err(
                        STATE_FEATURE,
                        format!("{other:?} is not a list of {width} numbers"),
                    ))
                }
                (name @ ("episode_index" | "frame_index"), f) => {
                    // Any integer type a writer may choose (pandas and pyarrow write int64,
                    // others uint64 or narrower).
                    let v = match f {
                        Field::Long(v) => Some(*v),
                        Field::Int(v) => Some(i64::from(*v)),
                        Field::Short(v) => Some(i64::from(*v)),
                        Field::Byte(v) => Some(i64::from(*v)),
                        Field::ULong(v) => i64::try_from(*v).ok(),
                        Field::UInt(v) => Some(i64::from(*v)),
                        Field::UShort(v) => Some(i64::from(*v)),
                        Field::UByte(v) => Some(i64::from(*v)),
                        _ => None,
                    };
                    let Some(v) = v else {
                        return Err(feature_err(
                            name,
                            format!("{f:?}: not an integer of at most 63 bits"),
                        ));
                    };
                    if name == "episode_index" {
                        episode = Some(v);
                    } else {
                        frame = Some(v);
                    }
                }
                _ => {}
            }
        }
        let (Some(s), Some(e), Some(k)) = (state, episode, frame) else {
            return Err(feature_err(STATE_FEATURE, "a row without a value".into()));
        };
        if frames.entry(e).or_default().insert(k, s).is_some() {
            return Err(feature_err(
                "frame_index",
                format!("episode {e} holds frame {k} twice"),
            ));
        }
    }
    Ok(())
}
