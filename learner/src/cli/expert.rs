//! `learner expert`: command-line front of [`imitation::expert`].

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use ur5_shared::config::{parse_pose, parse_triple, SimConfig, TaskConfig};

use imitation::expert::{square_goals, ExpertConfig, IterationLog};

use super::CommonArgs;
use crate::run::{train_and_record, ExpertSummary};

/// Arguments of `learner expert`.
#[derive(Args, Debug)]
pub struct ExpertArgs {
    /// Goal point x,y,z (m, arm base frame); overrides the config.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub goal: Option<[f64; 3]>,
    /// Goal pose of the tool, UR's p[x, y, z, rx, ry, rz]: x,y,z (m) and a rotation vector
    /// rx,ry,rz (rad), arm base frame, as the teach pendant shows it. Sets `[task] goal_pose`
    /// (and `goal` to its position) and six joints, unless the config gives `[task] joints`;
    /// overrides the config. Refused if the arm cannot reach it.
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true, conflicts_with_all = ["goal", "square"])]
    pub goal_pose: Option<[f64; 6]>,
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

/// Makes `task` a pose task toward UR's pose `pose` (`--goal-pose`): its goal pose and goal
/// point, and six joints (a three-angle start pose gets the wrist at `sim.wrist_q`, as a
/// config file that leaves `start_q` out does) unless `joints_given` (the config says how many
/// joints: a pose then needs six). Checks the task and that the arm reaches the pose within
/// its joint limits (inverse kinematics of `sim.model`), the error naming the pose.
pub(super) fn set_goal_pose(
    task: &mut TaskConfig,
    sim: &SimConfig,
    pose: [f64; 6],
    joints_given: bool,
) -> anyhow::Result<()> {
    if !joints_given && task.joints == 3 {
        task.joints = 6;
        if task.start_q.len() == 3 {
            task.start_q = task.start_q.extended(&sim.wrist_q)?;
        }
    }
    task.goal_pose = Some(pose);
    task.goal = [pose[0], pose[1], pose[2]];
    task.validate()
        .with_context(|| format!("--goal-pose {}", pose_text(&pose)))?;
    let ik = ur5_shared::ik::UrIk::new(sim.model, sim.ee_offset);
    ik.nearest_pose(
        &ur5_shared::pose::isometry(&pose),
        &task.start_six(&sim.wrist_q),
    )
    .map_err(|e| {
        anyhow::anyhow!(
            "--goal-pose {}: out of the {}'s reach: {e}",
            pose_text(&pose),
            sim.model
        )
    })?;
    Ok(())
}

/// UR's pose as the teach pendant writes it: `p[x, y, z, rx, ry, rz]`.
pub(super) fn pose_text(p: &[f64; 6]) -> String {
    format!(
        "p[{}]",
        p.iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// Trains and records the expert of `c` into `out` ([`train_and_record`]), one progress line
/// per iteration under a header, with a bar and ETA over `c.iterations` on a terminal.
pub(super) fn train_with_progress(c: &ExpertConfig, out: &Path) -> anyhow::Result<ExpertSummary> {
    eprintln!("{}", IterationLog::PROGRESS_HEADER);
    let bar =
        crate::progress::Progress::new(c.iterations_for(c.task.layout().du()) as u64, "iterations");
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
    if let Some(p) = args.goal_pose {
        let joints_given = args.common.config_gives("task", "joints")?;
        set_goal_pose(&mut cfg.task, &cfg.sim, p, joints_given)?;
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
