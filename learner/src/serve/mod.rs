//! `learner serve`: the learner end of the three processes (docs/design.md §3.6)
//!
//! ```text
//! hil-sim serve  <-->  rt-controller  -- learner/samples -->  learner serve
//!                                     <-- controller/gains --
//! ```
//!
//! Algorithm 1 with step 1 ("execute the controller") done by the real-time loop: the learner
//! publishes a gain table, assembles the episodes the controller runs with it from the
//! [`ur5_shared::StepSample`] stream, and when `samples` noisy episodes and one noise-free episode of that
//! table version are in, runs steps 2–6 and publishes the next version. One loop serves both
//! learners ([`ServeLearner`]):
//! - `--algo expert` (default): [`ExpertLearner::update`] on the true task cost (the same code
//!   as the in-process [`imitation::expert::train`]); the task is the config's `[task]`;
//! - `--algo lqr-gaifo --demos FILE`: [`LqrGaifo::learn`] (the same code as the in-process
//!   `learner train`); the task (goal, start pose, T, dt) is the
//!   demonstrations'.
//!
//! # Same episodes as in process
//! The controller draws the noise of the k-th episode of a table version from
//! `Noise::new(seed, version, k)`, episodes k = 0 … N−1 of a version with noise and k = N
//! without (`noisy_episodes = N`, `eval_episodes = 1`), exactly the order of
//! [`imitation::rollout::execute`]. With the same seed, task and arm (lockstep), the episodes over
//! IPC equal the in-process ones bit for bit, and so does everything learned from them. The
//! dynamics are fitted on the executed actions (`StepSample::a_sent`, after the clamp).
//!
//! # The task must be the controller's and the arm's
//! The learner checks what the sample stream shows and stops with an error naming the setting:
//! a step t ≥ T, or three episodes in a row that end after the same number of steps < T (the
//! controller's horizon differs); on the first complete episode (of any table version), a
//! first state whose joint angles (start pose) or end effector minus goal differ from the
//! task's by more than `serve.task_tolerance`; on the first complete noisy episode of its own
//! table version, motion per step that is not what the task's dt gives (ratio of
//! Σ Δq·q̄̇ / Σ q̄̇² — q̄̇ the mean joint velocity of the two ends of a step — to the same on an
//! in-process replay of that table with the episode-0 noise, outside [1/2, 2]; the band and
//! its measurement: docs/design.md §5 D21). The dt check is a heuristic: in
//! lockstep the samples carry no simulated time. In real time it also catches an arm that
//! cannot keep up with its clock (less simulated time per control period than dt).
//!
//! # Which episodes count
//! Only complete episodes (t = 0 … T−1 in order, one table version, one noise flag) of the
//! version the learner waits for; the first N noisy and the first noise-free one, in arrival
//! order. Partial (aborted, or samples lost), mixed-version episodes are discarded and counted;
//! complete episodes of other versions (the controller keeps running the old table while the
//! learner updates) and surplus ones are recorded but not used.
//!
//! # Files (`--out`)
//! - `episodes/NNNNNN_eEPISODE_vVERSION.npz`: every complete episode as it arrives
//!   ([`crate::io::episode`]);
//! - `tables/vVERSION.npz`: every table published ([`crate::io::table`]); `latest_table.npz`;
//! - the checkpoint of the controller to execute next, written before its table is published:
//!   expert: `checkpoint.npz` (all GPS policy arrays, its iteration, the random-policy cost,
//!   the best controller so far with its noise-free episode and the patience count);
//!   lqr-gaifo: `iter_NNN_table.npz`, `iter_NNN_critic.json` and `iter_NNN_state.npz`, as
//!   `learner train` writes them ([`crate::run::Checkpoint`]);
//! - the per-iteration CSV: expert: `serve_log.csv` ([`crate::io::log::EXPERT_CSV_HEADER`], appended
//!   across runs); lqr-gaifo: `gaifo_log.csv` ([`crate::io::log::CSV_HEADER`], as `learner train`;
//!   `t_execute_s` is the time from the version's first sample to its last needed episode;
//!   appended across resumes); `best_table.npz` at exit;
//! - with `--mcap`, `run.mcap`: the run's recorded episodes and tables as one MCAP file
//!   ([`crate::io::run_mcap::RunMcap`]), written episode by episode (one chunk each), its
//!   summary at exit; a killed learner leaves it readable by streaming readers up to its last
//!   complete episode; a resumed one writes it again from the folder's episodes, then goes on.
//!
//! # Peers that die
//! A dead or absent controller: the learner keeps waiting and says so every `wait_report_s`.
//! A restarted learner: `--resume DIR` continues from DIR's checkpoint (expert:
//! `checkpoint.npz`; lqr-gaifo: the latest complete `iter_NNN_*` checkpoint,
//! [`crate::run::resume`]) and publishes that table version again.
//!
//! # Exact resume
//! The resumed learner publishes its version with the next epoch (one more than the epoch
//! of `DIR/tables/vVERSION.npz`; [`ur5_shared::GainTable::epoch`]). A controller running
//! that version takes it again at its next boundary and restarts the version's episode count,
//! so the episodes k = 0 … N of the new publication draw the noise of the first publication's;
//! samples carry the epoch (`StepSample::table_epoch`) and episodes of an earlier publication
//! count as an older version. LQR+GAIfO's whole learner state (critic, GMM dynamics prior,
//! step size, previous controller, RNG positions) resumes exactly, so with an arm whose reset
//! is exact (`hil-sim serve` in lockstep) a served run killed anywhere and resumed learns what
//! the uninterrupted run learns, bit for bit (tests/tests/suite/resume_ipc.rs). Without `--resume` a
//! new learner starts at version 1, which a controller running a newer version rejects: the
//! learner then reports the newer version it sees in the samples and keeps waiting.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use imitation::controller::to_gain_table;
use imitation::demos::Demos;
use imitation::expert::{ExpertConfig, ExpertLearner, IterationLog};
use imitation::gaifo::{GaifoConfig, GaifoLog, LqrGaifo};
use serde::{Deserialize, Serialize};

