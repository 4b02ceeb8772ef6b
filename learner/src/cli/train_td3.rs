//! `learner train --algo gaifo-td3`: off-policy GAIfO in process, with a checkpoint before every
//! iteration and `--resume` (exact: the replay buffer is part of the checkpoint).

use imitation::iteration_log::GaifoLog;
use imitation::offpolicy::{GaifoTd3Config, UpdateStats};

use super::train::{
    check_resumed_algo, demos_file, report, take_folder, warn_unrecorded_model, TrainArgs,
};
use crate::io::manifest::{Claim, Manifest};

/// The progress line of an off-policy GAIfO iteration.
fn line(l: &GaifoLog, u: &UpdateStats) -> String {
    format!(
        "{:>4} {:>9.4} {:>7.3} {:>8.4} {:>9.4} {:>8.4} {:>9.3e} {:>9.3e} {:>8.3} {:>7} {:>7.1} {:>7.1}",
        l.iteration,
        l.task_cost,
        l.performance,
        l.final_distance,
        l.critic_loss,
        l.wasserstein,
        u.critic_loss,
        u.actor_loss,
        u.mean_reward,
        u.buffer_rows,
        1e3 * (l.t_critic + l.t_cost + l.t_lqr),
        1e3 * l.t_execute
    )
}

/// Runs `learner train --algo gaifo-td3` (its `--config` a [`GaifoTd3Config`] layered over its
/// defaults, i.e. LQR+GAIfO's shared settings, then the command line).
pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    check_resumed_algo(args)?;
    let mut cfg: GaifoTd3Config = args.common.settings()?;
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
    let pre = Manifest::new("train", "gaifo-td3", cfg.seed, None, &cfg)?;
    let (path, claimed) = demos_file(args, cfg.seed, &cfg.sim, &pre)?;
    let demos = crate::io::demos::load_checked(&path, &cfg.sim)?;
    let spread = imitation::iteration_log::demo_spread(&demos).map(|s| s.rmse_m);
    warn_unrecorded_model(&path, &cfg.sim)?;
    let m = Manifest::new("train", "gaifo-td3", cfg.seed, Some(&path), &cfg)?;
    let claim = match args.resume {
        Some(_) => Claim::Resume,
        None => Claim::New {
            force: args.force || claimed,
        },
    };
    take_folder(args.record_episodes, &out, &m, claim)?;
    eprintln!(
        "GAIfO (TD3) on {} demonstrations of T = {} (goal {:?} m), seed {}, -> {}{}",
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
    eprintln!(
        "{:>4} {:>9} {:>7} {:>8} {:>9} {:>8} {:>9} {:>9} {:>8} {:>7} {:>7} {:>7}",
        "iter",
        "task_cost",
        "perf",
        "final_m",
        "critic",
        "W1_est",
        "q_loss",
        "pi_loss",
        "reward",
        "rows",
        "lrn_ms",
        "sim_ms"
    );
    let start = match &args.resume {
        Some(dir) => crate::run::latest_checkpoint(dir).map_or(0, |(n, _, _)| n),
        None => 0,
    };
    let bar =
        crate::progress::Progress::new(cfg.iterations.saturating_sub(start) as u64, "iterations");
    let print = |l: &GaifoLog, u: &UpdateStats| bar.done_one(&line(l, u));
    let logs = match &args.resume {
        Some(dir) => crate::run::train_td3_resumed(&cfg, demos, dir, print)?,
        None => crate::run::train_td3(&cfg, demos, Some(&out), print)?,
    };
    drop(bar);
    if logs.is_empty() && args.resume.is_some() {
        eprintln!(
            "done: {} already holds all {} iterations; nothing to resume",
            out.display(),
            cfg.iterations
        );
    }
    report(&logs, "gaifo-td3", cfg.seed, &out, args.common.json, spread);
    Ok(())
}
