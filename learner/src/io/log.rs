//! The per-iteration CSV of the imitation runs (`gaifo_log.csv`, the same columns for
//! LQR+GAIfO and GAIfO (PPO); `mdgps_log.csv` for MDGPS; docs/design.md §4). A pose task's
//! `gaifo_log.csv` has one more column at the end, [`ORIENTATION_COLUMN`]; a point task's
//! columns are [`CSV_HEADER`]'s alone, as they were before pose tasks.

use std::path::Path;

use super::IoError;
use crate::error::ensure;

use imitation::gaifo::GaifoLog;
use imitation::mdgps::MdgpsLog;
use serde::{Deserialize, Serialize};
use ur5_shared::StateLayout;

/// Header of the per-iteration CSV (`gaifo_log.csv`), the same for both algorithms: the fields
/// of [`GaifoRow`].
pub const CSV_HEADER: &str = "iteration,seed,algorithm,normalised_performance,task_cost,final_distance_m,critic_loss,wasserstein,kl,eta,step_mult,t_execute_s,t_dynamics_s,t_critic_s,t_cost_s,t_lqr_s,cpu_learner_s";

/// The column a pose task's `gaifo_log.csv` adds after [`CSV_HEADER`]'s: the noise-free
/// episode's final orientation error (degrees), the name of the `--json` line's field.
pub const ORIENTATION_COLUMN: &str = "final_orientation_error_deg";

/// Header of the expert's per-iteration CSV (`expert_log.csv`, `serve_log.csv`): the serde
/// fields of [`imitation::expert::IterationLog`].
pub const EXPERT_CSV_HEADER: &str =
    "iteration,eval_cost,mean_sample_cost,final_distance_m,performance_proxy,kl,eta,step_mult,seconds";

/// One row of `gaifo_log.csv`: a [`GaifoLog`] of run `seed` of `algorithm`, with the CSV's
/// column names and units (m, s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaifoRow {
    pub iteration: usize,
    pub seed: u64,
    pub algorithm: String,
    pub normalised_performance: f64,
    pub task_cost: f64,
    pub final_distance_m: f64,
    pub critic_loss: f64,
    pub wasserstein: f64,
    pub kl: f64,
    pub eta: f64,
    pub step_mult: f64,
    pub t_execute_s: f64,
    pub t_dynamics_s: f64,
    pub t_critic_s: f64,
    pub t_cost_s: f64,
    pub t_lqr_s: f64,
    /// Absent in logs written before it was added: NaN.
    #[serde(default = "nan")]
    pub cpu_learner_s: f64,
    /// A pose task's final orientation error (degrees; [`ORIENTATION_COLUMN`]); `None` for a
    /// point task, whose rows have no such column.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub final_orientation_error_deg: Option<f64>,
}

fn nan() -> f64 {
    f64::NAN
}

impl GaifoRow {
    /// The row of `log` of run `seed` of `algorithm` of a point task (no orientation column).
    pub fn new(log: &GaifoLog, seed: u64, algorithm: &str) -> Self {
        Self::of_task(log, seed, algorithm, false)
    }

    /// The row of `log` of run `seed` of `algorithm`; with `pose` (a pose task) its
    /// orientation error in [`ORIENTATION_COLUMN`].
    pub fn of_task(log: &GaifoLog, seed: u64, algorithm: &str, pose: bool) -> Self {
        Self {
            iteration: log.iteration,
            seed,
            algorithm: algorithm.into(),
            normalised_performance: log.performance,
            task_cost: log.task_cost,
            final_distance_m: log.final_distance,
            critic_loss: log.critic_loss,
            wasserstein: log.wasserstein,
            kl: log.kl,
            eta: log.eta,
            step_mult: log.step_mult,
            t_execute_s: log.t_execute,
            t_dynamics_s: log.t_dynamics,
            t_critic_s: log.t_critic,
            t_cost_s: log.t_cost,
            t_lqr_s: log.t_lqr,
            cpu_learner_s: log.cpu_learner,
            final_orientation_error_deg: pose.then_some(log.final_orientation_error_deg),
        }
    }