use crate::io::learned::LearnedEvent;
use crate::io::table::save_table;
use gps::policy::lin_gauss::LinGaussPolicy;
use iceoryx2::port::update_connections::UpdateConnections;

pub mod assemble;
mod learner;
pub mod policy;
mod ports;
mod task_check;

pub use assemble::{episode_from_samples, Assembled, Assembler, Batch, Counts};
pub use learner::ServeLearner;
pub use task_check::motion_per_step;

use learner::Run;
use ports::Ports;
use task_check::{validate, TaskCheck};

/// Which learner `learner serve` runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ServeAlgo {
    /// The expert's iteration on the true task cost (the config is an `ExpertConfig`).
    #[default]
    Expert,
    /// LQR+GAIfO from state-only demonstrations (the config is a `GaifoConfig`; needs `demos`).
    LqrGaifo,
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
    /// (goal, start pose, T, dt) is the one the controller and the arm must run.
    pub demos: Option<PathBuf>,
    /// iceoryx2 service prefix; the controller and the arm must use the same.
    pub prefix: String,
    /// Output folder.
    pub out: PathBuf,
    /// Continue from the checkpoint in this folder of an earlier run (see the module docs).
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

/// Reads a config file: its `[serve]` table (optional) and the rest, unparsed.
pub(crate) fn read_config(path: &Path) -> anyhow::Result<(toml::Table, ServeOptions)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut value: toml::Table =
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let serve = match value.remove("serve") {
        Some(v) => v
            .try_into()
            .with_context(|| format!("[serve] in {}", path.display()))?,
        None => ServeOptions::default(),
    };
    Ok((value, serve))
}

/// The settings of a config file without its `[serve]` table, read as `learner expert` and
/// `learner train` read theirs (`ur5_shared::config::from_toml_str`).
pub(crate) fn settings<C: Serialize + serde::de::DeserializeOwned + Default>(
    rest: toml::Table,
    path: &Path,
    what: &str,
) -> anyhow::Result<C> {
    let text = toml::to_string(&rest)?;
    ur5_shared::config::from_toml_str(&text)
        .with_context(|| format!("{what} settings in {}", path.display()))
}

