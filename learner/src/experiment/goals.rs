//! Goals over the workspace and the precision figures of runs at several goals: what
//! `learner experiment pilqr`, `learner experiment ablation` (with `ablation_workspace_goals`)
//! and `learner experiment comparison` (with `comparison_workspace_goals`) report beyond the
//! per-iteration curves (docs/results.md, "Steady precision").
//!
//! - `reach.txt` ([`reach_text`]): per variant, the training episodes each seed needed to first
//!   end within 1 cm and within 3 mm of the goal;
//! - `spread.csv` ([`spread_csv`]): the mean, standard deviation, minimum and maximum of the
//!   final distance over seeds at every iteration;
//! - `precision.txt` ([`precision_text`]): per variant over all its goals and seeds, the final
//!   distance at iterations 20, 30, 40 and 50 and how many runs stay within 1.5 cm from 20 on,
//!   both for the controller of each iteration and for the one kept by the task-cost-free
//!   criterion [`kept_by_demo_gap`];
//! - `summary_goals.txt` / `summary_goals.json` ([`summarise_over_goals`]): the experiment's
//!   summary with each variant's runs at every goal pooled (episodes to normalised 0.9 and to
//!   1 cm, final distance and normalised performance at the report iterations, learner CPU).

use std::path::Path;
use std::sync::Arc;

use rayon::prelude::*;

use imitation::demos::Demos;
use imitation::gaifo::GaifoLog;

use super::summary::{by_variant, summarise, summary_text, SummaryRow};
use super::{ExperimentConfig, ExperimentError, Job, Run};
use crate::error::ensure;

/// Goals spread over the UR5's workspace away from the default one (m, base frame), named
/// for the experiments that test precision beyond the goal the defaults were tuned on. The
/// first three are docs/design.md §5 D25's "other goals".
pub const WORKSPACE_GOALS: [(&str, [f64; 3]); 5] = [
    ("near-low", [-0.30, -0.40, 0.20]),
    ("far-high", [-0.55, 0.05, 0.35]),
    ("table", [-0.40, -0.10, 0.05]),
    ("side-high", [-0.20, -0.50, 0.40]),
    ("far-low", [-0.60, -0.20, 0.10]),
];

/// A goal's name in [`WORKSPACE_GOALS`], else its coordinates as `x/y/z` (m).
pub fn goal_name(g: [f64; 3]) -> String {
    match WORKSPACE_GOALS.iter().find(|(_, p)| *p == g) {
        Some((n, _)) => n.to_string(),
        None => format!("{}/{}/{}", g[0], g[1], g[2]),
    }
}

/// Per variant: seeds that reached 1 cm and 3 mm and the training episodes they needed.
pub fn reach_text(runs: &[Run]) -> String {
    let mut s = String::from(
        "variant | seeds | within 1 cm: seeds, episodes mean ± sd | within 3 mm: seeds, episodes mean ± sd | within 2 mm by iteration 30 (counted from 1) | final distance at the last iteration, mm, mean ± sd\n",
    );
    for (v, rs) in by_variant(runs) {
        let reach = |th: f64| -> String {
            let eps: Vec<f64> = rs
                .iter()
                .filter_map(|r| {
                    r.logs
                        .iter()
                        .position(|l| l.final_distance <= th)
                        .map(|i| (i * r.episodes_per_iteration) as f64)
                })
                .collect();
            let (m, sd) = mean_sd(&eps);
            format!("{}/{}, {m:.0} ± {sd:.0}", eps.len(), rs.len())
        };
        let by30 = rs
            .iter()
            .filter(|r| r.logs.iter().take(30).any(|l| l.final_distance <= 2e-3))
            .count();
        let last: Vec<f64> = rs
            .iter()
            .filter_map(|r| r.logs.last().map(|l| 1e3 * l.final_distance))
            .collect();
        let (m, sd) = mean_sd(&last);
        s += &format!(
            "{v} | {} | {} | {} | {by30}/{} | {m:.2} ± {sd:.2}\n",
            rs.len(),
            reach(0.01),
            reach(0.003),
            rs.len()
        );
    }
    s
}