    /// The log this row records.
    pub fn log(&self) -> GaifoLog {
        GaifoLog {
            iteration: self.iteration,
            task_cost: self.task_cost,
            performance: self.normalised_performance,
            final_distance: self.final_distance_m,
            critic_loss: self.critic_loss,
            wasserstein: self.wasserstein,
            kl: self.kl,
            eta: self.eta,
            step_mult: self.step_mult,
            t_execute: self.t_execute_s,
            t_dynamics: self.t_dynamics_s,
            t_critic: self.t_critic_s,
            t_cost: self.t_cost_s,
            t_lqr: self.t_lqr_s,
            cpu_learner: self.cpu_learner_s,
            demo_gap: f64::NAN,
            path_rmse: f64::NAN,
            final_orientation_error_deg: self.final_orientation_error_deg.unwrap_or(f64::NAN),
        }
    }
}

/// Writes `row` as one CSV record (newline included, no header) to `f`.
pub fn write_record(f: &mut impl std::io::Write, row: &impl Serialize) -> std::io::Result<()> {
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(f);
    w.serialize(row).map_err(std::io::Error::other)?;
    w.flush()
}

/// The header of `mdgps_log.csv` ([`MdgpsRow`]'s fields).
pub const MDGPS_CSV_HEADER: &str = "iteration,seed,mean_performance_at_conditions,mean_final_distance_m_at_conditions,mean_controller_cost,critic_loss,wasserstein,kl,eta,s_loss_before,s_loss_after,t_execute_s,t_dynamics_s,t_critic_s,t_cost_s,t_lqr_s,t_policy_s";

/// One row of `mdgps_log.csv`: an MDGPS iteration, its per-condition results as means over the
/// conditions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MdgpsRow {
    pub iteration: usize,
    pub seed: u64,
    pub mean_performance_at_conditions: f64,
    pub mean_final_distance_m_at_conditions: f64,
    pub mean_controller_cost: f64,
    pub critic_loss: f64,
    pub wasserstein: f64,
    pub kl: f64,
    pub eta: f64,
    pub s_loss_before: f64,
    pub s_loss_after: f64,
    pub t_execute_s: f64,
    pub t_dynamics_s: f64,
    pub t_critic_s: f64,
    pub t_cost_s: f64,
    pub t_lqr_s: f64,
    pub t_policy_s: f64,
}

impl MdgpsRow {
    /// The row of `log` of the run of `seed`.
    pub fn new(log: &MdgpsLog, seed: u64) -> Self {
        Self {
            iteration: log.iteration,
            seed,
            mean_performance_at_conditions: log.mean_performance(),
            mean_final_distance_m_at_conditions: log.mean_final_distance(),
            mean_controller_cost: log.controller_cost.iter().sum::<f64>()
                / log.controller_cost.len().max(1) as f64,
            critic_loss: log.critic_loss,
            wasserstein: log.wasserstein,
            kl: log.kl,
            eta: log.eta,
            s_loss_before: log.s_loss_before,
            s_loss_after: log.s_loss_after,
            t_execute_s: log.t_execute,
            t_dynamics_s: log.t_dynamics,
            t_critic_s: log.t_critic,
            t_cost_s: log.t_cost,
            t_lqr_s: log.t_lqr,
            t_policy_s: log.t_policy,
        }
    }
}

/// A learner's per-iteration log as a row of its run's CSV.
pub trait LogRow {
    /// The CSV's file name in the run folder.
    const FILE: &'static str;
    /// Its header for a point task.
    const HEADER: &'static str;
    /// Its header for a task of `layout` ([`LogRow::HEADER`] unless the log has columns for
    /// a pose task).
    fn header(_layout: &StateLayout) -> String {
        Self::HEADER.into()
    }
    /// Writes the row of run `seed` of `algorithm` on a task of `layout` (the columns of
    /// [`LogRow::header`]).
    fn write_row(
        &self,
        f: &mut impl std::io::Write,
        seed: u64,
        algorithm: &str,
        layout: &StateLayout,
    ) -> std::io::Result<()>;
}

/// Whether the log of a task of `layout` has [`ORIENTATION_COLUMN`]: a pose task's (three
/// tool points).
fn has_orientation(layout: &StateLayout) -> bool {
    layout.tool_points() == 3
}

impl LogRow for GaifoLog {
    const FILE: &'static str = "gaifo_log.csv";
    const HEADER: &'static str = CSV_HEADER;
    fn header(layout: &StateLayout) -> String {
        if has_orientation(layout) {
            format!("{CSV_HEADER},{ORIENTATION_COLUMN}")
        } else {
            CSV_HEADER.into()
        }
    }
    fn write_row(
        &self,
        f: &mut impl std::io::Write,
        seed: u64,
        algorithm: &str,
        layout: &StateLayout,
    ) -> std::io::Result<()> {
        let row = GaifoRow::of_task(self, seed, algorithm, has_orientation(layout));
        write_record(f, &row)
    }
}

