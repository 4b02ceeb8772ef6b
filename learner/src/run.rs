//! In-process runs (lockstep on hil-sim, no IPC): every learner driven through the one
//! [`Learn`] interface, one [`imitation::learn::iterate`] per iteration, with its per-iteration CSV and
//! checkpoints (docs/design.md §4), and resuming an LQR+GAIfO run from them exactly (§4.11).

use std::path::{Path, PathBuf};

use anyhow::Context;
use imitation::controller::to_gain_table;
use imitation::cost::composite::D_IN;
use imitation::demos::Demos;
use imitation::discriminator::Discriminator;
use imitation::expert::{
    record_demos, train as train_expert, ExpertConfig, ExpertRun, IterationLog,
};
use imitation::gaifo::{GaifoConfig, GaifoLog, LqrGaifo};
use imitation::learn::{iterate_observed, Learn};
use imitation::mdgps::{Mdgps, MdgpsConfig};
use imitation::ppo::gaifo_ppo::GaifoPpo;
use imitation::ppo::UpdateStats;
use serde::Serialize;

use crate::arm::SimArm;
use crate::io::checkpoint::{load_state, save_state};
use crate::io::episode::{EpisodeOrigin, EpisodeRecorder};
use crate::io::log::{open_log, write_csv_row, write_record, EXPERT_CSV_HEADER};
use crate::io::table::save_table;

/// The in-process arm of `learner`'s model of it (`Learn::sim_config`) at the task's control
/// period.
pub fn arm_for<L: Learn + ?Sized>(learner: &L) -> anyhow::Result<SimArm> {
    SimArm::new(learner.sim_config().clone(), learner.task().dt)
        .context("building the simulated arm")
}

/// What a run saves before every iteration so that it can be resumed (in process, `learner
/// train`, and over IPC, `learner serve`) or its learning checked (`learner replay`).
pub trait Checkpoint {
    /// Saves the controller executed next and the rest of the learner state into `dir` (with
    /// the in-process `arm`'s noise position when there is one; `None` over IPC).
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> anyhow::Result<()>;
}

/// The name of checkpoint file `kind` (`table.npz`, `critic.json`, `state.npz`, ...) after `i`
/// iterations: `iter_{i:03}_{kind}`.
fn checkpoint_file(dir: &Path, i: usize, kind: &str) -> PathBuf {
    dir.join(format!("iter_{i:03}_{kind}"))
}

/// The entry of [`LqrGaifo::snapshot`] holding the in-process arm's noise position
/// ([`hil_sim::Ur5Sim::noise_position`], low and high word).
const ARM_NOISE: &str = "arm.noise_position";

