//! Demonstrations on disk: state-only trajectories of the expert (and, separately, its
//! actions for diagnostics), as `.npz` readable by numpy:
//!
//! | array | shape | meaning |
//! |---|---|---|
//! | `states` | (D, T, dX) f64 | s_t of each demonstration (layout: `state_names`) |
//! | `actions_diagnostic` | (D, T, dU) f64 | actions the expert took; never used for imitation |
//! | `goal` | (3,) f64 | goal point (m, base frame) |
//! | `start_q` | (3,) f64 | start pose (rad) |
//! | `dt` | () f64 | control period (s) |
//! | `seed` | () u64 | seed of the run that recorded them |
//! | `cost_random`, `cost_expert` | () f64 | mean task cost of the random policy / of these demos |
//! | `state_names`, `action_names` | (dX,), (dU,) str | layout |
//! | `schema_version` | () i64 | [`SCHEMA_VERSION`] |
//!
//! Loading checks every shape, the dimensions and layout, and that every number is finite,
//! and says exactly what is wrong.

use std::path::Path;

use ur5_shared::layout::{ACTION_NAMES, DU, DX, STATE_NAMES};

use imitation::demos::Demos;

use super::npz::{NpzError, NpzFile, NpzWriter};

/// Version of this file layout.
pub const SCHEMA_VERSION: i64 = 1;

/// Writes `demos` to `path` (atomically).
pub fn save(demos: &Demos, path: &Path) -> Result<(), NpzError> {
    let d = demos;
    let (n, t) = (d.count as u64, d.horizon as u64);
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    w.f64("states", &[n, t, DX as u64], &d.states)?;
    w.f64("actions_diagnostic", &[n, t, DU as u64], &d.actions)?;
    w.f64("goal", &[3], &d.goal)?;
    w.f64("start_q", &[3], &d.start_q)?;
    w.f64("dt", &[], &[d.dt])?;
    w.u64("seed", &[], &[d.seed])?;
    w.f64("cost_random", &[], &[d.cost_random])?;
    w.f64("cost_expert", &[], &[d.cost_expert])?;
    w.strings("state_names", &STATE_NAMES)?;
    w.strings("action_names", &ACTION_NAMES)?;
    w.finish()?;
    Ok(())
}

/// Reads and checks demonstrations.
pub fn load(path: &Path) -> Result<Demos, NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let bad = |name: &str, why: String| f.bad(name, why);
    let names = f.strings("state_names")?;
    if names != STATE_NAMES {
        return Err(bad(
            "state_names",
            format!("{names:?} is not this project's state layout {STATE_NAMES:?}"),
        ));
    }
    let (shape, states) = f.f64("states")?;
    let [d, t, dx] = shape[..] else {
        return Err(bad(
            "states",
            format!("shape {shape:?}, expected (D, T, {DX})"),
        ));
    };
    if dx != DX as u64 {
        return Err(bad(
            "states",
            format!("state dimension {dx}, expected dX = {DX}"),
        ));
    }
    if d == 0 || t < 2 {
        return Err(bad(
            "states",
            format!("{d} demonstrations of {t} steps: need at least 1 of at least 2 steps"),
        ));
    }
    let actions = f.f64_shaped("actions_diagnostic", &[d, t, DU as u64])?;
    let scalar = |name: &str| -> Result<f64, NpzError> { Ok(f.f64_shaped(name, &[])?[0]) };
    let vec3 = |name: &str| -> Result<[f64; 3], NpzError> {
        Ok(f.f64_shaped(name, &[3])?.try_into().expect("3"))
    };
    let demos = Demos {
        count: d as usize,
        horizon: t as usize,
        goal: vec3("goal")?,
        start_q: vec3("start_q")?,
        dt: scalar("dt")?,
        seed: f.u64_scalar("seed")?,
        cost_random: scalar("cost_random")?,
        cost_expert: scalar("cost_expert")?,
        states,
        actions,
    };
    for (name, values) in [
        ("states", &demos.states),
        ("actions_diagnostic", &demos.actions),
    ] {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(bad(
                name,
                format!("non-finite value {} at flat index {i}", values[i]),
            ));
        }
    }
    if !(demos.dt > 0.0 && demos.dt.is_finite()) {
        return Err(bad("dt", format!("{} s must be finite and > 0", demos.dt)));
    }
    if demos
        .goal
        .iter()
        .chain(demos.start_q.iter())
        .any(|v| !v.is_finite())
    {
        return Err(bad("goal", "goal and start_q must be finite".into()));
    }
    Ok(demos)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Demos {
        let (d, t) = (2, 5);
        Demos {
            states: (0..d * t * DX).map(|i| i as f64 * 0.01).collect(),
            actions: (0..d * t * DU).map(|i| -(i as f64)).collect(),
            count: d,
            horizon: t,
            goal: [-0.4, -0.2, 0.3],
            start_q: [0.0, -2.0, 2.4],
            dt: 0.1,
            seed: 11,
            cost_random: 20.0,
            cost_expert: 3.0,
        }
    }

    #[test]
    fn round_trip_and_each_bad_file_is_named() {
        let dir = std::env::temp_dir().join(format!("demos-test-{}", std::process::id()));
        let path = dir.join("demos.npz");
        let demos = sample();
        save(&demos, &path).unwrap();
        assert_eq!(load(&path).unwrap(), demos);

        // Non-finite state.
        let mut nan = sample();
        nan.states[17] = f64::NAN;
        save(&nan, &path).unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("states") && e.contains("non-finite") && e.contains("17"),
            "{e}"
        );

        // Wrong state dimension: write a (2, 5, 11) array by hand.
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.strings("state_names", &STATE_NAMES).unwrap();
        w.f64("states", &[2, 5, 11], &vec![0.0; 110]).unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("state dimension 11, expected dX = 12"), "{e}");

        // Missing array.
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("no array `state_names`"), "{e}");

        // Action array of the wrong size.
        let mut w = NpzWriter::create(&path).unwrap();
        w.i64("schema_version", &[], &[SCHEMA_VERSION]).unwrap();
        w.strings("state_names", &STATE_NAMES).unwrap();
        w.f64("states", &[2, 5, 12], &vec![0.0; 120]).unwrap();
        w.f64("actions_diagnostic", &[2, 4, 3], &vec![0.0; 24])
            .unwrap();
        w.finish().unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("actions_diagnostic") && e.contains("expected [2, 5, 3]"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
