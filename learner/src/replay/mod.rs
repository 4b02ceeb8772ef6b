//! `learner replay RUN_DIR`: the learning of a recorded run done again from its recorded
//! episodes, every recorded checkpoint checked bit for bit against the replayed one
//! (docs/design.md §4.13).
//!
//! The learner is rebuilt from the run's `run.json` (algorithm, seed, the settings in full, the
//! demonstrations' path and hash; [`crate::io::manifest`]) exactly as the run built it, and
//! driven through the same [`imitation::learn::Learn::learn`] the serve loop and
//! [`imitation::learn::iterate`] call. Which episodes each update learns from:
//! - a served run (`learner serve`) lists them in `episodes/learned.jsonl`
//!   ([`crate::io::learned`]): the replay takes the files listed for each table version (the
//!   last list of a version), and where the list says a learner was resumed (`--resume`) the
//!   replay resumes too, through the same code: the learner's checkpoint written to a scratch
//!   folder and read back as `learner serve --resume` reads it (the expert restarts its GPS
//!   state there, LQR+GAIfO restores its whole state);
//! - otherwise (`learner train --record-episodes`, served runs of builds before 2026-12-02),
//!   for each table version v in arrival order (`episodes/NNNNNN_eEPISODE_vVERSION.npz`), the
//!   first N noisy and the first noise-free episode of v ([`Batch`], as `learner serve`
//!   picks them). An in-process run executes exactly these (a resumed one executes the same
//!   bits again); a served run without the list that was resumed learned from later episodes,
//!   so its replay differs from the resume on, and the report says why.
//!
//! Compared before each update and after the last: gain-table learners (expert, LQR+GAIfO) the
//! table of version v entry by entry against every recorded copy (`iter_NNN_table.npz`, NNN =
//! v − 1, and `tables/vVERSION.npz`); LQR+GAIfO also `iter_NNN_critic.json`, byte for byte;
//! GAIfO (PPO) (`learner train --algo gaifo-ppo --record-episodes`) its policy nets
//! `iter_NNN_policy.json` and critic `iter_NNN_critic.json`, byte for byte (the replayed ones
//! written by the same [`Checkpoint`] code; JSON numbers are shortest round-trip decimals, so
//! equal bytes are equal bits); GAIfO (TD3) (`learner train --algo gaifo-td3
//! --record-episodes`) its critic `iter_NNN_critic.json` byte for byte and its learner state
//! `iter_NNN_state.npz` (nets, optimisers, RNG, replay buffer) bit for bit. The first difference
//! ends the replay.
//!
//! Every random draw of the learners (critic minibatches, gradient-penalty points, GMM
//! initialisation, PPO's minibatch order) comes from RNGs seeded by the run seed and advanced
//! only by the learning itself, so the same settings, demonstrations and episodes give the
//! same bits. What a replay cannot redo, and says so: a served run resumed from another folder
//! (`--resume OTHER --out THIS`: the iterations before the resume are in OTHER).

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use imitation::expert::{ExpertConfig, ExpertLearner};
use imitation::gaifo::{GaifoConfig, LqrGaifo};
use imitation::learn::Learn;
use imitation::mdgps::{Mdgps, MdgpsConfig};
use imitation::offpolicy::{GaifoTd3, GaifoTd3Config};
use imitation::ppo::gaifo_ppo::{GaifoPpo, GaifoPpoConfig};
use imitation::rollout::Episode;
use serde::Serialize;

mod error;

pub use error::ReplayError;

mod check;

use check::{checkpoint_files, gain_tables, state_file, tables};

use crate::error::ensure;
use crate::io::episode::{recorded_episodes, EpisodeOrigin};
use crate::io::learned::{read_events, LearnedEvent};
use crate::io::manifest::{self, Manifest};
use crate::run::Checkpoint;
use crate::serve::Batch;

/// The learners whose runs a replay redoes.
pub(crate) const REPLAYED: [&str; 7] = [
    "lqr-gaifo",
    "expert",
    "gaifo-ppo",
    "mdgps",
    "gaifo-td3",
    "bco",
    "replay-mean",
];