/// Reads a config file: an [`ExpertConfig`] at the top level plus an optional `[serve]` table.
pub fn load_config(path: &Path) -> anyhow::Result<(ExpertConfig, ServeOptions)> {
    let (rest, serve) = read_config(path)?;
    Ok((settings(rest, path, "expert")?, serve))
}

/// Reads a config file: a [`GaifoConfig`] at the top level plus an optional `[serve]` table.
pub fn load_gaifo_config(path: &Path) -> anyhow::Result<(GaifoConfig, ServeOptions)> {
    let (rest, serve) = read_config(path)?;
    Ok((settings(rest, path, "LQR+GAIfO")?, serve))
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
    /// `expert` or `lqr-gaifo`.
    pub algorithm: &'static str,
    /// Why it ended.
    pub exit_reason: ServeExit,
    /// Version this run started from (1, or the resumed checkpoint's).
    pub start_version: u64,
    /// Latest table version published.
    pub table_version: u64,
    /// Iterations (updates) run by this process.
    pub iterations: usize,
    /// Task cost of the noise-free episode of each iteration of this run.
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
) -> anyhow::Result<ServeSummary> {
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
pub fn expert_from_checkpoint(cfg: ExpertConfig, dir: &Path) -> anyhow::Result<ExpertLearner> {
    let path = dir.join("checkpoint.npz");
    let c = crate::io::checkpoint::load_checkpoint(&path)
        .with_context(|| format!("resuming from {}", path.display()))?;
    let best_t = c.best.as_ref().map(|(p, e)| (p.t, e.horizon()));
    anyhow::ensure!(
        c.pol.t == cfg.task.horizon
            && best_t.is_none_or(|(p, e)| p == cfg.task.horizon && e == cfg.task.horizon),
        "{} holds a controller of T = {} (best: {best_t:?}), the task has T = {}",
        path.display(),
        c.pol.t,
        cfg.task.horizon
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
) -> anyhow::Result<ServeSummary<GaifoLog>> {
    let task = demos.task()?;
    validate(&task, cfg.samples, cfg.init_var, &opts)
        .context("the demonstrations' task or the settings")?;
    cfg.validate()?;
    claim_dirs(&opts, "lqr-gaifo", cfg.seed, &cfg)?;
    let run = match &opts.resume {
        Some(dir) => crate::run::resume(cfg, demos, dir)?.0,
        None => LqrGaifo::new(cfg, demos)?,
    };
    serve_loop(run, opts, progress)
}

/// Takes the run directories ([`crate::io::manifest`]): `resume` must hold this run; `out`,
/// unless it is that folder, is taken for a new one.
fn claim_dirs<S: Serialize>(
    opts: &ServeOptions,
    algo: &str,
    seed: u64,
    settings: &S,
) -> anyhow::Result<()> {
    use crate::io::manifest::{claim, Claim, Manifest};
    let m = Manifest::new("serve", algo, seed, opts.demos.as_deref(), settings)?;
    if let Some(dir) = &opts.resume {
        claim(dir, &m, Claim::Resume)?;
        if *dir == opts.out {
            return crate::io::files::adopt(dir);
        }
    }
    claim(&opts.out, &m, Claim::New { force: opts.force })
}

/// The epoch a resumed learner publishes `version` with: one more than the epoch of the
/// copy recorded in `dir/tables/` (0 if there is none), so that the controller takes it again
/// and restarts the version's episode count (module docs, "Exact resume").
fn republication_epoch(dir: &Path, version: u64) -> anyhow::Result<u32> {
    let path = crate::io::table::version_path(dir, version);
    let recorded = if path.is_file() {
        crate::io::npz::NpzFile::open_schema(&path, crate::io::table::SCHEMA_VERSION)?
            .u32_scalar_or_zero("epoch")?
    } else {
        0
    };
    recorded
        .checked_add(1)
        .with_context(|| format!("{}: epoch {recorded} cannot be increased", path.display()))
}

/// `v` or `v (publication e)` for the log.
fn publication(version: u64, epoch: u32) -> String {
    if epoch == 0 {
        version.to_string()
    } else {
        format!("{version} (publication {epoch})")
    }
}

/// The one serve loop (module docs) around `learner`.
fn serve_loop<L: ServeLearner>(
    learner: L,
    opts: ServeOptions,
    mut progress: impl FnMut(&L::Log),
) -> anyhow::Result<ServeSummary<L::Log>> {
    anyhow::ensure!(
        !opts.mcap || opts.record_episodes,
        "mcap = true needs record_episodes = true: run.mcap is written from the recorded episodes"
    );
    let out = opts.out.clone();
    for d in [out.clone(), out.join("tables"), out.join("episodes")] {
        crate::io::create_dir(&d)?;
    }
    let csv = learner.open_csv(&out, opts.resume.is_some())?;
    let epoch = match &opts.resume {
        Some(dir) => republication_epoch(dir, learner.version())?,
        None => 0,
    };
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
            let mut m = crate::io::run_mcap::RunMcap::create(&out.join("run.mcap"))?;
            m.add_run(&out)?;
            Some(m)
        } else {
            None
        },
        opts,
    };

    // Setup: every port before anything runs.
    let ports = Ports::create(&run.opts.prefix)?;
    // Any error from here on is told to the controller before it is returned (§3.12).
    let result = serve_with_ports(&ports, run, &mut progress);
    if let Err(e) = &result {
        ports.status.stopping(e);
    }
    result
}

