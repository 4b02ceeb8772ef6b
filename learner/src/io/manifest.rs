//! Who owns a run directory (docs/design.md §4.4): `run.json` records what made the run in it
//! (command, algorithm, seed, a hash of the demonstrations' file, a hash of the settings), so
//! that a second run cannot mix its files and rows into the first one's and a resume cannot
//! continue a run with other demonstrations or settings.
//!
//! - A new run ([`Claim::New`]) into a directory that already holds a run's files is refused,
//!   naming the run found there, unless `force` is set: then those files (and only those) are
//!   deleted first.
//! - A resume ([`Claim::Resume`]) needs the directory's `run.json` and its `gaifo_log.csv` or
//!   `serve_log.csv`, and the same command, algorithm, seed, demonstrations and settings
//!   (the number of iterations may differ: a resume extends the run); it deletes what writes
//!   cut short by a kill left there (`*.partial`, `*.tmp`).
//!
//! The hashes are FNV-1a 64 (identity, not security): of the demonstrations file's bytes, and
//! of the settings serialised as JSON with `iterations` removed.

use std::path::{Path, PathBuf};

use super::IoError;
use crate::error::ensure;
use serde::{Deserialize, Serialize};

/// The file name of the manifest.
pub const MANIFEST: &str = "run.json";

/// What made a run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// `train` or `serve`.
    pub command: String,
    /// `lqr-gaifo`, `gaifo-ppo` or `expert`.
    pub algo: String,
    /// The run's seed.
    pub seed: u64,
    /// The demonstrations' path as given (informative) and the FNV-1a 64 hash of their bytes
    /// (`-` for the expert, which has none).
    pub demos: String,
    pub demos_hash: String,
    /// FNV-1a 64 of the settings as JSON without `iterations`.
    pub config_hash: String,
    /// When the run was made (s since the Unix epoch).
    pub created_unix_s: u64,
    /// The settings in full (iterations included), so that `learner replay` can rebuild the
    /// learner; absent in manifests written before replay (such runs cannot be replayed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<serde_json::Value>,
    /// The record of the run's files ([`crate::io::files::FILES`]), kept as the run goes so
    /// that `learner replay` checks every file; absent in runs of builds before that record.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub files: Option<String>,
}

/// How a run takes a directory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Claim {
    /// A new run; `force` deletes another run's files found there first.
    New { force: bool },
    /// Continue the run in the directory.
    Resume,
}

pub use crate::io::files::fnv1a64;

/// A run folder that cannot be taken for a run, or a manifest that does not describe it.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    /// `--resume` of a folder without a manifest.
    #[error(
        "{} has no {MANIFEST}: it is not a run of this build (or not a run at all); start a new \
         run instead of resuming",
        dir.display()
    )]
    NoManifest {
        /// The folder.
        dir: PathBuf,
    },
    /// `--resume` of a folder that holds a run of other settings.
    #[error(
        "{} holds another run than this one: {}; resume it with its own command, algorithm, \
         seed, demonstrations and settings, or start a new run in another --out",
        dir.display(),
        differences.join("; ")
    )]
    AnotherRun {
        /// The folder.
        dir: PathBuf,
        /// What differs, one entry per field.
        differences: Vec<String>,
    },
    /// `--resume` of a run whose per-iteration log is gone.
    #[error(
        "{} has no {log}: its per-iteration log is missing, so a resumed run would write rows \
         with a gap; restore the file or start a new run",
        dir.display()
    )]
    NoLog {
        /// The folder.
        dir: PathBuf,
        /// The log's file name.
        log: &'static str,
    },
    /// A new run into a folder that holds a run's files.
    #[error(
        "{} already holds {what} ({count} of its files, e.g. {}): continue it with --resume {}, \
         choose another --out, or pass --force to delete those files and start over",
        dir.display(),
        example.display(),
        dir.display()
    )]
    Occupied {
        /// The folder.
        dir: PathBuf,
        /// The run found there.
        what: String,
        /// How many of its files are there.
        count: usize,
        /// One of them.
        example: PathBuf,
    },
    /// A manifest without settings (replay needs them).
    #[error("{MANIFEST} records no settings (written by a build before `learner replay`)")]
    NoSettings,
    /// Settings that do not read back as this build's.
    #[error("the settings in {MANIFEST}")]
    Settings(#[source] serde_json::Error),
    /// Settings that read back other than they were written.
    #[error(
        "the settings in {MANIFEST} hash to {hash}, the run's settings to {recorded}: not this \
         build's settings"
    )]
    SettingsHash {
        /// The hash of the settings read back.
        hash: String,
        /// The hash the manifest records.
        recorded: String,
    },
    /// A `run.json` that does not parse.
    #[error("{}: not a run manifest of this build", path.display())]
    NotManifest {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        source: serde_json::Error,
    },
}

