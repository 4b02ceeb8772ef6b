//! `learner experiment multi-goal` (docs/design.md §6.6): one MDGPS policy trained
//! on the 8 demonstrated square points, evaluated noise-free at goals nobody demonstrated — the
//! centre, `eval_inside` seeded goals inside the square and `eval_outside` just outside it —
//! and at the 8 demonstrated points, side by side with the linear-Gaussian controller that
//! LQR+GAIfO trains for the centre from the same demonstrations (the generalisation
//! experiment's 8-point run). Each goal's normalised performance uses an expert trained at that
//! goal for the evaluation only.
//!
//! Outputs in `--out`: `multi-goal.csv` (one row per method, seed, iterations done, goal),
//! `mdgps_log.csv` (MDGPS's per-iteration training log), `multi-goal.png` (mean over goals
//! of each kind, mean ± standard error over seeds, per iteration), `summary.txt`,
//! `summary.json`, `experts/` (the demonstrations and evaluation experts),
//! `policy_seed<S>.npz` (each seed's trained policy, `learner policy eval` runs it) and
//! `mdgps_seed<S>/` (each seed's MDGPS run folder as `learner train --algo mdgps` writes it:
//! checkpoints before every iteration and after the last, its `mdgps_log.csv`).

use crate::progress::Progress;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use super::ExperimentError;
use crate::error::ensure;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use imitation::demos::Demos;
use imitation::expert::square_goals;
use imitation::gaifo::LqrGaifo;
use imitation::learn::{iterate, LinGaussLearn};
use imitation::mdgps::{Mdgps, MdgpsConfig, MdgpsLog};
use imitation::mlp_policy::global::GlobalActor;
use imitation::rollout::{run_episode, Arm, Episode, Policy};
use ur5_shared::config::TaskConfig;

use super::{combine_demos, experts_at, pool, ExperimentConfig};
use crate::io::log::MdgpsRow;
use crate::io::policy::{save_policy, PolicyFile};
use crate::plot::{mean_stderr, plot_panels, Panel, Series};

/// The two methods compared.
pub const METHODS: [&str; 2] = ["mdgps-policy", "lqr-gaifo-centre"];

/// Kinds of evaluation goal, in the order of [`eval_goals`].
pub const KINDS: [&str; 4] = ["centre", "inside", "outside", "demonstrated"];

/// A goal the methods are evaluated at.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct EvalGoal {
    /// One of [`KINDS`].
    pub kind: &'static str,
    /// Goal point (m, base frame).
    pub goal: [f64; 3],
}

/// The evaluation goals: the centre; `inside` goals drawn uniformly in the square (half side
/// `h`, m) at least 1 cm from every demonstrated point; `outside` goals at a uniform place
/// along an edge (edges in turn: −y, +x, +y, −x), `margin` (m) outside it; then the 8
/// demonstrated points. All at the centre's height; drawn from `seed`.
pub fn eval_goals(
    centre: [f64; 3],
    h: f64,
    inside: usize,
    outside: usize,
    margin: f64,
    seed: u64,
) -> Vec<EvalGoal> {
    let square = square_goals(centre, h);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let at = |dx: f64, dy: f64| [centre[0] + dx, centre[1] + dy, centre[2]];
    let mut out = vec![EvalGoal {
        kind: "centre",
        goal: centre,
    }];
    while out.len() < 1 + inside {
        let g = at(rng.random_range(-h..h), rng.random_range(-h..h));
        let near = |p: &[f64; 3]| ((p[0] - g[0]).powi(2) + (p[1] - g[1]).powi(2)).sqrt() < 0.01;
        if !square.iter().any(near) {
            out.push(EvalGoal {
                kind: "inside",
                goal: g,
            });
        }
    }
    for i in 0..outside {
        let (u, d) = (rng.random_range(-h..h), h + margin);
        let g = match i % 4 {
            0 => at(u, -d),
            1 => at(d, u),
            2 => at(u, d),
            _ => at(-d, u),
        };
        out.push(EvalGoal {
            kind: "outside",
            goal: g,
        });
    }
    out.extend(square.iter().map(|&goal| EvalGoal {
        kind: "demonstrated",
        goal,
    }));
    out
}

