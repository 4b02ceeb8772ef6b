//! `learner replay RUN_DIR`: the learning of a recorded run done again from its recorded
//! episodes, every table checked bit for bit against the recorded one (docs/design.md §4.13).
//!
//! The learner is rebuilt from the run's `run.json` (algorithm, seed, the settings in full, the
//! demonstrations' path and hash; [`crate::io::manifest`]) exactly as the run built it, and
//! driven through the same [`imitation::learn::Learn::learn`] the serve loop and [`imitation::learn::iterate`]
//! call: for each table version v, from the first noisy episode on, in arrival order
//! (`episodes/NNNNNN_eEPISODE_vVERSION.npz`), the first N noisy and the first noise-free
//! episode of v ([`Batch`], as `learner serve` picks them) are learned from. Before each
//! update and after the last, the learner's table of version v is compared entry by entry with
//! every recorded copy of it: `iter_NNN_table.npz` (NNN = v − 1, LQR+GAIfO) and
//! `tables/vVERSION.npz` (`learner serve`); for LQR+GAIfO also the critic checkpoint
//! `iter_NNN_critic.json`, byte for byte. The first difference ends the replay.
//!
//! Every random draw of the learners (critic minibatches, gradient-penalty points, GMM
//! initialisation) comes from RNGs seeded by the run seed and advanced only by the learning
//! itself, so the same settings, demonstrations and episodes give the same bits. What a
//! replay cannot redo: a served run that was resumed (`learner serve --resume`) learned after
//! the resume from fresh episodes of the resumed version, which the replay cannot tell from
//! the earlier ones of that version; runs of the GAIfO (PPO) baseline (no gain tables).

use std::path::{Path, PathBuf};

use anyhow::Context;
use imitation::expert::{ExpertConfig, ExpertLearner};
use imitation::gaifo::{GaifoConfig, LqrGaifo};
use imitation::learn::LinGaussLearn;
use imitation::rollout::Episode;
use serde::Serialize;

use crate::io::episode::{recorded_episodes, EpisodeOrigin};
use crate::io::manifest::{self, Manifest};
use crate::io::table::{load_stored, table_arrays};
use crate::serve::Batch;

/// The first place where the replay and the recorded run differ.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Difference {
    /// The iteration (1-based) whose update produced the table; 0 for the initial table.
    pub iteration: usize,
    /// The table version.
    pub version: u64,
    /// The recorded file.
    pub file: PathBuf,
    /// The array (`K`, `k`, `s_hat`, `a_hat`, `L`, `version`, `checksum`) or `critic`.
    pub array: String,
    /// The entry's index in the array (t, row, column as the array has them; the byte
    /// offset for the critic file); empty for a scalar.
    pub index: Vec<u64>,
    /// The recorded value (f64: shortest round-trip decimal and its bits in hex).
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
    /// `lqr-gaifo` or `expert`.
    pub algorithm: String,
    /// The run seed.
    pub seed: u64,
    /// Updates done again.
    pub iterations: usize,
    /// Recorded table files compared (all equal unless `difference`).
    pub tables_checked: usize,
    /// Recorded critic checkpoints compared.
    pub critics_checked: usize,
    /// Recorded episodes found.
    pub episodes: usize,
    /// Episodes learned from.
    pub episodes_used: usize,
    /// The first difference (`None`: the replay equals the run bit for bit).
    pub difference: Option<Difference>,
}

/// Replays the run in `dir` (module docs). `demos` replaces the demonstrations' path recorded
/// in `run.json` (their hash must still be the run's).
pub fn replay(dir: &Path, demos: Option<&Path>) -> anyhow::Result<ReplayReport> {
    let m = manifest::read(dir)?.ok_or_else(|| {
        anyhow::anyhow!(
            "{} has no {}: not a run folder of `learner train` or `learner serve`",
            dir.display(),
            manifest::MANIFEST
        )
    })?;
    let episodes = recorded_episodes(&dir.join("episodes"))?;
    anyhow::ensure!(
        !episodes.is_empty(),
        "{} holds no recorded episodes (episodes/*.npz): a replay needs them; `learner serve` \
         records every episode, `learner train` only with --record-episodes",
        dir.display()
    );
    let mut report = ReplayReport {
        command: "replay",
        run: dir.to_owned(),
        run_command: m.command.clone(),
        algorithm: m.algo.clone(),
        seed: m.seed,
        iterations: 0,
        tables_checked: 0,
        critics_checked: 0,
        episodes: episodes.len(),
        episodes_used: 0,
        difference: None,
    };
    match m.algo.as_str() {
        "lqr-gaifo" => {
            let cfg: GaifoConfig = m.settings_as()?;
            let path = demos_path(&m, demos)?;
            let d = crate::io::demos::load_checked(&path, &cfg.sim)?;
            let learner = LqrGaifo::new(cfg, d)?;
            drive(learner, dir, &episodes, &mut report, |l, dir, i| {
                critic_difference(l, dir, i)
            })?;
        }
        "expert" => {
            let cfg: ExpertConfig = m.settings_as()?;
            drive(
                ExpertLearner::new(cfg, None),
                dir,
                &episodes,
                &mut report,
                |_, _, _| Ok(None),
            )?;
        }
        other => anyhow::bail!(
            "{}: a replay redoes runs whose controller is a gain table (lqr-gaifo, expert), \
             not {other}",
            dir.display()
        ),
    }
    Ok(report)
}

/// The demonstrations of run `m`: `demos` or the recorded path, with the run's hash.
fn demos_path(m: &Manifest, demos: Option<&Path>) -> anyhow::Result<PathBuf> {
    let path = demos.map_or_else(|| PathBuf::from(&m.demos), Path::to_owned);
    let hash = manifest::demos_hash(&path).with_context(|| {
        format!(
            "the run's demonstrations {} (pass --demos with their new place)",
            path.display()
        )
    })?;
    anyhow::ensure!(
        hash == m.demos_hash,
        "{} hashes to {hash}, the run's demonstrations to {}: not the run's demonstrations",
        path.display(),
        m.demos_hash
    );
    Ok(path)
}