impl Manifest {
    /// The manifest of a run of `command`/`algo` with `seed` on the demonstrations in `demos`
    /// (read and hashed) and `settings`.
    pub fn new<S: Serialize>(
        command: &str,
        algo: &str,
        seed: u64,
        demos: Option<&Path>,
        settings: &S,
    ) -> Result<Self, IoError> {
        let (demos, demos_hash) = match demos {
            Some(p) => (p.display().to_string(), demos_hash(p)?),
            None => ("-".into(), "-".into()),
        };
        let full = serde_json::to_value(settings)?;
        let config_hash = settings_hash(&full)?;
        Ok(Self {
            command: command.into(),
            algo: algo.into(),
            seed,
            demos,
            demos_hash,
            config_hash,
            settings: Some(full),
            files: Some(crate::io::files::FILES.into()),
            created_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        })
    }

    /// The differences that make `other` another run than `self` (empty: the same run).
    fn differences(&self, other: &Self) -> Vec<String> {
        let mut d = Vec::new();
        let mut cmp = |what: &str, a: &str, b: &str| {
            if a != b {
                d.push(format!("{what} {a} there, {b} now"));
            }
        };
        cmp("command", &self.command, &other.command);
        cmp("algorithm", &self.algo, &other.algo);
        cmp("seed", &self.seed.to_string(), &other.seed.to_string());
        if !self.same_settings_but_iterations(other) {
            cmp("settings hash", &self.config_hash, &other.config_hash);
        }
        if self.demos_hash != other.demos_hash {
            d.push(format!(
                "demonstrations {} (hash {}) there, {} (hash {}) now",
                self.demos, self.demos_hash, other.demos, other.demos_hash
            ));
        }
        d
    }

    /// Whether the two runs' settings differ at most in their iterations: the hash leaves out
    /// the top-level `iterations`, and MDGPS's, nested in its `lqr_gaifo` settings, are
    /// compared here on the settings in full (which both manifests of a resume hold), so that
    /// an MDGPS run extends as an LQR+GAIfO run does while recorded hashes stay as they were.
    fn same_settings_but_iterations(&self, other: &Self) -> bool {
        if self.config_hash == other.config_hash {
            return true;
        }
        let strip = |v: &serde_json::Value| {
            let mut v = v.clone();
            if let Some(m) = v.as_object_mut() {
                m.remove("iterations");
                if let Some(inner) = m.get_mut("lqr_gaifo").and_then(|i| i.as_object_mut()) {
                    inner.remove("iterations");
                }
            }
            v
        };
        match (&self.settings, &other.settings) {
            (Some(a), Some(b)) => strip(a) == strip(b),
            _ => false,
        }
    }

    /// The run's settings as `C`, checked against [`Manifest::config_hash`] (the settings
    /// read back must hash as the run's did, so a value that did not survive the JSON round
    /// trip is found).
    pub fn settings_as<C: Serialize + serde::de::DeserializeOwned>(&self) -> Result<C, IoError> {
        let v = self.settings.clone().ok_or(ManifestError::NoSettings)?;
        let c: C = serde_json::from_value(v).map_err(ManifestError::Settings)?;
        let hash = settings_hash(&serde_json::to_value(&c)?)?;
        ensure!(
            hash == self.config_hash,
            ManifestError::SettingsHash {
                hash,
                recorded: self.config_hash.clone()
            }
        );
        Ok(c)
    }

