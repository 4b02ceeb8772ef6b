//! `learner experiment`: its arguments and the command.

use std::path::PathBuf;

use super::CommonArgs;
use crate::experiment::{ipc, multi_goal, run, ExperimentConfig, ExperimentName};

/// Arguments of `learner experiment`.
#[derive(clap::Args, Debug)]
pub struct ExperimentArgs {
    /// Which experiment.
    #[arg(value_enum)]
    pub name: ExperimentName,
    /// Seeds per variant; overrides the config.
    #[arg(long)]
    pub seeds: Option<usize>,
    /// Iterations per run; overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Worker threads (0 = one per core); overrides the config.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Demonstrations to use instead of training the expert (comparison, stability, ablation,
    /// sim-vs-physical's simulated arm); for multi-goal, the `experts/` folder of an earlier
    /// multi-goal run with the same square, evaluation goals and expert settings.
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// --config: an `ExperimentConfig` (keys `seeds`, `first_seed`, `iterations`, `threads`,
    /// `algorithms`, `subset_sizes`, `demos_per_point`, `critic_steps`, `time_compression`,
    /// `ablation_variants`, `eval_inside`, `eval_outside`, `eval_outside_margin`, `eval_seed`,
    /// `mdgps_kl_step`;
    /// tables `expert`, `lqr_gaifo`, `gaifo_ppo`, `physical`, `mdgps_policy`) layered over the experiment's
    /// defaults; --seed: the first seed (`first_seed`); --out [default:
    /// runs/experiments/<name>].
    #[command(flatten)]
    pub common: CommonArgs,
}

/// The experiment's settings from its defaults, the config file and the command line.
pub fn config_from_args(args: &ExperimentArgs) -> anyhow::Result<ExperimentConfig> {
    let base = ExperimentConfig::defaults(args.name);
    let mut cfg = match &args.common.config {
        Some(p) => ur5_shared::config::from_toml_file_over(p, base)?,
        None => base,
    };
    if let Some(s) = args.seeds {
        cfg.seeds = s;
    }
    if let Some(s) = args.common.seed {
        cfg.first_seed = s;
    }
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    if let Some(t) = args.threads {
        cfg.threads = t;
    }
    Ok(cfg)
}

/// Runs `learner experiment`.
pub fn run_cli(args: ExperimentArgs) -> anyhow::Result<()> {
    let cfg = config_from_args(&args)?;
    let out = args
        .common
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs/experiments").join(args.name.as_str()));
    let rows = match args.name {
        ExperimentName::SimVsPhysical => {
            serde_json::to_value(ipc::run(&cfg, &out, args.demos.as_deref())?.1)?
        }
        ExperimentName::MultiGoal => {
            serde_json::to_value(multi_goal::run(&cfg, &out, args.demos.as_deref())?)?
        }
        name => serde_json::to_value(run(name, &cfg, &out, args.demos.as_deref())?.1)?,
    };
    if args.common.json {
        println!(
            "{}",
            serde_json::json!({"command": "experiment", "name": args.name.as_str(), "out": out, "summary": rows})
        );
    }
    Ok(())
}
