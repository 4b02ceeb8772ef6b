//! `learner experiment pilqr`: the KL-bounded LQR step against PILQR (LQR followed by PI2 on
//! the residual cost, `[traj_opt] method`, docs/design.md §5 D34), for the expert (on the task
//! cost) and for LQR+GAIfO (on the critic's cost), on the nominal arm and on the perturbed one
//! (`physical`, whose one-step latency and friction the fitted linear dynamics get wrong), at
//! one or more goals.
//!
//! Jobs are learner × arm × goal × method × seed, independent and run on one pool. LQR+GAIfO
//! imitates the demonstrations of the nominal arm's default (LQR) expert at that goal, on either
//! arm (as `sim-vs-physical`, docs/design.md §5 D26), normalised by those demonstrations. The
//! expert's "normalised performance" is 1 − C / C_random (its `performance_proxy`; there are
//! no demonstrations to normalise it by), and it runs all `iterations` (patience off).
//!
//! Outputs as the other experiments' (`pilqr.csv`, `pilqr.png`, `summary.txt`,
//! `summary.json`), plus `reach.txt`: per variant, the training episodes (i·N before the
//! evaluated controller of iteration i) each seed needed to first end within 1 cm and within
//! 3 mm of the goal, and the mean ± standard deviation of the final distance over seeds at
//! every iteration (`spread.csv`).

use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use gps::traj_opt::pilqr::TrajOptMethod;
use imitation::demos::Demos;
use imitation::gaifo::GaifoLog;

use super::goals::{goal_demos, goal_list, goal_name, precision_text, reach_text, spread_csv};
use super::{pool, write_outputs, ExperimentConfig, ExperimentError, Run};
use crate::arm::SimArm;
use crate::error::ensure;

/// The experiment's defaults over `base`: 3 seeds × 30 iterations (the expert, both arms, both
/// methods).
pub fn defaults(base: ExperimentConfig) -> ExperimentConfig {
    ExperimentConfig {
        seeds: 3,
        iterations: 30,
        ..base
    }
}

/// Settings of `learner experiment pilqr` (`[pilqr]` of its config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PilqrExperimentConfig {
    /// Learners: `expert` (the task cost) and `lqr-gaifo`.
    pub learners: Vec<String>,
    /// Arms: `nominal`, `perturbed` (the experiment's `physical` perturbation).
    pub arms: Vec<String>,
    /// Trajectory optimisers to compare.
    pub methods: Vec<TrajOptMethod>,
    /// Goals (m); empty: the expert's `task.goal`. `workspace_goals = true` adds
    /// [`super::goals::WORKSPACE_GOALS`].
    pub goals: Vec<[f64; 3]>,
    /// Add the five [`super::goals::WORKSPACE_GOALS`].
    pub workspace_goals: bool,
}

impl Default for PilqrExperimentConfig {
    fn default() -> Self {
        Self {
            learners: vec!["expert".into()],
            arms: vec!["nominal".into(), "perturbed".into()],
            methods: vec![TrajOptMethod::Lqr, TrajOptMethod::Pilqr],
            goals: Vec::new(),
            workspace_goals: false,
        }
    }
}

impl PilqrExperimentConfig {
    /// Checks the names.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        let bad = |m: String| ExperimentError::Settings(m);
        for l in &self.learners {
            ensure!(
                ["expert", "lqr-gaifo"].contains(&l.as_str()),
                bad(format!(
                    "pilqr.learners: unknown `{l}`; known: expert, lqr-gaifo"
                ))
            );
        }
        for a in &self.arms {
            ensure!(
                ["nominal", "perturbed"].contains(&a.as_str()),
                bad(format!(
                    "pilqr.arms: unknown `{a}`; known: nominal, perturbed"
                ))
            );
        }
        ensure!(
            !self.learners.is_empty() && !self.arms.is_empty() && !self.methods.is_empty(),
            bad("pilqr.learners, arms and methods must each name at least one".into())
        );
        Ok(())
    }
}

fn method_name(m: TrajOptMethod) -> &'static str {
    match m {
        TrajOptMethod::Lqr => "lqr",
        TrajOptMethod::Pilqr => "pilqr",
    }
}

struct Job {
    learner: String,
    arm: String,
    goal: usize,
    method: TrajOptMethod,
    seed: u64,
}

