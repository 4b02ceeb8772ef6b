//! `learner train --algo bco` and `--algo replay-mean`: the baselines without a critic
//! ([`crate::baselines`]).

use imitation::bco::{Bco, BcoConfig};
use imitation::replay_mean::ReplayMeanConfig;

use super::{demos_file, report, take_folder, warn_unrecorded_model, TrainArgs};
use crate::io::manifest::{Claim, Manifest};

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
    let out = args.out_dir();
    if let Some(dir) = &args.resume {
        anyhow::ensure!(
            out == *dir,
            "--out {} and --resume {} differ: a resumed run continues in its own folder",
            out.display(),
            dir.display()
        );
    }
    let pre = Manifest::new("train", "bco", cfg.seed, None, &cfg)?;
    let (path, claimed) = demos_file(args, cfg.seed, &cfg.sim, &pre)?;
    let demos = crate::io::demos::load_checked(&path, &cfg.sim)?;
    warn_unrecorded_model(&path, &cfg.sim)?;
    let m = Manifest::new("train", "bco", cfg.seed, Some(&path), &cfg)?;
    let claim = match args.resume {
        Some(_) => Claim::Resume,
        None => Claim::New {
            force: args.force || claimed,
        },
    };
    take_folder(args.record_episodes, &out, &m, claim)?;
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
    report(&logs, "bco", cfg.seed, &out, args.common.json, spread);
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
    let out = args.out_dir();
    let pre = Manifest::new("train", "replay-mean", cfg.seed, None, &cfg)?;
    let (path, claimed) = demos_file(args, cfg.seed, &cfg.sim, &pre)?;
    let demos = crate::io::demos::load_checked(&path, &cfg.sim)?;
    warn_unrecorded_model(&path, &cfg.sim)?;
    let m = Manifest::new("train", "replay-mean", cfg.seed, Some(&path), &cfg)?;
    let claim = Claim::New {
        force: args.force || claimed,
    };
    take_folder(args.record_episodes, &out, &m, claim)?;
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
    report(
        &logs,
        "replay-mean",
        cfg.seed,
        &out,
        args.common.json,
        spread,
    );
    Ok(())
}