/// The first place where the replay and the recorded run differ.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Difference {
    /// The iteration (1-based) whose update produced the table; 0 for the initial table.
    pub iteration: usize,
    /// The table version.
    pub version: u64,
    /// The recorded file.
    pub file: PathBuf,
    /// The array (`K`, `k`, `s_hat`, `a_hat`, `L`, `version`, `checksum`), or `critic` or
    /// `policy` for a JSON file.
    pub array: String,
    /// The entry's index in the array (t, row, column as the array has them; the byte
    /// offset for a JSON file); empty for a scalar.
    pub index: Vec<u64>,
    /// The recorded value (f64: shortest round-trip decimal and its bits in hex; JSON: the
    /// text around the offset).
    pub recorded: String,
    /// The replayed value.
    pub replayed: String,
    /// The episode files the update learned from (empty for the initial table).
    pub episodes: Vec<PathBuf>,
}

/// What a replay did (`--json`).
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    /// Always "replay".
    pub command: &'static str,
    /// The run folder.
    pub run: PathBuf,
    /// `learner train` or `learner serve`, as `run.json` says.
    pub run_command: String,
    /// `lqr-gaifo`, `expert` or `gaifo-ppo`.
    pub algorithm: String,
    /// The run seed.
    pub seed: u64,
    /// Updates done again.
    pub iterations: usize,
    /// Recorded table files compared (all equal unless `difference`).
    pub tables_checked: usize,
    /// Recorded critic checkpoints compared.
    pub critics_checked: usize,
    /// Recorded policy checkpoints compared: GAIfO (PPO)'s policy files, MDGPS's learner states
    /// (its policy, S-step and every goal's LQR state, entry by entry).
    pub policies_checked: usize,
    /// Recorded episodes found.
    pub episodes: usize,
    /// Episodes learned from.
    pub episodes_used: usize,
    /// How the episodes of each update were picked: `learned.jsonl` (the served run's own
    /// list) or `arrival order` (module docs).
    pub selection: &'static str,
    /// Resumes of the recorded run redone.
    pub resumes: usize,
    /// Why a difference may be expected where the recorded data does not allow an exact
    /// replay (a served run without `learned.jsonl`).
    pub note: Option<String>,
    /// The first difference (`None`: the replay equals the run bit for bit).
    pub difference: Option<Difference>,
    /// Files of the run's record (`files.jsonl`, [`crate::io::files`]) found complete and
    /// unaltered before the replay; `None` for a run of a build without that record (then a
    /// missing or altered file cannot be told, and only what is there is compared).
    pub files_verified: Option<usize>,
    /// The recorded files compared (tables, critics, policies).
    #[serde(skip)]
    pub compared: BTreeSet<PathBuf>,
}

impl ReplayReport {
    /// Recorded files compared in all.
    pub fn files_checked(&self) -> usize {
        self.tables_checked + self.critics_checked + self.policies_checked
    }
}

