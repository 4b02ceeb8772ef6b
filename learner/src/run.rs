//! In-process runs (lockstep on hil-sim, no IPC): every learner driven through the one
//! [`Learn`] interface, one [`iterate`] per iteration, with its per-iteration CSV and
//! checkpoints (docs/design.md §4), and resuming an LQR+GAIfO run from them.

use std::path::{Path, PathBuf};

use anyhow::Context;
use imitation::controller::{policy_from_gain_table, to_gain_table};
use imitation::cost::composite::D_IN;
use imitation::demos::Demos;
use imitation::discriminator::Discriminator;
use imitation::expert::{
    record_demos, train as train_expert, ExpertConfig, ExpertRun, IterationLog,
};
use imitation::gaifo::{GaifoConfig, GaifoLog, LqrGaifo};
use imitation::learn::{iterate, Learn};
use imitation::ppo::gaifo_ppo::GaifoPpo;
use imitation::ppo::UpdateStats;
use serde::Serialize;

use crate::arm::SimArm;
use crate::io::log::{open_log, write_csv_row, write_record, EXPERT_CSV_HEADER};
use crate::io::table::{load_table, save_table};

/// The in-process arm of `learner`'s model of it (`Learn::sim_config`) at the task's control
/// period.
pub fn arm_for<L: Learn + ?Sized>(learner: &L) -> anyhow::Result<SimArm> {
    SimArm::new(learner.sim_config().clone(), learner.task().dt)
        .context("building the simulated arm")
}

/// What an imitation run saves before every iteration so that it can be resumed.
pub trait Checkpoint {
    /// Saves the policy executed next and the critic into `dir`; returns both paths.
    fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)>;
}

impl Checkpoint for LqrGaifo {
    /// `iter_NNN_table.npz` (the controller as gain table version NNN + 1) and
    /// `iter_NNN_critic.json`, NNN = iterations done.
    fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let table = dir.join(format!("iter_{i:03}_table.npz"));
        save_table(
            &table,
            &to_gain_table(self.policy(), self.version()),
            self.task().dt,
        )?;
        let critic = dir.join(format!("iter_{i:03}_critic.json"));
        self.discriminator().save(&critic)?;
        Ok((table, critic))
    }
}

impl Checkpoint for GaifoPpo {
    /// `iter_NNN_policy.json` (the policy nets) and `iter_NNN_critic.json`.
    fn checkpoint(&self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        crate::io::create_dir(dir)?;
        let i = self.iteration();
        let pol = dir.join(format!("iter_{i:03}_policy.json"));
        let file = self
            .ppo()
            .actor_critic()
            .policy_file(&self.config().ppo.pi_hidden);
        std::fs::write(&pol, serde_json::to_vec(&file)?)?;
        let critic = dir.join(format!("iter_{i:03}_critic.json"));
        self.discriminator().save(&critic)?;
        Ok((pol, critic))
    }
}

/// The latest complete checkpoint in `dir`: (NNN, `iter_NNN_table.npz`, `iter_NNN_critic.json`)
/// with the largest NNN for which both files exist. A clear error when there is none.
pub fn latest_checkpoint(dir: &Path) -> anyhow::Result<(usize, PathBuf, PathBuf)> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        anyhow::anyhow!(
            "cannot resume from {}: {e} (expected the --out folder of an earlier \
             `learner train` or `learner serve --algo lqr-gaifo` run)",
            dir.display()
        )
    })?;
    let mut best: Option<usize> = None;
    for entry in entries {
        let name = entry?.file_name();
        let Some(n) = name
            .to_str()
            .and_then(|n| n.strip_prefix("iter_"))
            .and_then(|n| n.strip_suffix("_table.npz"))
            .filter(|n| n.len() >= 3 && n.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|n| n.parse::<usize>().ok())
        else {
            continue;
        };
        if dir.join(format!("iter_{n:03}_critic.json")).is_file() && best.is_none_or(|b| n > b) {
            best = Some(n);
        }
    }
    let n = best.ok_or_else(|| {
        anyhow::anyhow!(
            "cannot resume from {}: no checkpoint in it (no pair iter_NNN_table.npz + \
             iter_NNN_critic.json, written by `learner train` and `learner serve --algo lqr-gaifo`)",
            dir.display()
        )
    })?;
    Ok((
        n,
        dir.join(format!("iter_{n:03}_table.npz")),
        dir.join(format!("iter_{n:03}_critic.json")),
    ))
}

