//! Errors of the learner library: one `thiserror` enum per area, each next to its code
//! ([`crate::io::IoError`], [`crate::io::demos::DemosError`], [`crate::run::RunError`],
//! [`crate::replay::ReplayError`], [`crate::serve::ServeError`],
//! [`crate::experiment::ExperimentError`], [`crate::plot::PlotError`],
//! [`crate::record::RecordError`], [`crate::bench::BenchError`]); an area's enum wraps the
//! errors of the areas and crates it calls (`#[from]`), so a failure keeps its cause chain. Only
//! the command line ([`crate::cli`]) and `main` turn them into `anyhow` errors, and `main` prints
//! the chain as one line (docs/dev.md, "Errors").

/// Returns `Err(err.into())` from the enclosing function unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $err:expr $(,)?) => {
        if !$cond {
            return Err($err.into());
        }
    };
}
pub(crate) use ensure;

/// `e` and its causes on one line, as the binaries print a failed command
/// ([`ur5_shared::report::error_line`]).
pub fn line(e: &(dyn std::error::Error + 'static)) -> String {
    ur5_shared::report::error_line(std::iter::successors(Some(e), |e| e.source()))
}