    fn describe(&self) -> String {
        format!(
            "`learner {}` {} seed {} on {} (made at Unix time {})",
            self.command, self.algo, self.seed, self.demos, self.created_unix_s
        )
    }
}

/// FNV-1a 64 of settings serialised as JSON without `iterations` ([`Manifest::config_hash`]).
fn settings_hash(settings: &serde_json::Value) -> Result<String, IoError> {
    let mut v = settings.clone();
    if let Some(m) = v.as_object_mut() {
        m.remove("iterations");
    }
    Ok(fnv1a64(serde_json::to_string(&v)?.as_bytes()))
}

/// The FNV-1a 64 of the demonstrations at `path` as [`Manifest::demos_hash`] records it.
pub fn demos_hash(path: &Path) -> Result<String, IoError> {
    Ok(fnv1a64(&content_bytes(path)?))
}

/// The bytes that identify the demonstrations at `path`: a file's bytes; for a folder (a
/// LeRobot dataset) every file below it in path order, each as its relative path, a zero
/// byte, then its bytes.
fn content_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    if !path.is_dir() {
        return std::fs::read(path).map_err(IoError::file("reading", &path));
    }
    let mut files = Vec::new();
    let mut todo = vec![path.to_path_buf()];
    while let Some(dir) = todo.pop() {
        for e in std::fs::read_dir(&dir).map_err(IoError::file("reading", &dir))? {
            let p = e.map_err(IoError::file("reading", &dir))?.path();
            if p.is_dir() {
                todo.push(p);
            } else {
                files.push(p);
            }
        }
    }
    files.sort();
    let mut bytes = Vec::new();
    for f in files {
        let rel = f.strip_prefix(path).unwrap_or(&f);
        bytes.extend_from_slice(rel.to_string_lossy().as_bytes());
        bytes.push(0);
        bytes.extend(std::fs::read(&f).map_err(IoError::file("reading", &f))?);
    }
    Ok(bytes)
}

/// Files and folders a run writes into its directory.
fn run_files(dir: &Path) -> Result<Vec<PathBuf>, IoError> {
    const NAMES: [&str; 12] = [
        MANIFEST,
        crate::io::files::FILES,
        "run.mcap",
        "gaifo_log.csv",
        "mdgps_log.csv",
        "serve_log.csv",
        "checkpoint.npz",
        "latest_table.npz",
        "best_table.npz",
        "demos.npz",
        "tables",
        "episodes",
    ];
    let mut found = Vec::new();
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(found),
        Err(e) => return Err(e).map_err(IoError::file("reading", &dir)),
    };
    for e in entries {
        let e = e.map_err(IoError::file("reading", &dir))?;
        let full = e.file_name().to_string_lossy().into_owned();
        // A write cut short by a kill leaves `<name>.partial` or `<name>.tmp`.
        let name = full
            .strip_suffix(".partial")
            .or_else(|| full.strip_suffix(".tmp"))
            .unwrap_or(&full);
        let iter_file = name.starts_with("iter_")
            && ["_table.npz", "_critic.json", "_policy.json", "_state.npz"]
                .iter()
                .any(|s| name.ends_with(s));
        if NAMES.contains(&name) || iter_file {
            found.push(e.path());
        }
    }
    found.sort();
    Ok(found)
}

