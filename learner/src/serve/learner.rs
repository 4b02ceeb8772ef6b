//! What the serve loop needs of a learner besides [`imitation::learn::LinGaussLearn`]: its
//! files (checkpoint, CSV) and progress line, and the table in force.

use std::io::Write;
use std::path::Path;

use imitation::expert::{ExpertLearner, IterationLog};
use imitation::gaifo::{GaifoLog, LqrGaifo};
use imitation::learn::{Learn, LinGaussLearn};
use imitation::rollout::Episode;
use serde::Serialize;
use ur5_shared::GainTable;

use super::{ServeError, ServeOptions};
use crate::arm::SimArm;
use crate::io::checkpoint::{save_checkpoint, ExpertCheckpoint};
use crate::io::episode::{EpisodeOrigin, EpisodeRecorder};
use crate::io::learned::{append_event, LearnedEvent};
use crate::io::log::{open_log, write_csv_row, write_record, EXPERT_CSV_HEADER};
use crate::io::run_mcap::{RunMcap, TableInfo};
use crate::io::table::save_table;
use crate::io::IoError;
use crate::run::Checkpoint;
use crate::run::RunError;

/// A learner `learner serve` runs: [`LinGaussLearn`] (steps 2–6 on the streamed episodes, the
/// controller to publish) plus its files and progress line. Implemented for the expert
/// ([`ExpertLearner`]) and LQR+GAIfO ([`LqrGaifo`]); [`Checkpoint`] writes what `--resume`
/// needs.
pub trait ServeLearner: LinGaussLearn<Log: Serialize> + Checkpoint {
    /// Where the task comes from (for messages).
    const TASK_SOURCE: &'static str;
    /// Header of [`ServeLearner::progress_line`].
    const PROGRESS_HEADER: &'static str;
    /// Opens the per-iteration CSV in `out` for appending (`resumed`: a resumed run).
    fn open_csv(&self, out: &Path, resumed: bool) -> Result<std::fs::File, ServeError>;
    /// One CSV row, newline included.
    fn csv_row(&self, log: &Self::Log) -> Result<String, ServeError>;
    /// The progress line of an iteration.
    fn progress_line(log: &Self::Log) -> String;
    /// Iterations the settings ask for in all (the progress bar's length).
    fn planned_iterations(&self) -> usize;
}

/// The expert's checkpoint of a served run: `checkpoint.npz` (controller, iteration,
/// random-policy cost, best controller and patience count), read by
/// [`super::expert_from_checkpoint`].
impl Checkpoint for ExpertLearner {
    fn checkpoint(&self, dir: &Path, _arm: Option<&SimArm>) -> Result<(), RunError> {
        let c = ExpertCheckpoint {
            pol: self.policy().clone(),
            iteration: self.iteration(),
            cost_random: self.cost_random(),
            best: self.best().map(|(p, e)| (p.clone(), e.clone())),
            since_best: self.since_best(),
        };
        Ok(save_checkpoint(
            &dir.join("checkpoint.npz"),
            &c,
            self.config().seed,
        )?)
    }
}

impl ServeLearner for ExpertLearner {
    const TASK_SOURCE: &'static str = "this learner's config ([task])";
    const PROGRESS_HEADER: &'static str = IterationLog::PROGRESS_HEADER;
    fn open_csv(&self, out: &Path, _resumed: bool) -> Result<std::fs::File, ServeError> {
        let path = out.join("serve_log.csv");
        let new_csv = !path.exists();
        let mut csv = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(IoError::file("opening", &path))?;
        if new_csv {
            writeln!(csv, "{EXPERT_CSV_HEADER}").map_err(IoError::file("writing", &path))?;
        }
        Ok(csv)
    }
    fn csv_row(&self, log: &IterationLog) -> Result<String, ServeError> {
        let mut row = Vec::new();
        write_record(&mut row, log).map_err(ServeError::Row)?;
        Ok(String::from_utf8_lossy(&row).into_owned())
    }
    fn progress_line(log: &IterationLog) -> String {
        log.progress_line()
    }
    fn planned_iterations(&self) -> usize {
        self.config().iterations
    }
}

