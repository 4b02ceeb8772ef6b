//! What the serve loop needs of a learner besides [`imitation::learn::LinGaussLearn`]: its
//! files (checkpoint, CSV) and progress line, and the table in force.

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use imitation::expert::{ExpertLearner, IterationLog};
use imitation::gaifo::{GaifoLog, LqrGaifo};
use imitation::learn::{Learn, LinGaussLearn};
use imitation::rollout::Episode;
use serde::Serialize;
use ur5_shared::GainTable;

use super::ServeOptions;
use crate::io::checkpoint::save_checkpoint;
use crate::io::episode::{save_episode, EpisodeOrigin};
use crate::io::log::{open_log, write_csv_row, write_record, EXPERT_CSV_HEADER};
use crate::io::table::save_table;
use crate::run::Checkpoint;

/// A learner `learner serve` runs: [`LinGaussLearn`] (steps 2–6 on the streamed episodes, the
/// controller to publish) plus its files and progress line. Implemented for the expert
/// ([`ExpertLearner`]) and LQR+GAIfO ([`LqrGaifo`]).
pub trait ServeLearner: LinGaussLearn<Log: Serialize> {
    /// Where the task comes from (for messages).
    const TASK_SOURCE: &'static str;
    /// Header of [`ServeLearner::progress_line`].
    const PROGRESS_HEADER: &'static str;
    /// Writes what `--resume` needs into `out`.
    fn checkpoint(&self, out: &Path) -> anyhow::Result<()>;
    /// Opens the per-iteration CSV in `out` for appending (`resumed`: a resumed run).
    fn open_csv(&self, out: &Path, resumed: bool) -> anyhow::Result<std::fs::File>;
    /// One CSV row, newline included.
    fn csv_row(&self, log: &Self::Log) -> anyhow::Result<String>;
    /// The progress line of an iteration.
    fn progress_line(log: &Self::Log) -> String;
}

impl ServeLearner for ExpertLearner {
    const TASK_SOURCE: &'static str = "this learner's config ([task])";
    const PROGRESS_HEADER: &'static str = IterationLog::PROGRESS_HEADER;
    fn checkpoint(&self, out: &Path) -> anyhow::Result<()> {
        save_checkpoint(
            &out.join("checkpoint.npz"),
            self.policy(),
            self.iteration(),
            self.cost_random(),
            self.config().seed,
        )
    }
    fn open_csv(&self, out: &Path, _resumed: bool) -> anyhow::Result<std::fs::File> {
        let path = out.join("serve_log.csv");
        let new_csv = !path.exists();
        let mut csv = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        if new_csv {
            writeln!(csv, "{EXPERT_CSV_HEADER}")?;
        }
        Ok(csv)
    }
    fn csv_row(&self, log: &IterationLog) -> anyhow::Result<String> {
        let mut row = Vec::new();
        write_record(&mut row, log)?;
        Ok(String::from_utf8(row)?)
    }
    fn progress_line(log: &IterationLog) -> String {
        log.progress_line()
    }
}

impl ServeLearner for LqrGaifo {
    const TASK_SOURCE: &'static str = "the demonstrations";
    const PROGRESS_HEADER: &'static str = GaifoLog::PROGRESS_HEADER;
    fn checkpoint(&self, out: &Path) -> anyhow::Result<()> {
        Checkpoint::checkpoint(self, out, None).map(|_| ())
    }
    fn open_csv(&self, out: &Path, resumed: bool) -> anyhow::Result<std::fs::File> {
        open_log(
            &out.join("gaifo_log.csv"),
            resumed.then_some(self.iteration()),
        )
    }
    fn csv_row(&self, log: &GaifoLog) -> anyhow::Result<String> {
        let mut row = Vec::new();
        write_csv_row(&mut row, log, self.seed(), Self::ALGO)?;
        Ok(String::from_utf8(row)?)
    }
    fn progress_line(log: &GaifoLog) -> String {
        log.progress_line()
    }
}

/// The learner's side of the run: files and the table in force.
pub(super) struct Run<L> {
    pub(super) learner: L,
    pub(super) opts: ServeOptions,
    pub(super) csv: std::fs::File,
    /// Episodes recorded in the folder so far, by any run of the learner: the numbering goes
    /// on across restarts, so a restarted learner never overwrites a recorded episode (the
    /// controller's episode numbers start again at 0 when it restarts).
    pub(super) arrivals: u64,
}

/// The highest arrival number `NNNNNN` of the episode files `NNNNNN_e…_v….npz` in `dir` (0 if
/// none).
pub(super) fn last_arrival(dir: &Path) -> u64 {
    std::fs::read_dir(dir).map_or(0, |entries| {
        entries
            .flatten()
            .filter_map(|e| {
                let name = e.file_name();
                let name = name.to_str()?;
                name.ends_with(".npz").then_some(())?;
                name.split_once('_')?.0.parse::<u64>().ok()
            })
            .max()
            .unwrap_or(0)
    })
}

impl<L: ServeLearner> Run<L> {
    /// Saves the checkpoint and the table of the controller to execute next; returns the table.
    pub(super) fn save_current(&self) -> anyhow::Result<Box<GainTable>> {
        let out = &self.opts.out;
        let version = self.learner.version();
        let table = self.learner.table();
        self.learner.checkpoint(out)?;
        let dt = self.learner.task().dt;
        save_table(
            &out.join("tables").join(format!("v{version:04}.npz")),
            &table,
            dt,
        )?;
        save_table(&out.join("latest_table.npz"), &table, dt)?;
        Ok(table)
    }

    pub(super) fn record(
        &mut self,
        ep: &Episode,
        episode: u64,
        version: u64,
    ) -> anyhow::Result<()> {
        self.arrivals += 1;
        if !self.opts.record_episodes {
            return Ok(());
        }
        let name = format!("{:06}_e{episode:06}_v{version:04}.npz", self.arrivals);
        let origin = EpisodeOrigin {
            table_version: version,
            episode,
            seed: self.learner.seed(),
        };
        save_episode(
            &self.opts.out.join("episodes").join(name),
            ep,
            &origin,
            self.learner.task(),
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::last_arrival;

    #[test]
    fn a_restarted_learner_numbers_on_from_the_recorded_episodes() {
        let dir = std::env::temp_dir().join(format!("ur5-last-arrival-{}", std::process::id()));
        assert_eq!(last_arrival(&dir), 0, "no folder yet");
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(last_arrival(&dir), 0, "empty folder");
        // The controller restarted: episode 0 of version 1 again, under a later arrival.
        for name in [
            "000001_e000000_v0001.npz",
            "000012_e000000_v0001.npz",
            "000007_e000004_v0002.npz",
            "000099_e000000_v0003.npz.tmp",
            "notes.txt",
        ] {
            std::fs::write(dir.join(name), b"").unwrap();
        }
        assert_eq!(last_arrival(&dir), 12);
        std::fs::remove_dir_all(&dir).ok();
    }
}