/// [`serve_loop`] once its ports exist.
fn serve_with_ports<L: ServeLearner>(
    ports: &Ports,
    mut run: Run<L>,
    progress: &mut impl FnMut(&L::Log),
) -> anyhow::Result<ServeSummary<L::Log>> {
    let out = run.opts.out.clone();
    let start_version = run.learner.version();
    let table = run.save_current()?;
    ports.publish(&table)?;
    if let Some(from) = &run.opts.resume {
        let same = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_owned());
        run.note(&LearnedEvent::Resumed {
            iteration: run.learner.iteration(),
            same_folder: same(from) == same(&out),
        })?;
    }
    let (n, t_len) = (run.learner.samples(), run.learner.task().horizon);
    eprintln!(
        "learner serve ({}): prefix `{}`, published gain table version {start_version}{}; waiting for {n} noisy + 1 noise-free episodes of T = {t_len} per version",
        L::ALGO,
        run.opts.prefix,
        if run.opts.resume.is_some() {
            format!(" (resumed; publication {} of it)", run.epoch)
        } else {
            String::new()
        },
    );
    eprintln!("{}", L::PROGRESS_HEADER);

    let mut asm = Assembler::new(t_len);
    let mut batch = Batch {
        noisy: Vec::with_capacity(n),
        eval: None,
    };
    // The seed is checked on the first version this learner publishes itself: the controller
    // may have run the start version (a resumed one, or one it already had) for longer, with
    // later episodes' noise.
    let mut check = TaskCheck::default();
    check.seed_from_version = start_version + 1;
    let mut counts = Counts::default();
    let mut log = Vec::new();
    let mut best: Option<(LinGaussPolicy, f64)> = None;
    let mut finishing = run.learner.done();
    let report = Duration::from_secs_f64(run.opts.wait_report_s);
    let idle = Duration::from_micros(run.opts.idle_sleep_us.max(1));
    let mut last_sample = Instant::now();
    let mut last_report = Instant::now();
    let mut version_started: Option<Instant> = None;
    let mut newer_reported = (0u64, 0u32);
    // The recorded files of the batch's episodes (`episodes/learned.jsonl`).
    let mut used_noisy: Vec<String> = Vec::with_capacity(n);
    let mut used_eval: Option<String> = None;

    let bar = crate::progress::Progress::new(
        run.learner
            .planned_iterations()
            .saturating_sub(run.learner.iteration()) as u64,
        "iterations",
    );
    let exit = 'outer: loop {
        let mut got = false;
        while let Some(sample) = ports
            .samples
            .receive()
            .map_err(|e| anyhow::anyhow!("receiving samples: {e:?}"))?
        {
            let s = *sample;
            drop(sample);
            got = true;
            counts.samples += 1;
            check.sample(&s, &run.learner)?;
            if (s.table_version, s.table_epoch) == (run.learner.version(), run.epoch)
                && version_started.is_none()
            {
                version_started = Some(Instant::now());
            }
            for a in asm.push(&s) {
                let (episode, version, epoch, ep) = match a {
                    Assembled::Complete {
                        episode,
                        version,
                        epoch,
                        ep,
                    } => (episode, version, epoch, ep),
                    Assembled::Partial { episode, have } => {
                        counts.partial += 1;
                        bar.println(&format!(
                            "learner serve: discarded episode {episode}: {have} of {t_len} steps"
                        ));
                        check.partial(have, &run.learner)?;
                        continue;
                    }
                    Assembled::Mixed { episode } => {
                        counts.mixed += 1;
                        bar.println(&format!("learner serve: discarded episode {episode}: table version or noise flag changed inside it"));
                        continue;
                    }
                };
                counts.episodes += 1;
                let file = run.record(&ep, episode, version, epoch)?;
                check.episode(&ep, version, &run.learner, run.opts.task_tolerance)?;
                let current = run.learner.version();
                // An earlier publication of the current version counts as an older version:
                // its episodes carry later noise keys than the ones this learner waits for.
                if (version, epoch) < (current, run.epoch) {
                    counts.old_version += 1;
                } else if (version, epoch) > (current, run.epoch) {
                    counts.newer_version += 1;
                    if (version, epoch) != newer_reported {
                        newer_reported = (version, epoch);
                        bar.println(&format!(
                            "learner serve: the controller runs table version {}, newer than this learner's {}: \
                             another learner published it; restart this one with --resume <its out dir> to continue from there",
                            publication(version, epoch),
                            publication(current, run.epoch)
                        ));
                    }
                } else if finishing {
                    // The controller took the last table: nothing more to learn.
                    break 'outer ServeExit::Done;
                } else {
                    let noisy = ep.noisy;
                    if batch.offer(ep, n) {
                        counts.used += 1;
                        match (noisy, file) {
                            (true, Some(f)) => used_noisy.push(f),
                            (false, f) => used_eval = f,
                            (true, None) => {}
                        }
                    } else {
                        counts.surplus += 1;
                    }
                }
            }
            if batch.full(n) {
                let eval = batch.eval.take().expect("full batch");
                let cost = eval.task_cost();
                if best.as_ref().is_none_or(|(_, c)| cost < *c) {
                    best = Some((run.learner.policy().clone(), cost));
                }
                let waited = version_started
                    .take()
                    .map_or(0.0, |t0| t0.elapsed().as_secs_f64());
                // Before the update's checkpoint: the last line of a version counts.
                if let Some(eval) = used_eval.take() {
                    run.note(&LearnedEvent::Learned {
                        iteration: run.learner.iteration() + 1,
                        version: run.learner.version(),
                        noisy: std::mem::take(&mut used_noisy),
                        eval,
                    })?;
                }
                let entry = run.learner.learn(&batch.noisy, &eval, waited)?;
                batch.noisy.clear();
                // The row before the checkpoint, as `learner train` writes them: a kill between
                // the two leaves a row that a resume from the previous checkpoint drops and
                // writes again, never a checkpoint without its row.
                let row = run.learner.csv_row(&entry)?;
                run.csv.write_all(row.as_bytes())?;
                run.epoch = 0;
                let table = run.save_current()?;
                ports.publish(&table)?;
                bar.done_one(&L::progress_line(&entry));
                progress(&entry);
                log.push(entry);
                finishing = run.learner.done();
                if finishing {
                    bar.println(&format!(
                        "learner serve: learning done ({} iterations); published the last table, version {}; \
                         exiting once the controller runs it",
                        run.learner.iteration(),
                        run.learner.version()
                    ));
                }
            }
        }
        if got {
            last_sample = Instant::now();
            continue;
        }
        // Idle: deliver the table (history) to a controller that connected late, and stop
        // with the controller's message if it stopped (§3.12).
        let _ = ports.gains.update_connections();
        ports.status.check_controller()?;
        if last_sample.elapsed() >= report && last_report.elapsed() >= report {
            last_report = Instant::now();
            bar.println(&format!(
                "learner serve: waiting for episodes of table version {} on prefix `{}`: no sample for {:.0} s \
                 (is rt-controller running with --prefix {}?)",
                run.learner.version(),
                run.opts.prefix,
                last_sample.elapsed().as_secs_f64(),
                run.opts.prefix
            ));
        }
        if ports.node.wait(idle).is_err() {
            break ServeExit::Stopped;
        }
    };

    drop(bar);
    if let Some((pol, _)) = &best {
        save_table(
            &out.join("best_table.npz"),
            &to_gain_table(pol, run.learner.version()),
            run.learner.task().dt,
        )?;
    }
    if let Some(m) = run.mcap.take() {
        let c = m.finish()?;
        eprintln!(
            "learner serve: {} episodes and {} tables -> {}",
            c.episodes,
            c.tables,
            out.join("run.mcap").display()
        );
    }
    Ok(ServeSummary {
        command: "serve",
        algorithm: L::ALGO,
        exit_reason: exit,
        start_version,
        table_version: run.learner.version(),
        iterations: log.len(),
        eval_costs: log.iter().map(L::eval_cost).collect(),
        best_eval_cost: best.map(|(_, c)| c),
        log,
        counts,
        out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arm::SimArm;
    use crate::io::checkpoint::{load_checkpoint, save_checkpoint, ExpertCheckpoint};
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
            s: [t as f64; DX],
            a: [1.0; DU],
            a_sent: [0.5; DU],
            ..StepSample::default()
        }
    }

    #[test]
    fn assembler_keeps_complete_episodes_and_discards_the_rest() {
        let mut a = Assembler::new(3);
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
            let mut table = table.clone();
            run_episode(&mut sim, task, &mut table, Some(&mut Noise::new(0, 1, k))).unwrap()
        };
        let check = |ep: &Episode| TaskCheck::default().episode(ep, 1, &el, 0.01);
        // The same task (another episode of the version than the replayed k = 0 included).
        check(&episode(&cfg.task, 0)).unwrap();
        check(&episode(&cfg.task, 3)).unwrap();
        let mut physical = SimConfig::default();
        physical.perturbation = ur5_shared::config::Perturbation::physical_stand_in(1);
        let mut sim = SimArm::new(physical, cfg.task.dt).unwrap();
        let ep = run_episode(
            &mut sim,
            &cfg.task,
            &mut table.clone(),
            Some(&mut Noise::new(0, 1, 2)),
        )
        .unwrap();
        check(&ep).unwrap();
        // A controller with another seed.
        let mut sim = SimArm::new(SimConfig::default(), cfg.task.dt).unwrap();
        let other_seed = run_episode(
            &mut sim,
            &cfg.task,
            &mut table.clone(),
            Some(&mut Noise::new(7, 1, 0)),
        )
        .unwrap();
        let e = format!("{:#}", check(&other_seed).unwrap_err());
        assert!(
            e.contains("learner's seed 0") && e.contains("seed = 0"),
            "{e}"
        );
        let err = |task: TaskConfig| format!("{:#}", check(&episode(&task, 0)).unwrap_err());
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
            .episode(&other_goal, 5, &el, 0.01)
            .is_err());
        let half_dt = episode(
            &TaskConfig {
                dt: 0.05,
                ..cfg.task.clone()
            },
            0,
        );
        TaskCheck::default()
            .episode(&half_dt, 5, &el, 0.01)
            .unwrap();
        let e = err(TaskConfig {
            start_q: [0.05, -2.0, 2.4],
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
        assert!(format!("{:#}", c.sample(&s, &el).unwrap_err()).contains("horizon = 30"));
        c.sample(&sample(4, 29, 1, 1), &el).unwrap();
        c.partial(20, &el).unwrap();
        c.partial(20, &el).unwrap();
        let e = format!("{:#}", c.partial(20, &el).unwrap_err());
        assert!(
            e.contains("end after 20 steps") && e.contains("horizon = 30"),
            "{e}"
        );
        let mut c = TaskCheck::default();
        for have in [20, 20, 7, 20, 20] {
            c.partial(have, &el).unwrap();
        }
    }
}