/// Replays the run in `dir` (module docs). `demos` replaces the demonstrations' path recorded
/// in `run.json` (their hash must still be the run's).
pub fn replay(dir: &Path, demos: Option<&Path>) -> Result<ReplayReport, ReplayError> {
    let m = manifest::read(dir)?.ok_or_else(|| ReplayError::NotRun {
        dir: dir.to_owned(),
    })?;
    if let Some(s) = m.settings.as_ref().and_then(|s| s.get("seed")) {
        ensure!(
            s.as_u64() == Some(m.seed),
            ReplayError::SeedAltered {
                path: dir.join(manifest::MANIFEST),
                seed: m.seed,
                settings: s.to_string()
            }
        );
    }
    let record = crate::io::files::verify(dir)?;
    match (&record, &m.files) {
        (None, Some(name)) => {
            return Err(ReplayError::NoRecord {
                dir: dir.to_owned(),
                name: name.clone(),
            })
        }
        (Some(v), _) if !v.problems.is_empty() => {
            let shown: Vec<String> = v.problems.iter().take(4).map(|p| p.to_string()).collect();
            let more = v.problems.len() - shown.len();
            return Err(ReplayError::Altered {
                dir: dir.to_owned(),
                count: v.problems.len(),
                shown: shown.join(", ")
                    + &if more > 0 {
                        format!(" and {more} more")
                    } else {
                        String::new()
                    },
            });
        }
        _ => {}
    }
    let folder = dir.join("episodes");
    let episodes = recorded_episodes(&folder)?;
    ensure!(
        !episodes.is_empty(),
        ReplayError::NoEpisodes {
            dir: dir.to_owned()
        }
    );
    // A non-finite value would surface deep in the dynamics fit (a covariance that is not
    // positive definite); name the file, step and state instead.
    for (path, ep, _) in &episodes {
        let dx = ep.dx();
        if let Some(k) = ep.x.iter().position(|v| !v.is_finite()) {
            return Err(ReplayError::StateNotFinite {
                path: path.clone(),
                step: k / dx,
                name: ep.layout.state_name(k % dx),
                value: ep.x[k],
            });
        }
        if let Some(k) = ep.u.iter().position(|v| !v.is_finite()) {
            return Err(ReplayError::ActionNotFinite {
                path: path.clone(),
                index: k,
                value: ep.u[k],
            });
        }
    }
    let events = read_events(&folder)?;
    if let Some(LearnedEvent::Resumed { iteration, .. }) = events.iter().flatten().find(|e| {
        matches!(
            e,
            LearnedEvent::Resumed {
                same_folder: false,
                ..
            }
        )
    }) {
        return Err(ReplayError::ResumedElsewhere {
            dir: dir.to_owned(),
            iteration: *iteration,
        });
    }
    let mut report = ReplayReport {
        command: "replay",
        run: dir.to_owned(),
        run_command: m.command.clone(),
        algorithm: m.algo.clone(),
        seed: m.seed,
        iterations: 0,
        tables_checked: 0,
        critics_checked: 0,
        policies_checked: 0,
        episodes: episodes.len(),
        episodes_used: 0,
        selection: if events.is_some() {
            "learned.jsonl"
        } else {
            "arrival order"
        },
        resumes: 0,
        note: (events.is_none() && m.command == "serve").then(|| {
            "this served run has no episodes/learned.jsonl (a build before 2026-12-02): the \
             replay takes the first episodes of each version; if the run was resumed \
             (--resume), its learner learned after the resume from later episodes, and the \
             replay differs from there on"
                .to_string()
        }),
        difference: None,
        files_verified: record.as_ref().map(|v| v.files.len()),
        compared: BTreeSet::new(),
    };
    if record.is_none() {
        let old = format!(
            "this run has no {} (a build before 2026-12-03): a missing or altered file cannot \
             be told, so only the files found are compared",
            crate::io::files::FILES
        );
        report.note = Some(match report.note.take() {
            Some(n) => format!("{n}; {old}"),
            None => old,
        });
    }
    let picks = Picks::new(&folder, &episodes, events.as_deref());
    match m.algo.as_str() {
        "lqr-gaifo" => {
            let cfg: GaifoConfig = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_checked(&path, &cfg.sim)?;
            let learner = LqrGaifo::new(cfg.clone(), d.clone())?;
            let resume = |tmp: &Path| Ok(crate::run::resume(cfg.clone(), d.clone(), tmp)?.0);
            drive(
                learner,
                dir,
                &picks,
                &mut report,
                Some(&resume),
                |l, dir, i, r| {
                    match tables(l, dir, i, r)? {
                        // A table without its critic file (a kill between the two) is compared
                        // alone.
                        Checked::Equal => match checkpoint_files(l, dir, i, &["critic.json"], r)? {
                            Checked::NothingRecorded => Ok(Checked::Equal),
                            other => Ok(other),
                        },
                        other => Ok(other),
                    }
                },
            )?;
        }
        "expert" => {
            let cfg: ExpertConfig = m.settings_as()?;
            let resume = |tmp: &Path| {
                crate::serve::expert_from_checkpoint(cfg.clone(), tmp)
                    .map_err(|e| ReplayError::from(Box::new(e)))
            };
            let learner = ExpertLearner::new(cfg.clone(), None);
            drive(learner, dir, &picks, &mut report, Some(&resume), tables)?;
        }
        "gaifo-ppo" => {
            let cfg: GaifoPpoConfig = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_checked(&path, &cfg.sim)?;
            // Never resumed (`learner train --algo gaifo-ppo` has no --resume).
            drive(
                GaifoPpo::new(cfg, d)?,
                dir,
                &picks,
                &mut report,
                None,
                |l, dir, i, r| checkpoint_files(l, dir, i, &["policy.json", "critic.json"], r),
            )?;
        }
        "gaifo-td3" => {
            let cfg: GaifoTd3Config = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_checked(&path, &cfg.sim)?;
            let resume = |tmp: &Path| Ok(crate::run::resume_td3(cfg.clone(), d.clone(), tmp)?.0);
            drive(
                GaifoTd3::new(cfg.clone(), d.clone())?,
                dir,
                &picks,
                &mut report,
                Some(&resume),
                |l, dir, i, r| match checkpoint_files(l, dir, i, &["critic.json"], r)? {
                    Checked::Equal => state_file(&l.snapshot(), dir, i, r),
                    other => Ok(other),
                },
            )?;
        }
        "mdgps" => {
            let cfg: MdgpsConfig = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_goals(&path, &cfg.lqr_gaifo.sim)?;
            // Where a served run was resumed the replay resumes as `learner serve --resume` did
            // (an in-process run's list has no resume: exact resume changes no bit).
            let resume = |tmp: &Path| Ok(crate::run::resume_mdgps(cfg.clone(), d.clone(), tmp)?.0);
            drive(
                Mdgps::new(cfg.clone(), d.clone())?,
                dir,
                &picks,
                &mut report,
                Some(&resume),
                |l, dir, i, r| {
                    let state = match checkpoint_files(l, dir, i, &["critic.json"], r)? {
                        Checked::Equal => state_file(&l.snapshot(), dir, i, r)?,
                        other => return Ok(other),
                    };
                    // A served run's `tables/vVERSION.npz`: the version's first publication,
                    // goal 0's gain table (its epoch is not in its checksum).
                    Ok(
                        match (state, gain_tables(&l.gain_table(0, 0), dir, i, r)?) {
                            (Checked::Differs(d), _) | (_, Checked::Differs(d)) => {
                                Checked::Differs(d)
                            }
                            (Checked::NothingRecorded, Checked::NothingRecorded) => {
                                Checked::NothingRecorded
                            }
                            _ => Checked::Equal,
                        },
                    )
                },
            )?;
        }
        "bco" => {
            let cfg: imitation::bco::BcoConfig = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_checked(&path, &cfg.sim)?;
            let resume =
                |tmp: &Path| Ok(crate::baselines::resume_bco(cfg.clone(), d.clone(), tmp)?.0);
            // The whole learner state, bit for bit (the policy file is a view of it).
            drive(
                imitation::bco::Bco::new(cfg.clone(), d.clone())?,
                dir,
                &picks,
                &mut report,
                Some(&resume),
                |l, dir, i, r| match dir.join(format!("iter_{i:03}_state.npz")).is_file() {
                    true => state_file(&l.snapshot(), dir, i, r),
                    false => Ok(Checked::NothingRecorded),
                },
            )?;
        }
        "replay-mean" => {
            let cfg: imitation::replay_mean::ReplayMeanConfig = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_checked(&path, &cfg.sim)?;
            let learner = imitation::replay_mean::ReplayMean::new(cfg, d)?;
            drive(learner, dir, &picks, &mut report, None, tables)?;
        }
        other => {
            return Err(ReplayError::Algorithm {
                dir: dir.to_owned(),
                algo: other.to_owned(),
            })
        }
    }
    if let (Some(v), None) = (&record, &report.difference) {
        let compared: BTreeSet<String> = report
            .compared
            .iter()
            .map(|p| {
                p.strip_prefix(dir)
                    .unwrap_or(p)
                    .to_string_lossy()
                    .replace('\\', "/")
            })
            .collect();
        let missed: Vec<&String> = v
            .files
            .iter()
            .filter(|f| {
                let checkpoint = f.starts_with("iter_")
                    && ["_table.npz", "_critic.json", "_policy.json"]
                        .iter()
                        .any(|s| f.ends_with(s));
                (checkpoint || f.starts_with("tables/")) && !compared.contains(*f)
            })
            .collect();
        ensure!(
            missed.is_empty(),
            ReplayError::Unreached {
                dir: dir.to_owned(),
                iterations: report.iterations,
                count: missed.len(),
                files: missed
                    .iter()
                    .take(3)
                    .map(|s| s.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
                    + if missed.len() > 3 { ", …" } else { "" },
            }
        );
    }
    Ok(report)
}

/// The demonstrations of run `m`: `demos` or the recorded path, with the run's hash.
pub(crate) fn demos_path(m: &Manifest, demos: Option<&Path>) -> Result<PathBuf, ReplayError> {
    let path = demos.map_or_else(|| PathBuf::from(&m.demos), Path::to_owned);
    let hash = manifest::demos_hash(&path).map_err(|source| ReplayError::DemosGone {
        path: path.clone(),
        source,
    })?;
    ensure!(
        hash == m.demos_hash,
        ReplayError::DemosHash {
            path,
            hash,
            recorded: m.demos_hash.clone()
        }
    );
    Ok(path)
}

/// A recorded file that differs: (file, array, index, recorded, replayed).
type Found = (PathBuf, String, Vec<u64>, String, String);

/// What a comparison after `i` iterations found.
enum Checked {
    /// No recorded file of that point: the run ended before it.
    NothingRecorded,
    /// Every recorded file equals the replay's.
    Equal,
    /// The first difference.
    Differs(Found),
}

/// Which episodes each update learns from (module docs).
struct Picks<'a> {
    folder: PathBuf,
    episodes: &'a [(PathBuf, Episode, EpisodeOrigin)],
    /// `learned.jsonl`, when the run has it.
    events: Option<&'a [LearnedEvent]>,
    by_name: HashMap<String, usize>,
}

