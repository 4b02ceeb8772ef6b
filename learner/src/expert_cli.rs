//! `learner expert`: command-line front of [`crate::expert`].

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use ur5_shared::config::parse_triple;

use crate::expert::{square_goals, train_and_record, ExpertConfig, IterationLog};

/// Arguments of `learner expert`.
#[derive(Args, Debug)]
pub struct ExpertArgs {
    /// TOML file with an `ExpertConfig` (tables `task`, `sim`, `cost`, `algorithm`, `prior`,
    /// `fit`, `traj_opt`; keys as in the Rust docs; unknown keys are errors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Goal point x,y,z (m, arm base frame); overrides the config.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub goal: Option<[f64; 3]>,
    /// Train and record experts for the 8 points of the generalisation square around the goal
    /// (corners and mid-edges, half side `square_half_side`), one folder each.
    #[arg(long)]
    pub square: bool,
    /// Seed of the run; overrides the config.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Largest number of iterations; overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Output folder.
    #[arg(long, default_value = "runs/expert")]
    pub out: PathBuf,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

fn print_header() {
    eprintln!("{}", IterationLog::PROGRESS_HEADER);
}

fn print_line(l: &IterationLog) {
    eprintln!("{}", l.progress_line());
}

/// Runs `learner expert`.
pub fn run(args: ExpertArgs) -> anyhow::Result<()> {
    let mut cfg: ExpertConfig = match &args.config {
        Some(p) => ur5_shared::config::from_toml_file(p)?,
        None => ExpertConfig::default(),
    };
    if let Some(g) = args.goal {
        cfg.task.goal = g;
    }
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    cfg.task.validate()?;
    cfg.sim.validate()?;
    anyhow::ensure!(
        cfg.samples >= 1 && cfg.iterations >= 1 && cfg.demos >= 1,
        "samples, iterations and demos must be >= 1"
    );
    anyhow::ensure!(
        cfg.init_var > 0.0 && cfg.init_var.is_finite(),
        "init_var must be finite and > 0 (rad²)"
    );

    let jobs: Vec<(ExpertConfig, PathBuf)> = if args.square {
        square_goals(cfg.task.goal, cfg.square_half_side)
            .iter()
            .enumerate()
            .map(|(i, g)| {
                let mut c = cfg.clone();
                c.task.goal = *g;
                c.seed = cfg.seed.wrapping_add(i as u64 + 1);
                (c, args.out.join(format!("square_{i}")))
            })
            .collect()
    } else {
        vec![(cfg.clone(), args.out.clone())]
    };
    let mut summaries = Vec::new();
    for (c, out) in &jobs {
        eprintln!(
            "expert for goal {:?} m (seed {}) -> {}",
            c.task.goal,
            c.seed,
            out.display()
        );
        print_header();
        let s = train_and_record(c, out, print_line)
            .with_context(|| format!("expert for goal {:?}", c.task.goal))?;
        eprintln!(
            "done: best eval cost {:.4} ({:.1} % of the random policy's {:.4}), final distance {:.4} m; \
             {} demos (mean cost {:.4}) in {}",
            s.eval_cost,
            100.0 * s.cost_ratio,
            s.cost_random,
            s.final_distance,
            c.demos,
            s.cost_demos,
            s.demos.display()
        );
        summaries.push(s);
    }
    if args.json {
        println!(
            "{}",
            serde_json::json!({"command": "expert", "runs": summaries})
        );
    }
    Ok(())
}
