//! One executed episode on disk, as `learner serve` records every episode it receives
//! (copper-rs: every run recorded and replayable). The layout of [`super::demos`] with D = 1,
//! plus where the episode came from:
//!
//! | array | shape | meaning |
//! |---|---|---|
//! | `states` | (1, T, dX) f64 | s_t (layout: `state_names`) |
//! | `actions` | (1, T, dU) f64 | actions executed by the arm (after the controller's clamp); the dynamics are fitted on these |
//! | `actions_policy` | (1, T, dU) f64 | actions the controller law asked for (before the clamp) |
//! | `table_version` | () u64 | gain-table version that computed the actions |
//! | `table_epoch` | () u64 | its publication (`GainTable::epoch`), written when not 0; absent: 0 |
//! | `episode` | () u64 | the controller's episode number |
//! | `noisy` | () u64 | 1 with exploration noise, 0 for the noise-free evaluation episode |
//! | `task_cost` | () f64 | C(τ) (`ur5_shared::cost`) |
//! | `goal`, `start_q` | (3,), (n,) f64 | goal point (m), start pose (rad; one angle per active joint) |
//! | `goal_pose`, `tool_points` | (6,), (3, 3) f64 | a pose task's goal and tool points (as in [`super::demos`]) |
//! | `dt` | () f64 | control period (s) |
//! | `seed` | () u64 | run seed (the exploration noise of episode k of version v is `ur5_shared::noise::Noise::new(seed, v, k)`) |
//! | `state_names`, `action_names` | (dX,), (dU,) str | layout |
//! | `schema_version` | () i64 | [`SCHEMA_VERSION`] |

use std::path::{Path, PathBuf};

use ur5_shared::config::TaskConfig;

use super::npz::{NpzError, NpzFile, NpzWriter};
use super::IoError;
use imitation::rollout::Episode;

/// Version of this file layout.
pub const SCHEMA_VERSION: i64 = 1;

/// Where an episode came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EpisodeOrigin {
    /// Gain-table version that computed the actions.
    pub table_version: u64,
    /// Its publication ([`ur5_shared::GainTable::epoch`]): a resumed `learner serve`
    /// publishes its version again with a higher epoch (docs/design.md §3.6).
    pub table_epoch: u32,
    /// The controller's episode number.
    pub episode: u64,
    /// Run seed.
    pub seed: u64,
}

/// Writes `ep` (atomically) with its origin and the task it ran.
pub fn save_episode(
    path: &Path,
    ep: &Episode,
    origin: &EpisodeOrigin,
    task: &TaskConfig,
) -> Result<(), NpzError> {
    let t = ep.horizon() as u64;
    let (dx, du) = (ep.dx() as u64, ep.du() as u64);
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[SCHEMA_VERSION])?;
    w.f64("states", &[1, t, dx], &ep.x)?;
    w.f64("actions", &[1, t, du], &ep.u)?;
    w.f64("actions_policy", &[1, t, du], &ep.u_policy)?;
    w.u64("table_version", &[], &[origin.table_version])?;
    if origin.table_epoch != 0 {
        w.u64("table_epoch", &[], &[u64::from(origin.table_epoch)])?;
    }
    w.u64("episode", &[], &[origin.episode])?;
    w.u64("noisy", &[], &[ep.noisy as u64])?;
    w.f64("task_cost", &[], &[ep.task_cost()])?;
    super::task_arrays::write_task(
        &mut w,
        &task.goal,
        &task.start_q,
        task.goal_pose.as_ref(),
        &task.tool_points,
    )?;
    w.f64("dt", &[], &[task.dt])?;
    w.u64("seed", &[], &[origin.seed])?;
    super::task_arrays::write_layout_names(&mut w, &ep.layout)?;
    w.finish()?;
    Ok(())
}

/// Writes episodes into a folder as they arrive, as `NNNNNN_eEPISODE_vVERSION.npz` (NNNNNN:
/// arrival number, so that the names sort in arrival order; `learner replay` relies on it).
/// Used by `learner serve` and `learner train --record-episodes`.
pub struct EpisodeRecorder {
    dir: PathBuf,
    arrivals: u64,
}

