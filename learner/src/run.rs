//! In-process runs (lockstep on hil-sim, no IPC): every learner driven through the one
//! [`Learn`] interface, one [`imitation::learn::iterate`] per iteration, with its per-iteration CSV and
//! checkpoints (docs/design.md §4), and resuming an LQR+GAIfO run from them exactly (§4.11).

use std::path::{Path, PathBuf};

use imitation::controller::to_gain_table;
use imitation::demos::Demos;
use imitation::discriminator::Discriminator;
use imitation::expert::{
    record_demos, train as train_expert, ExpertConfig, ExpertRun, IterationLog,
};
use imitation::gaifo::{GaifoConfig, GaifoLog, LqrGaifo};
use imitation::learn::{iterate_observed, Learn};
use imitation::mdgps::{Mdgps, MdgpsConfig, MdgpsLog};
use imitation::offpolicy::{GaifoTd3, GaifoTd3Config};
use imitation::ppo::gaifo_ppo::GaifoPpo;
use imitation::ppo::UpdateStats;
use serde::Serialize;

use crate::arm::SimArm;
use crate::error::ensure;
use crate::io::checkpoint::{load_state, save_state};
use crate::io::episode::{EpisodeOrigin, EpisodeRecorder};
use crate::io::log::{open_log_with, write_record, LogRow, EXPERT_CSV_HEADER};
use crate::io::npz::NpzError;
use crate::io::table::save_table;
use crate::io::IoError;