impl Checkpoint for LqrGaifo {
    /// `iter_NNN_table.npz` (the controller as gain table version NNN + 1),
    /// `iter_NNN_critic.json` and, last, `iter_NNN_state.npz` (the rest of the learner state,
    /// [`LqrGaifo::snapshot`], and the arm's noise position), NNN = iterations done; each file
    /// written atomically, so that a state file marks a complete checkpoint.
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> anyhow::Result<()> {
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
    fn checkpoint(&self, dir: &Path, arm: Option<&SimArm>) -> anyhow::Result<()> {
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
fn with_arm_noise(
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
    fn checkpoint(&self, dir: &Path, _arm: Option<&SimArm>) -> anyhow::Result<()> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let pol = checkpoint_file(dir, i, "policy.json");
        let file = self
            .ppo()
            .actor_critic()
            .policy_file(&self.config().ppo.pi_hidden);
        ur5_shared::atomic_file::write(&pol, &serde_json::to_vec(&file)?)?;
        let critic = checkpoint_file(dir, i, "critic.json");
        self.discriminator().save(&critic)?;
        Ok(())
    }
}

/// The latest complete checkpoint in `dir`: (NNN, `iter_NNN_state.npz`,
/// `iter_NNN_critic.json`) with the largest NNN for which both files exist (the state file is
/// written last, atomically). A clear error when there is none.
pub fn latest_checkpoint(dir: &Path) -> anyhow::Result<(usize, PathBuf, PathBuf)> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        anyhow::anyhow!(
            "cannot resume from {}: {e} (expected the --out folder of an earlier \
             `learner train` or `learner serve --algo lqr-gaifo` run)",
            dir.display()
        )
    })?;
    let mut best: Option<usize> = None;
    let mut tables_only = false;
    for entry in entries {
        let name = entry?.file_name();
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
    let n = best.ok_or_else(|| {
        let older = if tables_only {
            " (its iter_NNN_table.npz files come from a build before exact resume, which wrote \
             no learner state: start a new run)"
        } else {
            ""
        };
        anyhow::anyhow!(
            "cannot resume from {}: no checkpoint in it (no iter_NNN_state.npz with its \
             iter_NNN_critic.json, written by `learner train` and `learner serve --algo \
             lqr-gaifo`){older}",
            dir.display()
        )
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
) -> anyhow::Result<(LqrGaifo, Option<u128>)> {
    let (snap, disc, arm, state_path) = load_checkpoint(dir, "lqr.iteration")?;
    let run = LqrGaifo::from_snapshot(cfg, demos, &snap, disc)
        .map_err(|e| anyhow::anyhow!("{}: {e}", state_path.display()))?;
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
) -> anyhow::Result<(Mdgps, Option<u128>)> {
    let (snap, disc, arm, state_path) = load_checkpoint(dir, "mdgps.iteration")?;
    let run = Mdgps::from_snapshot(cfg, demos, &snap, disc)
        .map_err(|e| anyhow::anyhow!("{}: {e}", state_path.display()))?;
    Ok((run, arm))
}

/// The latest checkpoint in `dir`: its learner state (whose iteration, entry `iteration_key`,
/// must be the one its name says), critic, the arm's noise position when it holds one, and the
/// state file's path.
fn load_checkpoint(
    dir: &Path,
    iteration_key: &str,
) -> anyhow::Result<(
    gps::snapshot::Snapshot,
    Discriminator,
    Option<u128>,
    PathBuf,
)> {
    let (iteration, state_path, critic_path) = latest_checkpoint(dir)?;
    let snap = load_state(&state_path)?;
    let at = snap
        .words(iteration_key, 1)
        .map_err(|e| anyhow::anyhow!("{}: {e}", state_path.display()))?[0];
    anyhow::ensure!(
        at == iteration as u64,
        "{}: holds iteration {at}, its name says {iteration}",
        state_path.display()
    );
    let arm = match snap.words.get(ARM_NOISE).map(Vec::as_slice) {
        None => None,
        Some(&[lo, hi]) => Some(u128::from(lo) | (u128::from(hi) << 64)),
        Some(w) => anyhow::bail!(
            "{}: array `{ARM_NOISE}` has {} values, expected 2",
            state_path.display(),
            w.len()
        ),
    };
    let disc = Discriminator::load(&critic_path, D_IN)
        .with_context(|| format!("resuming from {}", critic_path.display()))?;
    Ok((snap, disc, arm, state_path))
}

/// Runs `iterations` iterations of `run` on `arm`, calling `progress` after each, writing
/// `gaifo_log.csv` (column `algorithm` = `R::ALGO`) and per-iteration checkpoints into `out`
/// when it is given.
pub fn run_iterations<R: Learn<Log = GaifoLog> + Checkpoint>(
    run: &mut R,
    arm: &SimArm,
    iterations: usize,
    out: Option<&Path>,
    progress: impl FnMut(&GaifoLog, &R),
) -> anyhow::Result<Vec<GaifoLog>> {
    let csv = match out {
        Some(dir) => {
            crate::io::create_dir(dir)?;
            let f = open_log(&dir.join("gaifo_log.csv"), None)?;
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
fn drive<R: Learn<Log = GaifoLog> + Checkpoint>(
    run: &mut R,
    arm: &SimArm,
    iterations: usize,
    mut csv: Option<(std::fs::File, &Path)>,
    mut progress: impl FnMut(&GaifoLog, &R),
) -> anyhow::Result<Vec<GaifoLog>> {
    use std::io::Write;
    let mut logs = Vec::with_capacity(iterations);
    let mut recorder = match &csv {
        Some((_, dir)) if dir.join("episodes").is_dir() => {
            Some(EpisodeRecorder::new(&dir.join("episodes"))?)
        }
        _ => None,
    };
    for _ in 0..iterations {
        let (version, n) = (run.version(), run.samples() as u64);
        let (seed, task) = (run.seed(), run.task().clone());
        let mut recorded: anyhow::Result<()> = Ok(());
        let run_dir = csv.as_ref().map(|(_, d)| d.to_path_buf());
        let (log, _) = iterate_observed(run, arm, &mut |noisy, evals| {
            let Some(rec) = recorder.as_mut() else { return };
            // Numbered as a controller started with version 1 numbers its episodes.
            for (k, ep) in noisy.iter().chain(evals).enumerate() {
                let origin = EpisodeOrigin {
                    table_version: version,
                    table_epoch: 0,
                    episode: (version - 1) * (n + 1) + k as u64,
                    seed,
                };
                if recorded.is_ok() {
                    recorded = rec
                        .record(ep, &origin, &task)
                        .map_err(anyhow::Error::from)
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
            write_csv_row(f, &log, run.seed(), R::ALGO)?;
            f.flush()?;
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
) -> anyhow::Result<Vec<GaifoLog>> {
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
) -> anyhow::Result<Vec<GaifoLog>> {
    let mut run = GaifoPpo::new(cfg.clone(), demos)?;
    let arm = arm_for(&run)?;
    run_iterations(&mut run, &arm, cfg.iterations, out, |l, r| {
        progress(l, &r.last_update)
    })
}

/// Continues the LQR+GAIfO run whose checkpoints are in `dir` ([`resume`], with the arm's noise
/// stream where the checkpoint left it) up to `cfg.iterations` iterations in all, appending to
/// `dir/gaifo_log.csv` ([`open_log`]) and writing the next checkpoints into `dir`. Iterations
/// are numbered on from the checkpoint; tables and CSV rows are the uninterrupted run's bit
/// for bit (timing columns aside). A run that already holds `cfg.iterations` iterations is
/// complete: nothing is run and the result is empty; one that holds more is refused.
pub fn train_resumed(
    cfg: &GaifoConfig,
    demos: Demos,
    dir: &Path,
    mut progress: impl FnMut(&GaifoLog),
) -> anyhow::Result<Vec<GaifoLog>> {
    let (mut run, arm_noise) = resume(cfg.clone(), demos, dir)?;
    let start = run.iteration();
    anyhow::ensure!(
        start <= cfg.iterations,
        "{} already holds {start} iterations, more than iterations = {} asks for: a resume \
         never shortens a run (raise --iterations)",
        dir.display(),
        cfg.iterations
    );
    if start == cfg.iterations {
        // The run is complete (a kill after its last checkpoint, or a retried job): resuming
        // it again is a no-op, not an error, so a scheduler may re-run the same command.
        return Ok(Vec::new());
    }
    let mut arm = arm_for(&run)?;
    if let Some(pos) = arm_noise {
        arm.sim_mut().set_noise_position(pos);
    }
    let csv = open_log(&dir.join("gaifo_log.csv"), Some(start))?;
    drive(
        &mut run,
        &arm,
        cfg.iterations - start,
        Some((csv, dir)),
        |l, _| progress(l),
    )
}

/// Trains the expert of `cfg` on a fresh in-process arm ([`imitation::expert::train`]).
pub fn expert(
    cfg: &ExpertConfig,
    progress: impl FnMut(&IterationLog),
) -> anyhow::Result<ExpertRun> {
    let arm = SimArm::new(cfg.sim.clone(), cfg.task.dt).context("building the simulated arm")?;
    Ok(train_expert(cfg, &arm, progress)?)
}

/// Records `cfg.demos` demonstrations of `run`'s best controller on a fresh in-process arm
/// ([`imitation::expert::record_demos`]).
pub fn demos(cfg: &ExpertConfig, run: &ExpertRun) -> anyhow::Result<Demos> {
    let arm = SimArm::new(cfg.sim.clone(), cfg.task.dt).context("building the simulated arm")?;
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
) -> anyhow::Result<ExpertSummary> {
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
    let mut csv = std::fs::File::create(&log_path)?;
    writeln!(csv, "{EXPERT_CSV_HEADER}")?;
    for l in &run.log {
        write_record(&mut csv, l)?;
    }
    let demos = demos(cfg, &run)?;
    let demos_path = out.join("demos.npz");
    crate::io::demos::save(&demos, &demos_path)?;
    Ok(ExpertSummary {
        goal: cfg.task.goal,
        iterations: run.log.len(),
        eval_cost: run.eval.task_cost(),
        final_distance: run.eval.final_distance(),
        cost_random: run.cost_random,
        cost_demos: demos.cost_expert,
        cost_ratio: run.eval.task_cost() / run.cost_random,
        table: table_path,
        demos: demos_path,
        log: log_path,
    })
}
