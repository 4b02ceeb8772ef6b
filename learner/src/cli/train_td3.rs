//! `learner train --algo gaifo-td3`: off-policy GAIfO in process, with a checkpoint before every
//! iteration and `--resume` (exact: the replay buffer is part of the checkpoint).

use imitation::iteration_log::GaifoLog;
use imitation::offpolicy::{GaifoTd3Config, UpdateStats};

use super::train::{check_resumed_algo, demos_are_paths, open_run, report_motion, TrainArgs};

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
    let (out, demos) = open_run(args, "gaifo-td3", cfg.seed, &cfg.sim, &cfg)?;
    let spread = imitation::iteration_log::demo_spread(&demos).map(|s| s.rmse_m);
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
    report_motion(
        &logs,
        "gaifo-td3",
        cfg.seed,
        &out,
        args.common.json,
        spread,
        demos_are_paths(args),
    );
    Ok(())
}
