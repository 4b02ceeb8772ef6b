//! The comparisons of a replay: the recorded tables, checkpoint files and learner states
//! against the replayed learner's.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use imitation::learn::LinGaussLearn;

use super::{Checked, ReplayError, ReplayReport, Scratch};
use crate::io::table::{load_stored, table_arrays};
use crate::io::IoError;
use crate::run::Checkpoint;

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

/// The recorded tables of the state after `i` iterations of a gain-table learner
/// (`iter_NNN_table.npz`, `tables/vVERSION.npz`) against its table, entry by entry.
pub(super) fn tables<L: LinGaussLearn>(
    learner: &L,
    dir: &Path,
    i: usize,
    report: &mut ReplayReport,
) -> Result<Checked, ReplayError> {
    gain_tables(&learner.table(), dir, i, report)
}

/// The recorded tables of the state after `i` iterations (`iter_NNN_table.npz`,
/// `tables/vVERSION.npz`, VERSION = `table.version`) against `table`, entry by entry.
pub(super) fn gain_tables(
    table: &ur5_shared::GainTable,
    dir: &Path,
    i: usize,
    report: &mut ReplayReport,
) -> Result<Checked, ReplayError> {
    let v = table.version;
    let files: Vec<PathBuf> = [
        dir.join(format!("iter_{i:03}_table.npz")),
        crate::io::table::version_path(dir, v),
    ]
    .into_iter()
    .filter(|p| p.is_file())
    .collect();
    if files.is_empty() {
        return Ok(Checked::NothingRecorded);
    }
    let arrays = table_arrays(table);
    for f in files {
        let stored = load_stored(&f)?;
        report.tables_checked += 1;
        report.compared.insert(f.clone());
        if let Some((array, index, rec, rep)) = table_difference(&stored, &arrays, table) {
            return Ok(Checked::Differs((f, array, index, rec, rep)));
        }
    }
    Ok(Checked::Equal)
}

/// The recorded checkpoint files `iter_NNN_KIND` (NNN = `i`) of each of `kinds`
/// (`critic.json`, `policy.json`) against the replayed learner's, written by the same
/// [`Checkpoint`] code into a scratch folder, byte for byte; the difference names the first
/// differing byte offset and the text around it.
pub(super) fn checkpoint_files<L: Checkpoint>(
    learner: &L,
    dir: &Path,
    i: usize,
    kinds: &[&str],
    report: &mut ReplayReport,
) -> Result<Checked, ReplayError> {
    let name = |kind: &str| format!("iter_{i:03}_{kind}");
    let recorded: Vec<&str> = kinds
        .iter()
        .copied()
        .filter(|k| dir.join(name(k)).is_file())
        .collect();
    if recorded.is_empty() {
        return Ok(Checked::NothingRecorded);
    }
    let tmp = Scratch::new()?;
    learner.checkpoint(&tmp.0, None)?;
    for kind in recorded {
        let file = dir.join(name(kind));
        let rec = std::fs::read(&file).map_err(IoError::file("reading", &file))?;
        let written = tmp.0.join(name(kind));
        let rep = std::fs::read(&written).map_err(IoError::file("reading", &written))?;
        report.compared.insert(file.clone());
        match kind {
            "policy.json" => report.policies_checked += 1,
            _ => report.critics_checked += 1,
        }
        let Some(at) = (0..rec.len().max(rep.len())).find(|&j| rec.get(j) != rep.get(j)) else {
            continue;
        };
        let around = |b: &[u8]| {
            let lo = at.saturating_sub(20);
            String::from_utf8_lossy(&b[lo.min(b.len())..(at + 40).min(b.len())]).into_owned()
        };
        let array = kind.trim_end_matches(".json").to_string();
        return Ok(Checked::Differs((
            file,
            array,
            vec![at as u64],
            around(&rec),
            around(&rep),
        )));
    }
    Ok(Checked::Equal)
}

/// The recorded learner state `iter_NNN_state.npz` (NNN = `i`) against the replayed learner's
/// `snap`, entry by entry and bit for bit, without the in-process arm's noise position (a
/// replay runs no arm); a critic file without its state (a kill between the two) is compared
/// alone.
pub(super) fn state_file(
    snap: &gps::snapshot::Snapshot,
    dir: &Path,
    i: usize,
    report: &mut ReplayReport,
) -> Result<Checked, ReplayError> {
    let file = dir.join(format!("iter_{i:03}_state.npz"));
    if !file.is_file() {
        return Ok(Checked::Equal);
    }
    let mut rec = crate::io::checkpoint::load_state(&file)?;
    rec.words.remove(crate::run::ARM_NOISE);
    report.policies_checked += 1;
    report.compared.insert(file.clone());
    let names: BTreeSet<&String> = rec.reals.keys().chain(snap.reals.keys()).collect();
    for name in names {
        let differs = |r: String, p: String| {
            Ok(Checked::Differs((
                file.clone(),
                name.clone(),
                Vec::new(),
                r,
                p,
            )))
        };
        let (Some((rs, rv)), Some((ps, pv))) = (rec.reals.get(name), snap.reals.get(name)) else {
            let has = |b: bool| if b { "present" } else { "absent" }.to_string();
            return differs(
                has(rec.reals.contains_key(name)),
                has(snap.reals.contains_key(name)),
            );
        };
        if rs != ps {
            return differs(format!("shape {rs:?}"), format!("shape {ps:?}"));
        }
        if let Some(j) = (0..rv.len()).find(|&j| rv[j].to_bits() != pv[j].to_bits()) {
            return Ok(Checked::Differs((
                file.clone(),
                name.clone(),
                vec![j as u64],
                show(rv[j]),
                show(pv[j]),
            )));
        }
    }
    if rec.words != snap.words {
        let name = rec
            .words
            .keys()
            .chain(snap.words.keys())
            .find(|k| rec.words.get(*k) != snap.words.get(*k))
            .cloned()
            .unwrap_or_default();
        return Ok(Checked::Differs((
            file.clone(),
            name.clone(),
            Vec::new(),
            format!("{:?}", rec.words.get(&name)),
            format!("{:?}", snap.words.get(&name)),
        )));
    }
    Ok(Checked::Equal)
}