/// Deletes what writes cut short by a kill left in a run folder and its `tables/` and
/// `episodes/`: `*.partial` (an [`crate::io::npz::NpzWriter`] before its rename) and `*.tmp`
/// (an atomic file before its rename). Neither is ever a complete file, and the run's record
/// (`files.jsonl`) lists none of them.
fn remove_cut_writes(dir: &Path) -> Result<(), IoError> {
    for d in [dir.to_path_buf(), dir.join("tables"), dir.join("episodes")] {
        let entries = match std::fs::read_dir(&d) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => return Err(e).map_err(IoError::file("reading", &d)),
        };
        for e in entries {
            let p = e.map_err(IoError::file("reading", &d))?.path();
            let name = p.file_name().unwrap_or_default().to_string_lossy();
            if p.is_file() && (name.ends_with(".partial") || name.ends_with(".tmp")) {
                std::fs::remove_file(&p).map_err(IoError::file("deleting the cut write", &p))?;
            }
        }
    }
    Ok(())
}

/// Reads `dir`'s manifest, if any.
pub fn read(dir: &Path) -> Result<Option<Manifest>, IoError> {
    let p = dir.join(MANIFEST);
    match std::fs::read(&p) {
        Ok(bytes) => Ok(Some(serde_json::from_slice(&bytes).map_err(|source| {
            ManifestError::NotManifest {
                path: p.clone(),
                source,
            }
        })?)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(IoError::file("reading", &p)(e)),
    }
}

/// Takes `dir` for the run `m` as `claim` says (module docs); creates `dir` if needed.
pub fn claim(dir: &Path, m: &Manifest, claim: Claim) -> Result<(), IoError> {
    let found = read(dir)?;
    match claim {
        Claim::Resume => {
            let Some(there) = found else {
                return Err(ManifestError::NoManifest {
                    dir: dir.to_owned(),
                }
                .into());
            };
            let d = there.differences(m);
            ensure!(
                d.is_empty(),
                ManifestError::AnotherRun {
                    dir: dir.to_owned(),
                    differences: d
                }
            );
            let log = match m.algo.as_str() {
                "expert" => "serve_log.csv",
                "mdgps" => "mdgps_log.csv",
                _ => "gaifo_log.csv",
            };
            ensure!(
                dir.join(log).is_file(),
                ManifestError::NoLog {
                    dir: dir.to_owned(),
                    log
                }
            );
            remove_cut_writes(dir)
        }
        Claim::New { force } => {
            let files = run_files(dir)?;
            if !files.is_empty() {
                let what = found
                    .as_ref()
                    .map(Manifest::describe)
                    .unwrap_or_else(|| "a run without a manifest".into());
                ensure!(
                    force,
                    ManifestError::Occupied {
                        dir: dir.to_owned(),
                        what,
                        count: files.len(),
                        example: files[0].clone(),
                    }
                );
                for f in &files {
                    let r = if f.is_dir() {
                        std::fs::remove_dir_all(f)
                    } else {
                        std::fs::remove_file(f)
                    };
                    r.map_err(IoError::file("--force: deleting", f))?;
                }
            }
            crate::io::create_dir(dir)?;
            let path = dir.join(MANIFEST);
            ur5_shared::atomic_file::write(&path, &serde_json::to_vec_pretty(m)?)
                .map_err(IoError::file("writing the run manifest", &path))?;
            crate::io::files::start(dir)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("manifest-{name}-{}", std::process::id()));
        std::fs::remove_dir_all(&d).ok();
        d
    }

    fn manifest(seed: u64, settings: &serde_json::Value) -> Manifest {
        Manifest::new("train", "lqr-gaifo", seed, None, settings).unwrap()
    }

    #[test]
    fn fnv1a64_matches_the_reference_vectors() {
        // The FNV reference's test vectors for FNV-1a 64.
        assert_eq!(fnv1a64(b""), "cbf29ce484222325");
        assert_eq!(fnv1a64(b"a"), "af63dc4c8601ec8c");
        assert_eq!(fnv1a64(b"foobar"), "85944171f73967e8");
    }

    #[test]
    fn a_second_run_is_refused_unless_forced_and_force_deletes_only_run_files() {
        let dir = tmp("new");
        let s = serde_json::json!({"iterations": 20, "kl": 1.0});
        claim(&dir, &manifest(0, &s), Claim::New { force: false }).unwrap();
        std::fs::write(dir.join("gaifo_log.csv"), "x").unwrap();
        std::fs::write(dir.join("iter_003_table.npz"), "x").unwrap();
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        let e = claim(&dir, &manifest(5, &s), Claim::New { force: false })
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("seed 0") && e.contains("--force") && e.contains("--resume"),
            "{e}"
        );
        claim(&dir, &manifest(5, &s), Claim::New { force: true }).unwrap();
        assert!(!dir.join("iter_003_table.npz").exists());
        assert!(!dir.join("gaifo_log.csv").exists());
        assert!(dir.join("notes.txt").exists(), "not a run file: kept");
        assert_eq!(read(&dir).unwrap().unwrap().seed, 5);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_resume_needs_the_same_run_and_its_log() {
        let dir = tmp("resume");
        let s = serde_json::json!({"iterations": 20, "kl": 1.0});
        let e = claim(&dir, &manifest(0, &s), Claim::Resume)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no run.json"), "{e}");
        claim(&dir, &manifest(0, &s), Claim::New { force: false }).unwrap();
        let e = claim(&dir, &manifest(0, &s), Claim::Resume)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no gaifo_log.csv"), "{e}");
        std::fs::write(dir.join("gaifo_log.csv"), "x").unwrap();
        // Writes a kill cut short: deleted by the resume, nothing else.
        std::fs::create_dir_all(dir.join("episodes")).unwrap();
        let cut = [
            dir.join("iter_003_table.npz.partial"),
            dir.join("episodes")
                .join("000004_e000003_v0001.npz.partial"),
            dir.join("best_table.npz.tmp"),
        ];
        for f in &cut {
            std::fs::write(f, "cut").unwrap();
        }
        std::fs::write(
            dir.join("episodes").join("000001_e000000_v0001.npz"),
            "kept",
        )
        .unwrap();
        // More iterations: the same run.
        let more = serde_json::json!({"iterations": 40, "kl": 1.0});
        claim(&dir, &manifest(0, &more), Claim::Resume).unwrap();
        // So for MDGPS, whose iterations are LQR+GAIfO's settings' (other settings still
        // differ).
        let mdgps = |iterations: u64, kl: f64| {
            let s = serde_json::json!({"lqr_gaifo": {"iterations": iterations, "kl": 1.0},
                "kl_step": kl});
            Manifest::new("train", "mdgps", 0, None, &s).unwrap()
        };
        let mdir = tmp("mdgps");
        claim(&mdir, &mdgps(2, 1.0), Claim::New { force: false }).unwrap();
        std::fs::write(mdir.join("mdgps_log.csv"), "x").unwrap();
        claim(&mdir, &mdgps(5, 1.0), Claim::Resume).unwrap();
        let e = claim(&mdir, &mdgps(5, 0.5), Claim::Resume)
            .unwrap_err()
            .to_string();
        assert!(e.contains("settings hash"), "{e}");
        std::fs::remove_dir_all(&mdir).ok();
        assert!(cut.iter().all(|f| !f.exists()), "cut writes deleted");
        assert!(dir
            .join("episodes")
            .join("000001_e000000_v0001.npz")
            .exists());
        assert!(dir.join("gaifo_log.csv").exists());
        let e = claim(&dir, &manifest(1, &s), Claim::Resume)
            .unwrap_err()
            .to_string();
        assert!(e.contains("seed 0 there, 1 now"), "{e}");
        let other = serde_json::json!({"iterations": 20, "kl": 2.0});
        let e = claim(&dir, &manifest(0, &other), Claim::Resume)
            .unwrap_err()
            .to_string();
        assert!(e.contains("settings hash"), "{e}");
        let demos = dir.join("d.npz");
        std::fs::write(&demos, "other demos").unwrap();
        let m = Manifest::new("train", "lqr-gaifo", 0, Some(&demos), &s).unwrap();
        let e = claim(&dir, &m, Claim::Resume).unwrap_err().to_string();
        assert!(e.contains("demonstrations"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
