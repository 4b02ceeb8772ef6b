//! The experiments' outputs: the per-variant summary table (text and JSON), the CSV and the
//! figure (module docs of `experiment`).

use std::path::Path;

use anyhow::Context;
use serde::Serialize;

use super::Run;
use crate::io::log::CSV_HEADER;
use crate::plot::{mean_stderr, plot_curves, Series};
use crate::stats::median;

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
    /// Mean (± SE over seeds) normalised performance over the last 10 iterations.
    pub last10_mean: f64,
    pub last10_se: f64,
    /// First iteration at which the mean over seeds reaches 0.8 (None: never).
    pub first_iteration_mean_ge_0_8: Option<usize>,
    /// Median learner CPU time per iteration, ms.
    pub learner_cpu_ms_median: f64,
    /// Median simulator time per iteration (episodes), ms.
    pub execute_ms_median: f64,
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
fn by_variant(runs: &[Run]) -> Vec<(String, Vec<&Run>)> {
    let mut out: Vec<(String, Vec<&Run>)> = Vec::new();
    for r in runs {
        match out.iter_mut().find(|(v, _)| *v == r.variant) {
            Some((_, rs)) => rs.push(r),
            None => out.push((r.variant.clone(), vec![r])),
        }
    }
    out
}

/// The summary table of `runs`.
pub fn summarise(runs: &[Run]) -> Vec<SummaryRow> {
    by_variant(runs)
        .into_iter()
        .map(|(variant, rs)| {
            let perf: Vec<Vec<f64>> = rs
                .iter()
                .map(|r| r.logs.iter().map(|l| l.performance).collect())
                .collect();
            let (mean, se, _) = mean_stderr(&perf);
            let iterations = mean.len();
            let last10: Vec<Vec<f64>> = perf
                .iter()
                .map(|p| {
                    let tail = &p[p.len().saturating_sub(10)..];
                    vec![tail.iter().sum::<f64>() / tail.len().max(1) as f64]
                })
                .collect();
            let (l10, l10se, _) = mean_stderr(&last10);
            SummaryRow {
                seeds: rs.len(),
                iterations,
                performance: report_points(iterations.max(1))
                    .into_iter()
                    .filter(|&i| i < iterations)
                    .map(|i| (i, mean[i], se[i]))
                    .collect(),
                last10_mean: l10.first().copied().unwrap_or(f64::NAN),
                last10_se: l10se.first().copied().unwrap_or(f64::NAN),
                first_iteration_mean_ge_0_8: mean.iter().position(|&m| m >= 0.8),
                learner_cpu_ms_median: 1e3
                    * median(
                        &mut rs
                            .iter()
                            .flat_map(|r| r.logs.iter().map(|l| l.cpu_learner))
                            .collect::<Vec<_>>(),
                    ),
                execute_ms_median: 1e3
                    * median(
                        &mut rs
                            .iter()
                            .flat_map(|r| r.logs.iter().map(|l| l.t_execute))
                            .collect::<Vec<_>>(),
                    ),
                variant,
            }
        })
        .collect()
}

/// The summary as a text table.
pub fn summary_text(rows: &[SummaryRow]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let points: Vec<usize> = rows
        .first()
        .map(|r| r.performance.iter().map(|p| p.0).collect())
        .unwrap_or_default();
    let _ = write!(s, "{:<20} {:>5}", "variant", "seeds");
    for p in &points {
        let _ = write!(s, " {:>13}", format!("it {}", p + 1));
    }
    let _ = writeln!(
        s,
        " {:>13} {:>8} {:>9} {:>8}",
        "last 10", ">=0.8 at", "lrn ms", "sim ms"
    );
    for r in rows {
        let _ = write!(s, "{:<20} {:>5}", r.variant, r.seeds);
        for p in &points {
            match r.performance.iter().find(|q| q.0 == *p) {
                Some((_, m, e)) => {
                    let _ = write!(s, " {:>13}", format!("{m:.3}±{e:.3}"));
                }
                None => {
                    let _ = write!(s, " {:>13}", "-");
                }
            }
        }
        let _ = writeln!(
            s,
            " {:>13} {:>8} {:>9.1} {:>8.0}",
            format!("{:.3}±{:.3}", r.last10_mean, r.last10_se),
            r.first_iteration_mean_ge_0_8
                .map(|i| (i + 1).to_string())
                .unwrap_or_else(|| "never".into()),
            r.learner_cpu_ms_median,
            r.execute_ms_median
        );
    }
    s.push_str("(normalised performance of the noise-free episode, mean ± standard error over seeds; iterations counted from 1; lrn ms = median learner CPU time per iteration)\n");
    s
}

/// Header of the experiment CSV.
pub fn csv_header() -> String {
    format!("experiment,variant,{CSV_HEADER}")
}

/// Writes `<name>.csv`, `<name>.png`, `summary.txt` and `summary.json` into `out`; returns
/// the summary.
pub fn write_outputs(
    name: &str,
    title: &str,
    runs: &[Run],
    out: &Path,
) -> anyhow::Result<Vec<SummaryRow>> {
    use std::io::Write;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join(format!("{name}.csv"));
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(&csv_path)
            .with_context(|| format!("creating {}", csv_path.display()))?,
    );
    writeln!(f, "{}", csv_header())?;
    for r in runs {
        for l in &r.logs {
            write!(f, "{name},{},", r.variant)?;
            crate::io::log::write_csv_row(&mut f, l, r.seed, &r.algorithm)?;
        }
    }
    f.flush()?;
    let series: Vec<Series> = by_variant(runs)
        .into_iter()
        .map(|(variant, rs)| {
            let perf: Vec<Vec<f64>> = rs
                .iter()
                .map(|r| r.logs.iter().map(|l| l.performance).collect())
                .collect();
            let (mean, stderr, _) = mean_stderr(&perf);
            Series {
                label: format!("{variant} ({} seeds)", rs.len()),
                x: (1..=mean.len()).map(|i| i as f64).collect(),
                mean,
                stderr,
            }
        })
        .collect();
    plot_curves(
        &out.join(format!("{name}.png")),
        title,
        "iteration",
        "normalised performance (1 = expert, 0 = random)",
        &series,
        (1000, 620),
    )?;
    let rows = summarise(runs);
    std::fs::write(out.join("summary.txt"), summary_text(&rows))?;
    std::fs::write(out.join("summary.json"), serde_json::to_vec_pretty(&rows)?)?;
    Ok(rows)
}
