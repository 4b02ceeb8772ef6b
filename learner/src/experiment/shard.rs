//! Sweeps larger than one machine (docs/design.md §4.8): `learner experiment NAME --shard K/N`
//! runs every N-th job of the experiment's list (variant × seed) starting at the K-th, and
//! notes which in `shard.json`; `learner experiment merge DIRS… --out DIR` joins the shards'
//! runs in the list's order and writes the outputs an unsharded run writes. A job's result
//! depends only on its own seed and settings, so the merged CSV, summary and plot are the
//! unsharded run's, bar the wall-time figures (the CSV's time columns, the summary's timing
//! medians).

use std::path::{Path, PathBuf};

use super::ExperimentError;
use crate::error::ensure;
use crate::io::IoError;
use serde::{Deserialize, Serialize};

use super::summary::{results_files, write_outputs};
use super::{Job, Run, SummaryRow};
use crate::io::log::GaifoRow;

/// The K-th (1-based) of N disjoint parts of an experiment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// K, 1 ≤ K ≤ N.
    pub k: usize,
    /// N ≥ 1.
    pub n: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;
    /// `K/N`, e.g. `2/8`: K is 1-based (a 0-based array or completion index + 1).
    fn from_str(s: &str) -> Result<Self, String> {
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}`: expected K/N, e.g. 1/4"))?;
        let k: usize = k.trim().parse().map_err(|e| format!("`{s}`: K: {e}"))?;
        let n: usize = n.trim().parse().map_err(|e| format!("`{s}`: N: {e}"))?;
        if n == 0 || k == 0 || k > n {
            return Err(format!("`{s}`: need 1 <= K <= N"));
        }
        Ok(Shard { k, n })
    }
}

impl Shard {
    /// Whether job `index` (0-based, in the experiment's list) is this shard's.
    pub fn has(&self, index: usize) -> bool {
        index % self.n == self.k - 1
    }
}

/// This shard's jobs of `jobs` and their indices in the list (all of them without a shard).
pub fn select(shard: Option<Shard>, jobs: Vec<Job>) -> (Vec<usize>, Vec<Job>) {
    jobs.into_iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|s| s.has(*i)))
        .unzip()
}

/// What a shard ran, beside its outputs in `shard.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardMeta {
    /// Experiment name (the CSV's name).
    pub experiment: String,
    /// Plot title.
    pub title: String,
    /// This part.
    pub shard: Shard,
    /// Jobs in the whole experiment.
    pub jobs_total: usize,
    /// Per run of this shard, in its CSV's order.
    pub runs: Vec<RunMeta>,
    /// FNV-1a 64 of the experiment's settings (seeds, iterations and every learner setting;
    /// not `threads`) and of its demonstrations' bytes: shards of one experiment run share
    /// it; absent in shards of builds before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings_hash: Option<String>,
}

/// What the CSV does not hold of a [`Run`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunMeta {
    /// Index of its job in the experiment's list.
    pub job: usize,
    pub variant: String,
    pub algorithm: String,
    pub seed: u64,
    pub episodes_per_iteration: usize,
    pub horizon: usize,
    pub wall_s: f64,
    /// Rows the run wrote into the shard's CSV (its iterations); absent in shards of builds
    /// before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
}

/// File name of a shard's notes.
pub const SHARD_FILE: &str = "shard.json";

/// [`ShardMeta::settings_hash`] of an experiment's settings `cfg` and its demonstrations'
/// file (`None`: recorded by the experiment itself, from its settings).
pub fn settings_hash(
    cfg: &impl Serialize,
    demos: Option<&Path>,
) -> Result<String, ExperimentError> {
    let mut v = serde_json::to_value(cfg)?;
    if let Some(m) = v.as_object_mut() {
        m.remove("threads");
    }
    let demos_hash = match demos {
        Some(p) => crate::io::manifest::demos_hash(p)?,
        None => "-".into(),
    };
    Ok(crate::io::files::fnv1a64(
        format!("{v}|{demos_hash}").as_bytes(),
    ))
}

