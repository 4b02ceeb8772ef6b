//! The `learner` command line: one module per subcommand, all sharing [`CommonArgs`].

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};

pub mod bench;
pub mod dataset;
pub mod experiment;
pub mod expert;
pub mod plot;
pub mod policy;
pub mod record;
pub mod replay;
pub mod serve;
pub mod sweep;
pub mod train;
pub mod train_td3;

/// The options every run-producing subcommand shares.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct CommonArgs {
    /// TOML settings, layered over the subcommand's defaults (unknown keys are errors; the
    /// settings type is named in the subcommand's help).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seed of the run (of the first run for `experiment`); overrides the config.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output folder (each subcommand's default in its help).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

impl CommonArgs {
    /// The settings of `--config` layered over `C::default()`, or the defaults.
    pub fn settings<C>(&self) -> anyhow::Result<C>
    where
        C: serde::Serialize + serde::de::DeserializeOwned + Default,
    {
        Ok(match &self.config {
            Some(p) => ur5_shared::config::from_toml_file(p)?,
            None => C::default(),
        })
    }

    /// Whether `--config` gives `key` in its table `table` (`[task] joints`): a command-line
    /// option that implies a setting leaves one the file gives alone.
    pub fn config_gives(&self, table: &str, key: &str) -> anyhow::Result<bool> {
        let Some(p) = &self.config else {
            return Ok(false);
        };
        let text =
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
        let t: toml::Table =
            toml::from_str(&text).with_context(|| format!("parsing {}", p.display()))?;
        Ok(t.get(table)
            .and_then(|v| v.as_table())
            .is_some_and(|t| t.contains_key(key)))
    }
}

#[derive(Parser)]
#[command(
    name = "learner",
    about = "LQR+GAIfO learner: the expert, imitation from state-only demonstrations, the GAIfO \
             (PPO) baseline, the learner end over IPC, the paper's experiments"
)]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// The subcommands.
#[derive(Subcommand)]
pub enum Cmd {
    /// Check every GPS piece against a reference-vectors file (gps-vectors layout); exits
    /// non-zero if any quantity fails its tolerance.
    Conformance(bench::ConformanceArgs),
    /// Train the expert on the true task cost (KL-bounded LQR with learned dynamics, in
    /// process), save its gain table, record demonstrations. --config: an `ExpertConfig`.
    /// Progress: one line per iteration.
    Expert(expert::ExpertArgs),
    /// The learner end of the three processes (hil-sim serve <-> rt-controller <-> learner):
    /// publishes gain tables on controller/gains, learns from the episodes on learner/samples
    /// (the expert's iteration on the true task cost, or LQR+GAIfO with --algo lqr-gaifo
    /// --demos FILE). --config: an `ExpertConfig` or `GaifoConfig` plus a [serve] table.
    /// Progress: one line per iteration.
    Serve(serve::ServeArgs),
    /// Imitate state-only demonstrations: LQR+GAIfO (default; --config: a `GaifoConfig`) or
    /// the GAIfO (PPO) baseline (--config: a `GaifoPpoConfig`); --resume DIR continues an
    /// LQR+GAIfO run. Progress: one line per iteration.
    Train(train::TrainArgs),
    /// Time one full learner update (GMM prior update, dynamics fit, η search) on a seeded
    /// synthetic linear problem; prints median wall-clock and CPU times in milliseconds.
    Bench(bench::BenchArgs),
    /// The paper's experiments (comparison, generalisation, sim-vs-physical, stability): CSV,
    /// PNG plot and summary table in the output folder; seeds run in parallel. --config: an
    /// `ExperimentConfig`.
    Experiment(experiment::ExperimentArgs),
    /// Time LQR+GAIfO iterations on real demonstrations; prints per-phase medians and the
    /// learner CPU time. --config: a `GaifoConfig`.
    BenchGaifo(bench::BenchGaifoArgs),
    /// Demonstrations and recorded episodes out as LeRobot v3.0 datasets or CSV
    /// (`dataset export --format lerobot IN OUT_DIR`); `dataset check` loads and checks
    /// demonstrations in any format `--demos` takes.
    #[command(subcommand)]
    Dataset(dataset::DatasetCmd),
    /// Re-run the learning of a recorded run (`learner serve`, or `learner train
    /// --record-episodes`) from its recorded episodes and compare every table bit for bit with
    /// the recorded ones; reports the first difference and exits non-zero if there is one.
    Replay(replay::ReplayArgs),
    /// Pictures: `plot arm RUN_DIR` draws the arm reaching (filmstrip PNG and animated GIF).
    #[command(subcommand)]
    Plot(plot::PlotCmd),
    /// Record demonstrations taught by hand from a UR's RTDE stream (a person guiding the arm
    /// in freedrive, or `hil-sim ur-sim --playback`): joint states at the arm's rate (500 Hz
    /// e-Series, 125 Hz CB3) resampled to task.dt, cut by rests (rest ≥ 1 s at the start pose,
    /// move, rest ≥ 1 s elsewhere: one demonstration; docs/data.md), T = task.horizon steps
    /// from the motion's onset padded with the final rest; start pose and goal (the mean end
    /// point, spread reported) from the recording; C_expert and C_random derived as for
    /// imported demonstrations; checked and written as OUT/demos.npz (or a LeRobot dataset).
    /// Progress: one line per demonstration.
    Record(record::RecordArgs),
    /// Run a saved MDGPS policy: `policy eval --policy FILE --goal x,y,z` in simulation,
    /// `policy serve --policy FILE` on the real-time controller.
    #[command(subcommand)]
    Policy(policy::PolicyCmd),
}

/// Parses the command line and runs the subcommand.
pub fn main() -> anyhow::Result<()> {
    match Cli::parse().cmd {
        Cmd::Expert(args) => crate::experiment::pool(args.threads)?.install(|| expert::run(args)),
        Cmd::Train(args) => crate::experiment::pool(args.threads)?.install(|| {
            if args.algo == train::Algo::GaifoTd3 {
                train_td3::run(&args)
            } else {
                train::run(args)
            }
        }),
        Cmd::Experiment(args) => experiment::run_cli(args),
        Cmd::Serve(args) => serve::run_cli(args),
        Cmd::Conformance(args) => bench::conformance(args),
        Cmd::BenchGaifo(args) => bench::run_gaifo(args),
        Cmd::Bench(args) => bench::run(args),
        Cmd::Policy(cmd) => policy::run(cmd),
        Cmd::Dataset(cmd) => dataset::run(cmd),
        Cmd::Plot(cmd) => plot::run(cmd),
        Cmd::Replay(args) => replay::run(args),
        Cmd::Record(args) => record::run(args),
    }
}
