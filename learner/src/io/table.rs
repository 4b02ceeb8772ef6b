//! Gain tables on disk (`.npz`, docs/design.md §4.4), in the project's form
//! a = K_t (s − ŝ_t) + k_t + â_t + L_t ε:
//!
//! | array | shape | meaning |
//! |---|---|---|
//! | `K` | (T, dU, dX) | feedback gains |
//! | `k` | (T, dU) | feed-forward (action units) |
//! | `s_hat` | (T, dX) | state the gains are centred on |
//! | `a_hat` | (T, dU) | nominal action |
//! | `L` | (T, dU, dU) | lower Cholesky factor of the action covariance |
//! | `version`, `checksum` | () u64 | as in `ur5_shared::GainTable` |
//! | `epoch` | () u64 | the publication of the version (`GainTable::epoch`), written when not 0; absent: 0 |
//! | `plan_flags`, `plan_noise_stream` | () u64 | the episode plan (`ur5_shared::EpisodePlan`), written when it is not the default; absent: 0 |
//! | `plan_goal` | (3,) f64 | the plan's goal (m), with the two above; absent: 0 |
//! | `dt` | () f64 | control period (s) |
//! | `state_names`, `action_names` | | the layout's names (`ur5_shared::StateLayout`) |
//! | `schema_version` | () i64 | [`SCHEMA_VERSION`] |
//!
//! A learner whose policy is an MLP (BCO, GAIfO (TD3)) publishes policy tables instead; `learner
//! serve` records them under the same names ([`save_policy_table`], schema
//! [`POLICY_SCHEMA_VERSION`]): `params` (P,) f64 θ as sent (`ur5_shared::PolicyTable`), `hidden`
//! (H,) u64, `action_mode` and `model` () u64 (the table's codes), then `version`, `checksum`,
//! `epoch`, the plan, `dt` and the names as above. [`stored_epoch`] reads the epoch of either.
//!
//! dX and dU are the table's task's (K's shape): loading takes them from the file, refuses
//! dimensions of no task naming them, rebuilds the table, checks the stored checksum and runs
//! `GainTable::validate`. Whether they are the caller's task's is `GainTable::check_layout`.

use std::path::{Path, PathBuf};

use ur5_shared::{EpisodePlan, GainBounds, GainStep, GainTable, PolicyTable, StateLayout};

use super::npz::{NpzError, NpzFile, NpzWriter};

/// Version of this file layout: 2 since the checksum became XXH3-64 (schema 1 stored FNV-1a 64;
/// such files are refused by their schema version rather than by a checksum mismatch).
pub const SCHEMA_VERSION: i64 = 2;

/// The float arrays of the file layout (module docs) of `table`'s used steps: (name, shape,
/// row-major values).
pub fn table_arrays(table: &GainTable) -> Vec<(&'static str, Vec<u64>, Vec<f64>)> {
    let t = table.horizon();
    let (dx, du) = table.dims();
    let flat = |f: fn(GainStep<'_>) -> &[f64]| {
        (0..t)
            .flat_map(|i| f(table.step(i)).to_vec())
            .collect::<Vec<f64>>()
    };
    let (t, dx, du) = (t as u64, dx as u64, du as u64);
    vec![
        ("K", vec![t, du, dx], flat(|s| s.k_mat)),
        ("k", vec![t, du], flat(|s| s.k_vec)),
        ("s_hat", vec![t, dx], flat(|s| s.s_hat)),
        ("a_hat", vec![t, du], flat(|s| s.a_hat)),
        ("L", vec![t, du, du], flat(|s| s.chol)),
    ]
}

/// `run_dir/tables/vVERSION.npz`: where `learner serve` records each table it publishes.
pub fn version_path(run_dir: &Path, version: u64) -> PathBuf {
    run_dir.join("tables").join(format!("v{version:04}.npz"))
}

/// Writes `table` (its used steps) with control period `dt` (s).
pub fn save_table(path: &Path, table: &GainTable, dt: f64) -> Result<(), NpzError> {
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    for (name, shape, data) in table_arrays(table) {
        w.f64(name, &shape, &data)?;
    }
    let (dx, du) = table.dims();
    let head = Header {
        version: table.version,
        epoch: table.epoch,
        plan: &table.plan,
        checksum: table.checksum,
        dims: (dx, du),
        dt,
    };
    head.write(&mut w, path, "K")?;
    w.finish()?;
    Ok(())
}

/// Version of the policy-table file layout (module docs).
pub const POLICY_SCHEMA_VERSION: i64 = 1;

/// Writes policy table `table` with control period `dt` (s) (module docs).
pub fn save_policy_table(path: &Path, table: &PolicyTable, dt: f64) -> Result<(), NpzError> {
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[POLICY_SCHEMA_VERSION])?;
    let theta = table.theta();
    w.f64("params", &[theta.len() as u64], theta)?;
    let hidden: Vec<u64> = table.hidden_widths().map(|h| h as u64).collect();
    w.u64("hidden", &[hidden.len() as u64], &hidden)?;
    w.u64("action_mode", &[], &[u64::from(table.action_mode)])?;
    w.u64("model", &[], &[u64::from(table.model)])?;
    let head = Header {
        version: table.version,
        epoch: table.epoch,
        plan: &table.plan,
        checksum: table.checksum,
        dims: table.dims(),
        dt,
    };
    head.write(&mut w, path, "params")?;
    w.finish()?;
    Ok(())
}