/// Continues an LQR+GAIfO run from the latest checkpoint in `dir` ([`latest_checkpoint`]): the
/// controller of `iter_NNN_table.npz` (executed next, as table version NNN + 1), the critic of
/// `iter_NNN_critic.json`, NNN iterations done ([`LqrGaifo::from_checkpoint`]). `cfg` and
/// `demos` must be the run's own: the critic's settings and seed are checked against `cfg`, the
/// table's horizon and control period against the demonstrations.
pub fn resume(cfg: GaifoConfig, demos: Demos, dir: &Path) -> anyhow::Result<LqrGaifo> {
    let (iteration, table_path, critic_path) = latest_checkpoint(dir)?;
    let task = demos.task()?;
    let (table, dt) = load_table(&table_path, &ur5_shared::GainBounds::default())
        .with_context(|| format!("resuming from {}", table_path.display()))?;
    anyhow::ensure!(
        table.horizon() == task.horizon && dt.to_bits() == task.dt.to_bits(),
        "{}: a controller of T = {} steps at dt = {dt} s, the demonstrations have T = {} at \
         dt = {} s: resume with the run's own demonstrations",
        table_path.display(),
        table.horizon(),
        task.horizon,
        task.dt
    );
    anyhow::ensure!(
        table.version == iteration as u64 + 1,
        "{}: table version {}, expected {} for iteration {iteration}",
        table_path.display(),
        table.version,
        iteration + 1
    );
    let pol = policy_from_gain_table(&table)
        .with_context(|| format!("resuming from {}", table_path.display()))?;
    let disc = Discriminator::load(&critic_path, D_IN)
        .with_context(|| format!("resuming from {}", critic_path.display()))?;
    LqrGaifo::from_checkpoint(cfg, demos, pol, disc, iteration)
        .map_err(|e| anyhow::anyhow!("{}: {e}", critic_path.display()))
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
            run.checkpoint(dir)?;
            Some((f, dir))
        }
        None => None,
    };
    drive(run, arm, iterations, csv, progress)
}

/// The iterations of [`run_iterations`] and [`train_resumed`]: iterate, report, log, checkpoint.
fn drive<R: Learn<Log = GaifoLog> + Checkpoint>(
    run: &mut R,
    arm: &SimArm,
    iterations: usize,
    mut csv: Option<(std::fs::File, &Path)>,
    mut progress: impl FnMut(&GaifoLog, &R),
) -> anyhow::Result<Vec<GaifoLog>> {
    use std::io::Write;
    let mut logs = Vec::with_capacity(iterations);
    for _ in 0..iterations {
        let (log, _) = iterate(run, arm)?;
        progress(&log, run);
        if let Some((f, dir)) = csv.as_mut() {
            write_csv_row(f, &log, run.seed(), R::ALGO)?;
            f.flush()?;
            run.checkpoint(dir)?;
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

/// Continues the LQR+GAIfO run whose checkpoints are in `dir` ([`resume`]) up to
/// `cfg.iterations` iterations in all, appending to `dir/gaifo_log.csv` ([`open_log`]) and
/// writing the next checkpoints into `dir`. Iterations are numbered on from the checkpoint.
pub fn train_resumed(
    cfg: &GaifoConfig,
    demos: Demos,
    dir: &Path,
    mut progress: impl FnMut(&GaifoLog),
) -> anyhow::Result<Vec<GaifoLog>> {
    let mut run = resume(cfg.clone(), demos, dir)?;
    let start = run.iteration();
    anyhow::ensure!(
        start < cfg.iterations,
        "{} already holds {start} iterations, as many as iterations = {} asks for: nothing to \
         resume (raise --iterations)",
        dir.display(),
        cfg.iterations
    );
    let arm = arm_for(&run)?;
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
