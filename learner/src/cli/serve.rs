//! `learner serve`: its arguments and the command.

use std::path::PathBuf;

use serde::Serialize;

use imitation::expert::ExpertConfig;
use imitation::gaifo::GaifoConfig;

use super::CommonArgs;
use crate::serve::{
    read_config, serve, serve_bco, serve_gaifo, serve_mdgps, serve_replay_mean, serve_td3,
    settings, ServeAlgo, ServeOptions, ServeSummary,
};

/// Units and files, shown after `learner serve --help`.
pub const HELP_UNITS: &str = "Units: angles rad (actions are goal joint angles), positions m (arm base frame), \
times s (task.dt is the control period; progress `sec` (expert) and `sim_ms` (lqr-gaifo) are wall-clock from the \
version's first sample to its update), task cost C(τ) = d_T + Σ (i/T) d_i in m; init_var rad². Every option lives \
in the TOML file (an ExpertConfig as for `learner expert --config`, or with --algo lqr-gaifo a GaifoConfig, with \
--algo mdgps an MdgpsConfig, as for `learner train --config`, plus a [serve] table with algo, demos, prefix, out, resume, record_episodes, mcap, \
wait_report_s, idle_sleep_us, task_tolerance); the flags above override it. The controller must run with the \
same seed, task (lqr-gaifo: the demonstrations' goal, start_q, horizon, dt), noisy_episodes = samples and \
eval_episodes = 1; the learner checks the task on the sample stream and stops with an error naming the \
setting. Files in --out: episodes/*.npz, tables/v*.npz, latest_table.npz, best_table.npz; expert: \
checkpoint.npz, serve_log.csv; lqr-gaifo: iter_NNN_table.npz + iter_NNN_critic.json, gaifo_log.csv (the \
columns of `learner train`, and iter_NNN_state.npz). --resume restores LQR+GAIfO's whole learner state (critic \
with Adam moments, GMM dynamics prior and its data, previous controller, step size, RNG positions) and \
republishes its version at a higher epoch, so the controller restarts that version's noise draws: against an \
arm whose reset is exact (hil-sim serve, lockstep) the resumed run equals an uninterrupted one bit for bit, \
against one whose reset is not (ur-sim, a real arm) it does not; the expert's restores its controller only (its GMM prior starts afresh). mdgps (--demos DIR, one .npz per \
goal): per version, goal after goal, the goal's gain table (its goal and noise stream in the table's episode plan) \
until its N noisy episodes are in, then the policy as a noise-free policy table at the goal until its evaluation is \
in; the checkpoints iter_NNN_critic.json + iter_NNN_state.npz and mdgps_log.csv of `learner train --algo mdgps`; \
tables/v*.npz and latest_table.npz hold each version's first gain table. bco, gaifo-td3, replay-mean \
(--demos FILE; config a BcoConfig, GaifoTd3Config or ReplayMeanConfig, as for `learner train --algo …`): \
bco and gaifo-td3 publish their MLP policy as a policy table per version (tables/v*.npz: params, hidden, \
the header of a gain table's file), which the controller runs like a gain table (N noisy episodes, \
then the noise-free one); replay-mean publishes the mean path as a gain table; their files are \
those of `learner train`, and --resume continues exactly from the latest iter_NNN_state.npz.";

