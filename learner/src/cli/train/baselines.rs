//! `learner train --algo bco` and `--algo replay-mean`: the baselines without a critic
//! ([`crate::baselines`]).

use imitation::bco::{Bco, BcoConfig};
use imitation::replay_mean::ReplayMeanConfig;

use super::{demos_are_paths, open_run, report_motion, TrainArgs};

/// `learner train --algo bco`: BCO(α) in process, a checkpoint before every iteration, exact
/// `--resume`.
pub(super) fn run_bco(args: &TrainArgs) -> anyhow::Result<()> {
    let mut cfg: BcoConfig = args.common.settings()?;
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    if let Some(s) = args.common.seed {
        cfg.seed = s;
    }
    cfg.validate()?;
    let (out, demos) = open_run(args, "bco", cfg.seed, &cfg.sim, &cfg)?;
    eprintln!(
        "BCO(α = {}) on {} demonstrations of T = {} (goal {:?} m), seed {}, -> {}{}",
        1.0 / cfg.pre_iterations as f64,
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
    eprintln!("{}", Bco::PROGRESS_HEADER);
    let start = match &args.resume {
        Some(dir) => crate::baselines::latest_state(dir).map_or(0, |(n, _)| n),
        None => 0,
    };
    let bar =
        crate::progress::Progress::new(cfg.iterations.saturating_sub(start) as u64, "iterations");
    let print = |l: &_, r: &Bco| bar.done_one(&r.progress_line(l));
    let spread = imitation::iteration_log::demo_spread(&demos).map(|s| s.rmse_m);
    let logs = match &args.resume {
        Some(dir) => crate::baselines::train_bco_resumed(&cfg, demos, dir, print)?,
        None => crate::baselines::train_bco(&cfg, demos, Some(&out), print)?,
    };
    drop(bar);
    if logs.is_empty() {
        eprintln!(
            "done: {} already holds all {} iterations; nothing to resume",
            out.display(),
            cfg.iterations
        );
    }
    report_motion(
        &logs,
        "bco",
        cfg.seed,
        &out,
        args.common.json,
        spread,
        demos_are_paths(args),
    );
    Ok(())
}

/// `learner train --algo replay-mean`: the naive baseline's evaluation (one iteration unless
/// asked for more, each the same table).
pub(super) fn run_replay_mean(args: &TrainArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.resume.is_none(),
        "--algo replay-mean learns nothing, so there is nothing to resume: run it again"
    );
    let mut cfg: ReplayMeanConfig = args.common.settings()?;
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    if let Some(s) = args.common.seed {
        cfg.seed = s;
    }
    cfg.validate()?;
    let (out, demos) = open_run(args, "replay-mean", cfg.seed, &cfg.sim, &cfg)?;
    eprintln!(
        "the demonstrations' mean joint path ({} demonstrations of T = {}, goal {:?} m) as the \
         commands -> {}",
        demos.count,
        demos.horizon,
        demos.goal,
        out.display()
    );
    let spread = imitation::iteration_log::demo_spread(&demos).map(|s| s.rmse_m);
    let logs = crate::baselines::train_replay_mean(&cfg, demos, Some(&out), |l| {
        eprintln!(
            "iter {:>3}  task cost {:.4}  perf {:.3}  final distance {:.4} m",
            l.iteration, l.task_cost, l.performance, l.final_distance
        )
    })?;
    report_motion(
        &logs,
        "replay-mean",
        cfg.seed,
        &out,
        args.common.json,
        spread,
        demos_are_paths(args),
    );
    Ok(())
}
