//! `learner train`: imitation from state-only demonstrations.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};

use crate::gaifo::{train, train_resumed, GaifoConfig, GaifoLog};
use crate::io::demos::Demos;
use crate::ppo::gaifo_ppo::GaifoPpoConfig;

/// Which imitation algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Algo {
    /// LQR+GAIfO (Torabi et al. 2019, Algorithm 1).
    LqrGaifo,
    /// GAIfO with a PPO policy (the baseline).
    GaifoPpo,
}

/// Arguments of `learner train`.
#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Demonstrations (.npz from `learner expert`): state trajectories only are used.
    #[arg(long)]
    pub demos: PathBuf,
    /// Algorithm.
    #[arg(long, value_enum, default_value = "lqr-gaifo")]
    pub algo: Algo,
    /// TOML settings, layered over the defaults (unknown keys are errors): for lqr-gaifo a
    /// `GaifoConfig` (keys `samples`, `iterations`, `init_var`, `critic_updates`, `adapt_step`,
    /// `psd_hessian`, `seed`; tables `sim`, `discriminator`, `algorithm`, `prior`, `fit`,
    /// `traj_opt`), for gaifo-ppo a `GaifoPpoConfig` (keys `samples`, `iterations`,
    /// `critic_updates`, `seed`; tables `sim`, `discriminator`, `ppo`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Iterations; overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Seed; overrides the config.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output folder: per-iteration CSV, gain tables and critic checkpoints [default:
    /// runs/train; with --resume, DIR].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue the LQR+GAIfO run in DIR (its --out) from its latest checkpoint
    /// (iter_NNN_table.npz + iter_NNN_critic.json) up to --iterations in all, with the run's
    /// own demonstrations, config and seed: iterations are numbered on from NNN and rows are
    /// appended to DIR/gaifo_log.csv. The critic resumes exactly (weights, normalisation, Adam
    /// moments, RNG); the GMM dynamics prior, the previous controller and the step size are not
    /// checkpointed and start afresh, so the result differs from an uninterrupted run.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

/// The end of a `learner train` run: the summary line on stderr and, with `--json`, the
/// one-line JSON summary on stdout (both algorithms).
pub fn report(logs: &[GaifoLog], algo: &str, seed: u64, out: &std::path::Path, json: bool) {
    let Some(last) = logs.last() else { return };
    eprintln!(
        "done: normalised performance {:.3} (task cost {:.4}, final distance {:.4} m); log and checkpoints in {}",
        last.performance,
        last.task_cost,
        last.final_distance,
        out.display()
    );
    if json {
        let best = logs
            .iter()
            .map(|l| l.performance)
            .fold(f64::NEG_INFINITY, f64::max);
        println!(
            "{}",
            serde_json::json!({"command": "train", "algo": algo, "iterations": logs.len(), "seed": seed,
                "final_performance": last.performance, "best_performance": best, "final_task_cost": last.task_cost,
                "final_distance_m": last.final_distance, "out": out})
        );
    }
}

impl TrainArgs {
    /// The output folder: `--out`, else the `--resume` folder, else `runs/train`.
    pub fn out_dir(&self) -> PathBuf {
        self.out
            .clone()
            .or_else(|| self.resume.clone())
            .unwrap_or_else(|| PathBuf::from("runs/train"))
    }
}

/// Runs `learner train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    let demos = Demos::load(&args.demos)
        .with_context(|| format!("loading demonstrations {}", args.demos.display()))?;
    if args.algo == Algo::GaifoPpo {
        anyhow::ensure!(
            args.resume.is_none(),
            "--resume continues LQR+GAIfO runs only (not --algo gaifo-ppo)"
        );
        let mut pcfg: GaifoPpoConfig = match &args.config {
            Some(p) => ur5_shared::config::from_toml_file(p)?,
            None => GaifoPpoConfig::default(),
        };
        if let Some(i) = args.iterations {
            pcfg.iterations = i;
        }
        if let Some(s) = args.seed {
            pcfg.seed = s;
        }
        pcfg.sim.validate()?;
        anyhow::ensure!(
            pcfg.samples >= 1 && pcfg.iterations >= 1,
            "samples and iterations must be >= 1"
        );
        return crate::ppo::gaifo_ppo::run_cli(&args, demos, &pcfg);
    }
    let mut cfg: GaifoConfig = match &args.config {
        Some(p) => ur5_shared::config::from_toml_file(p)?,
        None => GaifoConfig::default(),
    };
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    cfg.sim.validate()?;
    anyhow::ensure!(
        cfg.samples >= 1 && cfg.iterations >= 1,
        "samples and iterations must be >= 1"
    );
    let out = args.out_dir();
    if let Some(dir) = &args.resume {
        anyhow::ensure!(
            args.algo == Algo::LqrGaifo,
            "--resume continues LQR+GAIfO runs only (not --algo gaifo-ppo)"
        );
        anyhow::ensure!(
            out == *dir,
            "--out {} and --resume {} differ: a resumed run continues in its own folder",
            out.display(),
            dir.display()
        );
    }
    eprintln!(
        "LQR+GAIfO on {} demonstrations of T = {} (goal {:?} m), seed {}, -> {}{}",
        demos.count,
        demos.horizon,
        demos.goal,
        cfg.seed,
        out.display(),
        if args.resume.is_some() {
            " (resumed)"
        } else {
            ""
        }
    );
    eprintln!("{}", GaifoLog::PROGRESS_HEADER);
    let print = |l: &GaifoLog| eprintln!("{}", l.progress_line());
    let logs = match &args.resume {
        Some(dir) => train_resumed(&cfg, demos, dir, print)?,
        None => train(&cfg, demos, Some(&out), print)?,
    };
    crate::train_cli::report(&logs, "lqr-gaifo", cfg.seed, &out, args.json);
    Ok(())
}
