//! The per-iteration CSV of the imitation runs (`gaifo_log.csv`, the same columns for
//! LQR+GAIfO and GAIfO (PPO); docs/design.md §4).

use std::path::Path;

use anyhow::Context;

use imitation::gaifo::GaifoLog;

/// Header of the per-iteration CSV (`gaifo_log.csv`), the same for both algorithms.
pub const CSV_HEADER: &str = "iteration,seed,algorithm,normalised_performance,task_cost,final_distance_m,critic_loss,wasserstein,kl,eta,step_mult,t_execute_s,t_dynamics_s,t_critic_s,t_cost_s,t_lqr_s,cpu_learner_s";

/// One CSV row (columns of [`CSV_HEADER`]) of run `seed` of `algorithm`.
pub fn write_csv_row(
    f: &mut impl std::io::Write,
    log: &GaifoLog,
    seed: u64,
    algorithm: &str,
) -> std::io::Result<()> {
    writeln!(
        f,
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        log.iteration,
        seed,
        algorithm,
        log.performance,
        log.task_cost,
        log.final_distance,
        log.critic_loss,
        log.wasserstein,
        log.kl,
        log.eta,
        log.step_mult,
        log.t_execute,
        log.t_dynamics,
        log.t_critic,
        log.t_cost,
        log.t_lqr,
        log.cpu_learner
    )
}

/// Opens the per-iteration CSV `path` ([`CSV_HEADER`]) for appending rows. `resume_at: None`
/// starts a new file. `Some(i)`, a run resumed at iteration i, keeps the rows of iterations
/// before i and appends after them (creating the file if it is missing); rows of iteration i
/// and later — written after the checkpoint it resumes from, by a run that was stopped before
/// its next checkpoint — are dropped, as the resumed run writes them again.
pub fn open_log(path: &Path, resume_at: Option<usize>) -> anyhow::Result<std::fs::File> {
    use anyhow::Context;
    use std::io::Write;
    let Some(start) = resume_at.filter(|_| path.exists()) else {
        let mut f =
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        writeln!(f, "{CSV_HEADER}")?;
        return Ok(f);
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    anyhow::ensure!(
        lines.next() == Some(CSV_HEADER),
        "{}: not a per-iteration log of this build (its first line is not the header {CSV_HEADER:?})",
        path.display()
    );
    let mut kept = String::new();
    let mut dropped = 0;
    for (k, line) in lines.enumerate() {
        let it: usize = line
            .split(',')
            .next()
            .and_then(|c| c.parse().ok())
            .with_context(|| format!("{} line {}: no iteration number", path.display(), k + 2))?;
        if it < start {
            kept.push_str(line);
            kept.push('\n');
        } else {
            dropped += 1;
        }
    }
    if dropped > 0 {
        eprintln!(
            "{}: dropping {dropped} row(s) of iteration {start} and later, written after the \
             checkpoint this run resumes from",
            path.display()
        );
        let mut f = std::fs::File::create(path)?;
        write!(f, "{CSV_HEADER}\n{kept}")?;
        return Ok(f);
    }
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))
}

/// Parses a `gaifo_log.csv` (columns of [`CSV_HEADER`], by name) back into logs.
pub fn read_gaifo_csv(path: &Path) -> anyhow::Result<Vec<GaifoLog>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().context("empty CSV")?.split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .with_context(|| format!("{}: no column {name}", path.display()))
    };
    let idx = [
        col("iteration")?,
        col("normalised_performance")?,
        col("task_cost")?,
        col("final_distance_m")?,
        col("critic_loss")?,
        col("wasserstein")?,
        col("kl")?,
        col("eta")?,
        col("step_mult")?,
        col("t_execute_s")?,
        col("t_dynamics_s")?,
        col("t_critic_s")?,
        col("t_cost_s")?,
        col("t_lqr_s")?,
    ];
    let cpu = header.iter().position(|h| *h == "cpu_learner_s");
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let num = |i: usize| -> anyhow::Result<f64> {
                f.get(i)
                    .context("short row")?
                    .parse::<f64>()
                    .with_context(|| format!("{}: bad number in `{l}`", path.display()))
            };
            Ok(GaifoLog {
                iteration: num(idx[0])? as usize,
                performance: num(idx[1])?,
                task_cost: num(idx[2])?,
                final_distance: num(idx[3])?,
                critic_loss: num(idx[4])?,
                wasserstein: num(idx[5])?,
                kl: num(idx[6])?,
                eta: num(idx[7])?,
                step_mult: num(idx[8])?,
                t_execute: num(idx[9])?,
                t_dynamics: num(idx[10])?,
                t_critic: num(idx[11])?,
                t_cost: num(idx[12])?,
                t_lqr: num(idx[13])?,
                cpu_learner: match cpu {
                    Some(i) => num(i)?,
                    None => f64::NAN,
                },
            })
        })
        .collect()
}
