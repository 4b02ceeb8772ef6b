//! The experiments' outputs: the per-variant summary table (text and JSON), the CSV and the
//! figure (module docs of `experiment`).

use std::path::Path;

use super::ExperimentError;
use crate::io::IoError;
use serde::Serialize;

use super::Run;
use crate::io::log::{CSV_HEADER, ORIENTATION_COLUMN};
use crate::plot::{mean_stderr, plot_panels, Panel, Series};
use crate::stats::median;
use imitation::gaifo::GaifoLog;

/// Per-variant summary of an experiment.
#[derive(Clone, Debug, Serialize)]
pub struct SummaryRow {
    /// Curve label.
    pub variant: String,
    /// Seeds run.
    pub seeds: usize,
    /// Iterations per run.
    pub iterations: usize,
    /// (iteration, mean, standard error) of the normalised performance at the report points.
    pub performance: Vec<(usize, f64, f64)>,
    /// (iteration, mean, standard error) of the final distance to the goal (m) of the
    /// noise-free episode at the report points.
    pub final_distance_m: Vec<(usize, f64, f64)>,
    /// Mean (± SE over seeds) normalised performance over the last 10 iterations.
    pub last10_mean: f64,
    pub last10_se: f64,
    /// Mean (± SE over seeds) final distance (m) over the last 10 iterations.
    pub last10_final_distance_m: f64,
    pub last10_final_distance_se: f64,
    /// A pose task's (iteration, mean, standard error) of the final orientation error of the
    /// noise-free episode (degrees) at the report points; `None` (and not in the JSON) for a
    /// point task.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_orientation_error_deg: Option<Vec<(usize, f64, f64)>>,
    /// A pose task's mean and standard error over seeds of the final orientation error
    /// (degrees) over the last 10 iterations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last10_final_orientation_error_deg: Option<(f64, f64)>,
    /// First iteration at which the mean over seeds reaches 0.8 (None: never).
    pub first_iteration_mean_ge_0_8: Option<usize>,
    /// First iteration at which the mean final distance over seeds is at most 1 cm (None:
    /// never).
    pub first_iteration_mean_within_1cm: Option<usize>,
    /// Noisy (training) episodes per iteration N and steps per episode T of the variant.
    pub episodes_per_iteration: usize,
    pub horizon: usize,
    /// Training episodes each seed needed to first reach normalised performance 0.9.
    pub to_performance_0_9: Reach,
    /// Training episodes each seed needed to first end within 1 cm of the goal.
    pub to_within_1cm: Reach,
    /// Median learner CPU time per iteration, ms.
    pub learner_cpu_ms_median: f64,
    /// Median simulator time per iteration (episodes), ms.
    pub execute_ms_median: f64,
}

/// How many training episodes the seeds of a variant needed to first reach a threshold with
/// the noise-free episode. The controller evaluated at iteration i (0-based) was learned from
/// the i·N noisy episodes of the iterations before it, so a seed that first reaches the
/// threshold there needed i·N episodes and i·N·T environment steps (the noise-free evaluation
/// episodes are measurements and are not counted, for either algorithm).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Reach {
    /// Seeds that reached the threshold within the run.
    pub seeds_reached: usize,
    /// Seeds run.
    pub seeds: usize,
    /// Mean and standard error over the seeds that reached it (NaN if none did); a lower
    /// bound of the true mean when some seeds never did.
    pub episodes_mean: f64,
    pub episodes_se: f64,
    /// The same in environment steps (episodes × T).
    pub env_steps_mean: f64,
    pub env_steps_se: f64,
}

impl Reach {
    /// From per-seed curves of a variant with N episodes per iteration and T steps.
    fn of(curves: &[Vec<f64>], reached: impl Fn(f64) -> bool, n: usize, t: usize) -> Self {
        let episodes: Vec<f64> = curves
            .iter()
            .filter_map(|c| c.iter().position(|&v| reached(v)))
            .map(|i| (i * n) as f64)
            .collect();
        let (m, e, _) = mean_stderr(&episodes.iter().map(|&x| vec![x]).collect::<Vec<_>>());
        let (m, e) = (
            m.first().copied().unwrap_or(f64::NAN),
            e.first().copied().unwrap_or(f64::NAN),
        );
        Self {
            seeds_reached: episodes.len(),
            seeds: curves.len(),
            episodes_mean: m,
            episodes_se: e,
            env_steps_mean: m * t as f64,
            env_steps_se: e * t as f64,
        }
    }
}