impl ServeLearner for LqrGaifo {
    const TASK_SOURCE: &'static str = "the demonstrations";
    const PROGRESS_HEADER: &'static str = GaifoLog::PROGRESS_HEADER;
    fn open_csv(&self, out: &Path, resumed: bool) -> Result<std::fs::File, ServeError> {
        Ok(open_log(
            &out.join("gaifo_log.csv"),
            resumed.then_some(self.iteration()),
        )?)
    }
    fn csv_row(&self, log: &GaifoLog) -> Result<String, ServeError> {
        let mut row = Vec::new();
        write_csv_row(&mut row, log, self.seed(), Self::ALGO).map_err(ServeError::Row)?;
        Ok(String::from_utf8_lossy(&row).into_owned())
    }
    fn progress_line(log: &GaifoLog) -> String {
        log.progress_line()
    }
    fn planned_iterations(&self) -> usize {
        self.config().iterations
    }
}

/// The learner's side of the run: files and the table in force.
pub(super) struct Run<L> {
    pub(super) learner: L,
    pub(super) opts: ServeOptions,
    pub(super) csv: std::fs::File,
    /// `None` when `record_episodes` is off.
    pub(super) recorder: Option<EpisodeRecorder>,
    /// The publication of the current version ([`GainTable::epoch`]): 0, or for the version a
    /// resumed learner starts with, one more than the one recorded (docs/design.md §3.6).
    pub(super) epoch: u32,
    /// `run.mcap` as the run goes (`--mcap`).
    pub(super) mcap: Option<RunMcap>,
}

impl<L: ServeLearner> Run<L> {
    /// Saves the checkpoint and the table of the controller to execute next; returns the table.
    pub(super) fn save_current(&mut self) -> Result<Box<GainTable>, ServeError> {
        let out = &self.opts.out;
        let version = self.learner.version();
        let mut table = self.learner.table();
        table.epoch = self.epoch;
        self.learner.checkpoint(out, None)?;
        let dt = self.learner.task().dt;
        let file = crate::io::table::version_path(out, version);
        save_table(&file, &table, dt)?;
        crate::io::files::note_checkpoint(out, self.learner.iteration())?;
        crate::io::files::note(out, &[&file])?;
        save_table(&out.join("latest_table.npz"), &table, dt)?;
        if let Some(m) = self.mcap.as_mut() {
            m.table(TableInfo {
                version,
                epoch: table.epoch,
                checksum: table.checksum,
                horizon: self.learner.task().horizon as u64,
                file,
            });
        }
        Ok(table)
    }

    /// Records `ep` when `record_episodes` is on; returns its file name in `episodes/`.
    pub(super) fn record(
        &mut self,
        ep: &Episode,
        episode: u64,
        version: u64,
        epoch: u32,
    ) -> Result<Option<String>, ServeError> {
        let Some(rec) = self.recorder.as_mut() else {
            return Ok(None);
        };
        let origin = EpisodeOrigin {
            table_version: version,
            table_epoch: epoch,
            episode,
            seed: self.learner.seed(),
        };
        let path = rec.record(ep, &origin, self.learner.task())?;
        crate::io::files::note(&self.opts.out, &[&path])?;
        if let Some(m) = self.mcap.as_mut() {
            m.episode(&path, ep, &origin, self.learner.task().dt)?;
        }
        Ok(Some(crate::io::learned::file_name(&path)))
    }

    /// Appends `event` to `episodes/learned.jsonl` ([`crate::io::learned`]) when episodes are
    /// recorded (without them there is nothing to replay).
    pub(super) fn note(&self, event: &LearnedEvent) -> Result<(), ServeError> {
        if self.recorder.is_none() {
            return Ok(());
        }
        let episodes = self.opts.out.join("episodes");
        let list = episodes.join(crate::io::learned::LEARNED);
        let from = crate::io::files::len(&list);
        append_event(&episodes, event)?;
        Ok(crate::io::files::note_appended(
            &self.opts.out,
            &list,
            from,
        )?)
    }
}
