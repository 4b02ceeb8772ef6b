//! `learner policy`: run a saved MDGPS policy (`learner::io::policy`) in simulation (`eval`) or
//! on the real-time controller (`serve`).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use serde::Serialize;

use imitation::mlp_policy::global::GlobalActor;
use imitation::rollout::run_episode;
use ur5_shared::config::{parse_triple, SimConfig, TaskConfig};
use ur5_shared::UrModel;

use crate::arm::SimArm;
use crate::io::policy::load_policy;
use crate::serve::policy::{serve_policy, PolicyServeOptions};

/// What `learner policy` does.
#[derive(Subcommand, Debug)]
pub enum PolicyCmd {
    /// One noise-free episode of a saved policy to any goal on the simulated arm (from the
    /// start pose it was trained from); prints the final distance to the goal (m) and the task
    /// cost C(τ) (m).
    Eval(EvalArgs),
    /// Publish a saved policy to the real-time controller as a policy table on
    /// `controller/policy` (docs/design.md §3.11) and report the episodes it runs with it
    /// (steps, distance to the goal at the last step, and for noise-free episodes the actions
    /// that differ from the policy's own on the recorded states: 0 means executed exactly).
    /// The goal is the controller's: `rt-controller run --goal x,y,z`.
    Serve(ServeArgs),
}

/// Arguments of `learner policy serve`.
#[derive(Args, Debug)]
pub struct ServeArgs {
    /// The policy file (`policy_seed<S>.npz` of `learner experiment multi-goal`).
    #[arg(long)]
    pub policy: PathBuf,
    /// iceoryx2 service prefix (the controller's).
    #[arg(long, default_value = "")]
    pub prefix: String,
    /// Table version to publish (the controller takes a table only if it is newer than its
    /// active one).
    #[arg(long, default_value_t = 1)]
    pub version: u64,
    /// Steps per episode: the controller's task.horizon (default: the policy file's T).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Stop after this many complete episodes.
    #[arg(long, default_value_t = 1)]
    pub episodes: usize,
    /// Give up when no sample arrives for this long (s).
    #[arg(long, default_value_t = 60.0)]
    pub timeout_s: f64,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `learner policy eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// The policy file (`policy_seed<S>.npz` of `learner experiment multi-goal`).
    #[arg(long)]
    pub policy: PathBuf,
    /// Goal point x,y,z (m, arm base frame), e.g. `-0.45,-0.25,0.25`.
    #[arg(long, value_parser = parse_triple, allow_hyphen_values = true)]
    pub goal: [f64; 3],
    /// Steps of the episode (control periods of the file's dt); default: the training T.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

/// What `learner policy eval` reports (also its `--json` line).
#[derive(Clone, Debug, Serialize)]
pub struct EvalSummary {
    /// The policy file.
    pub policy: PathBuf,
    /// Goal point (m).
    pub goal: [f64; 3],
    /// Steps run.
    pub steps: usize,
    /// Final end-effector distance to the goal (m).
    pub final_distance_m: f64,
    /// Task cost C(τ) of the episode (m, docs/design.md §1.6).
    pub task_cost: f64,
    /// The arm it ran on: the policy file's.
    pub model: UrModel,
}

/// Runs `learner policy`.
pub fn run(cmd: PolicyCmd) -> anyhow::Result<()> {
    match cmd {
        PolicyCmd::Eval(args) => {
            let s = eval(&args)?;
            eprintln!(
                "policy {} on the {} to goal {:?}: final distance {:.4} m, task cost {:.4} ({} \
                 steps)",
                s.policy.display(),
                s.model,
                s.goal,
                s.final_distance_m,
                s.task_cost,
                s.steps
            );
            if args.json {
                println!(
                    "{}",
                    serde_json::json!({"command": "policy eval", "result": s})
                );
            }
            Ok(())
        }
        PolicyCmd::Serve(args) => {
            let file = load_policy(&args.policy)?;
            let mut table = file
                .policy
                .to_table(args.version, file.mode)
                .with_context(|| format!("{} as a policy table", args.policy.display()))?;
            // The controller refuses a policy of another arm than it drives.
            table.set_arm_model(file.model);
            let opts = PolicyServeOptions {
                prefix: args.prefix.clone(),
                steps: args.steps.unwrap_or(file.horizon),
                episodes: args.episodes,
                timeout_s: args.timeout_s,
            };
            eprintln!(
                "learner policy serve: {} as policy table version {} on prefix `{}` ({} parameters); waiting for {} episode(s) of {} steps",
                args.policy.display(),
                args.version,
                args.prefix,
                table.n_params,
                opts.episodes,
                opts.steps
            );
            let episodes = serve_policy(&table, &opts, |e| {
                eprintln!(
                    "episode {} ({}, table v{}): {} steps, distance to the goal at the last step {:.4} m{}",
                    e.episode,
                    if e.noisy { "noisy" } else { "noise-free" },
                    e.version,
                    e.steps,
                    e.distance_last_m,
                    e.mismatched_actions
                        .map(|m| format!(", actions differing from the policy's: {m}"))
                        .unwrap_or_default()
                );
            })?;
            if args.json {
                println!(
                    "{}",
                    serde_json::json!({"command": "policy serve", "policy": args.policy, "version": args.version, "episodes": episodes})
                );
            }
            Ok(())
        }
    }
}

/// One noise-free episode of the policy of `args.policy` to `args.goal`.
pub fn eval(args: &EvalArgs) -> anyhow::Result<EvalSummary> {
    let file = load_policy(&args.policy)?;
    let task = TaskConfig {
        dt: file.dt,
        horizon: args.steps.unwrap_or(file.horizon),
        joints: file.start_q.len(),
        start_q: file.start_q,
        goal: args.goal,
        ..TaskConfig::default()
    };
    task.validate()
        .with_context(|| format!("--goal {:?} / --steps {}", args.goal, task.horizon))?;
    // `--goal` is a point: a policy of a pose task would act on states it was not made for.
    file.check_layout(&task.layout()).with_context(|| {
        format!(
            "{}: a policy of a task with {} cannot run to the goal point --goal {:?}",
            args.policy.display(),
            file.layout(),
            args.goal
        )
    })?;
    // The task cost sums over steps 1..T (its distance term is normalised by T − 1).
    anyhow::ensure!(
        task.horizon >= 2,
        "--steps {}: an episode needs at least 2 steps (its task cost is undefined for 1)",
        task.horizon
    );
    // The policy's own arm: its kinematics and limits are the policy's world.
    let sim = SimConfig {
        mode: file.mode,
        ..SimConfig::for_model(file.model)
    };
    let mut arm = SimArm::for_task(sim, &task).context("building the simulated arm")?;
    let mut ws = file.policy.workspace();
    let ep = run_episode(
        &mut arm,
        &task,
        &mut GlobalActor::new(&file.policy, &mut ws),
        None,
    )?;
    anyhow::ensure!(
        ep.task_cost().is_finite() && ep.final_distance().is_finite(),
        "the episode of {} ended with task cost {} and final distance {} m: not finite",
        args.policy.display(),
        ep.task_cost(),
        ep.final_distance()
    );
    Ok(EvalSummary {
        policy: args.policy.clone(),
        goal: args.goal,
        steps: task.horizon,
        final_distance_m: ep.final_distance(),
        task_cost: ep.task_cost(),
        model: file.model,
    })
}