/// Iterations reported in the summary (0-based), those below `iterations`, and the last.
pub(super) fn report_points(iterations: usize) -> Vec<usize> {
    let mut v: Vec<usize> = [0, 4, 9, 14, 19, 24, 49, 59, 79, 99, 149, 199]
        .into_iter()
        .filter(|&i| i < iterations)
        .collect();
    if v.last() != Some(&(iterations - 1)) {
        v.push(iterations - 1);
    }
    v
}

/// Variants in order of first appearance, each with its runs.
pub(super) fn by_variant(runs: &[Run]) -> Vec<(String, Vec<&Run>)> {
    let mut out: Vec<(String, Vec<&Run>)> = Vec::new();
    for r in runs {
        match out.iter_mut().find(|(v, _)| *v == r.variant) {
            Some((_, rs)) => rs.push(r),
            None => out.push((r.variant.clone(), vec![r])),
        }
    }
    out
}

/// Whether `runs` are of a pose task: their logs carry the final orientation error (NaN for a
/// point task, `GaifoLog::final_orientation_error_deg`).
pub fn is_pose(runs: &[Run]) -> bool {
    runs.iter().any(|r| {
        r.logs
            .iter()
            .any(|l| l.final_orientation_error_deg.is_finite())
    })
}

/// `f` of every iteration's log, one vector per run (seed) of a variant.
fn per_seed(rs: &[&Run], f: fn(&GaifoLog) -> f64) -> Vec<Vec<f64>> {
    rs.iter().map(|r| r.logs.iter().map(f).collect()).collect()
}

/// The summary table of `runs`.
pub fn summarise(runs: &[Run]) -> Vec<SummaryRow> {
    by_variant(runs)
        .into_iter()
        .map(|(variant, rs)| {
            let perf = per_seed(&rs, |l| l.performance);
            let dist = per_seed(&rs, |l| l.final_distance);
            let (mean, se, _) = mean_stderr(&perf);
            let (dmean, dse, _) = mean_stderr(&dist);
            let iterations = mean.len();
            let last10 = |v: &[Vec<f64>]| -> (f64, f64) {
                let tails: Vec<Vec<f64>> = v
                    .iter()
                    .map(|p| {
                        let tail = &p[p.len().saturating_sub(10)..];
                        vec![tail.iter().sum::<f64>() / tail.len().max(1) as f64]
                    })
                    .collect();
                let (m, e, _) = mean_stderr(&tails);
                (
                    m.first().copied().unwrap_or(f64::NAN),
                    e.first().copied().unwrap_or(f64::NAN),
                )
            };
            let (l10, l10se) = last10(&perf);
            let (d10, d10se) = last10(&dist);
            let pose = rs.iter().any(|r| is_pose(std::slice::from_ref(*r)));
            let orient = pose.then(|| per_seed(&rs, |l| l.final_orientation_error_deg));
            let at_points = |m: &[f64], e: &[f64]| -> Vec<(usize, f64, f64)> {
                report_points(iterations.max(1))
                    .into_iter()
                    .filter(|&i| i < iterations)
                    .map(|i| (i, m[i], e[i]))
                    .collect()
            };
            let median_ms = |f: fn(&GaifoLog) -> f64| {
                1e3 * median(
                    &mut rs
                        .iter()
                        .flat_map(|r| r.logs.iter().map(f))
                        .collect::<Vec<_>>(),
                )
            };
            let (n, t) = (rs[0].episodes_per_iteration, rs[0].horizon);
            let final_orientation_error_deg = orient.as_ref().map(|o| {
                let (m, e, _) = mean_stderr(o);
                at_points(&m, &e)
            });
            SummaryRow {
                final_orientation_error_deg,
                last10_final_orientation_error_deg: orient.as_ref().map(|o| last10(o)),
                episodes_per_iteration: n,
                horizon: t,
                to_performance_0_9: Reach::of(&perf, |p| p >= 0.9, n, t),
                to_within_1cm: Reach::of(&dist, |d| d <= 0.01, n, t),
                seeds: rs.len(),
                iterations,
                performance: at_points(&mean, &se),
                final_distance_m: at_points(&dmean, &dse),
                last10_mean: l10,
                last10_se: l10se,
                last10_final_distance_m: d10,
                last10_final_distance_se: d10se,
                first_iteration_mean_ge_0_8: mean.iter().position(|&m| m >= 0.8),
                first_iteration_mean_within_1cm: dmean.iter().position(|&d| d <= 0.01),
                learner_cpu_ms_median: median_ms(|l| l.cpu_learner),
                execute_ms_median: median_ms(|l| l.t_execute),
                variant,
            }
        })
        .collect()
}