/// One evaluation episode's figures.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct GoalResult {
    /// Task cost C(τ) (m).
    pub task_cost: f64,
    /// Normalised performance against the goal's evaluation expert.
    pub performance: f64,
    /// Final distance to the goal (m).
    pub final_distance_m: f64,
}

/// One method at one seed: `evals[i][g]` after i iterations (i = 0 … iterations) at goal g.
#[derive(Clone, Debug)]
pub struct MethodRun {
    /// One of [`METHODS`].
    pub method: &'static str,
    /// Seed.
    pub seed: u64,
    /// Per iteration done, per evaluation goal.
    pub evals: Vec<Vec<GoalResult>>,
    /// MDGPS's training log (empty for the baseline).
    pub mdgps_logs: Vec<MdgpsLog>,
}

/// Noise-free episodes of `policy` from `base`'s start pose at every goal of `goals`, each
/// normalised by its expert in `experts` (same order).
pub fn evaluate(
    arm: &mut dyn Arm,
    base: &TaskConfig,
    policy: &mut dyn Policy,
    goals: &[EvalGoal],
    experts: &[Demos],
) -> Result<Vec<GoalResult>, ExperimentError> {
    goals
        .iter()
        .zip(experts)
        .map(|(g, e)| {
            let task = TaskConfig {
                goal: g.goal,
                ..base.clone()
            };
            let ep: Episode = run_episode(arm, &task, policy, None)?;
            let c = ep.task_cost();
            Ok(GoalResult {
                task_cost: c,
                performance: ur5_shared::normalised_performance(c, e.cost_random, e.cost_expert)
                    .unwrap_or(f64::NAN),
                final_distance_m: ep.final_distance(),
            })
        })
        .collect()
}

/// The MDGPS settings of the experiment's run at `seed`: its LQR+GAIfO settings with that seed
/// and `iterations`, its C-step KL bound and its policy.
pub fn mdgps_config(cfg: &ExperimentConfig, seed: u64) -> MdgpsConfig {
    let mut c = MdgpsConfig {
        lqr_gaifo: cfg.lqr_gaifo.clone(),
        kl_step: cfg.mdgps_kl_step,
        policy: cfg.mdgps_policy.clone(),
    };
    c.lqr_gaifo.seed = seed;
    c.lqr_gaifo.iterations = cfg.iterations;
    c
}

/// MDGPS at one seed on the `square`'s demonstrations through `learn::Learn`
/// ([`crate::run::run_iterations`], as `learner train --algo mdgps`): `mdgps_log.csv` and a
/// checkpoint before every iteration and after the last in `out/mdgps_seed<seed>/`, so that
/// the run can be resumed (`run::train_mdgps_resumed`) or checked; the policy is evaluated at
/// every goal of `goals` before the first iteration and after each, on an arm of its own (step
/// 1 runs on fresh arms, so this changes no bit). Saves the policy as
/// `out/policy_seed<seed>.npz`.
pub fn run_mdgps(
    cfg: &ExperimentConfig,
    seed: u64,
    square: &[Demos],
    goals: &[EvalGoal],
    experts: &[Demos],
    out: &Path,
    progress: &Progress,
) -> Result<MethodRun, ExperimentError> {
    let c = mdgps_config(cfg, seed);
    let mut run = Mdgps::new(c.clone(), square.to_vec())?;
    let base = run.task(0).clone();
    let arm = crate::run::arm_for(&run)?;
    let mut eval_arm = crate::run::arm_for(&run)?;
    let mut ws = run.policy().workspace();
    let mut evals = Vec::with_capacity(cfg.iterations + 1);
    let mut actor = GlobalActor::new(run.policy(), &mut ws);
    evals.push(evaluate(&mut eval_arm, &base, &mut actor, goals, experts)?);
    let mut failed = None;
    let logs = crate::run::run_iterations(
        &mut run,
        &arm,
        cfg.iterations,
        Some(&out.join(format!("mdgps_seed{seed}"))),
        |log, run| {
            progress.done_one(&format!("[mdgps seed {seed}] {}", log.progress_line()));
            let mut actor = GlobalActor::new(run.policy(), &mut ws);
            match evaluate(&mut eval_arm, &base, &mut actor, goals, experts) {
                Ok(e) if failed.is_none() => evals.push(e),
                Ok(_) => {}
                Err(e) => {
                    failed.get_or_insert(e);
                }
            }
        },
    )?;
    if let Some(e) = failed {
        return Err(e);
    }
    let file = PolicyFile {
        policy: run.policy().clone(),
        mode: c.lqr_gaifo.sim.mode,
        start_q: base.start_q,
        dt: base.dt,
        horizon: base.horizon,
        seed,
        iterations: cfg.iterations as u64,
        model: c.lqr_gaifo.sim.model,
    };
    save_policy(&file, &out.join(format!("policy_seed{seed}.npz")))?;
    Ok(MethodRun {
        method: METHODS[0],
        seed,
        evals,
        mdgps_logs: logs,
    })
}

