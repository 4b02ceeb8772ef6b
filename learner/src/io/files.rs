//! `files.jsonl`: the record of every file a run writes for `learner replay`, kept as the run
//! goes (docs/reliability.md, docs/design.md §4.13), so that a replay checks the whole run or
//! fails naming what is missing, altered or unrecorded, instead of comparing whatever is
//! left in the folder.
//!
//! One JSON line per written file or appended line, in the order written:
//! `{"file":"episodes/000001_e000000_v0001.npz","from":0,"to":4242,"fnv1a64":"…"}`: the
//! file (relative to the run folder, `/`-separated) held bytes `from..to` with that FNV-1a 64
//! hash ([`fnv1a64`]). A whole file is `from` 0 and `to` its length; a
//! line appended to an append-only file (`episodes/learned.jsonl`) is `from` its length before
//! the append. A file written again (a checkpoint redone after a resume) gets a new line: the
//! last line with `from` 0 and the appends after it describe the file as it must be.
//!
//! What the record covers ([`in_scope`]): the checkpoints `iter_NNN_{table.npz, critic.json,
//! policy.json, state.npz}`, the published tables `tables/vVERSION.npz`, the recorded episodes
//! `episodes/*.npz` and `episodes/learned.jsonl`. Each line is appended after its file is
//! complete (files are written atomically), so a kill leaves at most a file without its line
//! or a cut last line; a resume ([`adopt`]) records what the killed run left, as it is.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::{Path, PathBuf};

use super::IoError;
use serde::{Deserialize, Serialize};

/// FNV-1a 64 of `bytes`, as 16 hex digits (identity, not security; also the hashes of
/// `run.json`, [`crate::io::manifest`]).
pub fn fnv1a64(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// The record's file name in the run folder.
pub const FILES: &str = "files.jsonl";

/// One line of the record (module docs).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Entry {
    /// The file, relative to the run folder, `/`-separated.
    pub file: String,
    /// First byte covered.
    pub from: u64,
    /// One past the last byte covered (the file's length after the write).
    pub to: u64,
    /// FNV-1a 64 of bytes `from..to`, 16 hex digits.
    pub fnv1a64: String,
}

/// `path` relative to `run`, `/`-separated.
fn rel(run: &Path, path: &Path) -> String {
    let r = path.strip_prefix(run).unwrap_or(path);
    r.components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("/")
}

fn append(run: &Path, entries: &[Entry]) -> Result<(), IoError> {
    if entries.is_empty() {
        return Ok(());
    }
    let mut text = Vec::new();
    for e in entries {
        serde_json::to_writer(&mut text, e)?;
        text.push(b'\n');
    }
    let path = run.join(FILES);
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(&text))
        .map_err(IoError::file("appending to", &path))
}

fn whole(run: &Path, path: &Path) -> Result<Entry, IoError> {
    let bytes = std::fs::read(path).map_err(IoError::file("reading", &path))?;
    Ok(Entry {
        file: rel(run, path),
        from: 0,
        to: bytes.len() as u64,
        fnv1a64: fnv1a64(&bytes),
    })
}

/// Starts an empty record in `run` (a new run).
pub fn start(run: &Path) -> Result<(), IoError> {
    ur5_shared::atomic_file::write(&run.join(FILES), b"")
        .map_err(IoError::file("writing", &run.join(FILES)))
}

/// Records the complete files `files` of the run in `run`.
pub fn note(run: &Path, files: &[&Path]) -> Result<(), IoError> {
    let entries = files
        .iter()
        .map(|f| whole(run, f))
        .collect::<Result<Vec<_>, IoError>>()?;
    append(run, &entries)
}

/// Records the checkpoint files `iter_NNN_*` (NNN = `i`) present in `run`.
pub fn note_checkpoint(run: &Path, i: usize) -> Result<(), IoError> {
    let prefix = format!("iter_{i:03}_");
    let mut files: Vec<PathBuf> = checkpoint_files(run)?
        .into_iter()
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(&prefix))
        })
        .collect();
    files.sort();
    let refs: Vec<&Path> = files.iter().map(PathBuf::as_path).collect();
    note(run, &refs)
}

/// Records the bytes from `from` to the end of the append-only `file` (a line just appended).
pub fn note_appended(run: &Path, file: &Path, from: u64) -> Result<(), IoError> {
    let bytes = std::fs::read(file).map_err(IoError::file("reading", &file))?;
    let from = from.min(bytes.len() as u64);
    append(
        run,
        &[Entry {
            file: rel(run, file),
            from,
            to: bytes.len() as u64,
            fnv1a64: fnv1a64(&bytes[from as usize..]),
        }],
    )
}