/// The episodes of one update: noisy, noise-free, their files in that order.
type Picked = (Vec<Episode>, Vec<Episode>, Vec<PathBuf>);

impl<'a> Picks<'a> {
    fn new(
        folder: &Path,
        episodes: &'a [(PathBuf, Episode, EpisodeOrigin)],
        events: Option<&'a [LearnedEvent]>,
    ) -> Self {
        let by_name = episodes
            .iter()
            .enumerate()
            .map(|(k, (p, _, _))| (crate::io::learned::file_name(p), k))
            .collect();
        Self {
            folder: folder.to_owned(),
            episodes,
            events,
            by_name,
        }
    }

    /// The iterations after which the recorded run was resumed.
    fn resumes(&self) -> BTreeSet<usize> {
        self.events
            .iter()
            .flat_map(|e| e.iter())
            .filter_map(|e| match e {
                LearnedEvent::Resumed { iteration, .. } => Some(*iteration),
                LearnedEvent::Learned { .. } => None,
            })
            .collect()
    }

    /// The `n` noisy and the noise-free episode per goal (of `goals`; noisy goal-major) the
    /// update of table version `v` learns from, as `learned.jsonl` lists them when there is
    /// one; `None` when the run has none (it ended before that update).
    fn pick(&self, v: u64, n: usize, goals: usize) -> Result<Option<Picked>, ReplayError> {
        let Some(events) = self.events else {
            if goals > 1 {
                return Ok(self.pick_goals(v, n, goals));
            }
            let mut batch = Batch::default();
            let mut used = Vec::new();
            for (path, ep, origin) in self.episodes {
                if origin.table_version == v && !batch.full(n) && batch.offer(ep.clone(), n) {
                    used.push(path.clone());
                }
            }
            return Ok(batch
                .eval
                .take()
                .filter(|_| batch.noisy.len() == n)
                .map(|eval| (batch.noisy, vec![eval], used)));
        };
        let Some((noisy, evals)) = events.iter().rev().find_map(|e| match e {
            LearnedEvent::Learned {
                version,
                noisy,
                eval,
                more_evals,
                ..
            } if *version == v => Some((noisy, std::iter::once(eval).chain(more_evals))),
            _ => None,
        }) else {
            return Ok(None);
        };
        let evals: Vec<&String> = evals.collect();
        let list = self.folder.join(crate::io::learned::LEARNED);
        ensure!(
            noisy.len() == n * goals && evals.len() == goals,
            ReplayError::Listed {
                list: list.clone(),
                why: format!(
                    "{} noisy and {} noise-free episodes for table version {v}, the run's \
                     settings ask for {} and {goals}",
                    noisy.len(),
                    evals.len(),
                    n * goals
                )
            }
        );
        let mut picked = (
            Vec::with_capacity(n * goals),
            Vec::with_capacity(goals),
            Vec::with_capacity((n + 1) * goals),
        );
        let listed = noisy.iter().map(|f| (f, true));
        for (name, want_noisy) in listed.chain(evals.into_iter().map(|f| (f, false))) {
            let k = *self.by_name.get(name).ok_or_else(|| ReplayError::Listed {
                list: list.clone(),
                why: format!(
                    "{name} for table version {v}, which is not among the recorded episodes in \
                     {}",
                    self.folder.display()
                ),
            })?;
            let (path, ep, origin) = &self.episodes[k];
            ensure!(
                origin.table_version == v && ep.noisy == want_noisy,
                ReplayError::Listed {
                    list: list.clone(),
                    why: format!(
                        "{name} as a {} episode of table version {v}; the file holds a {} \
                         episode of version {}",
                        if want_noisy { "noisy" } else { "noise-free" },
                        if ep.noisy { "noisy" } else { "noise-free" },
                        origin.table_version
                    )
                }
            );
            if want_noisy {
                picked.0.push(ep.clone());
            } else {
                picked.1.push(ep.clone());
            }
            picked.2.push(path.clone());
        }
        Ok(Some(picked))
    }

