//! `learner experiment sim-vs-physical`: LQR+GAIfO over IPC (hil-sim serve, rt-controller in
//! real time with time compression, learner serve) on the nominal and on the perturbed arm.

use std::path::Path;

use crate::experiment::{ExperimentConfig, Run, SummaryRow};

/// Runs the experiment (not wired yet: needs `learner serve --algo lqr-gaifo`).
pub fn run(
    _cfg: &ExperimentConfig,
    _out: &Path,
    _demos: Option<&Path>,
) -> anyhow::Result<(Vec<Run>, Vec<SummaryRow>)> {
    anyhow::bail!("sim-vs-physical is not implemented yet (needs `learner serve --algo lqr-gaifo`)")
}