/// The length of `file` (0 when it does not exist): where the next append starts.
pub fn len(file: &Path) -> u64 {
    std::fs::metadata(file).map_or(0, |m| m.len())
}

fn is_checkpoint(name: &str) -> bool {
    name.starts_with("iter_")
        && ["_table.npz", "_critic.json", "_policy.json", "_state.npz"]
            .iter()
            .any(|s| name.ends_with(s))
}

fn checkpoint_files(run: &Path) -> Result<Vec<PathBuf>, IoError> {
    Ok(list(run)?
        .into_iter()
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(is_checkpoint)
        })
        .collect())
}

/// The files of `dir` (none when it does not exist).
fn list(dir: &Path) -> Result<Vec<PathBuf>, IoError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e).map_err(IoError::file("reading", &dir)),
    };
    let mut out = Vec::new();
    for e in entries {
        let p = e.map_err(IoError::file("reading", &dir))?.path();
        if p.is_file() {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// The files of `run` that the record covers (module docs), sorted.
pub fn in_scope(run: &Path) -> Result<Vec<PathBuf>, IoError> {
    let mut files = checkpoint_files(run)?;
    let ends = |p: &Path, s: &str| p.to_str().is_some_and(|n| n.ends_with(s));
    files.extend(
        list(&run.join("tables"))?
            .into_iter()
            .filter(|p| ends(p, ".npz")),
    );
    files.extend(list(&run.join("episodes"))?.into_iter().filter(|p| {
        ends(p, ".npz")
            || p.file_name()
                .is_some_and(|n| n == crate::io::learned::LEARNED)
    }));
    files.sort();
    Ok(files)
}

/// The record's entries; `None` when `run` has none. A last line cut by a kill is left out.
pub fn read(run: &Path) -> Result<Option<Vec<Entry>>, IoError> {
    let path = run.join(FILES);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).map_err(IoError::file("reading", &path)),
    };
    let complete = text.is_empty() || text.ends_with('\n');
    let lines: Vec<&str> = text.lines().collect();
    let mut entries = Vec::with_capacity(lines.len());
    for (k, line) in lines.iter().enumerate() {
        match serde_json::from_str(line) {
            Ok(e) => entries.push(e),
            Err(_) if k + 1 == lines.len() && !complete => {}
            Err(e) => {
                return Err(IoError::Json {
                    path: path.clone(),
                    line: Some(k + 1),
                    source: e,
                })
            }
        }
    }
    Ok(Some(entries))
}

/// What is wrong with one file against the record.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Problem {
    /// Recorded, not in the folder.
    Missing(String),
    /// In the folder, different from what the record says (why).
    Altered(String, String),
    /// In the folder, not in the record.
    Unrecorded(String),
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Problem::Missing(p) => write!(f, "{p} missing"),
            Problem::Altered(p, why) => write!(f, "{p} altered ({why})"),
            Problem::Unrecorded(p) => write!(f, "{p} not in {FILES}"),
        }
    }
}

/// The record checked against the folder: the recorded files (relative names) and what is
/// wrong. `None` when `run` has no record.
pub struct Verified {
    /// Every recorded file, by relative name.
    pub files: BTreeSet<String>,
    /// Missing, altered and unrecorded files, in name order.
    pub problems: Vec<Problem>,
}

/// Checks every file the record of `run` lists (length and hash) and that every file of the
/// record's scope in the folder is listed; `None` when `run` has no record.
pub fn verify(run: &Path) -> Result<Option<Verified>, IoError> {
    let Some(entries) = read(run)? else {
        return Ok(None);
    };
    let mut by_file: BTreeMap<String, Vec<Entry>> = BTreeMap::new();
    for e in entries {
        by_file.entry(e.file.clone()).or_default().push(e);
    }
    let mut problems = Vec::new();
    for (name, es) in &by_file {
        let path = run.join(name);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                problems.push(Problem::Missing(name.clone()));
                continue;
            }
            Err(e) => return Err(e).map_err(IoError::file("reading", &path)),
        };
        if let Some(why) = mismatch(es, &bytes) {
            problems.push(Problem::Altered(name.clone(), why));
        }
    }
    for p in in_scope(run)? {
        let name = rel(run, &p);
        if !by_file.contains_key(&name) {
            problems.push(Problem::Unrecorded(name));
        }
    }
    problems.sort_by(|a, b| key(a).cmp(key(b)));
    Ok(Some(Verified {
        files: by_file.into_keys().collect(),
        problems,
    }))
}

fn key(p: &Problem) -> &str {
    match p {
        Problem::Missing(n) | Problem::Altered(n, _) | Problem::Unrecorded(n) => n,
    }
}