/// The summary as a text table: normalised performance, then final distance (cm), per variant.
pub fn summary_text(rows: &[SummaryRow]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let points: Vec<usize> = rows
        .first()
        .map(|r| r.performance.iter().map(|p| p.0).collect())
        .unwrap_or_default();
    let first = |i: Option<usize>| {
        i.map(|i| (i + 1).to_string())
            .unwrap_or_else(|| "never".into())
    };
    let cell = |v: &[(usize, f64, f64)], p: usize, scale: f64, digits: usize| match v
        .iter()
        .find(|q| q.0 == p)
    {
        Some((_, m, e)) => format!("{:.digits$}±{:.digits$}", scale * m, scale * e),
        None => "-".into(),
    };
    let header = |s: &mut String, what: &str, tail: &str| {
        let _ = write!(s, "{:<20} {:>5}", what, "seeds");
        for p in &points {
            let _ = write!(s, " {:>13}", format!("it {}", p + 1));
        }
        let _ = writeln!(s, "{tail}");
    };
    header(
        &mut s,
        "variant",
        &format!(
            " {:>13} {:>8} {:>9} {:>8}",
            "last 10", ">=0.8 at", "lrn ms", "sim ms"
        ),
    );
    for r in rows {
        let _ = write!(s, "{:<20} {:>5}", r.variant, r.seeds);
        for p in &points {
            let _ = write!(s, " {:>13}", cell(&r.performance, *p, 1.0, 3));
        }
        let _ = writeln!(
            s,
            " {:>13} {:>8} {:>9.1} {:>8.0}",
            format!("{:.3}±{:.3}", r.last10_mean, r.last10_se),
            first(r.first_iteration_mean_ge_0_8),
            r.learner_cpu_ms_median,
            r.execute_ms_median
        );
    }
    s.push_str("(normalised performance of the noise-free episode, mean ± standard error over seeds; iterations counted from 1; lrn ms = median learner CPU time per iteration)\n\n");
    header(
        &mut s,
        "final distance, cm",
        &format!(" {:>13} {:>8}", "last 10", "<=1cm at"),
    );
    for r in rows {
        let _ = write!(s, "{:<20} {:>5}", r.variant, r.seeds);
        for p in &points {
            let _ = write!(s, " {:>13}", cell(&r.final_distance_m, *p, 100.0, 2));
        }
        let _ = writeln!(
            s,
            " {:>13} {:>8}",
            format!(
                "{:.2}±{:.2}",
                100.0 * r.last10_final_distance_m,
                100.0 * r.last10_final_distance_se
            ),
            first(r.first_iteration_mean_within_1cm)
        );
    }
    s.push_str("(final distance to the goal of the noise-free episode, cm, mean ± standard error over seeds)\n\n");
    if rows.iter().any(|r| r.final_orientation_error_deg.is_some()) {
        header(&mut s, "orientation, deg", &format!(" {:>13}", "last 10"));
        for r in rows {
            let _ = write!(s, "{:<20} {:>5}", r.variant, r.seeds);
            let o = r.final_orientation_error_deg.as_deref().unwrap_or(&[]);
            for p in &points {
                let _ = write!(s, " {:>13}", cell(o, *p, 1.0, 2));
            }
            let last = r
                .last10_final_orientation_error_deg
                .map_or("-".into(), |(m, e)| format!("{m:.2}±{e:.2}"));
            let _ = writeln!(s, " {last:>13}");
        }
        s.push_str("(final orientation error of the tool in the noise-free episode, degrees, mean ± standard error over seeds; pose tasks)\n\n");
    }
    sample_efficiency_text(&mut s, rows);
    s
}

