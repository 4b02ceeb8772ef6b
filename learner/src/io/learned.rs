//! `episodes/learned.jsonl`: which recorded episodes each update of a served run learned
//! from, and where a learner was resumed (docs/design.md §4.13). `learner serve` appends one
//! JSON line per event; `learner replay` follows it, so that a run resumed with `--resume`
//! (whose learner learned from episodes that arrived after the restart, not from the first
//! ones of the version) replays bit for bit.
//!
//! Lines, in the order they happened:
//! - `{"event":"learned","iteration":I,"version":V,"noisy":[FILE…],"eval":FILE}`: update I
//!   (1-based; it makes table version V + 1) learned from the episode files (names in
//!   `episodes/`) of table version V: the noisy ones in the order learned, then the noise-free
//!   one. Written before the update's checkpoint, so a kill between the two leaves a line whose
//!   update a resume does again: the last `learned` line of a version is the one that counts.
//! - `{"event":"resumed","iteration":I,"same_folder":B}`: a learner resumed from a checkpoint
//!   after I updates (`--resume`); `same_folder`: the checkpoint was this folder's (false for
//!   `--resume OTHER --out THIS`: the iterations before I are in OTHER).
//!
//! Each line is one `write` of an append-only file; a kill can cut only the last line, which
//! [`read_events`] then leaves out.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::IoError;
use serde::{Deserialize, Serialize};

/// The file's name inside the `episodes/` folder.
pub const LEARNED: &str = "learned.jsonl";

/// One line of `learned.jsonl` (module docs).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case", deny_unknown_fields)]
pub enum LearnedEvent {
    /// Update `iteration` learned from these episode files of table `version` (with several
    /// goals: the noisy episodes goal-major, `eval` the first goal's evaluation and
    /// `more_evals` the others', in goal order).
    Learned {
        iteration: usize,
        version: u64,
        noisy: Vec<String>,
        eval: String,
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        more_evals: Vec<String>,
    },
    /// A learner resumed after `iteration` updates.
    Resumed { iteration: usize, same_folder: bool },
}

/// Appends `event` as one line to `episodes/learned.jsonl`.
pub fn append_event(episodes: &Path, event: &LearnedEvent) -> Result<(), IoError> {
    let path = episodes.join(LEARNED);
    let mut line = serde_json::to_vec(event)?;
    line.push(b'\n');
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(&line))
        .map_err(IoError::file("appending to", &path))
}

/// The events of `episodes/learned.jsonl`, in order; `None` when there is no such file (a run
/// of `learner train`, or of a build before 2026-12-02). A last line cut by a kill is left
/// out; any other line that does not parse is an error naming it.
pub fn read_events(episodes: &Path) -> Result<Option<Vec<LearnedEvent>>, IoError> {
    let path = episodes.join(LEARNED);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).map_err(IoError::file("reading", &path)),
    };
    let complete = text.ends_with('\n');
    let lines: Vec<&str> = text.lines().collect();
    let mut events = Vec::with_capacity(lines.len());
    for (k, line) in lines.iter().enumerate() {
        match serde_json::from_str(line) {
            Ok(e) => events.push(e),
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
    Ok(Some(events))
}

/// The file names of episode paths, as `learned.jsonl` lists them.
pub fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// The paths in `episodes` of the names an event lists.
pub fn paths(episodes: &Path, names: &[String]) -> Vec<PathBuf> {
    names.iter().map(|n| episodes.join(n)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_round_trip_and_a_cut_last_line_is_left_out() {
        let dir = std::env::temp_dir().join(format!("learned-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        assert_eq!(read_events(&dir).unwrap(), None);
        let a = LearnedEvent::Learned {
            iteration: 1,
            version: 1,
            noisy: vec!["000001_e000000_v0001.npz".into()],
            eval: "000002_e000001_v0001.npz".into(),
            more_evals: Vec::new(),
        };
        let b = LearnedEvent::Resumed {
            iteration: 1,
            same_folder: true,
        };
        append_event(&dir, &a).unwrap();
        append_event(&dir, &b).unwrap();
        assert_eq!(read_events(&dir).unwrap(), Some(vec![a.clone(), b.clone()]));
        // A kill in the middle of a line.
        let path = dir.join(LEARNED);
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str("{\"event\":\"learned\",\"iter");
        std::fs::write(&path, &text).unwrap();
        assert_eq!(read_events(&dir).unwrap(), Some(vec![a, b]));
        // Damage elsewhere is an error naming the line.
        std::fs::write(&path, format!("garbage\n{text}\n")).unwrap();
        let e = read_events(&dir).unwrap_err().to_string();
        assert!(e.contains("line 1"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
