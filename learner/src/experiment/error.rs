//! What stopped an experiment, or why it could not start.

use crate::io::IoError;

/// What stopped an experiment, or why it could not start.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// Settings out of range or unknown; the message names the setting and what it takes.
    #[error("{0}")]
    Settings(String),
    /// Shard folders that do not make one experiment run; the message says which and what to
    /// do.
    #[error("{0}")]
    Shards(String),
    /// A folder given to merge that is not a shard's.
    #[error(
        "{}: not a shard (run `learner experiment NAME --shard K/N`)",
        path.display()
    )]
    NotShard {
        /// Its `shard.json`.
        path: std::path::PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// An output folder that already holds an experiment's results (merge writes into a new
    /// folder or one without them; it never replaces results it did not write).
    #[error(
        "{} already holds {}: `experiment merge` never replaces results it did not write; \
         merge into a new folder (--out), or delete them",
        dir.display(),
        file.display()
    )]
    Occupied {
        /// The output folder.
        dir: std::path::PathBuf,
        /// The first of its results found.
        file: std::path::PathBuf,
    },
    /// A run over IPC that failed or did not finish; the message names its log.
    #[error("{0}")]
    Ipc(String),
    /// One run of the experiment (a variant, method or arm at a seed).
    #[error("{label}")]
    Job {
        /// The run: "<variant> seed <seed> (<algorithm>)".
        label: String,
        /// Why it failed.
        source: Box<ExperimentError>,
    },
    /// The worker threads.
    #[error("building the worker pool")]
    Pool(#[from] rayon::ThreadPoolBuildError),
    /// Writing an output file (CSV, summary).
    #[error("writing the experiment's outputs")]
    Output(#[from] std::io::Error),
    /// Writing an output CSV.
    #[error("writing the experiment's CSV")]
    Csv(#[from] csv::Error),
    /// Writing a process's config file.
    #[error("writing a config file")]
    Toml(#[from] toml::ser::Error),
    /// The files read and written.
    #[error(transparent)]
    Io(#[from] IoError),
    /// An in-process run.
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    /// A learner piece (settings, the learner).
    #[error(transparent)]
    Imitation(#[from] imitation::ImitationError),
    /// The task or the arm's settings.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    /// A figure.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// The simulated arm.
    #[error(transparent)]
    Sim(#[from] hil_sim::SimError),
    /// A process of the IPC experiment.
    #[error(transparent)]
    Process(#[from] crate::process::ProcessError),
}

impl From<crate::io::npz::NpzError> for ExperimentError {
    fn from(e: crate::io::npz::NpzError) -> Self {
        Self::Io(e.into())
    }
}

impl From<serde_json::Error> for ExperimentError {
    fn from(e: serde_json::Error) -> Self {
        Self::Io(e.into())
    }
}