impl EpisodeRecorder {
    /// A recorder into `dir` (created), numbering on after the highest arrival number of the
    /// episode files already there (a resumed run).
    pub fn new(dir: &Path) -> Result<Self, NpzError> {
        let io = |source| NpzError::Io {
            path: dir.to_owned(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let mut arrivals = 0;
        for e in std::fs::read_dir(dir).map_err(io)? {
            let name = e.map_err(io)?.file_name();
            // Episode files only (not a `.npz.tmp` a kill left behind).
            let n = name
                .to_str()
                .filter(|n| n.ends_with(".npz"))
                .and_then(|n| n.split('_').next())
                .and_then(|n| n.parse::<u64>().ok());
            arrivals = arrivals.max(n.unwrap_or(0));
        }
        Ok(Self {
            dir: dir.to_owned(),
            arrivals,
        })
    }

    /// Writes `ep` ([`save_episode`]) as the next arrival; returns its path.
    pub fn record(
        &mut self,
        ep: &Episode,
        origin: &EpisodeOrigin,
        task: &TaskConfig,
    ) -> Result<PathBuf, NpzError> {
        self.arrivals += 1;
        let path = self.dir.join(format!(
            "{:06}_e{:06}_v{:04}.npz",
            self.arrivals, origin.episode, origin.table_version
        ));
        save_episode(&path, ep, origin, task)?;
        Ok(path)
    }
}

/// Reads an episode written by [`save_episode`] (`eps` is not recorded: left empty).
pub fn load_episode(path: &Path) -> Result<(Episode, EpisodeOrigin), NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let bad = |name: &str, why: String| f.bad(name, why);
    let layout = super::task_arrays::read_task(&f)?.layout;
    let (want_dx, du) = (layout.dx() as u64, layout.du() as u64);
    let (shape, x) = f.f64("states")?;
    let [1, t, dx] = shape[..] else {
        return Err(bad(
            "states",
            format!("shape {shape:?}, expected (1, T, {want_dx})"),
        ));
    };
    if dx != want_dx || t == 0 {
        return Err(bad(
            "states",
            format!("shape {shape:?}, expected (1, T, {want_dx}) for a task with {layout}"),
        ));
    }
    let ep = Episode {
        layout,
        x,
        u: f.f64_shaped("actions", &[1, t, du])?,
        u_policy: f.f64_shaped("actions_policy", &[1, t, du])?,
        eps: Vec::new(),
        noisy: f.u64_scalar("noisy")? != 0,
    };
    let origin = EpisodeOrigin {
        table_version: f.u64_scalar("table_version")?,
        table_epoch: f.u32_scalar_or_zero("table_epoch")?,
        episode: f.u64_scalar("episode")?,
        seed: f.u64_scalar("seed")?,
    };
    Ok((ep, origin))
}

/// The episode files (`*.npz`) of `folder` in name order, which for an
/// [`EpisodeRecorder`]'s folder is arrival order, loaded; none when there is no folder.
pub fn recorded_episodes(folder: &Path) -> Result<Vec<(PathBuf, Episode, EpisodeOrigin)>, IoError> {
    episode_files(folder)?
        .into_iter()
        .map(|p| {
            let (ep, origin) = load_episode(&p)?;
            Ok((p, ep, origin))
        })
        .collect()
}

/// The episode files (`*.npz`) of `folder` in name order; none when there is no folder.
pub fn episode_files(folder: &Path) -> Result<Vec<PathBuf>, IoError> {
    let mut files: Vec<PathBuf> = match std::fs::read_dir(folder) {
        Ok(entries) => entries
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<_, _>>()
            .map_err(IoError::file("reading", &folder))?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e).map_err(IoError::file("reading", &folder)),
    };
    files.retain(|p| p.extension().is_some_and(|x| x == "npz"));
    files.sort();
    Ok(files)
}

/// The task an episode file ran (goal, start pose, control period, T).
pub fn load_episode_task(path: &Path) -> Result<TaskConfig, NpzError> {
    let f = NpzFile::open_schema(path, SCHEMA_VERSION)?;
    let (shape, _) = f.f64("states")?;
    let task = super::task_arrays::read_task(&f)?;
    Ok(TaskConfig {
        dt: f.f64_shaped("dt", &[])?[0],
        horizon: shape.get(1).copied().unwrap_or(0) as usize,
        joints: task.start_q.len(),
        start_q: task.start_q,
        goal: task.goal,
        goal_pose: task.goal_pose,
        tool_points: task.tool_points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn round_trip() {
        let dir = std::env::temp_dir().join(format!("episode-test-{}", std::process::id()));
        let path = dir.join("e.npz");
        let (t, layout) = (4, ur5_shared::StateLayout::REACH3);
        let (dx, du) = (layout.dx(), layout.du());
        let ep = Episode {
            layout,
            x: (0..t * dx).map(|i| i as f64 * 0.1).collect(),
            u: (0..t * du).map(|i| -(i as f64)).collect(),
            u_policy: (0..t * du).map(|i| i as f64 + 0.5).collect(),
            eps: Vec::new(),
            noisy: true,
        };
        let origin = EpisodeOrigin {
            table_version: 3,
            table_epoch: 2,
            episode: 17,
            seed: 9,
        };
        save_episode(&path, &ep, &origin, &TaskConfig::default()).unwrap();
        let (back, o) = load_episode(&path).unwrap();
        assert_eq!((back, o), (ep, origin));
        std::fs::remove_dir_all(&dir).ok();
    }
}

#[cfg(test)]
mod recorder_tests {
    use super::EpisodeRecorder;

    /// A restarted learner numbers on from the recorded episodes (the controller's episode
    /// numbers start again at 0 when it restarts, so only the arrival number keeps names
    /// apart): the highest arrival of the `.npz` files, nothing else counted.
    #[test]
    fn a_restarted_learner_numbers_on_from_the_recorded_episodes() {
        let dir = std::env::temp_dir().join(format!("ur5-last-arrival-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(
            EpisodeRecorder::new(&dir).unwrap().arrivals,
            0,
            "new folder"
        );
        for name in [
            "000001_e000000_v0001.npz",
            "000012_e000000_v0001.npz",
            "000007_e000004_v0002.npz",
            "000099_e000000_v0003.npz.tmp",
            "notes.txt",
        ] {
            std::fs::write(dir.join(name), b"").unwrap();
        }
        assert_eq!(EpisodeRecorder::new(&dir).unwrap().arrivals, 12);
        std::fs::remove_dir_all(&dir).ok();
    }
}
