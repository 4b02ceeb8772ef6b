//! In-process runs of the baselines without a critic: BCO(α) ([`Bco`]) and the naive mean
//! path ([`ReplayMean`]), through [`crate::run`]'s loop (CSV `gaifo_log.csv`, a checkpoint
//! before every iteration and after the last, `--record-episodes`), and BCO's exact resume.
//!
//! Their checkpoints have no critic file: BCO writes `iter_NNN_policy.npz` (the cloned policy,
//! as `learner policy eval` reads it) and, last, `iter_NNN_state.npz` (its whole state,
//! [`Bco::snapshot`], with the in-process arm's noise position); the mean path writes
//! `iter_NNN_table.npz` and `iter_NNN_state.npz` (its iteration).

use std::path::{Path, PathBuf};

use imitation::bco::{Bco, BcoConfig};
use imitation::controller::to_gain_table;
use imitation::demos::Demos;
use imitation::gaifo::GaifoLog;
use imitation::learn::{Learn, LinGaussLearn};
use imitation::replay_mean::{ReplayMean, ReplayMeanConfig};

use crate::arm::SimArm;
use crate::error::ensure;
use crate::io::checkpoint::{load_state, save_state};
use crate::io::policy::{save_policy, PolicyFile};
use crate::io::table::save_table;
use crate::io::IoError;
use crate::run::{
    arm_for, checkpoint_file, continue_run, run_iterations, with_arm_noise, Checkpoint, RunError,
    ARM_NOISE,
};

/// Iterations done of a mean-path run (u64, 1).
const REPLAY_MEAN_ITERATION: &str = "replay_mean.iteration";

impl Checkpoint for Bco {
    /// `iter_NNN_policy.npz` (the policy executed next) and, last, `iter_NNN_state.npz` (the
    /// rest of the learner state, [`Bco::snapshot`], and the arm's noise position), NNN =
    /// iterations done; each written atomically.
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> Result<(), RunError> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let task = self.task();
        let file = PolicyFile {
            policy: self.policy().clone(),
            mode: self.config().sim.mode,
            start_q: task.start_q,
            dt: task.dt,
            horizon: task.horizon,
            seed: self.seed(),
            iterations: i as u64,
            model: self.config().sim.model,
        };
        save_policy(&file, &checkpoint_file(dir, i, "policy.npz"))?;
        save_state(
            &checkpoint_file(dir, i, "state.npz"),
            &with_arm_noise(self.snapshot(), arm),
        )?;
        Ok(())
    }
}

impl Checkpoint for ReplayMean {
    /// `iter_NNN_table.npz` (the mean path as gain table version NNN + 1) and
    /// `iter_NNN_state.npz` (its iteration, the arm's noise position).
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> Result<(), RunError> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let table = to_gain_table(self.policy(), self.version());
        save_table(
            &checkpoint_file(dir, i, "table.npz"),
            &table,
            self.task().dt,
        )?;
        let mut snap = gps::snapshot::Snapshot::default();
        snap.put_words(REPLAY_MEAN_ITERATION, &[i as u64]);
        save_state(
            &checkpoint_file(dir, i, "state.npz"),
            &with_arm_noise(snap, arm),
        )?;
        Ok(())
    }
}

/// The latest learner state in `dir` of a run without a critic: (NNN, `iter_NNN_state.npz`)
/// with the largest NNN (the state file is written last, atomically).
pub fn latest_state(dir: &Path) -> Result<(usize, PathBuf), RunError> {
    let entries = std::fs::read_dir(dir).map_err(|source| RunError::NoFolder {
        dir: dir.to_owned(),
        source,
    })?;
    let mut best: Option<usize> = None;
    for entry in entries {
        let name = entry.map_err(IoError::file("reading", dir))?.file_name();
        let n = name
            .to_str()
            .and_then(|n| n.strip_prefix("iter_"))
            .and_then(|n| n.strip_suffix("_state.npz"))
            .filter(|n| n.len() >= 3 && n.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|n| n.parse::<usize>().ok());
        if let Some(n) = n {
            best = Some(best.map_or(n, |b| b.max(n)));
        }
    }
    let n = best.ok_or_else(|| RunError::NoCheckpoint {
        dir: dir.to_owned(),
        tables_only: false,
    })?;
    Ok((n, checkpoint_file(dir, n, "state.npz")))
}

/// Continues a BCO run exactly from the latest state in `dir` ([`latest_state`],
/// [`Bco::from_snapshot`]); also returns the in-process arm's noise position when the state
/// holds one. `cfg` and `demos` must be the run's own.
pub fn resume_bco(
    cfg: BcoConfig,
    demos: Demos,
    dir: &Path,
) -> Result<(Bco, Option<u128>), RunError> {
    let (iteration, path) = latest_state(dir)?;
    let snap = load_state(&path)?;
    let at = snap
        .words(imitation::bco::ITERATION, 1)
        .map_err(|source| RunError::StateEntry {
            path: path.clone(),
            source,
        })?[0];
    ensure!(
        at == iteration as u64,
        RunError::Iteration {
            path,
            at,
            named: iteration
        }
    );
    let arm = match snap.words.get(ARM_NOISE).map(Vec::as_slice) {
        None => None,
        Some(&[lo, hi]) => Some(u128::from(lo) | (u128::from(hi) << 64)),
        Some(w) => return Err(RunError::ArmNoise { path, len: w.len() }),
    };
    let run = Bco::from_snapshot(cfg, demos, &snap)
        .map_err(|source| RunError::Restore { path, source })?;
    Ok((run, arm))
}

/// Runs `cfg.iterations` iterations of BCO on `demos` in process, writing `gaifo_log.csv` and
/// the checkpoints into `out` when it is given; `progress` sees each log and the run.
pub fn train_bco(
    cfg: &BcoConfig,
    demos: Demos,
    out: Option<&Path>,
    progress: impl FnMut(&GaifoLog, &Bco),
) -> Result<Vec<GaifoLog>, RunError> {
    let mut run = Bco::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(&mut run, &arm, cfg.iterations, out, progress)
}

/// Continues the BCO run in `dir` ([`resume_bco`], the arm's noise where the checkpoint left
/// it) up to `cfg.iterations` in all, appending to `dir/gaifo_log.csv`: checkpoints and rows
/// (timing columns aside) are the uninterrupted run's bit for bit.
pub fn train_bco_resumed(
    cfg: &BcoConfig,
    demos: Demos,
    dir: &Path,
    progress: impl FnMut(&GaifoLog, &Bco),
) -> Result<Vec<GaifoLog>, RunError> {
    let (run, arm_noise) = resume_bco(cfg.clone(), demos, dir)?;
    continue_run(run, arm_noise, dir, cfg.iterations, progress)
}

/// Runs the naive mean path on `demos` in process for `cfg.iterations` iterations (each the
/// same evaluation), writing `gaifo_log.csv` and its table into `out` when it is given.
pub fn train_replay_mean(
    cfg: &ReplayMeanConfig,
    demos: Demos,
    out: Option<&Path>,
    mut progress: impl FnMut(&GaifoLog),
) -> Result<Vec<GaifoLog>, RunError> {
    let mut run = ReplayMean::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(&mut run, &arm, cfg.iterations, out, |l, _| progress(l))
}
