//! Why a run folder cannot be replayed, or what stopped the replay.

use std::path::PathBuf;

use crate::io::manifest;
use crate::io::IoError;
use crate::run::RunError;
use crate::serve::ServeError;

/// Why a run folder cannot be replayed, or what stopped the replay.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// A folder without a run manifest.
    #[error(
        "{} has no {}: not a run folder of `learner train` or `learner serve`",
        dir.display(),
        manifest::MANIFEST
    )]
    NotRun {
        /// The folder.
        dir: PathBuf,
    },
    /// A manifest whose seed and settings disagree.
    #[error(
        "{}: seed {seed} but settings.seed {settings}: the run's manifest was altered (a run \
         has one seed)",
        path.display()
    )]
    SeedAltered {
        /// The manifest.
        path: PathBuf,
        /// Its seed.
        seed: u64,
        /// Its settings' seed.
        settings: String,
    },
    /// A run whose record of files is gone.
    #[error(
        "{} has no {name}, the record of its files that its {} says the run kept: without it a \
         replay cannot tell which files are missing or altered; restore it (or the run)",
        dir.display(),
        manifest::MANIFEST
    )]
    NoRecord {
        /// The folder.
        dir: PathBuf,
        /// The record's file name.
        name: String,
    },
    /// Files missing, altered or unrecorded.
    #[error(
        "{}: {count} of the run's files are not as its record {} says: {shown}; a replay of \
         what is left would check only part of the run: restore the files (or the run)",
        dir.display(),
        crate::io::files::FILES
    )]
    Altered {
        /// The folder.
        dir: PathBuf,
        /// How many files.
        count: usize,
        /// The first of them.
        shown: String,
    },
    /// A run without recorded episodes.
    #[error(
        "{} holds no recorded episodes (episodes/*.npz): a replay needs them; `learner serve` \
         records every episode, `learner train` only with --record-episodes",
        dir.display()
    )]
    NoEpisodes {
        /// The folder.
        dir: PathBuf,
    },
    /// A recorded episode with a NaN or infinite state.
    #[error(
        "{}: step {step}: {name} = {value}: a recorded episode's states must be finite",
        path.display()
    )]
    StateNotFinite {
        /// The episode file.
        path: PathBuf,
        /// Step.
        step: usize,
        /// The state's name.
        name: String,
        /// The value.
        value: f64,
    },
    /// A recorded episode with a NaN or infinite action.
    #[error(
        "{}: action {index} = {value}: a recorded episode's actions must be finite",
        path.display()
    )]
    ActionNotFinite {
        /// The episode file.
        path: PathBuf,
        /// Index in the flat action array.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A served run resumed from another folder.
    #[error(
        "{} continues a run resumed from another folder after {iteration} iterations (`learner \
         serve --resume OTHER --out {}`): the iterations before it, and the learner state it \
         started from, are in that folder, not here, so this folder alone cannot be replayed; \
         resume into the run's own folder (--resume DIR --out DIR) to keep a run replayable",
        dir.display(),
        dir.display()
    )]
    ResumedElsewhere {
        /// The folder.
        dir: PathBuf,
        /// Iterations done before the resume.
        iteration: usize,
    },
    /// A run of a learner the replay does not redo.
    #[error("{}: a replay redoes runs of {}, not {algo}", dir.display(), super::REPLAYED.join(", "))]
    Algorithm {
        /// The folder.
        dir: PathBuf,
        /// The run's learner.
        algo: String,
    },
    /// Recorded checkpoint files the replay did not reach.
    #[error(
        "{}: the replay ended after {iterations} iterations, before {count} recorded checkpoint \
         file(s) of the run ({files}): the episodes it learns from (episodes/, {}) do not carry \
         it that far",
        dir.display(),
        crate::io::learned::LEARNED
    )]
    Unreached {
        /// The folder.
        dir: PathBuf,
        /// Iterations replayed.
        iterations: usize,
        /// Files not reached.
        count: usize,
        /// The first of them.
        files: String,
    },
    /// The run's demonstrations cannot be read where the manifest says.
    #[error(
        "the run's demonstrations {} (pass --demos with their new place)",
        path.display()
    )]
    DemosGone {
        /// The demonstrations' path.
        path: PathBuf,
        /// Why.
        source: IoError,
    },
    /// Other demonstrations than the run's.
    #[error(
        "{} hashes to {hash}, the run's demonstrations to {recorded}: not the run's \
         demonstrations",
        path.display()
    )]
    DemosHash {
        /// The demonstrations given.
        path: PathBuf,
        /// Their hash.
        hash: String,
        /// The run's.
        recorded: String,
    },
    /// `learned.jsonl` that does not fit the recorded episodes.
    #[error("{} lists {why}", list.display())]
    Listed {
        /// `episodes/learned.jsonl`.
        list: PathBuf,
        /// What it lists and why that does not fit.
        why: String,
    },
    /// Rebuilding the learner from its checkpoint where the run was resumed.
    #[error("redoing the resume after iteration {iteration}")]
    Resume {
        /// Iterations done.
        iteration: usize,
        /// Why.
        source: Box<ReplayError>,
    },
    /// An update of the learner.
    #[error("replaying iteration {iteration}")]
    Learn {
        /// The iteration (from 1).
        iteration: usize,
        /// Why.
        source: imitation::ImitationError,
    },
    /// The run's files.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The learner's checkpoint and resume.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The served learner's resume.
    #[error(transparent)]
    Serve(#[from] Box<ServeError>),
    /// Building the learner.
    #[error(transparent)]
    Imitation(#[from] imitation::ImitationError),
}

impl From<crate::io::npz::NpzError> for ReplayError {
    fn from(e: crate::io::npz::NpzError) -> Self {
        Self::Io(e.into())
    }
}