/// What went wrong in an in-process run, its checkpoints or its resume.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The simulated arm cannot be built for the learner's model and period.
    #[error("building the simulated arm")]
    Arm(#[source] hil_sim::SimError),
    /// `--resume` of a folder that cannot be read.
    #[error(
        "cannot resume from {}: {source} (expected the --out folder of an earlier `learner \
         train` or `learner serve --algo lqr-gaifo` run)",
        dir.display()
    )]
    NoFolder {
        /// The folder.
        dir: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// `--resume` of a folder without a complete checkpoint.
    #[error(
        "cannot resume from {}: no checkpoint in it (no iter_NNN_state.npz with its \
         iter_NNN_critic.json, written by `learner train` and `learner serve --algo \
         lqr-gaifo`){}",
        dir.display(),
        if *tables_only {
            " (its iter_NNN_table.npz files come from a build before exact resume, which wrote \
             no learner state: start a new run)"
        } else {
            ""
        }
    )]
    NoCheckpoint {
        /// The folder.
        dir: PathBuf,
        /// Whether it holds the tables of a build before exact resume.
        tables_only: bool,
    },
    /// A learner state that does not fit the run's settings and demonstrations.
    #[error("{}", path.display())]
    Restore {
        /// The state file.
        path: PathBuf,
        /// Why it does not fit.
        source: imitation::ImitationError,
    },
    /// A learner state without an entry it must have.
    #[error("{}", path.display())]
    StateEntry {
        /// The state file.
        path: PathBuf,
        /// The missing or malformed entry.
        source: gps::GpsError,
    },
    /// A state file whose iteration is not the one its name says (renamed or edited).
    #[error("{}: holds iteration {at}, its name says {named}", path.display())]
    Iteration {
        /// The state file.
        path: PathBuf,
        /// Iteration it holds.
        at: u64,
        /// Iteration its name says.
        named: usize,
    },
    /// A state file whose arm noise position is malformed.
    #[error("{}: array `{ARM_NOISE}` has {len} values, expected 2", path.display())]
    ArmNoise {
        /// The state file.
        path: PathBuf,
        /// Values found.
        len: usize,
    },
    /// A checkpoint's critic that cannot be read.
    #[error("resuming from {}", path.display())]
    Critic {
        /// The critic file.
        path: PathBuf,
        /// Why.
        source: imitation::discriminator::DiscriminatorError,
    },
    /// A resume asked for fewer iterations than the run holds.
    #[error(
        "{} already holds {start} iterations, more than iterations = {asked} asks for: a resume \
         never shortens a run (raise --iterations)",
        dir.display()
    )]
    Shorter {
        /// The run folder.
        dir: PathBuf,
        /// Iterations it holds.
        start: usize,
        /// Iterations asked for.
        asked: usize,
    },
    /// The run's files.
    #[error(transparent)]
    Io(#[from] IoError),
    /// A learner piece (an iteration, the expert, a policy).
    #[error(transparent)]
    Imitation(#[from] imitation::ImitationError),
    /// The critic (saving it).
    #[error(transparent)]
    Discriminator(#[from] imitation::discriminator::DiscriminatorError),
}

impl From<NpzError> for RunError {
    fn from(e: NpzError) -> Self {
        Self::Io(e.into())
    }
}

/// The in-process arm of `learner`'s model of it (`Learn::sim_config`) at the task's control
/// period.
pub fn arm_for<L: Learn + ?Sized>(learner: &L) -> Result<SimArm, RunError> {
    SimArm::for_task(learner.sim_config().clone(), learner.task()).map_err(RunError::Arm)
}

/// What a run saves before every iteration so that it can be resumed (in process, `learner
/// train`, and over IPC, `learner serve`) or its learning checked (`learner replay`).
pub trait Checkpoint {
    /// Saves the controller executed next and the rest of the learner state into `dir` (with
    /// the in-process `arm`'s noise position when there is one; `None` over IPC).
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> Result<(), RunError>;
}

/// The name of checkpoint file `kind` (`table.npz`, `critic.json`, `state.npz`, ...) after `i`
/// iterations: `iter_{i:03}_{kind}`.
pub(crate) fn checkpoint_file(dir: &Path, i: usize, kind: &str) -> PathBuf {
    dir.join(format!("iter_{i:03}_{kind}"))
}

/// The entry of [`LqrGaifo::snapshot`] holding the in-process arm's noise position
/// ([`hil_sim::Ur5Sim::noise_position`], low and high word).
pub(crate) const ARM_NOISE: &str = "arm.noise_position";

impl Checkpoint for LqrGaifo {
    /// `iter_NNN_table.npz` (the controller as gain table version NNN + 1),
    /// `iter_NNN_critic.json` and, last, `iter_NNN_state.npz` (the rest of the learner state,
    /// [`LqrGaifo::snapshot`], and the arm's noise position), NNN = iterations done; each file
    /// written atomically, so that a state file marks a complete checkpoint.
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> Result<(), RunError> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let table = checkpoint_file(dir, i, "table.npz");
        save_table(
            &table,
            &to_gain_table(self.policy(), self.version()),
            self.task().dt,
        )?;
        let critic = checkpoint_file(dir, i, "critic.json");
        self.discriminator().save(&critic)?;
        save_state(
            &checkpoint_file(dir, i, "state.npz"),
            &with_arm_noise(self.snapshot(), arm),
        )?;
        Ok(())
    }
}

impl Checkpoint for Mdgps {
    /// `iter_NNN_critic.json` (the one critic) and, last, `iter_NNN_state.npz` (the rest of the
    /// learner state, [`Mdgps::snapshot`]: the policy, its S-step and every condition's LQR
    /// state, and the arm's noise position), NNN = iterations done; each written atomically.
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> Result<(), RunError> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let critic = checkpoint_file(dir, i, "critic.json");
        self.critic().save(&critic)?;
        let state = checkpoint_file(dir, i, "state.npz");
        save_state(&state, &with_arm_noise(self.snapshot(), arm))?;
        Ok(())
    }
}

/// `snap` with the in-process `arm`'s noise position (entry [`ARM_NOISE`]) when there is one.
pub(crate) fn with_arm_noise(
    mut snap: gps::snapshot::Snapshot,
    arm: Option<&SimArm>,
) -> gps::snapshot::Snapshot {
    if let Some(arm) = arm {
        let pos = arm.sim().noise_position();
        snap.put_words(ARM_NOISE, &[pos as u64, (pos >> 64) as u64]);
    }
    snap
}