    /// The episodes of the update of version `v` of a learner of `goals` goals without
    /// `learned.jsonl` (MDGPS recorded in process: `learner train --record-episodes`): the version's noisy episodes in arrival
    /// order (goal-major, `n` each), then its evaluations (one per goal); `None` when the run
    /// recorded fewer (it ended before that update).
    fn pick_goals(&self, v: u64, n: usize, goals: usize) -> Option<Picked> {
        let mine = || {
            self.episodes
                .iter()
                .filter(|(_, _, o)| o.table_version == v)
        };
        let noisy: Vec<_> = mine().filter(|(_, ep, _)| ep.noisy).collect();
        let evals: Vec<_> = mine().filter(|(_, ep, _)| !ep.noisy).collect();
        if noisy.len() != n * goals || evals.len() != goals {
            return None;
        }
        let files = noisy
            .iter()
            .chain(&evals)
            .map(|(p, _, _)| p.clone())
            .collect();
        let eps =
            |v: &[&(PathBuf, Episode, EpisodeOrigin)]| v.iter().map(|e| e.1.clone()).collect();
        Some((eps(&noisy), eps(&evals), files))
    }
}

/// A scratch folder, deleted on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new() -> Result<Self, ReplayError> {
        static K: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let k = K.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!("learner-replay-{}-{k}", std::process::id()));
        crate::io::create_dir(&p)?;
        Ok(Self(p))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// A resume function: the learner `learner serve --resume DIR` builds from the checkpoint in
