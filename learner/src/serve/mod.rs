//! `learner serve`: the learner end of the three processes (docs/design.md §3.6)
//!
//! ```text
//! hil-sim serve  <-->  rt-controller  -- learner/samples -->  learner serve
//!                                     <-- controller/gains --
//! ```
//!
//! Algorithm 1 with step 1 ("execute the controller") done by the real-time loop, for the
//! learners ([`ServeLearner`]: `--algo expert`, [`ExpertLearner`]; `--algo lqr-gaifo`,
//! [`LqrGaifo`]; `--algo mdgps`, [`Mdgps`], a gain table per goal and the policy's evaluation
//! at each goal per version, docs/design.md §6.5; the baselines `--algo bco`, `gaifo-td3`
//! (a policy table per version) and `replay-mean` (a gain table), [`baselines`]). The protocol (same episodes as in process, the task checks, which episodes
//! count, the files, peers that die, exact resume): docs/design.md §3.6; the loop:
//! `session.rs`.

use std::path::{Path, PathBuf};

use imitation::demos::Demos;
use imitation::expert::{ExpertConfig, ExpertLearner, IterationLog};
use imitation::gaifo::{GaifoConfig, GaifoLog, LqrGaifo};
use imitation::learn::Learn;
use imitation::mdgps::{Mdgps, MdgpsConfig, MdgpsLog};
use serde::{Deserialize, Serialize};

use ur5_shared::GainTable;

pub mod assemble;
// Before `baselines`: its learners take `learner`'s `gaifo_log_files!`.
#[macro_use]
mod learner;
mod baselines;
pub mod policy;
mod ports;
mod session;
mod task_check;

pub use assemble::{episode_from_samples, Assembled, Assembler, Batch, Counts};
pub use baselines::{serve_bco, serve_replay_mean, serve_td3};
pub use learner::{Publication, ServeLearner};
pub use task_check::motion_per_step;

use crate::error::ensure;
use crate::io::IoError;
use learner::Run;
use ports::{AnyTable, Ports};
use task_check::validate;

/// Which learner `learner serve` runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ServeAlgo {
    /// The expert's iteration on the true task cost (the config is an `ExpertConfig`).
    #[default]
    Expert,
    /// LQR+GAIfO from state-only demonstrations (the config is a `GaifoConfig`; needs `demos`).
    LqrGaifo,
    /// MDGPS on several goals (the config is an `MdgpsConfig`; needs `demos`, a folder with one
    /// `.npz` per goal).
    Mdgps,
    /// BCO(α) from state-only demonstrations (the config is a `BcoConfig`; needs `demos`).
    Bco,
    /// GAIfO with TD3 (the config is a `GaifoTd3Config`; needs `demos`).
    GaifoTd3,
    /// The demonstrations' mean joint path, no learning (the config is a `ReplayMeanConfig`;
    /// needs `demos`).
    ReplayMean,
}

/// Options of `learner serve` (the `[serve]` table of the config file; the rest of the file is
/// an [`ExpertConfig`], as for `learner expert`, or with `algo = "lqr-gaifo"` a
/// [`GaifoConfig`], as for `learner train`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServeOptions {
    /// Which learner.
    pub algo: ServeAlgo,
    /// Demonstrations (`.npz` from `learner expert`) for `algo = "lqr-gaifo"`; their task
    /// (goal, start pose, T, dt) is the one the controller and the arm must run. For
    /// `algo = "mdgps"` a folder of them, one per goal (in name order).
    pub demos: Option<PathBuf>,
    /// iceoryx2 service prefix; the controller and the arm must use the same.
    pub prefix: String,
    /// Output folder.
    pub out: PathBuf,
    /// Continue from the checkpoint in this folder of an earlier run (docs/design.md §3.6).
    pub resume: Option<PathBuf>,
    /// Start a new run in `out` even though another run's files are there: they are deleted
    /// first (without it such a folder is refused; [`crate::io::manifest`]).
    pub force: bool,
    /// Record every complete episode to `out/episodes/`.
    pub record_episodes: bool,
    /// Write the recorded episodes and the tables into `out/run.mcap` as they come
    /// ([`crate::io::run_mcap::RunMcap`]; needs `record_episodes`).
    pub mcap: bool,
    /// While no sample arrives, say so every this many seconds (wall clock).
    pub wait_report_s: f64,
    /// Sleep between polls when idle (µs).
    pub idle_sleep_us: u64,
    /// Largest difference (rad, m) allowed between the first state of the controller's
    /// episodes and the task's: joint angles (start pose) and end effector minus goal. Ours:
    /// 0.01, ten times the perturbed arm's sensor noise (1e-3).
    pub task_tolerance: f64,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            algo: ServeAlgo::Expert,
            demos: None,
            prefix: String::new(),
            out: PathBuf::from("runs/serve"),
            resume: None,
            force: false,
            record_episodes: true,
            mcap: false,
            wait_report_s: 5.0,
            idle_sleep_us: 500,
            task_tolerance: 0.01,
        }
    }
}