/// Runs the experiment into `out`; returns the runs.
pub fn run(cfg: &ExperimentConfig, out: &Path) -> Result<Vec<Run>, ExperimentError> {
    let p = &cfg.pilqr;
    p.validate()?;
    let goals = goal_list(&p.goals, p.workspace_goals, cfg.expert.task.goal);
    let t0 = Instant::now();
    let pool = pool(cfg.threads)?;
    let mut jobs = Vec::new();
    for learner in &p.learners {
        for arm in &p.arms {
            for goal in 0..goals.len() {
                for &method in &p.methods {
                    for s in 0..cfg.seeds {
                        jobs.push(Job {
                            learner: learner.clone(),
                            arm: arm.clone(),
                            goal,
                            method,
                            seed: cfg.first_seed + s as u64,
                        });
                    }
                }
            }
        }
    }
    eprintln!(
        "experiment pilqr: {} job(s) ({} seed(s) from {}, {} iterations, goals {:?}) on {} thread(s) -> {}",
        jobs.len(),
        cfg.seeds,
        cfg.first_seed,
        cfg.iterations,
        goals,
        pool.current_num_threads(),
        out.display()
    );
    crate::io::create_dir(out)?;
    // LQR+GAIfO's demonstrations: the nominal arm's default expert at each goal.
    let demos: Vec<Option<Demos>> = if p.learners.iter().any(|l| l == "lqr-gaifo") {
        goal_demos(cfg, &goals, &pool)?
            .into_iter()
            .map(Some)
            .collect()
    } else {
        vec![None; goals.len()]
    };
    let label = |j: &Job| {
        // No commas: the label is a CSV field.
        let g = if goals.len() > 1 {
            format!(" goal {}", goal_name(goals[j.goal]))
        } else {
            String::new()
        };
        format!("{} {} {}{g}", j.learner, j.arm, method_name(j.method))
    };
    // A run that fails (a learner error) keeps the iterations it finished: it is reported in
    // `reach.txt` and left out of the curves, and the other runs go on.
    let results: Vec<(Run, Option<String>)> = pool.install(|| {
        jobs.par_iter()
            .map(|j| {
                let t = Instant::now();
                let (logs, n, horizon, err) = if j.learner == "expert" {
                    expert_job(cfg, j, goals[j.goal])?
                } else {
                    let d = demos[j.goal].clone().expect("demonstrations trained above");
                    gaifo_job(cfg, j, d)?
                };
                let last = logs.last().map_or(f64::NAN, |l| l.final_distance);
                eprintln!(
                    "  {} seed {}: final distance {:.2} mm after {} iterations ({:.0} s){}",
                    label(j),
                    j.seed,
                    1e3 * last,
                    logs.len(),
                    t.elapsed().as_secs_f64(),
                    err.as_deref()
                        .map_or(String::new(), |e| format!("; failed: {e}"))
                );
                Ok((
                    Run {
                        variant: label(j),
                        algorithm: j.learner.clone(),
                        seed: j.seed,
                        episodes_per_iteration: n,
                        horizon,
                        logs,
                        wall_s: t.elapsed().as_secs_f64(),
                    },
                    err,
                ))
            })
            .collect::<Result<Vec<_>, ExperimentError>>()
    })?;
    let failed: Vec<(Run, String)> = results
        .iter()
        .filter_map(|(r, e)| e.as_ref().map(|e| (r.clone(), e.clone())))
        .collect();
    let runs: Vec<Run> = results
        .into_iter()
        .filter_map(|(r, e)| e.is_none().then_some(r))
        .collect();
    ensure!(
        !runs.is_empty(),
        ExperimentError::Settings(format!("every run failed; the first: {}", failed[0].1))
    );
    write_outputs(
        "pilqr",
        "LQR vs PILQR: noise-free episode per iteration",
        &runs,
        out,
    )?;
    let mut reach = reach_text(&runs);
    for (r, e) in &failed {
        reach += &format!(
            "FAILED {} seed {} after {} iterations (last final distance {:.2} mm): {e}\n",
            r.variant,
            r.seed,
            r.logs.len(),
            r.logs.last().map_or(f64::NAN, |l| 1e3 * l.final_distance)
        );
    }
    std::fs::write(out.join("reach.txt"), &reach)?;
    std::fs::write(out.join("spread.csv"), spread_csv(&runs))?;
    if goals.len() > 1 {
        std::fs::write(out.join("precision.txt"), precision_text(&runs))?;
    }
    eprint!("{reach}");
    eprintln!(
        "experiment pilqr done in {:.0} s; outputs in {}",
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(runs)
}

/// What a job returns: its logs, N, T, and the error that stopped it early, if one did.
type JobResult = (Vec<GaifoLog>, usize, usize, Option<String>);

/// One expert run with every iteration logged (patience off).
fn expert_job(
    cfg: &ExperimentConfig,
    j: &Job,
    goal: [f64; 3],
) -> Result<JobResult, ExperimentError> {
    let mut e = cfg.expert.clone();
    e.task.goal = goal;
    e.seed = j.seed;
    e.iterations = cfg.iterations;
    e.patience = cfg.iterations;
    e.traj_opt.method = j.method;
    if j.arm == "perturbed" {
        e.sim.perturbation = cfg.physical.clone();
    }
    let arm = SimArm::new(e.sim.clone(), e.task.dt)?;
    let mut logs = Vec::new();
    let res = imitation::expert::train(&e, &arm, |l| {
        logs.push(GaifoLog {
            iteration: l.iteration,
            task_cost: l.eval_cost,
            performance: l.performance_proxy,
            final_distance: l.final_distance,
            critic_loss: f64::NAN,
            wasserstein: f64::NAN,
            kl: l.kl,
            eta: l.eta,
            step_mult: l.step_mult,
            ..GaifoLog::default()
        })
    });
    Ok((
        logs,
        e.samples,
        e.task.horizon,
        res.err().map(|e| crate::error::line(&e)),
    ))
}

/// One LQR+GAIfO run on `demos`.
fn gaifo_job(cfg: &ExperimentConfig, j: &Job, demos: Demos) -> Result<JobResult, ExperimentError> {
    let mut g = cfg.lqr_gaifo.clone();
    g.seed = j.seed;
    g.iterations = cfg.iterations;
    g.traj_opt.method = j.method;
    if j.arm == "perturbed" {
        g.sim.perturbation = cfg.physical.clone();
    }
    let horizon = demos.task()?.horizon;
    let mut logs = Vec::new();
    let res = crate::run::train(&g, demos, None, |l| logs.push(l.clone()));
    Ok((
        logs,
        g.samples,
        horizon,
        res.err().map(|e| crate::error::line(&e)),
    ))
}
