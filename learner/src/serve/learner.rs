//! What the serve loop needs of a learner besides [`imitation::learn::Learn`]: the tables it
//! publishes per version (its publications), its files (checkpoint, CSV) and progress line.

use std::io::Write;
use std::path::Path;

use gps::policy::lin_gauss::LinGaussPolicy;
use imitation::expert::{ExpertLearner, IterationLog};
use imitation::gaifo::{GaifoLog, LqrGaifo};
use imitation::learn::{Learn, LinGaussLearn};
use imitation::mdgps::{Mdgps, MdgpsLog};
use imitation::rollout::Episode;
use serde::Serialize;

use super::ports::AnyTable;
use super::{ServeError, ServeOptions};
use crate::arm::SimArm;
use crate::io::checkpoint::{save_checkpoint, ExpertCheckpoint};
use crate::io::episode::{EpisodeOrigin, EpisodeRecorder};
use crate::io::learned::{append_event, LearnedEvent};
use crate::io::log::{open_log_with, write_record, LogRow, EXPERT_CSV_HEADER};
use crate::io::run_mcap::{RunMcap, TableInfo};
use crate::io::table::{save_policy_table, save_table};
use crate::io::IoError;
use crate::run::Checkpoint;
use crate::run::RunError;

/// One table of a version and the episodes the learner collects from it (docs/design.md §3.6):
/// a learner with one goal publishes one per version (its gain table: N noisy episodes and the
/// noise-free one); MDGPS 2M, goal after goal (goal m's gain table with its plan: N noisy
/// episodes; then the policy table at goal m: its evaluation).
#[derive(Clone, Debug)]
pub struct Publication {
    /// The table, with its version and epoch.
    pub table: AnyTable,
    /// Its goal: an index into [`Learn::goal_tasks`].
    pub goal: usize,
    /// Noisy episodes it gives the batch.
    pub noisy: usize,
    /// It gives the batch a noise-free episode (goal `goal`'s evaluation).
    pub eval: bool,
    /// Seed of its noisy episodes' noise: episode k draws `Noise::new(noise_seed, version, k)`.
    pub noise_seed: u64,
}

impl Publication {
    /// Its gain table (the noisy episodes' controller), if it is one.
    pub fn gain_table(&self) -> Option<&ur5_shared::GainTable> {
        match &self.table {
            AnyTable::Gain(t) => Some(t),
            AnyTable::Policy(_) => None,
        }
    }
}

/// The one publication per version of a learner with one goal and a linear-Gaussian
/// controller: its gain table at `epoch`, N noisy episodes and the noise-free one.
pub(super) fn single<L: LinGaussLearn>(learner: &L, epoch: u32) -> Vec<Publication> {
    let mut table = learner.table();
    table.epoch = epoch;
    vec![Publication {
        table: AnyTable::Gain(table),
        goal: 0,
        noisy: learner.samples(),
        eval: true,
        noise_seed: learner.seed(),
    }]
}

/// A learner `learner serve` runs: [`Learn`] (steps 2–6 on the streamed episodes) plus the
/// tables it publishes per version, its files and progress line. Implemented for the expert
/// ([`ExpertLearner`]), LQR+GAIfO ([`LqrGaifo`]) and MDGPS ([`Mdgps`]); [`Checkpoint`] writes
/// what `--resume` needs.
pub trait ServeLearner: Learn<Log: Serialize> + Checkpoint {
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
    /// The publications of version [`Learn::version`], in order, at epochs `epoch`,
    /// `epoch + 1`, …
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError>;
    /// The linear-Gaussian controller executed next, for `best_table.npz` (`None`: MDGPS,
    /// whose policy is in its checkpoints).
    fn served_policy(&self) -> Option<&LinGaussPolicy>;
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
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError> {
        Ok(single(self, epoch))
    }
    fn served_policy(&self) -> Option<&LinGaussPolicy> {
        Some(self.policy())
    }
}

/// [`ServeLearner::open_csv`] of a learner whose log is a [`LogRow`]: the CSV `learner train`
/// writes (`gaifo_log.csv`, `mdgps_log.csv`), for appending.
pub(super) fn open_log_row<L: Learn<Log: LogRow>>(
    learner: &L,
    out: &Path,
    resumed: bool,
) -> Result<std::fs::File, ServeError> {
    Ok(open_log_with(
        &out.join(L::Log::FILE),
        &L::Log::header(&learner.task().layout()),
        resumed.then_some(learner.iteration()),
    )?)
}

/// [`ServeLearner::csv_row`] of a learner whose log is a [`LogRow`].
pub(super) fn log_row<L: Learn<Log: LogRow>>(
    learner: &L,
    log: &L::Log,
) -> Result<String, ServeError> {
    let mut row = Vec::new();
    log.write_row(&mut row, learner.seed(), L::ALGO, &learner.task().layout())
        .map_err(ServeError::Row)?;
    Ok(String::from_utf8_lossy(&row).into_owned())
}