/// DIR.
type Resume<'a, L> = &'a dyn Fn(&Path) -> Result<L, ReplayError>;

/// The replay loop (module docs) of `learner`; `check` compares the recorded files of the
/// state after `i` iterations; `resume`, where the run was resumed, rebuilds the learner
/// from its own checkpoint as the resumed run did.
fn drive<L: Learn + Checkpoint>(
    mut learner: L,
    dir: &Path,
    picks: &Picks,
    report: &mut ReplayReport,
    resume: Option<Resume<L>>,
    check: impl Fn(&L, &Path, usize, &mut ReplayReport) -> Result<Checked, ReplayError>,
) -> Result<(), ReplayError> {
    let mut used: Vec<PathBuf> = Vec::new();
    let mut resumes = picks.resumes();
    loop {
        let (i, v) = (learner.iteration(), learner.version());
        match check(&learner, dir, i, report)? {
            Checked::NothingRecorded => break,
            Checked::Equal => {}
            Checked::Differs((file, array, index, recorded, replayed)) => {
                report.difference = Some(Difference {
                    iteration: i,
                    version: v,
                    file,
                    array,
                    index,
                    recorded,
                    replayed,
                    episodes: used,
                });
                return Ok(());
            }
        }
        if resumes.remove(&i) {
            if let Some(resume) = resume {
                let tmp = Scratch::new()?;
                learner.checkpoint(&tmp.0, None)?;
                learner = resume(&tmp.0).map_err(|e| ReplayError::Resume {
                    iteration: i,
                    source: Box::new(e),
                })?;
                report.resumes += 1;
            }
        }
        if learner.done() {
            break;
        }
        let goals = learner.goal_tasks().len();
        let Some((noisy, evals, files)) = picks.pick(v, learner.samples(), goals)? else {
            break;
        };
        learner
            .learn_goals(&noisy, &evals, 0.0)
            .map_err(|source| ReplayError::Learn {
                iteration: i + 1,
                source,
            })?;
        report.iterations += 1;
        report.episodes_used += files.len();
        used = files;
    }
    Ok(())
}
