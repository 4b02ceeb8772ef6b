//! Checkpoints (docs/design.md §4): the expert's of a served run (`checkpoint.npz`: the
//! controller executed next with all GPS policy arrays, its iteration, the random-policy
//! cost and the best controller so far with its noise-free episode and the patience count, §4.5) and LQR+GAIfO's learner state (`iter_NNN_state.npz`: a [`Snapshot`], one array
//! per entry, §4.11). Both are written atomically (temporary file, fsync, rename).

use std::path::Path;

use gps::linalg::MatSeq;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::snapshot::Snapshot;
use imitation::rollout::Episode;

use super::npz::{NpzError, NpzFile, NpzWriter};

/// Version of this file layout.
pub const SCHEMA_VERSION: i64 = 1;

/// What a served expert run's `checkpoint.npz` holds (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ExpertCheckpoint {
    /// The controller to execute next.
    pub pol: LinGaussPolicy,
    /// Iterations done.
    pub iteration: usize,
    /// The random policy's cost of the progress proxy, once known.
    pub cost_random: Option<f64>,
    /// The best controller executed so far and its noise-free episode (`best_*` arrays;
    /// absent in checkpoints written before they were added: then `None`).
    pub best: Option<(LinGaussPolicy, Episode)>,
    /// Iterations since the best one (the `patience` count).
    pub since_best: usize,
}

/// Writes the controller to execute next and where it stands (see the module docs).
pub fn save_checkpoint(path: &Path, c: &ExpertCheckpoint, seed: u64) -> Result<(), NpzError> {
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    write_policy(&mut w, "", &c.pol)?;
    w.u64("iteration", &[], &[c.iteration as u64])?;
    w.u64("table_version", &[], &[c.iteration as u64 + 1])?;
    w.f64("cost_random", &[], &[c.cost_random.unwrap_or(f64::NAN)])?;
    w.u64("seed", &[], &[seed])?;
    if let Some((pol, ep)) = &c.best {
        write_policy(&mut w, "best_", pol)?;
        let (t, du) = (ep.horizon() as u64, ep.du() as u64);
        w.f64("best_x", &[t, ep.dx() as u64], &ep.x)?;
        w.f64("best_u", &[t, du], &ep.u)?;
        w.f64("best_u_policy", &[t, du], &ep.u_policy)?;
        // Episodes assembled from the controller's samples carry no noise (empty).
        w.f64("best_eps", &[ep.eps.len() as u64 / du, du], &ep.eps)?;
        w.u64("best_noisy", &[], &[u64::from(ep.noisy)])?;
        w.u64("since_best", &[], &[c.since_best as u64])?;
    }
    w.finish()?;
    Ok(())
}

fn write_policy(w: &mut NpzWriter, prefix: &str, pol: &LinGaussPolicy) -> Result<(), NpzError> {
    let (t, dx, du) = (pol.t as u64, pol.dx as u64, pol.du as u64);
    w.f64(&format!("{prefix}K"), &[t, du, dx], &pol.gain.data)?;
    w.f64(&format!("{prefix}k"), &[t, du], &pol.k.data)?;
    for (name, m) in [
        ("pol_covar", &pol.pol_covar),
        ("chol_pol_covar", &pol.chol_pol_covar),
        ("inv_pol_covar", &pol.inv_pol_covar),
    ] {
        w.f64(&format!("{prefix}{name}"), &[t, du, du], &m.data)?;
    }
    Ok(())
}

fn read_policy(f: &NpzFile, prefix: &str) -> Result<LinGaussPolicy, NpzError> {
    let (shape, gain) = f.f64(&format!("{prefix}K"))?;
    let [t, du, dx] = shape[..] else {
        return Err(f.bad(
            &format!("{prefix}K"),
            format!("shape {shape:?}, expected (T, dU, dX)"),
        ));
    };
    if ur5_shared::StateLayout::from_dims(dx as usize, du as usize).is_none() {
        return Err(f.bad(
            &format!("{prefix}K"),
            format!("shape {shape:?}: (dU, dX) = ({du}, {dx}) is no task's (3 or 6 joints, 1 or 3 tool points)"),
        ));
    }
    let (tn, dun) = (t as usize, du as usize);
    let seq = |name: &str, cols: u64| -> Result<MatSeq, NpzError> {
        let data = f.f64_shaped(&format!("{prefix}{name}"), &[t, du, cols])?;
        Ok(MatSeq::from_vec(tn, dun, cols as usize, data))
    };
    let pol = LinGaussPolicy {
        t: tn,
        dx: dx as usize,
        du: dun,
        gain: MatSeq::from_vec(tn, dun, dx as usize, gain),
        k: MatSeq::from_vec(tn, dun, 1, f.f64_shaped(&format!("{prefix}k"), &[t, du])?),
        pol_covar: seq("pol_covar", du)?,
        chol_pol_covar: seq("chol_pol_covar", du)?,
        inv_pol_covar: seq("inv_pol_covar", du)?,
    };
    let all = [&pol.gain, &pol.k, &pol.pol_covar, &pol.chol_pol_covar];
    if !all.iter().all(|m| m.data.iter().all(|v| v.is_finite())) {
        return Err(f.bad(&format!("{prefix}K"), "non-finite controller values".into()));
    }
    Ok(pol)
}

/// Reads a checkpoint written by [`save_checkpoint`].
pub fn load_checkpoint(path: &Path) -> Result<ExpertCheckpoint, NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let pol = read_policy(&f, "")?;
    let iteration = f.u64_scalar("iteration")? as usize;
    let cost_random = f.f64_shaped("cost_random", &[])?[0];
    let (best, since_best) = if f.names().iter().any(|n| n == "best_K") {
        let best = read_policy(&f, "best_")?;
        let (t, du) = (best.t as u64, best.du as u64);
        let layout = ur5_shared::StateLayout::from_dims(best.dx, best.du).expect("checked");
        let ep = Episode {
            layout,
            x: f.f64_shaped("best_x", &[t, best.dx as u64])?,
            u: f.f64_shaped("best_u", &[t, du])?,
            u_policy: f.f64_shaped("best_u_policy", &[t, du])?,
            eps: match f.f64("best_eps")? {
                (s, v) if s == [t, du] || s == [0, du] => v,
                (s, _) => {
                    return Err(f.bad(
                        "best_eps",
                        format!("shape {s:?}, expected ({t}, {du}) or (0, {du})"),
                    ))
                }
            },
            noisy: f.u64_scalar("best_noisy")? != 0,
        };
        if !ep.x.iter().chain(&ep.u).all(|v| v.is_finite()) {
            return Err(f.bad(
                "best_x",
                "non-finite values in the best controller's episode".into(),
            ));
        }
        (Some((best, ep)), f.u64_scalar("since_best")? as usize)
    } else {
        (None, 0)
    };
    Ok(ExpertCheckpoint {
        pol,
        iteration,
        cost_random: cost_random.is_finite().then_some(cost_random),
        best,
        since_best,
    })
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