impl Checkpoint for GaifoPpo {
    /// `iter_NNN_policy.json` (the policy nets) and `iter_NNN_critic.json` (not an exact
    /// checkpoint: there is no resume for this baseline).
    fn checkpoint(&self, dir: &Path, _arm: Option<&SimArm>) -> Result<(), RunError> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let pol = checkpoint_file(dir, i, "policy.json");
        let file = self
            .ppo()
            .actor_critic()
            .policy_file(&self.config().ppo.pi_hidden);
        let bytes = serde_json::to_vec(&file).map_err(IoError::from)?;
        ur5_shared::atomic_file::write(&pol, &bytes).map_err(IoError::file("writing", &pol))?;
        let critic = checkpoint_file(dir, i, "critic.json");
        self.discriminator().save(&critic)?;
        Ok(())
    }
}

impl Checkpoint for GaifoTd3 {
    /// `iter_NNN_critic.json` and, last, `iter_NNN_state.npz` (the rest of the learner state,
    /// [`GaifoTd3::snapshot`]: actor, critics, targets, optimisers, RNG position and the replay
    /// buffer, and the arm's noise position), NNN = iterations done; each written atomically.
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> Result<(), RunError> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        self.critic()
            .save(&checkpoint_file(dir, i, "critic.json"))?;
        let state = checkpoint_file(dir, i, "state.npz");
        save_state(&state, &with_arm_noise(self.snapshot(), arm))?;
        Ok(())
    }
}

/// The latest complete checkpoint in `dir`: (NNN, `iter_NNN_state.npz`,
/// `iter_NNN_critic.json`) with the largest NNN for which both files exist (the state file is
/// written last, atomically). A clear error when there is none.
pub fn latest_checkpoint(dir: &Path) -> Result<(usize, PathBuf, PathBuf), RunError> {
    let entries = std::fs::read_dir(dir).map_err(|source| RunError::NoFolder {
        dir: dir.to_owned(),
        source,
    })?;
    let mut best: Option<usize> = None;
    let mut tables_only = false;
    for entry in entries {
        let name = entry.map_err(IoError::file("reading", dir))?.file_name();
        let number = |suffix: &str| {
            name.to_str()
                .and_then(|n| n.strip_prefix("iter_"))
                .and_then(|n| n.strip_suffix(suffix))
                .filter(|n| n.len() >= 3 && n.bytes().all(|b| b.is_ascii_digit()))
                .and_then(|n| n.parse::<usize>().ok())
        };
        tables_only |= number("_table.npz").is_some();
        let Some(n) = number("_state.npz") else {
            continue;
        };
        if checkpoint_file(dir, n, "critic.json").is_file() && best.is_none_or(|b| n > b) {
            best = Some(n);
        }
    }
    let n = best.ok_or_else(|| RunError::NoCheckpoint {
        dir: dir.to_owned(),
        tables_only,
    })?;
    Ok((
        n,
        checkpoint_file(dir, n, "state.npz"),
        checkpoint_file(dir, n, "critic.json"),
    ))
}

/// Continues an LQR+GAIfO run exactly from the latest checkpoint in `dir`
/// ([`latest_checkpoint`]): the learner state of `iter_NNN_state.npz` and the critic of
/// `iter_NNN_critic.json`, NNN iterations done ([`LqrGaifo::from_snapshot`]). Also returns the
/// in-process arm's noise position when the checkpoint holds one. `cfg` and `demos` must be the
/// run's own: the critic's settings and seed are checked against `cfg`, the state's horizon
/// against the demonstrations.
pub fn resume(
    cfg: GaifoConfig,
    demos: Demos,
    dir: &Path,
) -> Result<(LqrGaifo, Option<u128>), RunError> {
    let d_in = 2 * demos.layout().dx();
    let (snap, disc, arm, state_path) = load_checkpoint(dir, "lqr.iteration", d_in)?;
    let run =
        LqrGaifo::from_snapshot(cfg, demos, &snap, disc).map_err(|source| RunError::Restore {
            path: state_path,
            source,
        })?;
    Ok((run, arm))
}