/// [`ServeLearner`]'s files and lines of a learner whose log is [`GaifoLog`] (`gaifo_log.csv`,
/// as `learner train` writes it).
macro_rules! gaifo_log_files {
    () => {
        const TASK_SOURCE: &'static str = "the demonstrations";
        const PROGRESS_HEADER: &'static str = GaifoLog::PROGRESS_HEADER;
        fn open_csv(&self, out: &Path, resumed: bool) -> Result<std::fs::File, ServeError> {
            open_log_row(self, out, resumed)
        }
        fn csv_row(&self, log: &GaifoLog) -> Result<String, ServeError> {
            log_row(self, log)
        }
        fn progress_line(log: &GaifoLog) -> String {
            log.progress_line()
        }
        fn planned_iterations(&self) -> usize {
            self.config().iterations
        }
    };
}

impl ServeLearner for LqrGaifo {
    gaifo_log_files!();
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError> {
        Ok(single(self, epoch))
    }
    fn served_policy(&self) -> Option<&LinGaussPolicy> {
        Some(self.policy())
    }
}

/// MDGPS over IPC: per version, goal after goal, the goal's gain table ([`Mdgps::gain_table`]:
/// its goal and noise stream in the plan) for its N noisy episodes, then the global policy at
/// the goal ([`Mdgps::eval_table`]) for its evaluation; the files of `learner train --algo
/// mdgps` (`mdgps_log.csv`, the checkpoints).
impl ServeLearner for Mdgps {
    const TASK_SOURCE: &'static str = "the demonstrations";
    const PROGRESS_HEADER: &'static str = "";
    fn open_csv(&self, out: &Path, resumed: bool) -> Result<std::fs::File, ServeError> {
        open_log_row(self, out, resumed)
    }
    fn csv_row(&self, log: &MdgpsLog) -> Result<String, ServeError> {
        log_row(self, log)
    }
    fn progress_line(log: &MdgpsLog) -> String {
        log.progress_line()
    }
    fn planned_iterations(&self) -> usize {
        self.config().lqr_gaifo.iterations
    }
    fn publications(&self, epoch: u32) -> Result<Vec<Publication>, ServeError> {
        let (n, mut e) = (self.samples(), epoch);
        let mut next = || {
            let at = e;
            e = e.checked_add(1).ok_or_else(|| {
                ServeError::Range(format!("publication epoch beyond {}", u32::MAX))
            })?;
            Ok::<u32, ServeError>(at)
        };
        let mut out = Vec::with_capacity(2 * self.conditions());
        for m in 0..self.conditions() {
            out.push(Publication {
                table: AnyTable::Gain(self.gain_table(m, next()?)),
                goal: m,
                noisy: n,
                eval: false,
                noise_seed: self.noise_seed(m),
            });
            out.push(Publication {
                table: AnyTable::Policy(self.eval_table(m, next()?)?),
                goal: m,
                noisy: 0,
                eval: true,
                noise_seed: self.noise_seed(m),
            });
        }
        Ok(out)
    }
    fn served_policy(&self) -> Option<&LinGaussPolicy> {
        None
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
    /// Saves the checkpoint and the version's first publication's gain table (its epoch is
    /// what a resume publishes above, docs/design.md §3.6); returns the version's
    /// publications from epoch [`Run::epoch`] on.
    pub(super) fn save_current(&mut self) -> Result<Vec<Publication>, ServeError> {
        let out = &self.opts.out;
        let version = self.learner.version();
        let publications = self.learner.publications(self.epoch)?;
        let first = publications
            .first()
            .ok_or_else(|| ServeError::Range("a version without publications (a bug)".into()))?;
        self.learner.checkpoint(out, None)?;
        let dt = self.learner.task().dt;
        let file = crate::io::table::version_path(out, version);
        // The first publication as recorded: a gain table, or a policy learner's policy table.
        let save = |path: &Path| match &first.table {
            AnyTable::Gain(t) => save_table(path, t, dt),
            AnyTable::Policy(t) => save_policy_table(path, t, dt),
        };
        save(&file)?;
        crate::io::files::note_checkpoint(out, self.learner.iteration())?;
        crate::io::files::note(out, &[&file])?;
        save(&out.join("latest_table.npz"))?;
        if let Some(m) = self.mcap.as_mut() {
            let (_, epoch) = first.table.publication();
            let checksum = match &first.table {
                AnyTable::Gain(t) => t.checksum,
                AnyTable::Policy(t) => t.checksum,
            };
            m.table(TableInfo {
                version,
                epoch,
                checksum,
                horizon: self.learner.task().horizon as u64,
                file,
            });
        }
        Ok(publications)
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
            m.episode(&path, ep, &origin, self.learner.task())?;
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