/// LQR+GAIfO at one seed on the 8 points' demonstrations with the centre as its task (the
/// generalisation experiment's 8-point run); its controller evaluated at every goal.
fn run_lqr_centre(
    cfg: &ExperimentConfig,
    seed: u64,
    demos: &Demos,
    goals: &[EvalGoal],
    experts: &[Demos],
    progress: &Progress,
) -> Result<MethodRun, ExperimentError> {
    let mut c = cfg.lqr_gaifo.clone();
    c.seed = seed;
    c.iterations = cfg.iterations;
    let mut run = LqrGaifo::new(c, demos.clone())?;
    let base = run.task().clone();
    let mut arm = crate::run::arm_for(&run)?;
    let mut evals = Vec::with_capacity(cfg.iterations + 1);
    for _ in 0..cfg.iterations {
        evals.push(evaluate(
            &mut arm,
            &base,
            &mut *run.table(),
            goals,
            experts,
        )?);
        let (log, _) = iterate(&mut run, &arm)?;
        progress.done_one(&format!(
            "[lqr-gaifo centre seed {seed}] {}",
            log.progress_line()
        ));
    }
    evals.push(evaluate(
        &mut arm,
        &base,
        &mut *run.table(),
        goals,
        experts,
    )?);
    Ok(MethodRun {
        method: METHODS[1],
        seed,
        evals,
        mdgps_logs: Vec::new(),
    })
}

/// One row of the summary: a method on one kind of goal after the last iteration.
#[derive(Clone, Debug, Serialize)]
pub struct MultiGoalRow {
    /// One of [`METHODS`].
    pub method: String,
    /// One of [`KINDS`], or `inside+centre`.
    pub kind: String,
    /// Goals of that kind.
    pub goals: usize,
    /// Seeds.
    pub seeds: usize,
    /// Mean over goals, then mean ± standard error over seeds.
    pub performance_mean: f64,
    pub performance_se: f64,
    pub final_distance_m_mean: f64,
    pub final_distance_m_se: f64,
    /// Worst goal (over goals of the kind and seeds).
    pub performance_min: f64,
    pub final_distance_m_max: f64,
}