/// Continues an MDGPS run exactly from the latest checkpoint in `dir` ([`latest_checkpoint`],
/// written by [`Checkpoint::checkpoint`] of [`Mdgps`]): [`Mdgps::from_snapshot`] on the state
/// and critic files; also returns the in-process arm's noise position when the checkpoint holds
/// one. `cfg` and `demos` must be the run's own (goals, policy size, horizon and seed are
/// checked).
pub fn resume_mdgps(
    cfg: MdgpsConfig,
    demos: Vec<Demos>,
    dir: &Path,
) -> Result<(Mdgps, Option<u128>), RunError> {
    let d_in = 2 * demos.first().map_or(0, |d| d.layout().dx());
    let (snap, disc, arm, state_path) = load_checkpoint(dir, "mdgps.iteration", d_in)?;
    let run =
        Mdgps::from_snapshot(cfg, demos, &snap, disc).map_err(|source| RunError::Restore {
            path: state_path,
            source,
        })?;
    Ok((run, arm))
}

/// Continues an off-policy GAIfO run exactly from the latest checkpoint in `dir`
/// ([`GaifoTd3::from_snapshot`]); also returns the in-process arm's noise position when the
/// checkpoint holds one. `cfg` and `demos` must be the run's own.
pub fn resume_td3(
    cfg: GaifoTd3Config,
    demos: Demos,
    dir: &Path,
) -> Result<(GaifoTd3, Option<u128>), RunError> {
    let (snap, disc, arm, state_path) =
        load_checkpoint(dir, "td3.iteration", 2 * demos.layout().dx())?;
    let run =
        GaifoTd3::from_snapshot(cfg, demos, &snap, disc).map_err(|source| RunError::Restore {
            path: state_path,
            source,
        })?;
    Ok((run, arm))
}

/// The latest checkpoint in `dir`: its learner state (whose iteration, entry `iteration_key`,
/// must be the one its name says), critic, the arm's noise position when it holds one, and the
/// state file's path.
fn load_checkpoint(
    dir: &Path,
    iteration_key: &str,
    d_in: usize,
) -> Result<
    (
        gps::snapshot::Snapshot,
        Discriminator,
        Option<u128>,
        PathBuf,
    ),
    RunError,
> {
    let (iteration, state_path, critic_path) = latest_checkpoint(dir)?;
    let snap = load_state(&state_path)?;
    let at = snap
        .words(iteration_key, 1)
        .map_err(|source| RunError::StateEntry {
            path: state_path.clone(),
            source,
        })?[0];
    ensure!(
        at == iteration as u64,
        RunError::Iteration {
            path: state_path,
            at,
            named: iteration
        }
    );
    let arm = match snap.words.get(ARM_NOISE).map(Vec::as_slice) {
        None => None,
        Some(&[lo, hi]) => Some(u128::from(lo) | (u128::from(hi) << 64)),
        Some(w) => {
            return Err(RunError::ArmNoise {
                path: state_path,
                len: w.len(),
            })
        }
    };
    let disc = Discriminator::load(&critic_path, d_in).map_err(|source| RunError::Critic {
        path: critic_path,
        source,
    })?;
    Ok((snap, disc, arm, state_path))
}

/// Runs `iterations` iterations of `run` on `arm`, calling `progress` after each, writing
/// `gaifo_log.csv` (column `algorithm` = `R::ALGO`) and per-iteration checkpoints into `out`
/// when it is given.
pub fn run_iterations<R: Learn<Log: LogRow> + Checkpoint>(
    run: &mut R,
    arm: &SimArm,
    iterations: usize,
    out: Option<&Path>,
    progress: impl FnMut(&R::Log, &R),
) -> Result<Vec<R::Log>, RunError> {
    let csv = match out {
        Some(dir) => {
            crate::io::create_dir(dir)?;
            let header = R::Log::header(&run.task().layout());
            let f = open_log_with(&dir.join(R::Log::FILE), &header, None)?;
            run.checkpoint(dir, Some(arm))?;
            crate::io::files::note_checkpoint(dir, run.iteration())?;
            Some((f, dir))
        }
        None => None,
    };
    drive(run, arm, iterations, csv, progress)
}

