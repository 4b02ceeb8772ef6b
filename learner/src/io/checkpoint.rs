//! Checkpoints (docs/design.md §4): the expert's of a served run (`checkpoint.npz`: the
//! controller executed next with all GPS policy arrays, its iteration and the random-policy
//! cost, §4.5) and LQR+GAIfO's learner state (`iter_NNN_state.npz`: a [`Snapshot`], one array
//! per entry, §4.11). Both are written atomically (temporary file, fsync, rename).

use std::path::Path;

use gps::linalg::MatSeq;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::snapshot::Snapshot;
use ur5_shared::layout::{DU, DX};

use super::npz::{NpzError, NpzFile, NpzWriter};

/// Version of this file layout.
pub const SCHEMA_VERSION: i64 = 1;

/// Writes the controller to execute next and where it stands (see the module docs).
pub fn save_checkpoint(
    path: &Path,
    pol: &LinGaussPolicy,
    iteration: usize,
    cost_random: Option<f64>,
    seed: u64,
) -> anyhow::Result<()> {
    let (t, dx, du) = (pol.t as u64, pol.dx as u64, pol.du as u64);
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    w.f64("K", &[t, du, dx], &pol.gain.data)?;
    w.f64("k", &[t, du], &pol.k.data)?;
    w.f64("pol_covar", &[t, du, du], &pol.pol_covar.data)?;
    w.f64("chol_pol_covar", &[t, du, du], &pol.chol_pol_covar.data)?;
    w.f64("inv_pol_covar", &[t, du, du], &pol.inv_pol_covar.data)?;
    w.u64("iteration", &[], &[iteration as u64])?;
    w.u64("table_version", &[], &[iteration as u64 + 1])?;
    w.f64("cost_random", &[], &[cost_random.unwrap_or(f64::NAN)])?;
    w.u64("seed", &[], &[seed])?;
    w.finish()?;
    Ok(())
}

/// Reads a checkpoint: (controller, iteration, random-policy cost).
pub fn load_checkpoint(path: &Path) -> anyhow::Result<(LinGaussPolicy, usize, Option<f64>)> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let (shape, gain) = f.f64("K")?;
    let [t, du, dx] = shape[..] else {
        anyhow::bail!(
            "{}: K has shape {shape:?}, expected (T, dU, dX)",
            path.display()
        );
    };
    anyhow::ensure!(
        (du, dx) == (DU as u64, DX as u64),
        "{}: K has shape {shape:?}, expected (T, {DU}, {DX})",
        path.display()
    );
    let (tn, dun) = (t as usize, du as usize);
    let seq = |name: &str, cols: u64| -> anyhow::Result<MatSeq> {
        let data = f.f64_shaped(name, &[t, du, cols])?;
        Ok(MatSeq::from_vec(tn, dun, cols as usize, data))
    };
    let pol = LinGaussPolicy {
        t: tn,
        dx: DX,
        du: DU,
        gain: MatSeq::from_vec(tn, dun, DX, gain),
        k: MatSeq::from_vec(tn, dun, 1, f.f64_shaped("k", &[t, du])?),
        pol_covar: seq("pol_covar", du)?,
        chol_pol_covar: seq("chol_pol_covar", du)?,
        inv_pol_covar: seq("inv_pol_covar", du)?,
    };
    let all = [&pol.gain, &pol.k, &pol.pol_covar, &pol.chol_pol_covar];
    anyhow::ensure!(
        all.iter().all(|m| m.data.iter().all(|v| v.is_finite())),
        "{}: non-finite controller values",
        path.display()
    );
    let iteration = f.u64_scalar("iteration")? as usize;
    let cost_random = f.f64_shaped("cost_random", &[])?[0];
    Ok((
        pol,
        iteration,
        cost_random.is_finite().then_some(cost_random),
    ))
}

/// Version of the learner-state layout (`iter_NNN_state.npz`).
pub const STATE_SCHEMA_VERSION: i64 = 1;

/// Writes the learner state `snap` to `path`: `schema_version`, then each f64 entry with its
/// shape and each u64 entry as a 1-d uint64 array, under its own name.
pub fn save_state(path: &Path, snap: &Snapshot) -> Result<(), NpzError> {
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[STATE_SCHEMA_VERSION])?;
    for (name, (shape, data)) in &snap.reals {
        let shape: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
        w.f64(name, &shape, data)?;
    }
    for (name, data) in &snap.words {
        w.u64(name, &[data.len() as u64], data)?;
    }
    w.finish()?;
    Ok(())
}

/// Reads a learner state written by [`save_state`]. Whether it fits the run is checked where it
/// is restored (`imitation::gaifo::LqrGaifo::from_snapshot`).
pub fn load_state(path: &Path) -> Result<Snapshot, NpzError> {
    let f = NpzFile::open_schema(path, STATE_SCHEMA_VERSION)?;
    let mut snap = Snapshot::default();
    for name in f.names() {
        if name == "schema_version" {
            continue;
        }
        match f.dtype(&name)?.as_str() {
            "f8" => {
                let (shape, data) = f.f64(&name)?;
                let shape = shape
                    .iter()
                    .map(|&d| usize::try_from(d))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|_| f.bad(&name, format!("shape {shape:?} too large")))?;
                snap.reals.insert(name, (shape, data));
            }
            "u8" => {
                let (shape, data) = f.u64s(&name)?;
                if shape.len() != 1 {
                    return Err(f.bad(&name, format!("shape {shape:?}, expected 1-d")));
                }
                snap.words.insert(name, data);
            }
            other => {
                return Err(f.bad(&name, format!("dtype {other}, expected f8 or u8")));
            }
        }
    }
    Ok(snap)
}