/// The summary of the runs at the last iteration, per method and kind of goal.
pub fn summarise(runs: &[MethodRun], goals: &[EvalGoal]) -> Vec<MultiGoalRow> {
    let mut rows = Vec::new();
    let kinds: Vec<(&str, Vec<usize>)> = std::iter::once((
        "inside+centre",
        (0..goals.len())
            .filter(|&g| matches!(goals[g].kind, "inside" | "centre"))
            .collect(),
    ))
    .chain(KINDS.iter().map(|&k| {
        (
            k,
            (0..goals.len()).filter(|&g| goals[g].kind == k).collect(),
        )
    }))
    .collect();
    for method in METHODS {
        let rs: Vec<&MethodRun> = runs.iter().filter(|r| r.method == method).collect();
        for (kind, idx) in &kinds {
            if rs.is_empty() || idx.is_empty() {
                continue;
            }
            let last = |r: &MethodRun| r.evals.last().cloned().unwrap_or_default();
            let per_seed = |f: fn(&GoalResult) -> f64| -> Vec<Vec<f64>> {
                rs.iter()
                    .map(|r| {
                        let l = last(r);
                        vec![idx.iter().map(|&g| f(&l[g])).sum::<f64>() / idx.len() as f64]
                    })
                    .collect()
            };
            let all = |f: fn(&GoalResult) -> f64| -> Vec<f64> {
                rs.iter()
                    .flat_map(|r| {
                        let l = last(r);
                        idx.iter().map(move |&g| f(&l[g])).collect::<Vec<_>>()
                    })
                    .collect()
            };
            let (pm, pse, _) = mean_stderr(&per_seed(|g| g.performance));
            let (dm, dse, _) = mean_stderr(&per_seed(|g| g.final_distance_m));
            rows.push(MultiGoalRow {
                method: method.into(),
                kind: kind.to_string(),
                goals: idx.len(),
                seeds: rs.len(),
                performance_mean: pm[0],
                performance_se: pse[0],
                final_distance_m_mean: dm[0],
                final_distance_m_se: dse[0],
                performance_min: all(|g| g.performance)
                    .into_iter()
                    .fold(f64::INFINITY, f64::min),
                final_distance_m_max: all(|g| g.final_distance_m).into_iter().fold(0.0, f64::max),
            });
        }
    }
    rows
}

/// The summary as a table, with the target checked on the goals inside the square.
pub fn summary_text(rows: &[MultiGoalRow], iterations: usize) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "multi-goal after {iterations} iterations (noise-free; mean over goals, mean ± s.e. over seeds; worst goal)\n{:<18} {:<14} {:>5} {:>16} {:>8} {:>20} {:>10}\n",
        "method", "goals", "n", "normalised perf", "worst", "final distance (cm)", "worst (cm)"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<18} {:<14} {:>5} {:>8.3} ± {:<5.3} {:>8.3} {:>10.2} ± {:<7.2} {:>10.2}",
            r.method,
            r.kind,
            r.goals,
            r.performance_mean,
            r.performance_se,
            r.performance_min,
            100.0 * r.final_distance_m_mean,
            100.0 * r.final_distance_m_se,
            100.0 * r.final_distance_m_max
        );
    }
    if let Some(r) = rows
        .iter()
        .find(|r| r.method == METHODS[0] && r.kind == "inside+centre")
    {
        let met = r.performance_mean >= 0.9 && r.final_distance_m_mean <= 0.02;
        let _ = writeln!(
            s,
            "target (inside the square: mean normalised performance >= 0.9 and mean final distance <= 2 cm within 20 iterations): {} ({:.3}, {:.2} cm, {iterations} iterations)",
            if met && iterations <= 20 { "met" } else { "not met" },
            r.performance_mean,
            100.0 * r.final_distance_m_mean
        );
    }
    s
}

/// One CSV row of `multi-goal.csv`.
#[derive(Serialize)]
struct CsvRow<'a> {
    method: &'a str,
    seed: u64,
    iterations_done: usize,
    goal_index: usize,
    kind: &'a str,
    goal_x: f64,
    goal_y: f64,
    goal_z: f64,
    normalised_performance: f64,
    task_cost: f64,
    final_distance_m: f64,
}