impl LogRow for MdgpsLog {
    const FILE: &'static str = "mdgps_log.csv";
    const HEADER: &'static str = MDGPS_CSV_HEADER;
    fn write_row(
        &self,
        f: &mut impl std::io::Write,
        seed: u64,
        _algorithm: &str,
        _layout: &StateLayout,
    ) -> std::io::Result<()> {
        write_record(f, &MdgpsRow::new(self, seed))
    }
}

/// One CSV row (columns of [`CSV_HEADER`]) of run `seed` of `algorithm`.
pub fn write_csv_row(
    f: &mut impl std::io::Write,
    log: &GaifoLog,
    seed: u64,
    algorithm: &str,
) -> std::io::Result<()> {
    write_record(f, &GaifoRow::new(log, seed, algorithm))
}

/// Opens the per-iteration CSV `path` ([`CSV_HEADER`]) for appending rows. `resume_at: None`
/// starts a new file. `Some(i)`, a run resumed at iteration i, keeps the rows of iterations
/// before i and appends after them (creating the file if it is missing); rows of iteration i
/// and later — written after the checkpoint it resumes from, by a run that was stopped before
/// its next checkpoint — are dropped, as the resumed run writes them again, and so is a last
/// row cut short by a kill (fewer columns or no newline). The file is then rewritten
/// atomically ([`ur5_shared::atomic_file::write`]), so a kill during the rewrite loses nothing.
pub fn open_log(path: &Path, resume_at: Option<usize>) -> Result<std::fs::File, IoError> {
    open_log_with(path, CSV_HEADER, resume_at)
}

/// [`open_log`] of a CSV whose first line is `header` (an iteration number first in every row).
pub fn open_log_with(
    path: &Path,
    header: &str,
    resume_at: Option<usize>,
) -> Result<std::fs::File, IoError> {
    use std::io::Write;
    let Some(start) = resume_at.filter(|_| path.exists()) else {
        let mut f = std::fs::File::create(path).map_err(IoError::file("creating", &path))?;
        writeln!(f, "{header}").map_err(IoError::file("writing", path))?;
        return Ok(f);
    };
    let text = std::fs::read_to_string(path).map_err(IoError::file("reading", &path))?;
    let mut lines = text.split_inclusive('\n');
    ensure!(
        lines.next().map(|l| l.trim_end_matches('\n')) == Some(header),
        IoError::content(
            path,
            format!(
                "not a per-iteration log of this build (its first line is not the header \
                 {header:?})"
            )
        )
    );
    let columns = header.split(',').count();
    let mut kept = String::new();
    let mut dropped = 0;
    let mut lines = lines.enumerate().peekable();
    while let Some((k, line)) = lines.next() {
        let complete = line.ends_with('\n') && line.trim_end().split(',').count() == columns;
        if !complete && lines.peek().is_none() {
            dropped += 1; // the row being written when the run was killed
            continue;
        }
        let it: usize = line
            .split(',')
            .next()
            .and_then(|c| c.parse().ok())
            .filter(|_| complete)
            .ok_or_else(|| {
                IoError::content(
                    path,
                    format!(
                        "line {}: not a complete row ({columns} columns, an iteration number \
                         first)",
                        k + 2
                    ),
                )
            })?;
        if it < start {
            kept.push_str(line);
        } else {
            dropped += 1;
        }
    }
    if dropped > 0 {
        eprintln!(
            "{}: dropping {dropped} row(s) of iteration {start} and later or cut short, written \
             after the checkpoint this run resumes from",
            path.display()
        );
        ur5_shared::atomic_file::write(path, format!("{header}\n{kept}").as_bytes())
            .map_err(IoError::file("writing", path))?;
    }
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .map_err(IoError::file("opening", &path))
}