/// The iterations of [`run_iterations`] and [`train_resumed`]: iterate, report, log, checkpoint;
/// when the run folder has an `episodes/` folder (`learner train --record-episodes`, and its
/// resumes), every episode is recorded there first, as `learner serve` records them
/// ([`EpisodeRecorder`]), so that `learner replay` can redo the run.
fn drive<R: Learn<Log: LogRow> + Checkpoint>(
    run: &mut R,
    arm: &SimArm,
    iterations: usize,
    mut csv: Option<(std::fs::File, &Path)>,
    mut progress: impl FnMut(&R::Log, &R),
) -> Result<Vec<R::Log>, RunError> {
    use std::io::Write;
    let mut logs = Vec::with_capacity(iterations);
    let mut recorder = match &csv {
        Some((_, dir)) if dir.join("episodes").is_dir() => {
            Some(EpisodeRecorder::new(&dir.join("episodes"))?)
        }
        _ => None,
    };
    for _ in 0..iterations {
        let (version, n) = (run.version(), run.samples());
        let seed = run.seed();
        // Each episode's goal: noisy ones goal-major (N each), then one evaluation per goal.
        let tasks: Vec<_> = run.goal_tasks().into_iter().cloned().collect();
        let per_version = (tasks.len() * (n + 1)) as u64;
        let mut recorded: Result<(), IoError> = Ok(());
        let run_dir = csv.as_ref().map(|(_, d)| d.to_path_buf());
        let (log, _) = iterate_observed(run, arm, &mut |noisy, evals| {
            let Some(rec) = recorder.as_mut() else { return };
            // Numbered as a controller started with version 1 numbers its episodes.
            let goals = (0..noisy.len()).map(|k| k / n.max(1)).chain(0..evals.len());
            for (k, (ep, goal)) in noisy.iter().chain(evals).zip(goals).enumerate() {
                let origin = EpisodeOrigin {
                    table_version: version,
                    table_epoch: 0,
                    episode: (version - 1) * per_version + k as u64,
                    seed,
                };
                if recorded.is_ok() {
                    recorded = rec
                        .record(ep, &origin, &tasks[goal])
                        .map_err(IoError::from)
                        .and_then(|p| match &run_dir {
                            Some(d) => crate::io::files::note(d, &[&p]),
                            None => Ok(()),
                        });
                }
            }
        })?;
        recorded?;
        progress(&log, run);
        if let Some((f, dir)) = csv.as_mut() {
            let path = dir.join(R::Log::FILE);
            log.write_row(f, run.seed(), R::ALGO, &run.task().layout())
                .and_then(|()| f.flush())
                .map_err(IoError::file("writing", &path))?;
            run.checkpoint(dir, Some(arm))?;
            crate::io::files::note_checkpoint(dir, run.iteration())?;
        }
        logs.push(log);
    }
    Ok(logs)
}

/// Runs `cfg.iterations` iterations of LQR+GAIfO on `demos` ([`run_iterations`]).
pub fn train(
    cfg: &GaifoConfig,
    demos: Demos,
    out: Option<&Path>,
    mut progress: impl FnMut(&GaifoLog),
) -> Result<Vec<GaifoLog>, RunError> {
    let mut run = LqrGaifo::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(&mut run, &arm, cfg.iterations, out, |l, _| progress(l))
}

/// Runs `cfg.iterations` iterations of GAIfO (PPO) on `demos`, calling `progress` after each
/// with the PPO statistics of that iteration ([`run_iterations`]).
pub fn train_ppo(
    cfg: &imitation::ppo::gaifo_ppo::GaifoPpoConfig,
    demos: Demos,
    out: Option<&Path>,
    mut progress: impl FnMut(&GaifoLog, &UpdateStats),
) -> Result<Vec<GaifoLog>, RunError> {
    let mut run = GaifoPpo::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(&mut run, &arm, cfg.iterations, out, |l, r| {
        progress(l, &r.last_update)
    })
}

/// Runs `cfg.iterations` iterations of off-policy GAIfO on `demos`, calling `progress` after
/// each with the TD3 statistics of that iteration ([`run_iterations`]).
pub fn train_td3(
    cfg: &GaifoTd3Config,
    demos: Demos,
    out: Option<&Path>,
    mut progress: impl FnMut(&GaifoLog, &imitation::offpolicy::UpdateStats),
) -> Result<Vec<GaifoLog>, RunError> {
    let mut run = GaifoTd3::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(&mut run, &arm, cfg.iterations, out, |l, r| {
        progress(l, &r.last_update)
    })
}