/// What stopped `learner serve` or `learner policy serve`, or why it could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A controller of another task (other dimensions) on the sample stream.
    #[error("learner/samples")]
    Peer(#[source] ur5_shared::layout::DimensionMismatch),
    /// A config file that does not parse as TOML.
    #[error("parsing {}", path.display())]
    Toml {
        /// The config file.
        path: PathBuf,
        /// What the parser said.
        source: toml::de::Error,
    },
    /// A `[serve]` table with unknown keys or wrong types.
    #[error("[serve] in {}", path.display())]
    ServeTable {
        /// The config file.
        path: PathBuf,
        /// What the parser said.
        source: toml::de::Error,
    },
    /// A config file's learner settings that are not valid.
    #[error("{what} settings in {}", path.display())]
    Settings {
        /// "expert", "LQR+GAIfO".
        what: &'static str,
        /// The config file.
        path: PathBuf,
        /// What is wrong.
        source: ur5_shared::config::ConfigError,
    },
    /// Settings that cannot be written back as TOML (a bug).
    #[error("writing the settings as TOML")]
    ToToml(#[from] toml::ser::Error),
    /// An expert checkpoint that cannot be read.
    #[error("resuming from {}", path.display())]
    Checkpoint {
        /// `checkpoint.npz`.
        path: PathBuf,
        /// Why.
        source: crate::io::npz::NpzError,
    },
    /// An expert checkpoint of another horizon than the task's.
    #[error(
        "{} holds a controller of T = {t} (best: {best:?}), the task has T = {horizon}",
        path.display()
    )]
    CheckpointHorizon {
        /// `checkpoint.npz`.
        path: PathBuf,
        /// Its controller's T.
        t: usize,
        /// Its best controller's and best episode's T.
        best: Option<(usize, usize)>,
        /// The task's T.
        horizon: usize,
    },
    /// The task of the demonstrations, or settings, that serving cannot run.
    #[error("the demonstrations' task or the settings")]
    DemosTask(#[source] Box<ServeError>),
    /// A resumed version published too often to be published again.
    #[error("{}: epoch {recorded} cannot be increased", path.display())]
    Epoch {
        /// The recorded table.
        path: PathBuf,
        /// Its epoch.
        recorded: u32,
    },
    /// `mcap` without `record_episodes`.
    #[error(
        "mcap = true needs record_episodes = true: run.mcap is written from the recorded episodes"
    )]
    McapWithoutEpisodes,
    /// A setting out of its range; the message names it and the range.
    #[error("{0}")]
    Range(String),
    /// The controller or the arm runs another task than the learner (docs/design.md §3.6):
    /// the message says which part differs and what to run.
    #[error("{0}")]
    TaskMismatch(String),
    /// The learner's model of the arm cannot be built.
    #[error("the learner's model of the arm")]
    Model(#[source] hil_sim::SimError),
    /// The learner's model of the arm cannot be put at the task's start.
    #[error("the learner's model of the arm")]
    ModelReset(#[source] imitation::ImitationError),
    /// The first episode replayed on the learner's model of the arm.
    #[error("replaying the first episode in process")]
    FirstEpisode(#[source] imitation::ImitationError),
    /// An iceoryx2 operation that failed; the message names it, with iceoryx2's error.
    #[error("{0}")]
    Ipc(String),
    /// The controller said it stopped (docs/design.md §3.12).
    #[error("the controller stopped: {0}")]
    ControllerStopped(String),
    /// No sample came for the time allowed.
    #[error(
        "no sample on prefix `{prefix}` for {timeout_s} s: is `rt-controller run --prefix \
         {prefix}` running (with hil-sim serve or a robot)?"
    )]
    NoSamples {
        /// The prefix.
        prefix: String,
        /// The time allowed (s).
        timeout_s: f64,
    },
    /// A service that cannot be opened or created.
    #[error(transparent)]
    Service(#[from] ur5_shared::services::OpenServiceError),
    /// A service name iceoryx2 refuses.
    #[error(transparent)]
    ServiceName(#[from] ur5_shared::services::InvalidServiceName),
    /// Another learner holds the prefix.
    #[error(transparent)]
    Role(#[from] ur5_shared::services::RoleLockError),
    /// The task.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    /// A CSV row that cannot be formatted (a bug).
    #[error("formatting a CSV row")]
    Row(#[source] std::io::Error),
    /// The run's files.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The learner's checkpoints and resume.
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    /// A learner piece (an update, the settings, the demonstrations' task).
    #[error(transparent)]
    Imitation(#[from] imitation::ImitationError),
}

impl From<crate::io::npz::NpzError> for ServeError {
    fn from(e: crate::io::npz::NpzError) -> Self {
        Self::Io(e.into())
    }
}

/// Reads a config file: its `[serve]` table (optional) and the rest, unparsed.
pub(crate) fn read_config(path: &Path) -> Result<(toml::Table, ServeOptions), ServeError> {
    let text = std::fs::read_to_string(path).map_err(IoError::file("reading", path))?;
    let mut value: toml::Table = toml::from_str(&text).map_err(|source| ServeError::Toml {
        path: path.to_owned(),
        source,
    })?;
    let serve = match value.remove("serve") {
        Some(v) => v.try_into().map_err(|source| ServeError::ServeTable {
            path: path.to_owned(),
            source,
        })?,
        None => ServeOptions::default(),
    };
    Ok((value, serve))
}

/// The settings of a config file without its `[serve]` table, read as `learner expert` and
/// `learner train` read theirs (`ur5_shared::config::from_toml_str`).
pub(crate) fn settings<C: Serialize + serde::de::DeserializeOwned + Default>(
    rest: toml::Table,
    path: &Path,
    what: &'static str,
) -> Result<C, ServeError> {
    let text = toml::to_string(&rest)?;
    ur5_shared::config::from_toml_str(&text).map_err(|source| ServeError::Settings {
        what,
        path: path.to_owned(),
        source,
    })
}

/// Reads a config file: an [`ExpertConfig`] at the top level plus an optional `[serve]` table.
pub fn load_config(path: &Path) -> Result<(ExpertConfig, ServeOptions), ServeError> {
    let (rest, serve) = read_config(path)?;
    Ok((settings(rest, path, "expert")?, serve))
}

/// Reads a config file: a [`GaifoConfig`] at the top level plus an optional `[serve]` table.
pub fn load_gaifo_config(path: &Path) -> Result<(GaifoConfig, ServeOptions), ServeError> {
    let (rest, serve) = read_config(path)?;
    Ok((settings(rest, path, "LQR+GAIfO")?, serve))
}

/// Reads a config file: an [`MdgpsConfig`] at the top level plus an optional `[serve]` table.
pub fn load_mdgps_config(path: &Path) -> Result<(MdgpsConfig, ServeOptions), ServeError> {
    let (rest, serve) = read_config(path)?;
    Ok((settings(rest, path, "MDGPS")?, serve))
}

/// Why [`serve`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ServeExit {
    /// `iterations` reached (or `patience` ran out) and the controller took the last table.
    Done,
    /// SIGINT / SIGTERM.
    Stopped,
}

/// What a serve run did (`--json`).
#[derive(Clone, Debug, Serialize)]
pub struct ServeSummary<Log = IterationLog> {
    /// Always "serve".
    pub command: &'static str,
    /// `expert`, `lqr-gaifo` or `mdgps`.
    pub algorithm: &'static str,
    /// Why it ended.
    pub exit_reason: ServeExit,
    /// Version this run started from (1, or the resumed checkpoint's).
    pub start_version: u64,
    /// Latest table version published.
    pub table_version: u64,
    /// Iterations (updates) run by this process.
    pub iterations: usize,
    /// Task cost of the noise-free episode of each iteration of this run (MDGPS: the mean
    /// over its goals' evaluations).
    pub eval_costs: Vec<f64>,
    /// Lowest of them.
    pub best_eval_cost: Option<f64>,
    /// Per-iteration logs of this run.
    pub log: Vec<Log>,
    /// What arrived.
    pub counts: Counts,
    /// Output folder.
    pub out: PathBuf,
}

/// Runs the expert's learner end until the learning is done or SIGINT/SIGTERM. `progress`
/// receives each iteration's log (`seconds`: from the first sample of the version to the end
/// of its update).
pub fn serve(
    cfg: ExpertConfig,
    opts: ServeOptions,
    progress: impl FnMut(&IterationLog),
) -> Result<ServeSummary, ServeError> {
    validate(&cfg.task, cfg.samples, cfg.init_var, &opts)?;
    cfg.validate()?;
    claim_dirs(&opts, "expert", cfg.seed, &cfg)?;
    let el = match &opts.resume {
        Some(dir) => expert_from_checkpoint(cfg, dir)?,
        None => ExpertLearner::new(cfg, None),
    };
    serve_loop(el, opts, progress)
}

/// The expert learner `learner serve --resume DIR` continues with: DIR's `checkpoint.npz`
/// (controller, iteration, random-policy cost, best controller and patience count) through
/// [`ExpertLearner::resume`] and [`ExpertLearner::with_best`] (also what
/// `learner replay` does where a served expert run was resumed).
pub fn expert_from_checkpoint(cfg: ExpertConfig, dir: &Path) -> Result<ExpertLearner, ServeError> {
    let path = dir.join("checkpoint.npz");
    let c = match crate::io::checkpoint::load_checkpoint(&path) {
        Ok(c) => c,
        Err(source) => return Err(ServeError::Checkpoint { path, source }),
    };
    let best_t = c.best.as_ref().map(|(p, e)| (p.t, e.horizon()));
    ensure!(
        c.pol.t == cfg.task.horizon
            && best_t.is_none_or(|(p, e)| p == cfg.task.horizon && e == cfg.task.horizon),
        ServeError::CheckpointHorizon {
            path,
            t: c.pol.t,
            best: best_t,
            horizon: cfg.task.horizon
        }
    );
    Ok(
        ExpertLearner::resume(cfg, c.pol, c.iteration, c.cost_random)
            .with_best(c.best, c.since_best),
    )
}

/// Runs the LQR+GAIfO learner end on `demos` (their task) until `cfg.iterations` are done or
/// SIGINT/SIGTERM. `progress` receives each iteration's log (`t_execute`: from the first sample
/// of the version to its last needed episode).
pub fn serve_gaifo(
    cfg: GaifoConfig,
    demos: Demos,
    opts: ServeOptions,
    progress: impl FnMut(&GaifoLog),
) -> Result<ServeSummary<GaifoLog>, ServeError> {
    let task = demos.task()?;
    validate(&task, cfg.samples, cfg.init_var, &opts)
        .map_err(|e| ServeError::DemosTask(Box::new(e)))?;
    cfg.validate()?;
    claim_dirs(&opts, "lqr-gaifo", cfg.seed, &cfg)?;
    let run = match &opts.resume {
        Some(dir) => crate::run::resume(cfg, demos, dir)?.0,
        None => LqrGaifo::new(cfg, demos)?,
    };
    serve_loop(run, opts, progress)
}

/// Runs MDGPS's learner end on `demos` (one set per goal) until its iterations are done or
/// SIGINT/SIGTERM: per version, goal after goal, the goal's gain table for its N noisy
/// episodes and the policy table at the goal for its evaluation (docs/design.md §6.5), then
/// [`Mdgps`]'s learning step on the version's episodes; the checkpoints and `mdgps_log.csv` of
/// `learner train --algo mdgps`. `progress` receives each iteration's log.
pub fn serve_mdgps(
    cfg: MdgpsConfig,
    demos: Vec<imitation::demos::Demos>,
    opts: ServeOptions,
    progress: impl FnMut(&MdgpsLog),
) -> Result<ServeSummary<MdgpsLog>, ServeError> {
    cfg.validate()?;
    let run = match &opts.resume {
        Some(dir) => crate::run::resume_mdgps(cfg.clone(), demos, dir)?.0,
        None => Mdgps::new(cfg.clone(), demos)?,
    };
    for task in run.goal_tasks() {
        validate(task, run.samples(), cfg.lqr_gaifo.init_var, &opts)
            .map_err(|e| ServeError::DemosTask(Box::new(e)))?;
    }
    claim_dirs(&opts, "mdgps", run.seed(), &cfg)?;
    serve_loop(run, opts, progress)
}

/// Takes the run directories ([`crate::io::manifest`]): `resume` must hold this run; `out`,
/// unless it is that folder, is taken for a new one.
fn claim_dirs<S: Serialize>(
    opts: &ServeOptions,
    algo: &str,
    seed: u64,
    settings: &S,
) -> Result<(), ServeError> {
    use crate::io::manifest::{claim, Claim, Manifest};
    let m = Manifest::new("serve", algo, seed, opts.demos.as_deref(), settings)?;
    if let Some(dir) = &opts.resume {
        claim(dir, &m, Claim::Resume)?;
        if *dir == opts.out {
            return Ok(crate::io::files::adopt(dir)?);
        }
    }
    Ok(claim(&opts.out, &m, Claim::New { force: opts.force })?)
}

/// The epoch a resumed learner publishes `version` with: the epoch of the copy recorded in
/// `dir/tables/` (the first publication of the version's last run, 0 if there is none) plus
/// the `publications` per version, so that every publication is above all earlier ones and
/// the controller takes it again and restarts its episode count (docs/design.md §3.6, "Exact
/// resume").
fn republication_epoch(dir: &Path, version: u64, publications: u32) -> Result<u32, ServeError> {
    let path = crate::io::table::version_path(dir, version);
    let recorded = if path.is_file() {
        crate::io::table::stored_epoch(&path)?
    } else {
        0
    };
    recorded
        .checked_add(publications)
        .ok_or(ServeError::Epoch { path, recorded })
}

/// The one serve loop (docs/design.md §3.6) around `learner`.
fn serve_loop<L: ServeLearner>(
    learner: L,
    opts: ServeOptions,
    mut progress: impl FnMut(&L::Log),
) -> Result<ServeSummary<L::Log>, ServeError> {
    ensure!(
        !opts.mcap || opts.record_episodes,
        ServeError::McapWithoutEpisodes
    );
    let out = opts.out.clone();
    for d in [out.clone(), out.join("tables"), out.join("episodes")] {
        crate::io::create_dir(&d)?;
    }
    let csv = learner.open_csv(&out, opts.resume.is_some())?;
    let publications = learner.publications(0)?;
    let policy_tables = publications
        .iter()
        .any(|p| matches!(p.table, AnyTable::Policy(_)));
    let epoch = match &opts.resume {
        Some(dir) => {
            let per_version = u32::try_from(publications.len())
                .map_err(|_| ServeError::Range("too many publications per version".into()))?;
            republication_epoch(dir, learner.version(), per_version)?
        }
        None => 0,
    };
    let layout = learner.task().layout();
    let run = Run {
        learner,
        csv,
        epoch,
        recorder: if opts.record_episodes {
            Some(crate::io::episode::EpisodeRecorder::new(
                &out.join("episodes"),
            )?)
        } else {
            None
        },
        // The run so far (a resumed run's earlier episodes), then episode by episode.
        mcap: if opts.mcap {
            let mut m = crate::io::run_mcap::RunMcap::create(&out.join("run.mcap"), layout)?;
            m.add_run(&out)?;
            Some(m)
        } else {
            None
        },
        opts,
    };

    // Setup: every port before anything runs.
    let mut ports = Ports::<GainTable>::create(&run.opts.prefix)?;
    if policy_tables {
        ports = ports.with_policy_tables()?;
    }
    // Any error from here on is told to the controller before it is returned (§3.12).
    let result = session::serve_with_ports(&ports, run, &mut progress);
    if let Err(e) = &result {
        ports.status.stopping(e);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::task_check::{Reference, TaskCheck};
    use super::*;
    use crate::arm::SimArm;
    use crate::io::checkpoint::{load_checkpoint, save_checkpoint, ExpertCheckpoint};
    use imitation::controller::to_gain_table;
    use imitation::rollout::{run_episode, Episode};
    use ur5_shared::config::{SimConfig, TaskConfig};
    use ur5_shared::layout::{DU, DX};
    use ur5_shared::noise::Noise;
    use ur5_shared::StepSample;

    fn sample(episode: u64, t: u32, version: u64, noise: u32) -> StepSample {
        StepSample {
            table_version: version,
            episode,
            t,
            noise,
            ..StepSample::default()
        }
        .with_parts(&[t as f64; DX], &[1.0; DU], &[0.5; DU])
    }

    #[test]
    fn assembler_keeps_complete_episodes_and_discards_the_rest() {
        let mut a = Assembler::new(3, ur5_shared::StateLayout::REACH3);
        let mut got = Vec::new();
        // Starts mid-episode (a learner that joins late): partial.
        for s in [sample(0, 1, 1, 1), sample(0, 2, 1, 1)] {
            got.extend(a.push(&s));
        }
        // Complete.
        for t in 0..3 {
            got.extend(a.push(&sample(1, t, 1, 1)));
        }
        // Aborted after t = 1, then a complete noise-free one.
        for s in [sample(2, 0, 1, 1), sample(2, 1, 1, 1)] {
            got.extend(a.push(&s));
        }
        for t in 0..3 {
            got.extend(a.push(&sample(3, t, 2, 0)));
        }
        // Version changes inside; a sample lost inside.
        for s in [sample(4, 0, 2, 1), sample(4, 1, 3, 1), sample(4, 2, 3, 1)] {
            got.extend(a.push(&s));
        }
        for s in [sample(5, 0, 3, 1), sample(5, 2, 3, 1)] {
            got.extend(a.push(&s));
        }
        let kinds: Vec<String> = got
            .iter()
            .map(|g| match g {
                Assembled::Complete {
                    episode, version, ..
                } => format!("C{episode}v{version}"),
                Assembled::Partial { episode, have } => format!("P{episode}:{have}"),
                Assembled::Mixed { episode } => format!("M{episode}"),
                Assembled::WrongDimensions { episode, .. } => format!("W{episode}"),
            })
            .collect();
        assert_eq!(kinds, ["P0:2", "C1v1", "P2:2", "C3v2", "M4", "P5:2"]);
        let Assembled::Complete { ep, .. } = &got[3] else {
            panic!()
        };
        assert!(!ep.noisy);
        assert_eq!(ep.horizon(), 3);
        assert_eq!(ep.state(2), [2.0; DX]);
        assert_eq!(ep.u, vec![0.5; 3 * DU]);
        assert_eq!(ep.u_policy, vec![1.0; 3 * DU]);
    }

    #[test]
    fn checkpoint_round_trip_and_config_file() {
        let dir = std::env::temp_dir().join(format!("serve-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let task = ur5_shared::config::TaskConfig {
            horizon: 5,
            ..Default::default()
        };
        let mut pol = imitation::controller::init_hold(&task, 0.05);
        pol.gain.data[7] = 0.25;
        let path = dir.join("checkpoint.npz");
        let mut c = ExpertCheckpoint {
            pol: pol.clone(),
            iteration: 4,
            cost_random: Some(2.5),
            best: None,
            since_best: 0,
        };
        save_checkpoint(&path, &c, 3).unwrap();
        assert_eq!(load_checkpoint(&path).unwrap(), c);
        // With the best controller so far: restored with its episode and patience count.
        let mut best = pol.clone();
        best.k.data[2] = -0.5;
        let ep = imitation::rollout::Episode {
            layout: ur5_shared::StateLayout::REACH3,
            x: (0..5 * DX).map(|i| i as f64 * 0.01).collect(),
            u: vec![0.5; 5 * DU],
            u_policy: vec![0.25; 5 * DU],
            eps: Vec::new(),
            noisy: false,
        };
        c.best = Some((best, ep));
        c.since_best = 2;
        save_checkpoint(&path, &c, 3).unwrap();
        assert_eq!(load_checkpoint(&path).unwrap(), c);

        let cfg = dir.join("serve.toml");
        std::fs::write(
            &cfg,
            "samples = 3\nseed = 9\n[task]\nhorizon = 30\n[serve]\nprefix = \"x\"\nwait_report_s = 1.5\n",
        )
        .unwrap();
        let (c, o) = load_config(&cfg).unwrap();
        assert_eq!((c.samples, c.seed, c.task.horizon), (3, 9, 30));
        assert_eq!((o.prefix.as_str(), o.wait_report_s), ("x", 1.5));
        std::fs::write(&cfg, "[serve]\nprefixx = \"x\"\n").unwrap();
        assert!(load_config(&cfg).is_err(), "unknown keys are errors");

        // LQR+GAIfO: a GaifoConfig plus [serve], which may name the algorithm and the demos.
        std::fs::write(
            &cfg,
            "samples = 4\nseed = 5\niterations = 3\ncritic_updates = 2\n[sim]\nsubsteps = 2\n\
             [serve]\nalgo = \"lqr-gaifo\"\ndemos = \"d.npz\"\ntask_tolerance = 0.02\n",
        )
        .unwrap();
        let (g, o) = load_gaifo_config(&cfg).unwrap();
        assert_eq!((g.samples, g.seed, g.iterations), (4, 5, 3));
        assert_eq!((g.critic_updates, g.sim.substeps), (2, 2));
        assert_eq!(o.algo, ServeAlgo::LqrGaifo);
        assert_eq!(o.demos.as_deref(), Some(Path::new("d.npz")));
        assert_eq!(o.task_tolerance, 0.02);
        assert!(
            load_config(&cfg).is_err(),
            "a GaifoConfig is not an ExpertConfig"
        );
        std::fs::write(&cfg, "[task]\nhorizon = 30\n").unwrap();
        assert!(
            load_gaifo_config(&cfg).is_err(),
            "the task of LQR+GAIfO is the demonstrations'"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The task checks: an episode of the learner's own task passes; a different goal, start
    /// pose, control period or horizon is an error that names the setting.
    #[test]
    fn task_check_names_what_differs() {
        let cfg = ExpertConfig {
            task: TaskConfig {
                horizon: 30,
                ..TaskConfig::default()
            },
            ..ExpertConfig::default()
        };
        let el = ExpertLearner::new(cfg.clone(), None);
        let table = to_gain_table(el.policy(), 1);
        let table = &*table;
        let episode = |task: &TaskConfig, k: u64| {
            let mut sim = SimArm::new(SimConfig::default(), task.dt).unwrap();
            let mut table = table.boxed_clone();
            run_episode(&mut sim, task, &mut *table, Some(&mut Noise::new(0, 1, k))).unwrap()
        };
        let publications = el.publications(0).unwrap();
        let r = Reference::of(&el, &publications[0], 1);
        let check = |ep: &Episode| TaskCheck::default().episode(ep, (1, 0), &r, 0.01);
        // The same task (another episode of the version than the replayed k = 0 included).
        check(&episode(&cfg.task, 0)).unwrap();
        check(&episode(&cfg.task, 3)).unwrap();
        let mut physical = SimConfig::default();
        physical.perturbation = ur5_shared::config::Perturbation::physical_stand_in(1);
        let mut sim = SimArm::new(physical, cfg.task.dt).unwrap();
        let ep = run_episode(
            &mut sim,
            &cfg.task,
            &mut *table.boxed_clone(),
            Some(&mut Noise::new(0, 1, 2)),
        )
        .unwrap();
        check(&ep).unwrap();
        // A controller with another seed.
        let mut sim = SimArm::new(SimConfig::default(), cfg.task.dt).unwrap();
        let other_seed = run_episode(
            &mut sim,
            &cfg.task,
            &mut *table.boxed_clone(),
            Some(&mut Noise::new(7, 1, 0)),
        )
        .unwrap();
        let e = crate::error::line(&check(&other_seed).unwrap_err());
        assert!(
            e.contains("learner's seed 0") && e.contains("seed = 0"),
            "{e}"
        );
        let err = |task: TaskConfig| crate::error::line(&check(&episode(&task, 0)).unwrap_err());
        let e = err(TaskConfig {
            goal: [-0.45, -0.2, 0.25],
            ..cfg.task.clone()
        });
        assert!(e.contains("start_q and goal"), "{e}");
        // The start is checked on any version's episode (a controller running another
        // learner's table), the dt only on this learner's own (it replays its table).
        let other_goal = episode(
            &TaskConfig {
                goal: [-0.45, -0.2, 0.25],
                ..cfg.task.clone()
            },
            0,
        );
        assert!(TaskCheck::default()
            .episode(&other_goal, (5, 0), &r, 0.01)
            .is_err());
        let half_dt = episode(
            &TaskConfig {
                dt: 0.05,
                ..cfg.task.clone()
            },
            0,
        );
        TaskCheck::default()
            .episode(&half_dt, (5, 0), &r, 0.01)
            .unwrap();
        let e = err(TaskConfig {
            start_q: [0.05, -2.0, 2.4].into(),
            ..cfg.task.clone()
        });
        assert!(e.contains("start_q and goal"), "{e}");
        for dt in [0.05, 0.2] {
            let e = err(TaskConfig {
                dt,
                ..cfg.task.clone()
            });
            assert!(e.contains("[task] dt"), "dt {dt}: {e}");
        }
        // Horizon: a step beyond T, or episodes that keep ending early.
        let mut c = TaskCheck::default();
        let s = sample(4, 30, 1, 1);
        assert!(crate::error::line(&c.sample(&s, &el).unwrap_err()).contains("horizon = 30"));
        c.sample(&sample(4, 29, 1, 1), &el).unwrap();
        c.partial(20, &el).unwrap();
        c.partial(20, &el).unwrap();
        let e = crate::error::line(&c.partial(20, &el).unwrap_err());
        assert!(
            e.contains("end after 20 steps") && e.contains("horizon = 30"),
            "{e}"
        );
        let mut c = TaskCheck::default();
        for have in [20, 20, 7, 20, 20] {
            c.partial(have, &el).unwrap();
        }
    }

    /// MDGPS's publications of a version: per goal its gain table (the goal's controller, plan
    /// and noise) for N noisy episodes, then the policy table at the goal for the evaluation,
    /// at consecutive epochs; a resume publishes above every one of them.
    #[test]
    fn mdgps_publishes_each_goal_s_tables_and_a_resume_publishes_above_them() {
        let goals = imitation::expert::square_goals(TaskConfig::default().goal, 0.1);
        let demos = [goals[0], goals[4]].map(|goal| {
            let mut cfg = ExpertConfig::default();
            (cfg.task.horizon, cfg.task.goal, cfg.demos) = (8, goal, 2);
            let hold = imitation::controller::init_hold(&cfg.task, 0.01);
            let arm = SimArm::new(cfg.sim.clone(), cfg.task.dt).unwrap();
            let mut d = imitation::expert::record_demos(&cfg, &arm, &hold, 0.0).unwrap();
            d.cost_random = d.cost_expert + 1.0;
            d
        });
        let mut cfg = MdgpsConfig::default();
        cfg.policy.hidden = vec![4];
        let run = Mdgps::new(cfg, demos.to_vec()).unwrap();
        let publications = run.publications(7).unwrap();
        assert_eq!(publications.len(), 4);
        for (i, p) in publications.iter().enumerate() {
            let m = i / 2;
            assert_eq!(p.table.publication(), (1, 7 + i as u32));
            assert_eq!((p.goal, p.noise_seed), (m, run.noise_seed(m)));
            match &p.table {
                AnyTable::Gain(t) => {
                    assert_eq!((i % 2, p.noisy, p.eval), (0, run.samples(), false));
                    assert_eq!(t.checksum, run.gain_table(m, 0).checksum);
                    assert_eq!(t.plan, run.plan(m));
                }
                AnyTable::Policy(t) => {
                    assert_eq!((i % 2, p.noisy, p.eval), (1, 0, true));
                    assert_eq!(t.plan, run.plan(m).noise_free());
                }
            }
        }
        // The recorded first publication's epoch e: a resume publishes from e + 4 on.
        let dir = std::env::temp_dir().join(format!("serve-epoch-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("tables")).unwrap();
        assert_eq!(republication_epoch(&dir, 1, 4).unwrap(), 4);
        let AnyTable::Gain(first) = &publications[0].table else {
            panic!()
        };
        let path = crate::io::table::version_path(&dir, 1);
        crate::io::table::save_table(&path, first, 0.1).unwrap();
        assert_eq!(republication_epoch(&dir, 1, 4).unwrap(), 11);
        assert_eq!(republication_epoch(&dir, 1, 1).unwrap(), 8);
        let mut last = first.boxed_clone();
        last.epoch = u32::MAX - 2;
        crate::io::table::save_table(&path, &last, 0.1).unwrap();
        assert!(matches!(
            republication_epoch(&dir, 1, 4),
            Err(ServeError::Epoch { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A learner whose policy is an MLP (BCO) publishes one policy table per version: the
    /// policy's law, the default plan (the controller's own N noisy and one noise-free
    /// episodes), its seed's noise; the task checks hold its noisy episodes to that table
    /// (another seed's noise is refused); the version is recorded as a policy table with its
    /// epoch, above which a resume publishes; the mean path publishes a gain table with K = 0.
    #[test]
    fn a_policy_learner_publishes_and_records_policy_tables() {
        use imitation::bco::{Bco, BcoConfig};
        use imitation::rollout::Actors;
        let mut ecfg = ExpertConfig::default();
        (ecfg.task.horizon, ecfg.demos) = (8, 2);
        let hold = imitation::controller::init_hold(&ecfg.task, 0.01);
        let arm = SimArm::new(ecfg.sim.clone(), ecfg.task.dt).unwrap();
        let mut demos = imitation::expert::record_demos(&ecfg, &arm, &hold, 0.0).unwrap();
        demos.cost_random = demos.cost_expert + 1.0;
        let mut cfg = BcoConfig {
            samples: 3,
            seed: 4,
            ..BcoConfig::default()
        };
        cfg.policy.hidden = vec![4];
        let bco = Bco::new(cfg, demos.clone()).unwrap();
        let publications = bco.publications(5).unwrap();
        assert_eq!(publications.len(), 1);
        let p = &publications[0];
        assert_eq!((p.goal, p.noisy, p.eval, p.noise_seed), (0, 3, true, 4));
        let AnyTable::Policy(table) = &p.table else {
            panic!("{:?}", p.table)
        };
        assert_eq!((table.version, table.epoch), (1, 5));
        assert!(table.plan.is_default());
        assert_eq!(table.checksum, table.compute_checksum());
        // The table's law is the policy's, noise included.
        let s = demos.reach3_state(0, 3);
        let eps = [0.3, -1.0, 0.5];
        let (mut a, mut b) = ([0.0; DU], [0.0; DU]);
        let mode = bco.config().sim.mode;
        bco.policy().actor().act(0, &s, &eps, mode, &mut a);
        let mut scratch = ur5_shared::PolicyScratch::default();
        ur5_shared::policy_action(table, &s, &eps, &mut scratch, &mut b).unwrap();
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        // The task checks: its seed's noisy episode passes, another seed's does not.
        let task = bco.task().clone();
        let episode = |seed: u64, k: u64| {
            let mut sim = SimArm::new(SimConfig::default(), task.dt).unwrap();
            let mut actor = bco.policy().actor();
            run_episode(
                &mut sim,
                &task,
                &mut *actor,
                Some(&mut Noise::new(seed, 1, k)),
            )
            .unwrap()
        };
        let r = Reference::of(&bco, p, 1);
        TaskCheck::default()
            .episode(&episode(4, 2), (1, 5), &r, 0.01)
            .unwrap();
        let e = TaskCheck::default()
            .episode(&episode(7, 0), (1, 5), &r, 0.01)
            .unwrap_err();
        assert!(crate::error::line(&e).contains("seed 4"), "{e}");
        // Saved as the version's record: the policy table with its epoch; a resume above it.
        let dir = std::env::temp_dir().join(format!("serve-policy-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("tables")).unwrap();
        let theta = table.theta().to_vec();
        let mut run = Run {
            learner: bco,
            opts: ServeOptions {
                out: dir.clone(),
                ..ServeOptions::default()
            },
            csv: std::fs::File::create(dir.join("log.csv")).unwrap(),
            recorder: None,
            epoch: 2,
            mcap: None,
        };
        let saved = run.save_current().unwrap();
        assert_eq!(saved[0].table.publication(), (1, 2));
        for f in [
            crate::io::table::version_path(&dir, 1),
            dir.join("latest_table.npz"),
        ] {
            assert_eq!(crate::io::table::stored_epoch(&f).unwrap(), 2);
            let npz = crate::io::npz::NpzFile::open(&f).unwrap();
            assert_eq!(npz.f64("params").unwrap().1, theta);
        }
        assert!(dir.join("iter_000_policy.npz").is_file());
        assert_eq!(republication_epoch(&dir, 1, 1).unwrap(), 3);
        std::fs::remove_dir_all(&dir).ok();
        // The mean path: a gain table with K = 0.
        let mean = imitation::replay_mean::ReplayMean::new(Default::default(), demos).unwrap();
        let publications = mean.publications(0).unwrap();
        let t = publications[0].gain_table().unwrap();
        assert_eq!(publications[0].noisy, 5);
        assert!((0..8).all(|i| t.step(i).k_mat.iter().all(|&k| k == 0.0)));
        assert!((0..8).any(|i| t.step(i).k_vec.iter().any(|&k| k != 0.0)));
    }
}
