//! `learner expert`: command-line front of [`imitation::expert`].

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use ur5_shared::config::parse_triple;

use imitation::expert::{square_goals, ExpertConfig, IterationLog};

use super::CommonArgs;
use crate::run::{train_and_record, ExpertSummary};

/// Arguments of `learner expert`.
#[derive(Args, Debug)]
pub struct ExpertArgs {
    /// Goal point x,y,z (m, arm base frame); overrides the config.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub goal: Option<[f64; 3]>,
    /// Train and record experts for the 8 points of the generalisation square around the goal
    /// (corners and mid-edges, half side `square_half_side`), one folder each.
    #[arg(long)]
    pub square: bool,
    /// Largest number of iterations; overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Worker threads for the episodes of an iteration, which run in parallel (0 = one per
    /// core); results are the same for any number (docs/design.md §5 D29).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// --config: an `ExpertConfig` (tables `task`, `sim`, `cost`, `algorithm`, `prior`, `fit`,
    /// `traj_opt`); --out default `runs/expert`.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Trains and records the expert of `c` into `out` ([`train_and_record`]), one progress line
/// per iteration under a header, with a bar and ETA over `c.iterations` on a terminal.
pub(super) fn train_with_progress(c: &ExpertConfig, out: &Path) -> anyhow::Result<ExpertSummary> {
    eprintln!("{}", IterationLog::PROGRESS_HEADER);
    let bar = crate::progress::Progress::new(c.iterations as u64, "iterations");
    Ok(train_and_record(c, out, |l| {
        bar.done_one(&l.progress_line())
    })?)
}

/// The expert's closing line: its best cost, final distance and the `demos` recorded.
pub(super) fn print_done(s: &ExpertSummary, demos: usize) {
    let orientation = s
        .final_orientation_error_deg
        .map_or(String::new(), |e| format!(", orientation error {e:.3}°"));
    eprintln!(
        "done: best eval cost {:.4} ({:.1} % of the random policy's {:.4}), final distance {:.4} m\
         {orientation}; {} demos (mean cost {:.4}) in {}",
        s.eval_cost,
        100.0 * s.cost_ratio,
        s.cost_random,
        s.final_distance,
        demos,
        s.cost_demos,
        s.demos.display()
    );
}

/// Runs `learner expert`.
pub fn run(args: ExpertArgs) -> anyhow::Result<()> {
    let mut cfg: ExpertConfig = args.common.settings()?;
    let out_dir = args
        .common
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs/expert"));
    if let Some(g) = args.goal {
        cfg.task.goal = g;
    }
    if let Some(s) = args.common.seed {
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
                (c, out_dir.join(format!("square_{i}")))
            })
            .collect()
    } else {
        vec![(cfg.clone(), out_dir.clone())]
    };
    let mut summaries = Vec::new();
    for (c, out) in &jobs {
        eprintln!(
            "expert for goal {:?} m (seed {}) -> {}",
            c.task.goal,
            c.seed,
            out.display()
        );
        let s = train_with_progress(c, out)
            .with_context(|| format!("expert for goal {:?}", c.task.goal))?;
        print_done(&s, c.demos);
        summaries.push(s);
    }
    if args.common.json {
        println!(
            "{}",
            serde_json::json!({"command": "expert", "runs": summaries})
        );
    }
    Ok(())
}