/// Arguments of `learner serve`.
#[derive(clap::Args, Debug)]
#[command(after_help = HELP_UNITS)]
pub struct ServeArgs {
    /// Learner: `expert` (true task cost; default), `lqr-gaifo` (imitation from --demos),
    /// `mdgps` (several goals, a folder --demos), or the baselines `bco`, `gaifo-td3` (a policy
    /// table per version) and `replay-mean` (the demonstrations' mean path as a gain table with
    /// K = 0); overrides the config's [serve] algo.
    #[arg(long, value_enum)]
    pub algo: Option<ServeAlgo>,
    /// Demonstrations (.npz from `learner expert`) for --algo lqr-gaifo; their task (goal,
    /// start pose, T, dt) is the one rt-controller and hil-sim must run. For --algo mdgps a
    /// folder of them, one per goal (as for `learner train --algo mdgps`).
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// iceoryx2 service prefix (rt-controller and hil-sim must use the same).
    #[arg(long)]
    pub prefix: Option<String>,
    /// Continue from the checkpoint in DIR of an earlier (e.g. killed) run (expert:
    /// checkpoint.npz; lqr-gaifo: the latest iter_NNN_table.npz + iter_NNN_critic.json; mdgps:
    /// the latest iter_NNN_state.npz + iter_NNN_critic.json): re-publishes its table version
    /// (every publication of it above the earlier runs') and continues learning from there.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// Start a new run in --out even though another run's files are there: they are deleted
    /// first (without it such a folder is refused).
    #[arg(long)]
    pub force: bool,
    /// Largest number of iterations (counted from the first, across resumes); overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Write the run's recorded episodes and tables into OUT/run.mcap as they come, one chunk
    /// per episode, the summary at exit (JSON messages for Foxglove or Rerun: /joint_states,
    /// /state, /action, /fault, /episode, /table; docs/design.md §4.14); the same messages as
    /// `learner dataset export --format mcap OUT F.mcap`. A killed learner leaves the file
    /// readable by streaming readers up to its last complete episode.
    #[arg(long)]
    pub mcap: bool,
    /// --config: an `ExpertConfig` (as for `learner expert`) or, for lqr-gaifo, a
    /// `GaifoConfig` (as for `learner train`), plus an optional `[serve]` table; --seed must be
    /// the controller's `seed`; --out: episodes, tables, checkpoints, per-iteration CSV.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// `--algo`'s spelling of `algo`.
fn algo_name(algo: ServeAlgo) -> String {
    use clap::ValueEnum;
    algo.to_possible_value()
        .map_or_else(|| format!("{algo:?}"), |v| v.get_name().to_owned())
}

/// The end-of-run line (stderr) and, with `--json`, the summary (stdout).
fn finish<Log: Serialize>(summary: &ServeSummary<Log>, json: bool) -> anyhow::Result<()> {
    eprintln!(
        "learner serve: {:?} after {} iterations; table version {}; best noise-free cost {}; \
         {} samples, {} complete episodes ({} used), discarded {} partial and {} mixed",
        summary.exit_reason,
        summary.iterations,
        summary.table_version,
        summary
            .best_eval_cost
            .map_or("-".to_string(), |c| format!("{c:.4}")),
        summary.counts.samples,
        summary.counts.episodes,
        summary.counts.used,
        summary.counts.partial,
        summary.counts.mixed
    );
    if json {
        println!("{}", serde_json::to_string(summary)?);
    }
    Ok(())
}

/// Runs `learner serve`.
pub fn run_cli(args: ServeArgs) -> anyhow::Result<()> {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let (rest, mut opts) = match &args.common.config {
        Some(p) => read_config(p)?,
        None => (toml::Table::new(), ServeOptions::default()),
    };
    let path = args.common.config.clone().unwrap_or_default();
    if let Some(a) = args.algo {
        opts.algo = a;
    }
    if args.demos.is_some() {
        opts.demos = args.demos;
    }
    if let Some(p) = args.prefix {
        opts.prefix = p;
    }
    if let Some(o) = args.common.out {
        opts.out = o;
    }
    if args.resume.is_some() {
        opts.resume = args.resume;
    }
    opts.force |= args.force;
    opts.mcap |= args.mcap;
    match opts.algo {
        ServeAlgo::Expert => {
            anyhow::ensure!(
                opts.demos.is_none(),
                "--demos is for --algo lqr-gaifo and mdgps; the expert learns on the true task cost"
            );
            let mut cfg: ExpertConfig = settings(rest, &path, "expert")?;
            if let Some(s) = args.common.seed {
                cfg.seed = s;
            }
            if let Some(i) = args.iterations {
                cfg.iterations = i;
            }
            finish(&serve(cfg, opts, |_| {})?, args.common.json)
        }
        ServeAlgo::LqrGaifo => {
            let Some(demos_path) = opts.demos.clone() else {
                anyhow::bail!(
                    "--algo lqr-gaifo needs --demos FILE (or [serve] demos): the demonstrations \
                     to imitate, from `learner expert`"
                );
            };
            let mut cfg: GaifoConfig = settings(rest, &path, "LQR+GAIfO")?;
            if let Some(s) = args.common.seed {
                cfg.seed = s;
            }
            if let Some(i) = args.iterations {
                cfg.iterations = i;
            }
            let demos = crate::io::demos::load_checked(&demos_path, &cfg.sim)?;
            finish(&serve_gaifo(cfg, demos, opts, |_| {})?, args.common.json)
        }
        ServeAlgo::Bco | ServeAlgo::GaifoTd3 | ServeAlgo::ReplayMean => {
            let Some(demos_path) = opts.demos.clone() else {
                anyhow::bail!(
                    "--algo {} needs --demos FILE (or [serve] demos): the demonstrations to \
                     imitate, from `learner expert`",
                    algo_name(opts.algo)
                );
            };
            let (seed, iterations, json) = (args.common.seed, args.iterations, args.common.json);
            macro_rules! run {
                ($cfg:ty, $what:expr, $serve:ident) => {{
                    let mut cfg: $cfg = settings(rest, &path, $what)?;
                    if let Some(s) = seed {
                        cfg.seed = s;
                    }
                    if let Some(i) = iterations {
                        cfg.iterations = i;
                    }
                    let demos = crate::io::demos::load_checked(&demos_path, &cfg.sim)?;
                    finish(&$serve(cfg, demos, opts, |_| {})?, json)
                }};
            }
            match opts.algo {
                ServeAlgo::Bco => run!(imitation::bco::BcoConfig, "BCO", serve_bco),
                ServeAlgo::GaifoTd3 => {
                    run!(
                        imitation::offpolicy::GaifoTd3Config,
                        "GAIfO (TD3)",
                        serve_td3
                    )
                }
                _ => run!(
                    imitation::replay_mean::ReplayMeanConfig,
                    "mean path",
                    serve_replay_mean
                ),
            }
        }
        ServeAlgo::Mdgps => {
            let Some(folder) = opts.demos.clone() else {
                anyhow::bail!(
                    "--algo mdgps needs --demos DIR (or [serve] demos), a folder of .npz \
                     demonstrations, one file per goal"
                );
            };
            let mut cfg: imitation::mdgps::MdgpsConfig = settings(rest, &path, "MDGPS")?;
            if let Some(s) = args.common.seed {
                cfg.lqr_gaifo.seed = s;
            }
            if let Some(i) = args.iterations {
                cfg.lqr_gaifo.iterations = i;
            }
            let demos = crate::io::demos::load_goals(&folder, &cfg.lqr_gaifo.sim)?;
            finish(&serve_mdgps(cfg, demos, opts, |_| {})?, args.common.json)
        }
    }
}
