//! `learner experiment`: its arguments and the command.

use std::path::PathBuf;

use super::CommonArgs;
use crate::experiment::shard::{self, Shard};
use crate::experiment::{ipc, multi_goal, run_sharded, ExperimentConfig, ExperimentName};

/// Arguments of `learner experiment`.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct ExperimentArgs {
    /// `merge`: join shards.
    #[command(subcommand)]
    pub cmd: Option<ExperimentCmd>,
    /// Which experiment.
    #[arg(value_enum, required = true)]
    pub name: Option<ExperimentName>,
    /// Run only the K-th (1-based) of N disjoint parts of the experiment's jobs (variant ×
    /// seed: jobs K, K + N, K + 2N, … of its list), noting them in OUT/shard.json; join the
    /// parts' folders with `learner experiment merge`. Not for sim-vs-physical, multi-goal and
    /// pilqr; shapes writes each job's file into OUT/runs/ (copy the shards' runs/ together and
    /// run it again for the table).
    #[arg(long, value_name = "K/N")]
    pub shard: Option<Shard>,
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
    /// tables `expert`, `lqr_gaifo`, `gaifo_ppo`, `physical`, `mdgps_policy`, `pilqr`, `shapes`) layered over the experiment's
    /// defaults; --seed: the first seed (`first_seed`); --out [default:
    /// runs/experiments/<name>].
    #[command(flatten)]
    pub common: CommonArgs,
    /// Train only the experiment's expert and write OUT/demos.npz (the first job of a
    /// `--slurm` or `--k8s` sweep; the shards take it with `--demos`). Comparison, stability
    /// and ablation.
    #[arg(long, conflicts_with_all = ["shard", "demos"])]
    pub expert_only: bool,
    /// The --slurm and --k8s sweeps.
    #[command(flatten)]
    pub sweep: super::sweep::SweepArgs,
}

/// `learner experiment merge`.
#[derive(clap::Subcommand, Debug)]
pub enum ExperimentCmd {
    /// Join the output folders of the shards of one experiment (`--shard K/N`, every K once)
    /// into --out: the CSV, plot and summary of the unsharded run.
    Merge(MergeArgs),
}

/// Arguments of `learner experiment merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The shards' output folders.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Output folder of the joined experiment.
    #[arg(long)]
    pub out: PathBuf,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

/// The experiment's settings from its defaults, the config file and the command line.
pub fn config_from_args(args: &ExperimentArgs) -> anyhow::Result<ExperimentConfig> {
    let name = args
        .name
        .expect("clap requires a name without a subcommand");
    let base = ExperimentConfig::defaults(name);
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
    if let Some(ExperimentCmd::Merge(m)) = &args.cmd {
        let (runs, rows) = shard::merge(&m.dirs, &m.out)?;
        eprint!("{}", crate::experiment::summary_text(&rows));
        eprintln!(
            "{} runs from {} shards -> {}",
            runs.len(),
            m.dirs.len(),
            m.out.display()
        );
        if m.json {
            println!(
                "{}",
                serde_json::json!({"command": "experiment merge", "out": m.out, "summary": rows})
            );
        }
        return Ok(());
    }
    let cfg = config_from_args(&args)?;
    let name = args
        .name
        .expect("clap requires a name without a subcommand");
    if args.sweep.slurm.is_some() || args.sweep.k8s.is_some() {
        let jobs_get = super::sweep::JobArgs {
            seeds: args.seeds,
            iterations: args.iterations,
            seed: args.common.seed,
            config: args.common.config.as_deref(),
            demos: args.demos.as_deref(),
            threads: args.threads,
        };
        return super::sweep::write(&args.sweep, &jobs_get, name, &cfg);
    }
    if args.expert_only {
        anyhow::ensure!(
            crate::experiment::scheduler::trains_one_expert(name, &cfg),
            "--expert-only: {} does not train one expert (stability does, and comparison and \
             ablation at one goal)",
            name.as_str()
        );
        cfg.validate(name)?;
        let out = args
            .common
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from("."));
        let d = crate::experiment::expert_demos(&cfg.expert)?;
        crate::io::create_dir(&out)?;
        // Renamed into place: a retried expert job never leaves half a file for the shards.
        let (tmp, path) = (out.join(".demos.npz.partial"), out.join("demos.npz"));
        crate::io::demos::save(&d, &tmp)?;
        std::fs::rename(&tmp, &path)?;
        eprintln!("expert: {} demonstrations -> {}", d.count, path.display());
        return Ok(());
    }
    let out = args
        .common
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs/experiments").join(name.as_str()));
    anyhow::ensure!(
        args.shard.is_none()
            || !matches!(
                name,
                ExperimentName::SimVsPhysical | ExperimentName::MultiGoal | ExperimentName::Pilqr
            ),
        "--shard splits the in-process experiments (comparison, generalisation, stability, \
         ablation), not {}",
        name.as_str()
    );
    let rows = match name {
        ExperimentName::SimVsPhysical => {
            serde_json::to_value(ipc::run(&cfg, &out, args.demos.as_deref())?.1)?
        }
        ExperimentName::MultiGoal => {
            serde_json::to_value(multi_goal::run(&cfg, &out, args.demos.as_deref())?)?
        }
        ExperimentName::Pilqr => serde_json::to_value(crate::experiment::summarise(
            &crate::experiment::pilqr::run(&cfg, &out)?,
        ))?,
        ExperimentName::Shapes => {
            anyhow::ensure!(
                args.demos.is_none(),
                "--demos does not apply to shapes: it places the LASA drawings itself ([shapes] \
                 shapes, plane, size, duration)"
            );
            cfg.validate(name)?;
            crate::experiment::shapes::run(&cfg, &out, args.shard)?
        }
        name => serde_json::to_value(
            run_sharded(name, &cfg, &out, args.demos.as_deref(), args.shard)?.1,
        )?,
    };
    if args.common.json {
        println!(
            "{}",
            serde_json::json!({"command": "experiment", "name": name.as_str(), "out": out, "summary": rows})
        );
    }
    Ok(())
}