/// Continues the off-policy GAIfO run whose checkpoints are in `dir` ([`resume_td3`]) up to
/// `cfg.iterations` in all, as [`train_resumed`] continues an LQR+GAIfO run: bit for bit the
/// uninterrupted run (timing columns aside).
pub fn train_td3_resumed(
    cfg: &GaifoTd3Config,
    demos: Demos,
    dir: &Path,
    mut progress: impl FnMut(&GaifoLog, &imitation::offpolicy::UpdateStats),
) -> Result<Vec<GaifoLog>, RunError> {
    let (run, arm_noise) = resume_td3(cfg.clone(), demos, dir)?;
    continue_run(run, arm_noise, dir, cfg.iterations, |l, r| {
        progress(l, &r.last_update)
    })
}

/// Continues the LQR+GAIfO run whose checkpoints are in `dir` ([`resume`], with the arm's noise
/// stream where the checkpoint left it) up to `cfg.iterations` iterations in all, appending to
/// `dir/gaifo_log.csv` ([`crate::io::log::open_log`]) and writing the next checkpoints into `dir`. Iterations
/// are numbered on from the checkpoint; tables and CSV rows are the uninterrupted run's bit
/// for bit (timing columns aside). A run that already holds `cfg.iterations` iterations is
/// complete: nothing is run and the result is empty; one that holds more is refused.
pub fn train_resumed(
    cfg: &GaifoConfig,
    demos: Demos,
    dir: &Path,
    mut progress: impl FnMut(&GaifoLog),
) -> Result<Vec<GaifoLog>, RunError> {
    let (run, arm_noise) = resume(cfg.clone(), demos, dir)?;
    continue_run(run, arm_noise, dir, cfg.iterations, |l, _| progress(l))
}

/// Continues `run`, resumed from its checkpoint in `dir` (with the in-process arm's noise
/// position `arm_noise`), up to `iterations` in all ([`train_resumed`], [`train_mdgps_resumed`]).
pub(crate) fn continue_run<R: Learn<Log: LogRow> + Checkpoint>(
    mut run: R,
    arm_noise: Option<u128>,
    dir: &Path,
    iterations: usize,
    progress: impl FnMut(&R::Log, &R),
) -> Result<Vec<R::Log>, RunError> {
    let start = run.iteration();
    ensure!(
        start <= iterations,
        RunError::Shorter {
            dir: dir.to_owned(),
            start,
            asked: iterations
        }
    );
    if start == iterations {
        // The run is complete (a kill after its last checkpoint, or a retried job): resuming
        // it again is a no-op, not an error, so a scheduler may re-run the same command.
        return Ok(Vec::new());
    }
    let mut arm = arm_for(&run)?;
    if let Some(pos) = arm_noise {
        arm.sim_mut().set_noise_position(pos);
    }
    let header = R::Log::header(&run.task().layout());
    let csv = open_log_with(&dir.join(R::Log::FILE), &header, Some(start))?;
    drive(
        &mut run,
        &arm,
        iterations - start,
        Some((csv, dir)),
        progress,
    )
}

/// Runs `cfg.lqr_gaifo.iterations` iterations of MDGPS on `demos` (one set per goal, each a
/// condition) in process ([`run_iterations`]), writing `mdgps_log.csv` and a checkpoint before
/// every iteration into `out` (`learner train --algo mdgps`).
pub fn train_mdgps(
    cfg: &MdgpsConfig,
    demos: Vec<Demos>,
    out: &Path,
    mut progress: impl FnMut(&MdgpsLog),
) -> Result<Vec<MdgpsLog>, RunError> {
    let mut run = Mdgps::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(
        &mut run,
        &arm,
        cfg.lqr_gaifo.iterations,
        Some(out),
        |l, _| progress(l),
    )
}