fn write_csvs(runs: &[MethodRun], goals: &[EvalGoal], out: &Path) -> Result<(), ExperimentError> {
    let mut w = csv::Writer::from_path(out.join("multi-goal.csv"))?;
    for r in runs {
        for (i, ev) in r.evals.iter().enumerate() {
            for (g, (e, goal)) in ev.iter().zip(goals).enumerate() {
                w.serialize(CsvRow {
                    method: r.method,
                    seed: r.seed,
                    iterations_done: i,
                    goal_index: g,
                    kind: goal.kind,
                    goal_x: goal.goal[0],
                    goal_y: goal.goal[1],
                    goal_z: goal.goal[2],
                    normalised_performance: e.performance,
                    task_cost: e.task_cost,
                    final_distance_m: e.final_distance_m,
                })?;
            }
        }
    }
    w.flush()?;
    let mut w = csv::Writer::from_path(out.join("mdgps_log.csv"))?;
    for r in runs {
        for l in &r.mdgps_logs {
            w.serialize(MdgpsRow::new(l, r.seed))?;
        }
    }
    w.flush()?;
    Ok(())
}

/// Curves per (method, kind): per seed the mean over that kind's goals after each iteration,
/// then mean ± s.e. over seeds.
fn plot(runs: &[MethodRun], goals: &[EvalGoal], out: &Path) -> Result<(), ExperimentError> {
    let curves = |f: fn(&GoalResult) -> f64| -> Vec<Series> {
        let mut v = Vec::new();
        for method in METHODS {
            for kind in ["centre", "inside", "outside"] {
                let idx: Vec<usize> = (0..goals.len())
                    .filter(|&g| goals[g].kind == kind)
                    .collect();
                let rs: Vec<&MethodRun> = runs.iter().filter(|r| r.method == method).collect();
                if idx.is_empty() || rs.is_empty() {
                    continue;
                }
                let per_seed: Vec<Vec<f64>> = rs
                    .iter()
                    .map(|r| {
                        r.evals
                            .iter()
                            .map(|ev| {
                                idx.iter().map(|&g| f(&ev[g])).sum::<f64>() / idx.len() as f64
                            })
                            .collect()
                    })
                    .collect();
                let (mean, stderr, _) = mean_stderr(&per_seed);
                v.push(Series {
                    label: format!("{method}, {kind} ({} goals, {} seeds)", idx.len(), rs.len()),
                    x: (0..mean.len()).map(|i| i as f64).collect(),
                    mean,
                    stderr,
                });
            }
        }
        v
    };
    let (perf, dist) = (curves(|g| g.performance), curves(|g| g.final_distance_m));
    Ok(plot_panels(
        &out.join("multi-goal.png"),
        "One MDGPS policy vs the centre's LQR+GAIfO controller, never-demonstrated goals",
        "iterations done",
        &[
            Panel {
                y_label: "normalised performance (1 = goal's expert)",
                series: &perf,
                log_y: false,
            },
            Panel {
                y_label: "final distance to the goal (m, log scale)",
                series: &dist,
                log_y: true,
            },
        ],
        (1000, 1100),
    )?)
}

/// The experts of `wanted` from `dir` (the `experts/` folder of an earlier run: `names[i]`
/// holds expert i), each checked against the arm and against its goal and demonstration count.
fn load_experts(
    cfg: &ExperimentConfig,
    dir: &Path,
    wanted: &[([f64; 3], usize)],
    names: &[String],
) -> Result<Vec<Demos>, ExperimentError> {
    wanted
        .iter()
        .zip(names)
        .map(|(&(goal, n), name)| {
            let p = dir.join(name);
            let d = crate::io::demos::load_checked(&p, &cfg.lqr_gaifo.sim)?;
            ensure!(d.goal == goal && d.count == n, ExperimentError::Settings(format!("{}: {} demonstrations of goal {:?}, this run needs {n} of goal {goal:?} (another \
                 square, eval_seed or demos count: train the experts again without --demos)", p.display(), d.count, d.goal)));
            Ok(d)
        })
        .collect()
}

