//! Files that leave the program (docs/design.md §4): `.npz` containers, demonstrations (also
//! as LeRobot datasets, CSV and tool paths), gain tables, the MDGPS policy, MCAP logs of recorded runs.

pub mod checkpoint;
pub mod demos;
pub mod episode;
pub mod files;
pub mod foreign;
pub mod lasa;
pub mod learned;
pub mod lerobot;
pub mod log;
pub mod manifest;
pub mod npz;
pub mod policy;
pub mod run_mcap;
pub mod table;
pub mod task_arrays;
pub mod tool_path;

use std::path::{Path, PathBuf};

/// Creates the folder `dir` and its parents (an `--out` folder or one inside it); the error
/// names the folder, whatever the OS says.
pub fn create_dir(dir: impl AsRef<Path>) -> Result<(), IoError> {
    let dir = dir.as_ref();
    std::fs::create_dir_all(dir).map_err(|source| IoError::CreateDir {
        path: dir.to_owned(),
        source,
    })
}

/// What went wrong reading or writing the files of this module; each error names the file.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file system refused an operation on a file or folder (`doing`: "reading",
    /// "creating", "appending to", ...).
    #[error("{doing} {}", path.display())]
    File {
        /// What was being done to the file.
        doing: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// An output folder that cannot be created: check the path and its permissions.
    #[error("cannot create the folder {}: {source}", path.display())]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// A CSV file that cannot be opened, read or written as CSV.
    #[error("{doing} {}", path.display())]
    Csv {
        /// What was being done to the file.
        doing: &'static str,
        /// The file.
        path: PathBuf,
        /// What the CSV reader or writer said.
        source: csv::Error,
    },
    /// A CSV row that is not what the file's columns say.
    #[error("{} row {row}", path.display())]
    CsvRow {
        /// The file.
        path: PathBuf,
        /// Row number (the header is row 1 where it counts).
        row: usize,
        /// What the CSV reader said.
        source: csv::Error,
    },
    /// A JSON file (or one line of a JSON-lines file) that does not parse.
    #[error("{}{}", path.display(), line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Json {
        /// The file.
        path: PathBuf,
        /// The line of a JSON-lines file.
        line: Option<usize>,
        /// What the parser said.
        source: serde_json::Error,
    },
    /// A value that does not serialise to JSON (a bug).
    #[error("serialising to JSON")]
    ToJson(#[from] serde_json::Error),
    /// An `.npz` file (demonstrations, tables, episodes, checkpoints).
    #[error(transparent)]
    Npz(#[from] npz::NpzError),
    /// A LeRobot dataset.
    #[error(transparent)]
    LeRobot(#[from] lerobot::LeRobotError),
    /// A file whose content is not what its format or this build expects; `why` says what.
    #[error("{}: {why}", path.display())]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong and what to do.
        why: String,
    },
    /// A run folder that cannot be taken for a run ([`manifest::ManifestError`]).
    #[error(transparent)]
    Manifest(#[from] manifest::ManifestError),
    /// Demonstrations that do not fit the configured arm ([`demos::DemosError`]).
    #[error(transparent)]
    Demos(#[from] demos::DemosError),
    /// Trajectories at a control period the arm cannot run.
    #[error("time step dt of the trajectories (1 / fps, or the step of the time column): {0}")]
    TrajectoryDt(String),
    /// A task cost a dataset records (`ur5_task.cost_expert`, `cost_random`) that the data
    /// contradict: normalised performance would be computed against it.
    #[error("ur5_task.{field} = {recorded} but {recomputed} recomputed from {of}: the dataset was altered (or made with other settings); delete the field to have it recomputed")]
    TaskCost {
        /// `cost_expert` or `cost_random`.
        field: &'static str,
        /// The value in the file.
        recorded: f64,
        /// The value the data give.
        recomputed: f64,
        /// What it was recomputed from.
        of: &'static str,
    },
    /// Trajectories whose task (goal, start, horizon) is not one the learner takes.
    #[error("the task the trajectories show")]
    TrajectoryTask(#[source] ur5_shared::config::ConfigError),
    /// A file of the run, with the error of its content.
    #[error("{doing} {}", path.display())]
    In {
        /// What was being done with the file ("reading", "loading demonstrations", ...).
        doing: &'static str,
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: Box<IoError>,
    },
    /// Tool paths that cannot become demonstrations of the arm.
    #[error("{}", path.display())]
    ToolPath {
        /// The file.
        path: PathBuf,
        /// Which episode and time, and why.
        source: tool_path::ToolPathError,
    },
    /// The simulated arm the files are checked on.
    #[error(transparent)]
    Sim(#[from] hil_sim::SimError),
    /// The task a file describes.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    /// The task cost of recorded states.
    #[error(transparent)]
    Cost(#[from] ur5_shared::cost::CostError),
    /// A learner piece run on the files (the random policy's cost).
    #[error(transparent)]
    Imitation(#[from] imitation::ImitationError),
    /// A file of other dimensions than the task's (or the run's) layout: names both.
    #[error(transparent)]
    Layout(#[from] ur5_shared::layout::DimensionMismatch),
    /// An MCAP log.
    #[error("writing the MCAP log")]
    Mcap(#[from] mcap::McapError),
}

impl IoError {
    /// The error of `doing` (a verb: "reading") to `path`, for `map_err`.
    pub fn file<'a>(
        doing: &'static str,
        path: &'a Path,
    ) -> impl FnOnce(std::io::Error) -> Self + 'a {
        move |source| Self::File {
            doing,
            path: path.to_owned(),
            source,
        }
    }

    /// The error `self` met `doing` (a verb: "reading") the file `path`.
    pub fn at(self, doing: &'static str, path: &Path) -> Self {
        Self::In {
            doing,
            path: path.to_owned(),
            source: Box::new(self),
        }
    }

    /// The CSV error of `doing` (a verb: "reading") to `path`, for `map_err`.
    pub fn csv<'a>(doing: &'static str, path: &'a Path) -> impl FnOnce(csv::Error) -> Self + 'a {
        move |source| Self::Csv {
            doing,
            path: path.to_owned(),
            source,
        }
    }

    /// `why` about the content of `path`.
    pub fn content(path: &Path, why: impl Into<String>) -> Self {
        Self::Content {
            path: path.to_owned(),
            why: why.into(),
        }
    }
}