/// Continues the MDGPS run whose checkpoints are in `dir` ([`resume_mdgps`], the arm's noise
/// stream where the checkpoint left it) up to `cfg.lqr_gaifo.iterations` in all, as
/// [`train_resumed`] continues an LQR+GAIfO run: the checkpoints and CSV rows (timing columns
/// aside) are the uninterrupted run's bit for bit.
pub fn train_mdgps_resumed(
    cfg: &MdgpsConfig,
    demos: Vec<Demos>,
    dir: &Path,
    mut progress: impl FnMut(&MdgpsLog),
) -> Result<Vec<MdgpsLog>, RunError> {
    let (run, arm_noise) = resume_mdgps(cfg.clone(), demos, dir)?;
    continue_run(run, arm_noise, dir, cfg.lqr_gaifo.iterations, |l, _| {
        progress(l)
    })
}

/// Trains the expert of `cfg` on a fresh in-process arm ([`imitation::expert::train`]).
pub fn expert(
    cfg: &ExpertConfig,
    progress: impl FnMut(&IterationLog),
) -> Result<ExpertRun, RunError> {
    let arm = SimArm::for_task(cfg.sim.clone(), &cfg.task).map_err(RunError::Arm)?;
    Ok(train_expert(cfg, &arm, progress)?)
}

/// Records `cfg.demos` demonstrations of `run`'s best controller on a fresh in-process arm
/// ([`imitation::expert::record_demos`]).
pub fn demos(cfg: &ExpertConfig, run: &ExpertRun) -> Result<Demos, RunError> {
    let arm = SimArm::for_task(cfg.sim.clone(), &cfg.task).map_err(RunError::Arm)?;
    Ok(record_demos(cfg, &arm, &run.policy, run.cost_random)?)
}

/// What `learner expert` reports at the end (also its `--json` line).
#[derive(Clone, Debug, Serialize)]
pub struct ExpertSummary {
    /// Goal point (m).
    pub goal: [f64; 3],
    /// Iterations run.
    pub iterations: usize,
    /// Task cost of the best noise-free episode.
    pub eval_cost: f64,
    /// Its final end-effector distance (m).
    pub final_distance: f64,
    /// Its final orientation error of the tool (degrees; `ur5_shared::pose`): pose goals only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_orientation_error_deg: Option<f64>,
    /// Mean task cost of the random (initial) controller.
    pub cost_random: f64,
    /// Mean task cost of the recorded demonstrations.
    pub cost_demos: f64,
    /// eval_cost / cost_random.
    pub cost_ratio: f64,
    /// Files written.
    pub table: PathBuf,
    /// Demonstrations file.
    pub demos: PathBuf,
    /// Per-iteration CSV.
    pub log: PathBuf,
}

/// Trains the expert, saves its gain table (`expert_table.npz`), the per-iteration log
/// (`expert_log.csv`) and the demonstrations (`demos.npz`) into `out`.
pub fn train_and_record(
    cfg: &ExpertConfig,
    out: &Path,
    progress: impl FnMut(&IterationLog),
) -> Result<ExpertSummary, RunError> {
    use std::io::Write;
    let run = expert(cfg, progress)?;
    crate::io::create_dir(out)?;
    let table_path = out.join("expert_table.npz");
    save_table(
        &table_path,
        &to_gain_table(&run.policy, run.log.len() as u64),
        cfg.task.dt,
    )?;
    let log_path = out.join("expert_log.csv");
    let mut csv = std::fs::File::create(&log_path).map_err(IoError::file("creating", &log_path))?;
    writeln!(csv, "{EXPERT_CSV_HEADER}")
        .and_then(|()| run.log.iter().try_for_each(|l| write_record(&mut csv, l)))
        .map_err(IoError::file("writing", &log_path))?;
    let demos = demos(cfg, &run)?;
    let demos_path = out.join("demos.npz");
    crate::io::demos::save(&demos, &demos_path)?;
    Ok(ExpertSummary {
        goal: cfg.task.goal,
        iterations: run.log.len(),
        eval_cost: run.eval.task_cost(),
        final_distance: run.eval.final_distance(),
        final_orientation_error_deg: run
            .eval
            .final_orientation_error(&cfg.task.targets())
            .map(f64::to_degrees),
        cost_random: run.cost_random,
        cost_demos: demos.cost_expert,
        cost_ratio: run.eval.task_cost() / run.cost_random,
        table: table_path,
        demos: demos_path,
        log: log_path,
    })
}