/// Runs the experiment (module docs) and writes its outputs into `out`; the experts come from
/// `experts` (an earlier run's `experts/` folder) when it is given, else they are trained.
pub fn run(
    cfg: &ExperimentConfig,
    out: &Path,
    experts: Option<&Path>,
) -> Result<Vec<MultiGoalRow>, ExperimentError> {
    cfg.validate(super::ExperimentName::MultiGoal)?;
    let pool = pool(cfg.threads)?;
    let t0 = Instant::now();
    crate::io::create_dir(out)?;
    let centre = cfg.expert.task.goal;
    let h = cfg.expert.square_half_side;
    let goals = eval_goals(
        centre,
        h,
        cfg.eval_inside,
        cfg.eval_outside,
        cfg.eval_outside_margin,
        cfg.eval_seed,
    );
    eprintln!(
        "experiment multi-goal: {} seed(s) from {}, {} iterations, {} worker thread(s), {} evaluation goals -> {}",
        cfg.seeds,
        cfg.first_seed,
        cfg.iterations,
        pool.current_num_threads(),
        goals.len(),
        out.display()
    );
    // Experts: the 8 square points (their demonstrations train both methods and normalise the
    // "demonstrated" goals) and one per never-demonstrated goal (normalisation only).
    let square: Vec<[f64; 3]> = square_goals(centre, h).to_vec();
    let unseen: Vec<EvalGoal> = goals
        .iter()
        .filter(|g| g.kind != "demonstrated")
        .copied()
        .collect();
    let mut wanted: Vec<([f64; 3], usize)> =
        square.iter().map(|&g| (g, cfg.demos_per_point)).collect();
    wanted.extend(unseen.iter().map(|g| (g.goal, cfg.expert.demos)));
    let names: Vec<String> = (0..square.len())
        .map(|i| format!("point_{i}.npz"))
        .chain(
            unseen
                .iter()
                .enumerate()
                .map(|(i, g)| format!("eval_{i}_{}.npz", g.kind)),
        )
        .collect();
    let dir = out.join("experts");
    let experts = match experts {
        Some(from) => load_experts(cfg, from, &wanted, &names)?,
        None => experts_at(&cfg.expert, &pool, &wanted)?,
    };
    crate::io::create_dir(&dir)?;
    for (d, name) in experts.iter().zip(&names) {
        crate::io::demos::save(d, &dir.join(name))?;
    }
    let (square_demos, unseen_experts) = experts.split_at(square.len());
    let norm: Vec<Demos> = unseen_experts.iter().chain(square_demos).cloned().collect();
    let pts: Vec<&Demos> = square_demos.iter().collect();
    let centre_set = Arc::new(combine_demos(&unseen_experts[0], &pts)?);
    let square_demos = Arc::new(square_demos.to_vec());
    let jobs: Vec<(usize, u64)> = (0..2)
        .flat_map(|m| (0..cfg.seeds as u64).map(move |s| (m, s)))
        .collect();
    // A bar over the iterations of both methods at every seed (plain lines off a terminal).
    let progress = Progress::new((jobs.len() * cfg.iterations) as u64, "iterations");
    let runs: Vec<MethodRun> = pool.install(|| {
        jobs.par_iter()
            .map(|&(m, s)| {
                let seed = cfg.first_seed + s;
                let r = if m == 0 {
                    run_mdgps(cfg, seed, &square_demos, &goals, &norm, out, &progress)
                } else {
                    run_lqr_centre(cfg, seed, &centre_set, &goals, &norm, &progress)
                };
                r.map_err(|e| ExperimentError::Job {
                    label: format!("{} seed {seed}", METHODS[m]),
                    source: Box::new(e),
                })
            })
            .collect::<Result<Vec<_>, ExperimentError>>()
    })?;
    drop(progress);
    write_csvs(&runs, &goals, out)?;
    plot(&runs, &goals, out)?;
    let rows = summarise(&runs, &goals);
    let text = summary_text(&rows, cfg.iterations);
    std::fs::write(out.join("summary.txt"), &text)?;
    std::fs::write(
        out.join("summary.json"),
        serde_json::to_vec_pretty(&serde_json::json!({"goals": goals, "rows": rows}))?,
    )?;
    eprint!("{text}");
    eprintln!(
        "experiment multi-goal done in {:.0} s; multi-goal.csv, multi-goal.png, policy_seed*.npz in {}",
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(rows)
}