/// The replay loop (module docs) of `learner`; `critic` compares what else a checkpoint
/// after `i` iterations holds.
fn drive<L: LinGaussLearn>(
    mut learner: L,
    dir: &Path,
    episodes: &[(PathBuf, Episode, EpisodeOrigin)],
    report: &mut ReplayReport,
    critic: impl Fn(&L, &Path, usize) -> anyhow::Result<Option<(PathBuf, u64, String, String)>>,
) -> anyhow::Result<()> {
    let mut used: Vec<PathBuf> = Vec::new();
    loop {
        let (i, v) = (learner.iteration(), learner.version());
        let files: Vec<PathBuf> = [
            dir.join(format!("iter_{i:03}_table.npz")),
            crate::io::table::version_path(dir, v),
        ]
        .into_iter()
        .filter(|p| p.is_file())
        .collect();
        if files.is_empty() {
            break;
        }
        let arrays = table_arrays(&learner.table());
        let table = learner.table();
        for f in &files {
            let stored = load_stored(f).with_context(|| format!("reading {}", f.display()))?;
            report.tables_checked += 1;
            if let Some((array, index, rec, rep)) = table_difference(&stored, &arrays, &table) {
                report.difference = Some(Difference {
                    iteration: i,
                    version: v,
                    file: f.clone(),
                    array,
                    index,
                    recorded: rec,
                    replayed: rep,
                    episodes: used,
                });
                return Ok(());
            }
        }
        if let Some((file, offset, rec, rep)) = critic(&learner, dir, i)? {
            report.difference = Some(Difference {
                iteration: i,
                version: v,
                file,
                array: "critic".into(),
                index: vec![offset],
                recorded: rec,
                replayed: rep,
                episodes: used,
            });
            return Ok(());
        } else if dir.join(format!("iter_{i:03}_critic.json")).is_file() {
            report.critics_checked += 1;
        }
        if learner.done() {
            break;
        }
        let n = learner.samples();
        let mut batch = Batch::default();
        used = Vec::new();
        for (path, ep, origin) in episodes {
            if origin.table_version == v && !batch.full(n) && batch.offer(ep.clone(), n) {
                used.push(path.clone());
            }
        }
        let Some(eval) = batch.eval.take().filter(|_| batch.noisy.len() == n) else {
            break;
        };
        learner
            .learn(&batch.noisy, &eval, 0.0)
            .with_context(|| format!("replaying iteration {}", i + 1))?;
        report.iterations += 1;
        report.episodes_used += used.len();
    }
    Ok(())
}

/// An f64 as the report shows it: shortest round-trip decimal and its bits.
fn show(x: f64) -> String {
    format!("{x:?} ({:#018x})", x.to_bits())
}

/// The first entry where `stored` and the replayed `arrays` (of `table`) differ: (array,
/// index, recorded, replayed).
fn table_difference(
    stored: &crate::io::table::StoredTable,
    arrays: &[(&'static str, Vec<u64>, Vec<f64>)],
    table: &ur5_shared::GainTable,
) -> Option<(String, Vec<u64>, String, String)> {
    for ((name, shape, rec), (_, want_shape, rep)) in stored.arrays.iter().zip(arrays) {
        if shape != want_shape {
            return Some((
                format!("{name} (shape)"),
                Vec::new(),
                format!("{shape:?}"),
                format!("{want_shape:?}"),
            ));
        }
        if let Some(j) = (0..rec.len()).find(|&j| rec[j].to_bits() != rep[j].to_bits()) {
            // Row-major index of entry j.
            let mut index = vec![0; shape.len()];
            let mut rest = j as u64;
            for (d, len) in shape.iter().enumerate().rev() {
                index[d] = rest % len;
                rest /= len;
            }
            return Some((name.to_string(), index, show(rec[j]), show(rep[j])));
        }
    }
    for (name, rec, rep) in [
        ("version", stored.version, table.version),
        ("checksum", stored.checksum, table.checksum),
    ] {
        if rec != rep {
            return Some((
                name.into(),
                Vec::new(),
                format!("{rec:#018x}"),
                format!("{rep:#018x}"),
            ));
        }
    }
    None
}

/// The critic checkpoint `iter_{i:03}_critic.json` in `dir` against the replayed critic, byte
/// for byte: (file, first differing byte offset, recorded and replayed text there).
fn critic_difference(
    learner: &LqrGaifo,
    dir: &Path,
    i: usize,
) -> anyhow::Result<Option<(PathBuf, u64, String, String)>> {
    let file = dir.join(format!("iter_{i:03}_critic.json"));
    if !file.is_file() {
        return Ok(None);
    }
    let recorded = std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?;
    static SAVES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let k = SAVES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = std::env::temp_dir().join(format!(
        "learner-replay-critic-{}-{k}.json",
        std::process::id()
    ));
    learner.discriminator().save(&tmp)?;
    let replayed = std::fs::read(&tmp)?;
    std::fs::remove_file(&tmp).ok();
    let Some(at) =
        (0..recorded.len().max(replayed.len())).find(|&j| recorded.get(j) != replayed.get(j))
    else {
        return Ok(None);
    };
    let around = |b: &[u8]| {
        let lo = at.saturating_sub(20);
        String::from_utf8_lossy(&b[lo.min(b.len())..(at + 40).min(b.len())]).into_owned()
    };
    Ok(Some((
        file,
        at as u64,
        around(&recorded),
        around(&replayed),
    )))
}