/// The epoch recorded in a table file of either kind (0 when absent), its schema checked.
pub fn stored_epoch(path: &Path) -> Result<u32, NpzError> {
    let f = NpzFile::open(path)?;
    if f.names().iter().any(|n| n == "params") {
        f.check_schema(POLICY_SCHEMA_VERSION)?;
    } else {
        f.check_schema(SCHEMA_VERSION)?;
    }
    f.u32_scalar_or_zero("epoch")
}

/// What both kinds of table file store after their arrays.
struct Header<'a> {
    version: u64,
    epoch: u32,
    plan: &'a EpisodePlan,
    checksum: u64,
    /// (dX, dU).
    dims: (usize, usize),
    dt: f64,
}

impl Header<'_> {
    /// Writes the scalars, the plan unless it is the default, and the layout's names;
    /// `array`: the array to name when the dimensions are of no task.
    fn write(&self, w: &mut NpzWriter, path: &Path, array: &str) -> Result<(), NpzError> {
        w.u64("version", &[], &[self.version])?;
        if self.epoch != 0 {
            w.u64("epoch", &[], &[u64::from(self.epoch)])?;
        }
        if !self.plan.is_default() {
            w.u64("plan_flags", &[], &[u64::from(self.plan.flags)])?;
            w.u64(
                "plan_noise_stream",
                &[],
                &[u64::from(self.plan.noise_stream)],
            )?;
            w.f64("plan_goal", &[3], &self.plan.goal)?;
        }
        w.u64("checksum", &[], &[self.checksum])?;
        w.f64("dt", &[], &[self.dt])?;
        let (dx, du) = self.dims;
        let layout = StateLayout::from_dims(dx, du).ok_or_else(|| NpzError::Bad {
            path: path.to_path_buf(),
            name: array.into(),
            why: format!("dx = {dx}, du = {du} are the dimensions of no task"),
        })?;
        let (state, action) = (layout.state_names(), layout.action_names());
        w.strings(
            "state_names",
            &state.iter().map(String::as_str).collect::<Vec<_>>(),
        )?;
        w.strings(
            "action_names",
            &action.iter().map(String::as_str).collect::<Vec<_>>(),
        )?;
        Ok(())
    }
}

/// A table file as stored, without any check beyond its schema: the float arrays of
/// [`table_arrays`] (same order) and the `version`, `checksum` and `epoch` scalars (`learner replay`
/// compares them entry by entry).
pub struct StoredTable {
    /// (name, shape, values) of `K`, `k`, `s_hat`, `a_hat`, `L`.
    pub arrays: Vec<(&'static str, Vec<u64>, Vec<f64>)>,
    /// `version`.
    pub version: u64,
    /// `checksum`.
    pub checksum: u64,
    /// `epoch` (0 when absent).
    pub epoch: u32,
}

/// Reads a table file as stored ([`StoredTable`]).
pub fn load_stored(path: &Path) -> Result<StoredTable, NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let mut arrays = Vec::new();
    for name in ["K", "k", "s_hat", "a_hat", "L"] {
        let (shape, data) = f.f64(name)?;
        arrays.push((name, shape, data));
    }
    Ok(StoredTable {
        arrays,
        version: f.u64_scalar("version")?,
        checksum: f.u64_scalar("checksum")?,
        epoch: f.u32_scalar_or_zero("epoch")?,
    })
}