/// Writes `out/shard.json` for the runs of `shard` (jobs `indices` of `jobs_total`) of the
/// experiment whose settings hash to `settings_hash` ([`ShardMeta::settings_hash`]).
#[allow(clippy::too_many_arguments)]
pub fn write_meta(
    out: &Path,
    experiment: &str,
    title: &str,
    shard: Shard,
    jobs_total: usize,
    indices: &[usize],
    runs: &[Run],
    settings_hash: String,
) -> Result<(), ExperimentError> {
    let meta = ShardMeta {
        experiment: experiment.into(),
        title: title.into(),
        shard,
        jobs_total,
        settings_hash: Some(settings_hash),
        runs: indices
            .iter()
            .zip(runs)
            .map(|(&job, r)| RunMeta {
                job,
                variant: r.variant.clone(),
                algorithm: r.algorithm.clone(),
                seed: r.seed,
                episodes_per_iteration: r.episodes_per_iteration,
                horizon: r.horizon,
                wall_s: r.wall_s,
                iterations: Some(r.logs.len()),
            })
            .collect(),
    };
    let path = out.join(SHARD_FILE);
    let bytes = serde_json::to_vec_pretty(&meta)?;
    std::fs::write(&path, bytes).map_err(|e| IoError::file("writing", &path)(e).into())
}

/// The rows of a shard's `<experiment>.csv`: (variant, log row) in file order.
fn read_rows(path: &Path) -> Result<Vec<(String, GaifoRow)>, ExperimentError> {
    let mut r = csv::Reader::from_path(path).map_err(IoError::csv("reading", path))?;
    let header = r.headers().map_err(IoError::csv("reading", path))?.clone();
    ensure!(
        header.len() > 2 && &header[0] == "experiment" && &header[1] == "variant",
        ExperimentError::Shards(format!(
            "{}: not an experiment CSV (header {:?})",
            path.display(),
            header
        ))
    );
    let tail: csv::StringRecord = header.iter().skip(2).collect();
    let mut rows = Vec::new();
    for (k, rec) in r.records().enumerate() {
        let at_row = |source| IoError::CsvRow {
            path: path.to_owned(),
            row: k + 2,
            source,
        };
        let rec = rec.map_err(at_row)?;
        let fields: csv::StringRecord = rec.iter().skip(2).collect();
        let row: GaifoRow = fields.deserialize(Some(&tail)).map_err(at_row)?;
        rows.push((rec[1].to_string(), row));
    }
    Ok(rows)
}

/// Checks that the shards `parts` ((K, folder) in the order given) are each of 1..=`n` once,
/// naming every missing K and every K given more than once (with its folders).
pub fn check_parts(parts: &[(usize, &Path)], n: usize) -> Result<(), ExperimentError> {
    let mut by_k: Vec<Vec<&Path>> = vec![Vec::new(); n];
    for &(k, dir) in parts {
        ensure!(
            (1..=n).contains(&k),
            ExperimentError::Shards(format!(
                "{}: shard {k}/{n} is no part of {n} (need 1 <= K <= N)",
                dir.display()
            ))
        );
        by_k[k - 1].push(dir);
    }
    let missing: Vec<String> = (1..=n)
        .filter(|k| by_k[k - 1].is_empty())
        .map(|k| format!("{k}/{n}"))
        .collect();
    let twice: Vec<String> = (1..=n)
        .filter(|k| by_k[k - 1].len() > 1)
        .map(|k| {
            let dirs: Vec<String> = by_k[k - 1]
                .iter()
                .map(|d| d.display().to_string())
                .collect();
            format!("{k}/{n} ({})", dirs.join(", "))
        })
        .collect();
    let mut problems = Vec::new();
    if !missing.is_empty() {
        problems.push(format!("missing shard(s) {}", missing.join(", ")));
    }
    if !twice.is_empty() {
        problems.push(format!(
            "shard(s) given more than once: {}",
            twice.join("; ")
        ));
    }
    ensure!(
        problems.is_empty(),
        ExperimentError::Shards(format!(
            "merge needs every shard 1/{n} … {n}/{n} once: {} (run the missing shards; give each \
         shard's folder once)",
            problems.join("; ")
        ))
    );
    Ok(())
}