/// The sample-efficiency table: training episodes and environment steps to normalised 0.9
/// and to 1 cm ([`Reach`]), with the ratio to the first variant.
fn sample_efficiency_text(s: &mut String, rows: &[SummaryRow]) {
    use std::fmt::Write;
    let _ = writeln!(
        s,
        "{:<20} {:>5} | {:>6} {:>13} {:>17} {:>8} | {:>6} {:>13} {:>17} {:>8}",
        "to threshold",
        "ep/it",
        "≥0.9",
        "episodes",
        "env steps",
        "ratio",
        "≤1 cm",
        "episodes",
        "env steps",
        "ratio"
    );
    let reference = rows.first();
    let cells = |r: &Reach, base: Option<&Reach>| -> [String; 4] {
        let none = r.seeds_reached == 0;
        let fmt = |m: f64, e: f64| {
            if none {
                "never".to_string()
            } else {
                format!("{m:.0}±{e:.0}")
            }
        };
        let ratio = match base {
            // A reference that needed no episode (the mean path) makes no ratio.
            Some(b) if !none && b.seeds_reached > 0 && b.episodes_mean > 0.0 => {
                let bound = if r.seeds_reached < r.seeds { "≥" } else { "" };
                format!("{bound}{:.1}×", r.episodes_mean / b.episodes_mean)
            }
            _ => "-".into(),
        };
        [
            format!("{}/{}", r.seeds_reached, r.seeds),
            fmt(r.episodes_mean, r.episodes_se),
            fmt(r.env_steps_mean, r.env_steps_se),
            ratio,
        ]
    };
    for r in rows {
        let a = cells(
            &r.to_performance_0_9,
            reference.map(|b| &b.to_performance_0_9),
        );
        let b = cells(&r.to_within_1cm, reference.map(|b| &b.to_within_1cm));
        let _ = writeln!(
            s,
            "{:<20} {:>5} | {:>6} {:>13} {:>17} {:>8} | {:>6} {:>13} {:>17} {:>8}",
            r.variant, r.episodes_per_iteration, a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]
        );
    }
    let _ = writeln!(
        s,
        "(training episodes before the noise-free episode first reached normalised 0.9 / ended within 1 cm, mean ± standard error over the seeds that reached it (k/n); env steps = episodes × T; ratio to {}; ≥: some seeds never reached it, so a lower bound)",
        reference.map(|r| r.variant.as_str()).unwrap_or("-")
    );
}

/// Header of the experiment CSV.
pub fn csv_header() -> String {
    format!("experiment,variant,{CSV_HEADER}")
}

/// The files an experiment's results are, in its output folder: [`write_outputs`]'s and
/// `goals::write_precision`'s.
pub fn results_files(name: &str) -> [String; 9] {
    [
        format!("{name}.csv"),
        format!("{name}.png"),
        "summary.txt".into(),
        "summary.json".into(),
        "precision.txt".into(),
        "reach.txt".into(),
        "spread.csv".into(),
        "summary_goals.txt".into(),
        "summary_goals.json".into(),
    ]
}

/// Writes `<name>.csv`, `<name>.png`, `summary.txt` and `summary.json` into `out`; returns
/// the summary.
pub fn write_outputs(
    name: &str,
    title: &str,
    runs: &[Run],
    out: &Path,
) -> Result<Vec<SummaryRow>, ExperimentError> {
    use std::io::Write;
    crate::io::create_dir(out)?;
    let csv_path = out.join(format!("{name}.csv"));
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(&csv_path).map_err(IoError::file("creating", &csv_path))?,
    );
    let pose = is_pose(runs);
    if pose {
        writeln!(f, "{},{ORIENTATION_COLUMN}", csv_header())?;
    } else {
        writeln!(f, "{}", csv_header())?;
    }
    for r in runs {
        for l in &r.logs {
            write!(f, "{name},{},", r.variant)?;
            let row = crate::io::log::GaifoRow::of_task(l, r.seed, &r.algorithm, pose);
            crate::io::log::write_record(&mut f, &row)?;
        }
    }
    f.flush()?;
    let curves = |f: fn(&GaifoLog) -> f64| -> Vec<Series> {
        by_variant(runs)
            .into_iter()
            .map(|(variant, rs)| {
                let (mean, stderr, _) = mean_stderr(&per_seed(&rs, f));
                Series {
                    label: format!("{variant} ({} seeds)", rs.len()),
                    x: (1..=mean.len()).map(|i| i as f64).collect(),
                    mean,
                    stderr,
                }
            })
            .collect()
    };
    let (perf, dist) = (curves(|l| l.performance), curves(|l| l.final_distance));
    let orient = curves(|l| l.final_orientation_error_deg);
    let mut panels = vec![
        Panel {
            y_label: "normalised performance (1 = expert, 0 = random)",
            series: &perf,
            log_y: false,
        },
        Panel {
            y_label: "final distance to the goal (m, log scale)",
            series: &dist,
            log_y: true,
        },
    ];
    if pose {
        panels.push(Panel {
            y_label: "final orientation error (degrees, log scale)",
            series: &orient,
            log_y: true,
        });
    }
    let height = if pose { 1600 } else { 1100 };
    plot_panels(
        &out.join(format!("{name}.png")),
        title,
        "iteration",
        &panels,
        (1000, height),
    )?;
    let rows = summarise(runs);
    std::fs::write(out.join("summary.txt"), summary_text(&rows))?;
    std::fs::write(out.join("summary.json"), serde_json::to_vec_pretty(&rows)?)?;
    Ok(rows)
}