/// Reads a table and validates it against `bounds`; returns it with its control period (s).
pub fn load_table(path: &Path, bounds: &GainBounds) -> Result<(Box<GainTable>, f64), NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let bad = |name: &str, why: String| f.bad(name, why);
    let (shape, k_mat) = f.f64("K")?;
    let [t, du, dx] = shape[..] else {
        return Err(bad("K", format!("shape {shape:?}, expected (T, dU, dX)")));
    };
    let Some(layout) = StateLayout::from_dims(dx as usize, du as usize) else {
        return Err(bad(
            "K",
            format!("shape {shape:?}: dX = {dx}, dU = {du} are the dimensions of no task (dX = 2n + 6p, dU = n for n joints and p tool points)"),
        ));
    };
    let k_vec = f.f64_shaped("k", &[t, du])?;
    let s_hat = f.f64_shaped("s_hat", &[t, dx])?;
    let a_hat = f.f64_shaped("a_hat", &[t, du])?;
    let chol = f.f64_shaped("L", &[t, du, du])?;
    let dt = f.f64_shaped("dt", &[])?[0];
    let (dx, du) = (dx as usize, du as usize);
    let mut table = GainTable::new_boxed_for(&layout);
    table
        .set_horizon(t as usize)
        .map_err(|e| bad("K", e.to_string()))?;
    table.set_version(f.u64_scalar("version")?);
    table.epoch = f.u32_scalar_or_zero("epoch")?;
    if f.names().iter().any(|n| n == "plan_goal") {
        table.plan.flags = f.u32_scalar_or_zero("plan_flags")?;
        table.plan.noise_stream = f.u32_scalar_or_zero("plan_noise_stream")?;
        let goal = f.f64_shaped("plan_goal", &[3])?;
        table.plan.goal.copy_from_slice(&goal);
    }
    for ti in 0..t as usize {
        let step = table.step_mut(ti);
        step.k_mat
            .copy_from_slice(&k_mat[ti * du * dx..(ti + 1) * du * dx]);
        step.chol
            .copy_from_slice(&chol[ti * du * du..(ti + 1) * du * du]);
        step.k_vec.copy_from_slice(&k_vec[ti * du..(ti + 1) * du]);
        step.a_hat.copy_from_slice(&a_hat[ti * du..(ti + 1) * du]);
        step.s_hat.copy_from_slice(&s_hat[ti * dx..(ti + 1) * dx]);
    }
    table.checksum = f.u64_scalar("checksum")?;
    table
        .validate(bounds)
        .map_err(|e| bad("(table)", e.to_string()))?;
    Ok((table, dt))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_rejects_a_tampered_file() {
        let dir = std::env::temp_dir().join(format!("table-test-{}", std::process::id()));
        let path = dir.join("t.npz");
        let mut table = GainTable::new_boxed();
        table.set_horizon(4).unwrap();
        table.set_version(3);
        for t in 0..4 {
            let mut s = table.step_mut(t);
            s.set_k(1, 5, 0.5 + t as f64);
            s.k_vec.copy_from_slice(&[0.1, -0.2, 0.3]);
            s.s_hat[7] = -0.4;
            s.a_hat.copy_from_slice(&[1.0, -1.5, 2.0]);
            s.chol
                .copy_from_slice(&[0.2, 0.0, 0.0, 0.01, 0.3, 0.0, 0.0, -0.02, 0.1]);
        }
        table.seal();
        save_table(&path, &table, 0.1).unwrap();
        let (back, dt) = load_table(&path, &GainBounds::default()).unwrap();
        assert_eq!(dt, 0.1);
        assert_eq!(back.used_values(), table.used_values());
        assert_eq!(back.checksum, table.checksum);

        // A value changed without re-sealing: the checksum no longer matches.
        let mut tampered = table.boxed_clone();
        tampered.step_mut(2).k_vec[0] = 9.0;
        save_table(&path, &tampered, 0.1).unwrap();
        let e = load_table(&path, &GainBounds::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("checksum"), "{e}");

        // An episode plan round-trips (and is covered by the checksum); a file without one
        // (every file of an earlier build) reads as the default plan.
        let mut planned = table.boxed_clone();
        planned.plan = ur5_shared::EpisodePlan::to_goal([-0.45, 0.15, 0.2]).with_noise_stream(4);
        planned.seal();
        assert_ne!(planned.checksum, table.checksum);
        save_table(&path, &planned, 0.1).unwrap();
        let (back, _) = load_table(&path, &GainBounds::default()).unwrap();
        assert_eq!(*back, *planned);
        save_table(&path, &table, 0.1).unwrap();
        let (back, _) = load_table(&path, &GainBounds::default()).unwrap();
        assert!(back.plan.is_default());
        // The plan changed in the file (here: dropped) fails the checksum.
        let mut dropped = planned.boxed_clone();
        dropped.plan = ur5_shared::EpisodePlan::default();
        save_table(&path, &dropped, 0.1).unwrap();
        let e = load_table(&path, &GainBounds::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("checksum"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A table of another task (six joints and a pose) round-trips with its dimensions; a
    /// file whose K has the dimensions of no task is refused naming them.
    #[test]
    fn any_layout_round_trips_and_impossible_dimensions_are_refused() {
        let dir = std::env::temp_dir().join(format!("table-test-6-{}", std::process::id()));
        let path = dir.join("t.npz");
        let layout = StateLayout::POSE6;
        let mut table = GainTable::new_boxed_for(&layout);
        table.set_horizon(3).unwrap();
        table.set_version(2);
        for t in 0..3 {
            let mut s = table.step_mut(t);
            s.set_k(5, 29, 0.25 * t as f64);
            for i in 0..6 {
                s.set_l(i, i, 0.5);
            }
        }
        table.seal();
        save_table(&path, &table, 0.01).unwrap();
        let (back, _) = load_table(&path, &GainBounds::default()).unwrap();
        assert_eq!(back.dims(), (30, 6));
        assert_eq!(*back, *table);
        let e = back.check_layout(&StateLayout::REACH3).unwrap_err();
        assert!(e.to_string().contains("dX = 30, dU = 6"), "{e}");

        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.f64("K", &[1, 3, 13], &[0.0; 39]).unwrap();
        w.finish().unwrap();
        let e = load_table(&path, &GainBounds::default())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("dX = 13, dU = 3"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