/// Joins the shards in `dirs` into `out`: checks that they are parts of one experiment that
/// together hold every job once, puts their runs in the list's order and writes the
/// experiment's outputs ([`write_outputs`]).
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<(Vec<Run>, Vec<SummaryRow>), ExperimentError> {
    ensure!(
        !dirs.is_empty(),
        ExperimentError::Shards("merge: no shard folders given".into())
    );
    let mut all: Vec<(usize, Run)> = Vec::new();
    let mut first: Option<ShardMeta> = None;
    let mut parts: Vec<(usize, &Path)> = Vec::new();
    for dir in dirs {
        let path = dir.join(SHARD_FILE);
        let text = std::fs::read(&path).map_err(|source| ExperimentError::NotShard {
            path: path.clone(),
            source,
        })?;
        let meta: ShardMeta = serde_json::from_slice(&text).map_err(|source| IoError::Json {
            path: path.clone(),
            line: None,
            source,
        })?;
        if let Some(f) = &first {
            ensure!(
                meta.experiment == f.experiment
                    && meta.jobs_total == f.jobs_total
                    && meta.shard.n == f.shard.n
                    && meta.title == f.title,
                ExperimentError::Shards(format!(
                    "{}: shard {}/{} of `{}` ({} jobs), not of the first's `{}` ({} jobs, N = {})",
                    dir.display(),
                    meta.shard.k,
                    meta.shard.n,
                    meta.experiment,
                    meta.jobs_total,
                    f.experiment,
                    f.jobs_total,
                    f.shard.n
                ))
            );
        }
        if let (Some(a), Some(b)) = (
            &meta.settings_hash,
            first.as_ref().and_then(|f| f.settings_hash.as_ref()),
        ) {
            ensure!(a == b, ExperimentError::Shards(format!("{}: shard {}/{} ran other settings than {} (settings hash {a} there, {b} in the \
                 first shard): seeds, iterations, demonstrations or settings differ; merge the \
                 shards of one experiment run", dir.display(), meta.shard.k, meta.shard.n, dirs[0].display())));
        }
        parts.push((meta.shard.k, dir));
        // An empty shard (more shards than jobs) has no CSV.
        let csv = dir.join(format!("{}.csv", meta.experiment));
        let rows = if meta.runs.is_empty() {
            Vec::new()
        } else {
            read_rows(&csv)?
        };
        for m in &meta.runs {
            let logs: Vec<_> = rows
                .iter()
                .filter(|(v, r)| *v == m.variant && r.seed == m.seed && r.algorithm == m.algorithm)
                .map(|(_, r)| r.log())
                .collect();
            ensure!(!logs.is_empty() && m.iterations.is_none_or(|n| n == logs.len()), ExperimentError::Shards(format!("{}: {} rows for {} seed {} ({}), {} says {}: the CSV lost rows; run the shard \
                 again", csv.display(), logs.len(), m.variant, m.seed, m.algorithm, SHARD_FILE, m.iterations
                    .map_or("it ran".to_string(), |n| format!("{n} iterations")))));
            all.push((
                m.job,
                Run {
                    variant: m.variant.clone(),
                    algorithm: m.algorithm.clone(),
                    seed: m.seed,
                    episodes_per_iteration: m.episodes_per_iteration,
                    horizon: m.horizon,
                    logs,
                    wall_s: m.wall_s,
                },
            ));
        }
        first.get_or_insert(meta);
    }
    let meta = first.expect("at least one shard");
    check_parts(&parts, meta.shard.n)?;
    all.sort_by_key(|(job, _)| *job);
    let jobs: Vec<usize> = all.iter().map(|(j, _)| *j).collect();
    ensure!(
        jobs == (0..meta.jobs_total).collect::<Vec<_>>(),
        ExperimentError::Shards(format!(
            "the shards hold jobs {jobs:?} of 0..{}: each job exactly once is needed (a shard \
         missing or given twice?)",
            meta.jobs_total
        ))
    );
    if let Some(file) = results_files(&meta.experiment)
        .iter()
        .map(|f| out.join(f))
        .find(|p| std::fs::symlink_metadata(p).is_ok())
    {
        return Err(ExperimentError::Occupied {
            dir: out.to_owned(),
            file,
        });
    }
    let runs: Vec<Run> = all.into_iter().map(|(_, r)| r).collect();
    let rows = write_outputs(&meta.experiment, &meta.title, &runs, out)?;
    if super::goals::at_several_goals(&runs) {
        super::goals::write_precision(&runs, out)?;
    }
    Ok((runs, rows))
}