/// Parses a `gaifo_log.csv` (columns of [`CSV_HEADER`], and a pose task's
/// [`ORIENTATION_COLUMN`], by name) back into logs.
pub fn read_gaifo_csv(path: &Path) -> Result<Vec<GaifoLog>, IoError> {
    let mut r = csv::Reader::from_path(path).map_err(IoError::csv("reading", path))?;
    r.deserialize::<GaifoRow>()
        .enumerate()
        .map(|(k, row)| {
            row.map(|r| r.log()).map_err(|source| IoError::CsvRow {
                path: path.to_owned(),
                row: k + 1,
                source,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use imitation::expert::IterationLog;

    /// The headers written by hand are the serde fields, and a row reads back bit for bit.
    #[test]
    fn headers_are_the_serde_fields_and_rows_round_trip() {
        let log = GaifoLog {
            iteration: 3,
            task_cost: 1.25,
            performance: 0.1 + 0.2,
            final_distance: 1e-7,
            critic_loss: -0.5,
            wasserstein: 0.0,
            kl: f64::NAN,
            eta: 1e16,
            step_mult: 1.0,
            t_execute: 0.5,
            t_dynamics: 0.25,
            t_critic: 0.125,
            t_cost: 0.0625,
            t_lqr: 3.0,
            cpu_learner: 0.7,
            // Not a CSV column: it reads back as NaN.
            demo_gap: 0.25,
            path_rmse: f64::NAN,
            final_orientation_error_deg: f64::NAN,
        };
        let mut buf = Vec::new();
        let mut w = csv::Writer::from_writer(&mut buf);
        w.serialize(GaifoRow::new(&log, 7, "lqr-gaifo")).unwrap();
        drop(w);
        let text = String::from_utf8(buf).unwrap();
        assert_eq!(text.lines().next(), Some(CSV_HEADER));
        let dir = std::env::temp_dir().join(format!("log-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("gaifo_log.csv");
        std::fs::write(&path, &text).unwrap();
        let back = read_gaifo_csv(&path).unwrap();
        let bits = |l: &GaifoLog| {
            [
                l.task_cost,
                l.performance,
                l.final_distance,
                l.kl,
                l.eta,
                l.cpu_learner,
            ]
            .map(f64::to_bits)
        };
        assert_eq!((back[0].iteration, bits(&back[0])), (3, bits(&log)));

        let it = IterationLog {
            iteration: 0,
            eval_cost: 1.0,
            mean_sample_cost: 2.0,
            final_distance: 0.5,
            performance_proxy: 0.25,
            kl: 0.1,
            eta: 1.0,
            step_mult: 1.0,
            seconds: 0.2,
        };
        let mut buf = Vec::new();
        let mut w = csv::Writer::from_writer(&mut buf);
        w.serialize(&it).unwrap();
        drop(w);
        assert_eq!(
            String::from_utf8(buf).unwrap().lines().next(),
            Some(EXPERT_CSV_HEADER)
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A pose task's rows end with the orientation error, under the header that names it, and
    /// read back; a point task's rows and header are as before (no such column), whatever
    /// the log holds.
    #[test]
    fn a_pose_tasks_log_has_the_orientation_column_and_a_point_tasks_not() {
        let log = GaifoLog {
            iteration: 2,
            final_orientation_error_deg: 1.5,
            ..GaifoLog::default()
        };
        let (pose, point) = (StateLayout::POSE6, StateLayout::REACH3);
        let header = GaifoLog::header(&pose);
        assert_eq!(header, format!("{CSV_HEADER},final_orientation_error_deg"));
        assert_eq!(GaifoLog::header(&point), CSV_HEADER);
        let (mut a, mut b, mut old) = (Vec::new(), Vec::new(), Vec::new());
        log.write_row(&mut a, 1, "lqr-gaifo", &pose).unwrap();
        log.write_row(&mut b, 1, "lqr-gaifo", &point).unwrap();
        write_csv_row(&mut old, &log, 1, "lqr-gaifo").unwrap();
        let (a, b) = (String::from_utf8(a).unwrap(), String::from_utf8(b).unwrap());
        assert_eq!(b.as_bytes(), old, "a point task's row as before");
        assert_eq!(a.trim_end().split(',').count(), header.split(',').count());
        assert!(a.trim_end().ends_with(",1.5"), "{a}");
        assert_eq!(
            b.trim_end().split(',').count(),
            CSV_HEADER.split(',').count()
        );
        let dir = std::env::temp_dir().join(format!("log-pose-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("gaifo_log.csv");
        std::fs::write(&path, format!("{header}\n{a}")).unwrap();
        let back = read_gaifo_csv(&path).unwrap();
        assert_eq!(back[0].final_orientation_error_deg, 1.5);
        std::fs::write(&path, format!("{CSV_HEADER}\n{b}")).unwrap();
        assert!(read_gaifo_csv(&path).unwrap()[0]
            .final_orientation_error_deg
            .is_nan());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