/// Why `bytes` are not what the entries of one file say (`None`: they are).
fn mismatch(es: &[Entry], bytes: &[u8]) -> Option<String> {
    let start = es.iter().rposition(|e| e.from == 0).unwrap_or(0);
    let mut at = 0;
    for e in &es[start..] {
        if e.from != at || e.to < e.from {
            return Some(format!(
                "its record jumps from byte {at} to bytes {}..{}",
                e.from, e.to
            ));
        }
        let Some(seg) = bytes.get(e.from as usize..e.to as usize) else {
            return Some(format!(
                "{} bytes, the record says {}",
                bytes.len(),
                es.last().map_or(0, |l| l.to)
            ));
        };
        if fnv1a64(seg) != e.fnv1a64 {
            return Some(format!("bytes {}..{} differ from the record", e.from, e.to));
        }
        at = e.to;
    }
    (bytes.len() as u64 != at).then(|| format!("{} bytes, the record says {at}", bytes.len()))
}

/// A resume takes the folder as the killed or stopped run left it: every file of the record's
/// scope that is unrecorded, or differs from its record (a checkpoint rewritten by a kill
/// before its line), is recorded as it is now, and a cut last line of the record is dropped.
/// Starts the record of a run written by a build without one.
pub fn adopt(run: &Path) -> Result<(), IoError> {
    let path = run.join(FILES);
    if let Ok(text) = std::fs::read_to_string(&path) {
        if !text.is_empty() && !text.ends_with('\n') {
            let keep = text.rfind('\n').map_or(0, |k| k + 1);
            ur5_shared::atomic_file::write(&path, &text.as_bytes()[..keep])
                .map_err(IoError::file("writing", &path))?;
        }
    }
    let entries = read(run)?.unwrap_or_default();
    let mut by_file: BTreeMap<String, Vec<Entry>> = BTreeMap::new();
    for e in entries {
        by_file.entry(e.file.clone()).or_default().push(e);
    }
    let mut new = Vec::new();
    for p in in_scope(run)? {
        let name = rel(run, &p);
        let episode = name.starts_with("episodes/") && name.ends_with(".npz");
        match by_file.get(&name) {
            // Episode files are never rewritten (arrival numbers only grow): their length is
            // enough, which keeps a resume of a long served run cheap.
            Some(es) if episode && es.last().is_some_and(|e| e.to == len(&p)) => {}
            Some(es) => {
                let bytes = std::fs::read(&p).map_err(IoError::file("reading", &p))?;
                if mismatch(es, &bytes).is_some() {
                    new.push(whole(run, &p)?);
                }
            }
            None => new.push(whole(run, &p)?),
        }
    }
    append(run, &new)?;
    if !path.exists() {
        start(run)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_names_missing_altered_and_unrecorded_files() {
        let run = std::env::temp_dir().join(format!("files-record-{}", std::process::id()));
        std::fs::remove_dir_all(&run).ok();
        std::fs::create_dir_all(run.join("episodes")).unwrap();
        start(&run).unwrap();
        let a = run.join("iter_000_table.npz");
        let b = run.join("episodes/000001_e000000_v0001.npz");
        let l = run.join("episodes/learned.jsonl");
        std::fs::write(&a, b"table").unwrap();
        std::fs::write(&b, b"episode").unwrap();
        note(&run, &[&a, &b]).unwrap();
        for line in ["one\n", "two\n"] {
            let from = len(&l);
            let mut f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&l)
                .unwrap();
            f.write_all(line.as_bytes()).unwrap();
            note_appended(&run, &l, from).unwrap();
        }
        assert!(verify(&run).unwrap().unwrap().problems.is_empty());
        std::fs::write(&a, b"tablE").unwrap();
        std::fs::remove_file(&b).unwrap();
        std::fs::write(&l, b"one\n").unwrap();
        std::fs::write(run.join("iter_001_critic.json"), b"{}").unwrap();
        let v = verify(&run).unwrap().unwrap();
        let shown: Vec<String> = v.problems.iter().map(|p| p.to_string()).collect();
        assert_eq!(
            shown,
            [
                "episodes/000001_e000000_v0001.npz missing",
                "episodes/learned.jsonl altered (4 bytes, the record says 8)",
                "iter_000_table.npz altered (bytes 0..5 differ from the record)",
                "iter_001_critic.json not in files.jsonl",
            ]
        );
        // A resume takes the folder as it is (the missing file stays missing).
        adopt(&run).unwrap();
        let v = verify(&run).unwrap().unwrap();
        assert_eq!(
            v.problems,
            [Problem::Missing("episodes/000001_e000000_v0001.npz".into())]
        );
        std::fs::remove_dir_all(&run).ok();
    }
}