/// Mean and sample standard deviation (NaN when empty; sd 0 for one value).
pub fn mean_sd(x: &[f64]) -> (f64, f64) {
    if x.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let var = if x.len() > 1 {
        x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (m, var.sqrt())
}

/// `variant,iteration,seeds,final_distance_mean_m,final_distance_sd_m,min_m,max_m`, one row
/// per variant and iteration (1-based).
pub fn spread_csv(runs: &[Run]) -> String {
    let mut s = String::from(
        "variant,iteration,seeds,final_distance_mean_m,final_distance_sd_m,min_m,max_m\n",
    );
    for (v, rs) in by_variant(runs) {
        let iters = rs.iter().map(|r| r.logs.len()).max().unwrap_or(0);
        for i in 0..iters {
            let d: Vec<f64> = rs
                .iter()
                .filter_map(|r| r.logs.get(i).map(|l| l.final_distance))
                .collect();
            let (m, sd) = mean_sd(&d);
            let mn = d.iter().copied().fold(f64::INFINITY, f64::min);
            let mx = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            s += &format!("\"{v}\",{},{},{m:e},{sd:e},{mn:e},{mx:e}\n", i + 1, d.len());
        }
    }
    s
}

/// `goals`, then [`WORKSPACE_GOALS`] when `workspace`; `default` alone when that is empty.
pub fn goal_list(goals: &[[f64; 3]], workspace: bool, default: [f64; 3]) -> Vec<[f64; 3]> {
    let mut g = goals.to_vec();
    if workspace {
        g.extend(WORKSPACE_GOALS.iter().map(|(_, p)| *p));
    }
    if g.is_empty() {
        g.push(default);
    }
    g
}

/// The demonstrations of the nominal arm's expert (`cfg.expert`) at each goal, trained in
/// parallel on `pool`.
pub fn goal_demos(
    cfg: &ExperimentConfig,
    goals: &[[f64; 3]],
    pool: &rayon::ThreadPool,
) -> Result<Vec<Demos>, ExperimentError> {
    pool.install(|| {
        goals
            .par_iter()
            .map(|&g| {
                let mut e = cfg.expert.clone();
                e.task.goal = g;
                super::expert_demos(&e)
            })
            .collect()
    })
}

/// One demonstration set per [`WORKSPACE_GOALS`] goal (its expert's, [`goal_demos`]) with its
/// label suffix `" goal <name>"`, for an experiment run on the workspace goals by the setting
/// `setting`; `demos` (one set for one goal) is refused.
pub fn workspace_goal_sets(
    cfg: &ExperimentConfig,
    demos: Option<&Path>,
    setting: &str,
    pool: &rayon::ThreadPool,
) -> Result<Vec<(String, Arc<Demos>)>, ExperimentError> {
    ensure!(
        demos.is_none(),
        ExperimentError::Settings(format!(
            "--demos does not apply with {setting} (an expert per goal)"
        ))
    );
    let g = goal_list(&[], true, cfg.expert.task.goal);
    Ok(goal_demos(cfg, &g, pool)?
        .into_iter()
        .zip(&g)
        .map(|(d, &p)| (format!(" goal {}", goal_name(p)), Arc::new(d)))
        .collect())
}

/// The jobs `jobs` makes of each set's demonstrations, their variants labelled with the set's
/// suffix (`"<variant> goal <name>"` from [`workspace_goal_sets`]; none for one goal), goal by
/// goal.
pub fn at_goals(sets: &[(String, Arc<Demos>)], jobs: impl Fn(Arc<Demos>) -> Vec<Job>) -> Vec<Job> {
    sets.iter()
        .flat_map(|(goal, d)| {
            jobs(d.clone()).into_iter().map(move |mut j| {
                j.variant += goal;
                j
            })
        })
        .collect()
}

/// The summary ([`summarise`]) with each variant's runs at all its goals pooled: a row per
/// variant without its goal, whose `seeds` counts runs (goals × seeds). Normalised
/// performance is each run's own (against its goal's demonstrations and random policy).
pub fn summarise_over_goals(runs: &[Run]) -> Vec<SummaryRow> {
    let pooled: Vec<Run> = runs
        .iter()
        .map(|r| Run {
            variant: variant_of(&r.variant).to_string(),
            ..r.clone()
        })
        .collect();
    summarise(&pooled)
}

/// The final distance (m) of the controller a user would deploy after each iteration if
/// they kept, of the controllers run so far, the one with the smallest
/// [`GaifoLog::demo_gap`] (a criterion that needs no task cost: how far its noisy episodes
/// end from the demonstrations' final state). Iterations whose gap is not finite are never
/// kept; before the first finite one, the iteration's own controller counts.
pub fn kept_by_demo_gap(logs: &[GaifoLog]) -> Vec<f64> {
    let mut best: Option<(f64, f64)> = None;
    logs.iter()
        .map(|l| {
            if l.demo_gap.is_finite() && best.is_none_or(|(g, _)| l.demo_gap < g) {
                best = Some((l.demo_gap, l.final_distance));
            }
            best.map_or(l.final_distance, |(_, d)| d)
        })
        .collect()
}

/// Writes `precision.txt` ([`precision_text`]), `reach.txt`, `spread.csv` and
/// `summary_goals.txt` / `.json` ([`summarise_over_goals`]) of `runs` into `out`; returns the
/// precision table.
pub fn write_precision(runs: &[Run], out: &Path) -> Result<String, ExperimentError> {
    let precision = precision_text(runs);
    std::fs::write(out.join("precision.txt"), &precision)?;
    std::fs::write(out.join("reach.txt"), reach_text(runs))?;
    std::fs::write(out.join("spread.csv"), spread_csv(runs))?;
    let rows = summarise_over_goals(runs);
    std::fs::write(
        out.join("summary_goals.txt"),
        format!(
            "Every goal pooled: a row per variant over its goals x seeds (the seeds column counts runs)\n\n{}",
            summary_text(&rows)
        ),
    )?;
    std::fs::write(
        out.join("summary_goals.json"),
        serde_json::to_vec_pretty(&rows)?,
    )?;
    Ok(precision)
}

/// Whether `runs` ran at several goals (labels `"<variant> goal <name>"`).
pub fn at_several_goals(runs: &[Run]) -> bool {
    runs.iter().any(|r| r.variant.contains(" goal "))
}

/// A run's variant without its goal (labels `"<variant> goal <name>"`).
fn variant_of(label: &str) -> &str {
    label.split(" goal ").next().unwrap_or(label)
}

/// The steady-precision table: per variant (over its goals and seeds), the final distance at
/// iterations 20, 30, 40 and 50 (counted from 1; mean, standard deviation and worst, mm), the
/// runs that stay within 1.5 cm at every iteration from 20 to their last (up to 50), and the
/// same for the controller kept by [`kept_by_demo_gap`] where the runs log the gap.
pub fn precision_text(runs: &[Run]) -> String {
    const AT: [usize; 4] = [20, 30, 40, 50];
    let mut s = String::from(
        "variant | runs | final distance at iteration 20 / 30 / 40 / 50, mm: mean ± sd (worst) | runs within 15 mm at every iteration 20–50\n",
    );
    let mut variants: Vec<&str> = Vec::new();
    for r in runs {
        let v = variant_of(&r.variant);
        if !variants.contains(&v) {
            variants.push(v);
        }
    }
    for v in variants {
        let rs: Vec<&Run> = runs
            .iter()
            .filter(|r| variant_of(&r.variant) == v)
            .collect();
        let raw: Vec<Vec<f64>> = rs
            .iter()
            .map(|r| r.logs.iter().map(|l| l.final_distance).collect())
            .collect();
        s += &precision_row(v, &raw, &AT);
        if rs
            .iter()
            .all(|r| r.logs.iter().any(|l| l.demo_gap.is_finite()))
        {
            let kept: Vec<Vec<f64>> = rs.iter().map(|r| kept_by_demo_gap(&r.logs)).collect();
            s += &precision_row(&format!("{v}, kept by demo gap"), &kept, &AT);
        }
    }
    s
}

/// One row of [`precision_text`]: `curves` are the runs' final distances (m) per iteration.
fn precision_row(name: &str, curves: &[Vec<f64>], at: &[usize]) -> String {
    let cells: Vec<String> = at
        .iter()
        .map(|&i| {
            let d: Vec<f64> = curves
                .iter()
                .filter_map(|c| c.get(i - 1).map(|x| 1e3 * x))
                .collect();
            if d.is_empty() {
                return "–".into();
            }
            let (m, sd) = mean_sd(&d);
            let worst = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            format!("{m:.1} ± {sd:.1} ({worst:.1})")
        })
        .collect();
    let steady = curves
        .iter()
        .filter(|c| c.len() >= 20 && c.iter().skip(19).take(31).all(|&x| x <= 0.015))
        .count();
    format!(
        "{name} | {} | {} | {steady}/{}\n",
        curves.len(),
        cells.join(" / "),
        curves.len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(gap: f64, d: f64) -> GaifoLog {
        GaifoLog {
            demo_gap: gap,
            final_distance: d,
            ..GaifoLog::default()
        }
    }

    /// A demonstration set that only labels jobs (never run): its goal tells the sets apart.
    fn demos_at(goal: [f64; 3]) -> Arc<Demos> {
        Arc::new(Demos {
            states: Vec::new(),
            actions: Vec::new(),
            model: Default::default(),
            count: 0,
            horizon: 2,
            goal,
            goal_pose: None,
            tool_points: ur5_shared::config::DEFAULT_TOOL_POINTS,
            start_q: [0.0; 3].into(),
            dt: 0.05,
            seed: 0,
            cost_random: 1.0,
            cost_expert: 0.0,
        })
    }

    /// The comparison at two goals: every algorithm × seed at each goal, on that goal's
    /// demonstrations, labelled `"<algorithm> goal <name>"`; at one goal (no suffix) the
    /// labels are the algorithms'.
    #[test]
    fn the_comparison_runs_every_algorithm_and_seed_at_each_goal() {
        let mut cfg = ExperimentConfig::default();
        cfg.seeds = 2;
        cfg.algorithms = vec!["lqr-gaifo".into(), "bco".into(), "replay-mean".into()];
        let (a, b) = (WORKSPACE_GOALS[0], WORKSPACE_GOALS[2]);
        let sets = vec![
            (format!(" goal {}", goal_name(a.1)), demos_at(a.1)),
            (format!(" goal {}", goal_name(b.1)), demos_at(b.1)),
        ];
        let jobs = at_goals(&sets, |d| super::super::comparison_jobs(&cfg, d));
        assert_eq!(jobs.len(), 2 * 3 * 2);
        for (k, j) in jobs.iter().enumerate() {
            let (goal, algorithm, seed) =
                ([a, b][k / 6], cfg.algorithms[k / 2 % 3].as_str(), k % 2);
            assert_eq!(j.variant, format!("{algorithm} goal {}", goal.0), "job {k}");
            assert_eq!(
                (j.spec.algorithm(), j.spec.seed()),
                (algorithm, seed as u64)
            );
            assert_eq!(j.demos.goal, goal.1, "job {k}");
        }
        let one = at_goals(&[(String::new(), demos_at(a.1))], |d| {
            super::super::comparison_jobs(&cfg, d)
        });
        let labels: Vec<&str> = one.iter().map(|j| j.variant.as_str()).collect();
        assert_eq!(
            labels,
            [
                "lqr-gaifo",
                "lqr-gaifo",
                "bco",
                "bco",
                "replay-mean",
                "replay-mean"
            ]
        );
    }

    /// Over the goals, a variant's runs at every goal make one row: its episodes to 1 cm and
    /// its final distances are over all of them, and the variants keep their order.
    #[test]
    fn the_summary_over_goals_pools_a_variants_runs_at_every_goal() {
        let run = |variant: &str, seed: u64, d: [f64; 3]| Run {
            variant: variant.into(),
            algorithm: "lqr-gaifo".into(),
            seed,
            episodes_per_iteration: 5,
            horizon: 100,
            logs: d.iter().map(|&d| log(f64::NAN, d)).collect(),
            wall_s: 0.0,
        };
        let runs = [
            run("a goal table", 0, [0.1, 0.005, 0.004]),
            run("b goal table", 0, [0.1, 0.1, 0.1]),
            run("a goal far-low", 0, [0.1, 0.05, 0.002]),
            run("a goal far-low", 1, [0.1, 0.05, 0.05]),
        ];
        let rows = summarise_over_goals(&runs);
        let names: Vec<&str> = rows.iter().map(|r| r.variant.as_str()).collect();
        assert_eq!(names, ["a", "b"]);
        let a = &rows[0];
        assert_eq!(a.seeds, 3);
        // Within 1 cm: after 1·5 and 2·5 episodes; the third run never.
        assert_eq!(
            (a.to_within_1cm.seeds_reached, a.to_within_1cm.seeds),
            (2, 3)
        );
        assert!((a.to_within_1cm.episodes_mean - 7.5).abs() < 1e-12);
        let last = a.final_distance_m.last().unwrap();
        assert_eq!(last.0, 2);
        assert!((last.1 - (0.004 + 0.002 + 0.05) / 3.0).abs() < 1e-15);
        assert_eq!(rows[1].seeds, 1);
        assert_eq!(rows[1].to_within_1cm.seeds_reached, 0);
    }

    /// A run on the workspace goals trains an expert per goal: one set of demonstrations
    /// given on the command line is refused before any training, naming the setting.
    #[test]
    fn demonstrations_for_one_goal_are_refused_on_the_workspace_goals() {
        let cfg = ExperimentConfig::default();
        let pool = super::super::pool(1).unwrap();
        let e = workspace_goal_sets(
            &cfg,
            Some(Path::new("d.npz")),
            "comparison_workspace_goals",
            &pool,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("--demos") && e.contains("comparison_workspace_goals"),
            "{e}"
        );
        let mut c = cfg.clone();
        c.comparison_workspace_goals = true;
        use super::super::{scheduler::trains_one_expert, ExperimentName::Comparison};
        assert!(trains_one_expert(Comparison, &cfg) && !trains_one_expert(Comparison, &c));
        // Off, the setting is left out of the settings (their hash is as before it); on, in.
        let off = serde_json::to_value(&cfg).unwrap();
        assert!(off.get("comparison_workspace_goals").is_none(), "{off}");
        let on = serde_json::to_value(&c).unwrap();
        assert_eq!(on["comparison_workspace_goals"], serde_json::json!(true));
    }

    #[test]
    fn the_kept_controller_changes_only_on_a_smaller_gap() {
        let logs = [
            log(f64::NAN, 0.5),
            log(3.0, 0.2),
            log(4.0, 0.01),
            log(1.0, 0.03),
            log(f64::NAN, 0.001),
            log(1.0, 0.002),
        ];
        assert_eq!(
            kept_by_demo_gap(&logs),
            vec![0.5, 0.2, 0.2, 0.03, 0.03, 0.03]
        );
    }

    #[test]
    fn precision_counts_runs_that_stay_within_15_mm_from_iteration_20() {
        let run = |variant: &str, late: f64, spike: Option<usize>| Run {
            variant: variant.into(),
            algorithm: "lqr-gaifo".into(),
            seed: 0,
            episodes_per_iteration: 5,
            horizon: 100,
            logs: (0..50)
                .map(|i| {
                    let d = if i < 19 { 0.1 } else { late };
                    let d = if spike == Some(i) { 0.02 } else { d };
                    log(f64::NAN, d)
                })
                .collect(),
            wall_s: 0.0,
        };
        let runs = [
            run("a goal near-low", 0.005, None),
            run("a goal table", 0.005, Some(49)),
            run("b goal table", 0.01, Some(18)),
        ];
        let t = precision_text(&runs);
        let rows: Vec<&str> = t.lines().collect();
        assert_eq!(rows.len(), 3, "{t}");
        assert!(rows[1].starts_with("a | 2 | 5.0 ± 0.0 (5.0) / 5.0 ± 0.0 (5.0) / 5.0 ± 0.0 (5.0) / 12.5 ± 10.6 (20.0) | 1/2"), "{t}");
        assert!(
            rows[2].starts_with("b | 1 | 10.0") && rows[2].ends_with("| 1/1"),
            "{t}"
        );
    }
}
