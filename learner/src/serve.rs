//! `learner serve`: the learner end of the three processes (DESIGN.md §3)
//!
//! ```text
//! hil-sim serve  <-->  rt-controller  -- learner/samples -->  learner serve
//!                                     <-- controller/gains --
//! ```
//!
//! Algorithm 1 with line 1 ("execute the controller") done by the real-time loop: the learner
//! publishes a gain table, assembles the episodes the controller runs with it from the
//! [`StepSample`] stream, and when `samples` noisy episodes and one noise-free episode of that
//! table version are in, runs lines 2–6 and publishes the next version. One loop serves both
//! learners ([`ServeLearner`]):
//! - `--algo expert` (default): [`ExpertLearner::update`] on the true task cost (the same code
//!   as the in-process [`crate::expert::train`]); the task is the config's `[task]`;
//! - `--algo lqr-gaifo --demos FILE`: [`LqrGaifo::learn`] (the same code as the in-process
//!   [`LqrGaifo::iterate`], `learner train`); the task (goal, start pose, T, dt) is the
//!   demonstrations'.
//!
//! # Same episodes as in process
//! The controller draws the noise of the k-th episode of a table version from
//! `Noise::new(seed, version, k)`, episodes k = 0 … N−1 of a version with noise and k = N
//! without (`noisy_episodes = N`, `eval_episodes = 1`), exactly the order of
//! [`crate::iteration::execute`]. With the same seed, task and arm (lockstep), the episodes over
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
//! in-process replay of that table with the episode-0 noise, outside [1/2, 2]; measured on
//! the initial controller, T = 30: 0.89–1.0 for the same dt on the nominal and on the perturbed
//! "physical" arm, 0.38 at half and 2.8–3.9 at twice the dt). The dt check is a heuristic: in
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
//!   expert: `checkpoint.npz` (all GPS policy arrays, its iteration, the random-policy cost);
//!   lqr-gaifo: `iter_NNN_table.npz` + `iter_NNN_critic.json`, as `learner train` writes them
//!   ([`LqrGaifo::checkpoint`]);
//! - the per-iteration CSV: expert: `serve_log.csv` ([`IterationLog::CSV_HEADER`], appended
//!   across runs); lqr-gaifo: `gaifo_log.csv` ([`crate::gaifo::CSV_HEADER`], as `learner train`;
//!   `t_execute_s` is the time from the version's first sample to its last needed episode;
//!   appended across resumes); `best_table.npz` at exit.
//!
//! # Peers that die
//! A dead or absent controller: the learner keeps waiting and says so every `wait_report_s`.
//! A restarted learner: `--resume DIR` continues from DIR's checkpoint (expert:
//! `checkpoint.npz`; lqr-gaifo: the latest `iter_NNN_*` pair, [`LqrGaifo::resume`]: also a
//! `learner train` folder) and publishes that table version again (the controller already runs
//! it and ignores the duplicate), then waits for N + 1 fresh episodes of it. The GPS learner
//! state (GMM dynamics prior, step size, previous controller) is not checkpointed and starts
//! afresh; LQR+GAIfO's critic resumes exactly. Without `--resume` a new learner starts at
//! version 1, which a controller running a newer version rejects: the learner then reports the
//! newer version it sees in the samples and keeps waiting.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use hil_sim::Ur5Sim;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::layout::{DU, DX, MAX_HORIZON};
use ur5_shared::noise::Noise;
use ur5_shared::services::{self, Qos, ServiceNames};
use ur5_shared::{GainTable, StepSample};

use crate::expert::{to_gain_table, ExpertConfig, ExpertLearner, IterationLog};
use crate::gaifo::{open_log, write_csv_row, GaifoConfig, GaifoLog, LqrGaifo};
use crate::io::demos::Demos;
use crate::io::episode::{save_episode, EpisodeOrigin};
use crate::io::npz::{NpzFile, NpzWriter};
use crate::io::table::save_table;
use crate::linalg::MatSeq;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::rollout::{run_episode, Episode};

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
    /// Record every complete episode to `out/episodes/`.
    pub record_episodes: bool,
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
            record_episodes: true,
            wait_report_s: 5.0,
            idle_sleep_us: 500,
            task_tolerance: 0.01,
        }
    }
}

/// Reads a config file: its `[serve]` table (optional) and the rest, unparsed.
fn read_config(path: &Path) -> anyhow::Result<(toml::Table, ServeOptions)> {
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
fn settings<C: Serialize + serde::de::DeserializeOwned + Default>(
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

/// Counts of what arrived.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Samples received.
    pub samples: u64,
    /// Complete episodes received (any version).
    pub episodes: u64,
    /// Episodes used by an update.
    pub used: u64,
    /// Discarded: incomplete (aborted by the controller, or samples lost).
    pub partial: u64,
    /// Discarded: the table version or the noise flag changed inside the episode.
    pub mixed: u64,
    /// Complete episodes of an older table version (run while the learner was updating).
    pub old_version: u64,
    /// Complete episodes of a newer table version than this learner's (another learner).
    pub newer_version: u64,
    /// Complete episodes of the current version beyond the N + 1 an update needs.
    pub surplus: u64,
}

/// Builds an [`Episode`] from the samples of one complete episode (t = 0 … T−1):
/// `x` = s, `u` = a_sent (executed), `u_policy` = a; ε is not sent and stays empty.
pub fn episode_from_samples(samples: &[StepSample]) -> Episode {
    let mut ep = Episode {
        x: Vec::with_capacity(samples.len() * DX),
        u: Vec::with_capacity(samples.len() * DU),
        u_policy: Vec::with_capacity(samples.len() * DU),
        eps: Vec::new(),
        noisy: samples.first().is_some_and(StepSample::is_noisy),
    };
    for s in samples {
        ep.x.extend_from_slice(&s.s);
        ep.u.extend_from_slice(&s.a_sent);
        ep.u_policy.extend_from_slice(&s.a);
    }
    ep
}

/// What the [`Assembler`] made of an episode once it ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Assembled {
    /// All T steps in order, one version, one noise flag.
    Complete {
        /// Controller episode number.
        episode: u64,
        /// Table version.
        version: u64,
        /// The episode.
        ep: Episode,
    },
    /// Ended (or was cut) before t = T−1, or missed samples.
    Partial {
        /// Controller episode number.
        episode: u64,
        /// Samples it had.
        have: usize,
    },
    /// The version or noise flag changed inside the episode.
    Mixed {
        /// Controller episode number.
        episode: u64,
    },
}

/// Groups the sample stream into episodes.
pub struct Assembler {
    horizon: usize,
    cur: Vec<StepSample>,
    gap: bool,
    mixed: bool,
}

impl Assembler {
    /// For episodes of `horizon` steps.
    pub fn new(horizon: usize) -> Self {
        Self {
            horizon,
            cur: Vec::with_capacity(horizon),
            gap: false,
            mixed: false,
        }
    }

    fn close(&mut self) -> Option<Assembled> {
        let first = *self.cur.first()?;
        let out = if self.mixed {
            Assembled::Mixed {
                episode: first.episode,
            }
        } else if self.gap || self.cur.len() != self.horizon {
            Assembled::Partial {
                episode: first.episode,
                have: self.cur.len(),
            }
        } else {
            Assembled::Complete {
                episode: first.episode,
                version: first.table_version,
                ep: episode_from_samples(&self.cur),
            }
        };
        self.cur.clear();
        self.gap = false;
        self.mixed = false;
        Some(out)
    }

    /// Takes one sample; returns the episodes it ended (at most two: an unfinished one cut
    /// off by this sample, and this sample's own if it is the last step).
    pub fn push(&mut self, s: &StepSample) -> Vec<Assembled> {
        let mut out = Vec::new();
        if let Some(last) = self.cur.last() {
            if s.episode != last.episode {
                out.extend(self.close());
            } else {
                self.gap |= s.t != last.t + 1;
                self.mixed |= s.table_version != last.table_version || s.noise != last.noise;
            }
        }
        if self.cur.is_empty() {
            self.gap = s.t != 0;
        }
        self.cur.push(*s);
        if s.t as usize + 1 >= self.horizon {
            out.extend(self.close());
        }
        out
    }
}

/// The episodes of one table version an update waits for.
struct Batch {
    noisy: Vec<Episode>,
    eval: Option<Episode>,
}

impl Batch {
    fn full(&self, n: usize) -> bool {
        self.noisy.len() >= n && self.eval.is_some()
    }

    /// Takes `ep` if the batch still needs one of its kind.
    fn offer(&mut self, ep: Episode, n: usize) -> bool {
        if ep.noisy && self.noisy.len() < n {
            self.noisy.push(ep);
        } else if !ep.noisy && self.eval.is_none() {
            self.eval = Some(ep);
        } else {
            return false;
        }
        true
    }
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

/// Writes the controller to execute next and where it stands (see the module docs).
pub fn save_checkpoint(
    path: &Path,
    pol: &LinGaussPolicy,
    iteration: usize,
    cost_random: Option<f64>,
    seed: u64,
) -> anyhow::Result<()> {
    let (t, dx, du) = (pol.t as u64, pol.dx as u64, pol.du as u64);
    let mut w = NpzWriter::create(path)?;
    w.i64("schema_version", &[], &[1])?;
    w.f64("K", &[t, du, dx], &pol.gain.data)?;
    w.f64("k", &[t, du], &pol.k.data)?;
    w.f64("pol_covar", &[t, du, du], &pol.pol_covar.data)?;
    w.f64("chol_pol_covar", &[t, du, du], &pol.chol_pol_covar.data)?;
    w.f64("inv_pol_covar", &[t, du, du], &pol.inv_pol_covar.data)?;
    w.u64("iteration", &[], &[iteration as u64])?;
    w.u64("table_version", &[], &[iteration as u64 + 1])?;
    w.f64("cost_random", &[], &[cost_random.unwrap_or(f64::NAN)])?;
    w.u64("seed", &[], &[seed])?;
    w.finish()?;
    Ok(())
}

/// Reads a checkpoint: (controller, iteration, random-policy cost).
pub fn load_checkpoint(path: &Path) -> anyhow::Result<(LinGaussPolicy, usize, Option<f64>)> {
    let f = NpzFile::open(path)?;
    let (shape, gain) = f.f64("K")?;
    let [t, du, dx] = shape[..] else {
        anyhow::bail!(
            "{}: K has shape {shape:?}, expected (T, dU, dX)",
            path.display()
        );
    };
    anyhow::ensure!(
        (du, dx) == (DU as u64, DX as u64),
        "{}: K has shape {shape:?}, expected (T, {DU}, {DX})",
        path.display()
    );
    let (tn, dun) = (t as usize, du as usize);
    let seq = |name: &str, cols: u64| -> anyhow::Result<MatSeq> {
        let data = f.f64_shaped(name, &[t, du, cols])?;
        Ok(MatSeq::from_vec(tn, dun, cols as usize, data))
    };
    let pol = LinGaussPolicy {
        t: tn,
        dx: DX,
        du: DU,
        gain: MatSeq::from_vec(tn, dun, DX, gain),
        k: MatSeq::from_vec(tn, dun, 1, f.f64_shaped("k", &[t, du])?),
        pol_covar: seq("pol_covar", du)?,
        chol_pol_covar: seq("chol_pol_covar", du)?,
        inv_pol_covar: seq("inv_pol_covar", du)?,
    };
    let all = [&pol.gain, &pol.k, &pol.pol_covar, &pol.chol_pol_covar];
    anyhow::ensure!(
        all.iter().all(|m| m.data.iter().all(|v| v.is_finite())),
        "{}: non-finite controller values",
        path.display()
    );
    let iteration = f.u64_scalar("iteration")? as usize;
    let cost_random = f.f64_shaped("cost_random", &[])?[0];
    Ok((
        pol,
        iteration,
        cost_random.is_finite().then_some(cost_random),
    ))
}

/// The learner's iceoryx2 node and its two ports. Fields drop in order: ports before the node.
struct Ports {
    samples: Subscriber<ipc::Service, StepSample, ()>,
    gains: Publisher<ipc::Service, GainTable, ()>,
    node: Node<ipc::Service>,
}

fn open_service<T: core::fmt::Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    name: &str,
    qos: &Qos,
) -> anyhow::Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
> {
    let sname = ServiceNames::service_name(name)?;
    let mut last = String::new();
    // Another process may be creating the service at this moment: retry briefly.
    for attempt in 0..50 {
        match qos.open_or_create::<T>(node, &sname) {
            Ok(f) => return Ok(f),
            Err(e) => last = format!("{e:?}"),
        }
        std::thread::sleep(Duration::from_millis(2 + attempt));
    }
    anyhow::bail!(
        "cannot open or create service `{name}`: {last}; a service of that name may exist with \
         another payload type or smaller limits (a stale run or another build: use a fresh --prefix)"
    )
}

impl Ports {
    /// Setup: removes what dead processes left behind (e.g. this learner's killed
    /// predecessor), then opens both services with the project's QoS and creates the ports.
    fn create(prefix: &str) -> anyhow::Result<Self> {
        let _ = Node::<ipc::Service>::try_cleanup_dead_nodes(Config::global_config());
        let names = ServiceNames::new(prefix);
        let node = NodeBuilder::new().create::<ipc::Service>().map_err(|e| {
            anyhow::anyhow!("cannot create the iceoryx2 node: {e:?}; is /dev/shm writable?")
        })?;
        let samples_svc = open_service::<StepSample>(
            &node,
            &names.learner_samples,
            &services::LEARNER_SAMPLES_QOS,
        )?;
        let gains_svc = open_service::<GainTable>(
            &node,
            &names.controller_gains,
            &services::CONTROLLER_GAINS_QOS,
        )?;
        let samples = samples_svc
            .subscriber_builder()
            .buffer_size(services::LEARNER_SAMPLES_QOS.subscriber_buffer)
            .create()
            .map_err(|e| {
                anyhow::anyhow!("cannot subscribe to `{}`: {e:?}", names.learner_samples)
            })?;
        let gains = gains_svc.publisher_builder().create().map_err(|e| {
            anyhow::anyhow!("cannot publish on `{}`: {e:?}", names.controller_gains)
        })?;
        Ok(Self {
            samples,
            gains,
            node,
        })
    }

    fn publish(&self, table: &GainTable) -> anyhow::Result<()> {
        let mut slot = self
            .gains
            .loan_uninit()
            .map_err(|e| anyhow::anyhow!("loaning a gain-table sample: {e:?}"))?;
        table.copy_to_uninit(slot.payload_mut());
        // SAFETY: copy_to_uninit initialised the whole payload.
        unsafe { slot.assume_init() }
            .send()
            .map_err(|e| anyhow::anyhow!("publishing a gain table: {e:?}"))?;
        Ok(())
    }
}

/// The learning side of `learner serve`: lines 2–6 of Algorithm 1 on the episodes of one table
/// version, and what the loop needs around them (task, files, progress). Implemented by the
/// expert ([`ExpertLearner`]) and LQR+GAIfO ([`LqrGaifo`]).
pub trait ServeLearner {
    /// The per-iteration log.
    type Log: Serialize;
    /// Name in messages and the summary.
    const ALGO: &'static str;
    /// Where the task comes from (for messages).
    const TASK_SOURCE: &'static str;
    /// Header of [`ServeLearner::progress_line`].
    const PROGRESS_HEADER: &'static str;
    /// The task the controller and the arm must run.
    fn task(&self) -> &TaskConfig;
    /// The learner's model of the arm (the task check replays an episode on it).
    fn sim_config(&self) -> &SimConfig;
    /// Noisy episodes per iteration N.
    fn samples(&self) -> usize;
    /// Run seed (the controller's noise seed).
    fn seed(&self) -> u64;
    /// Iterations done (counting those before a resume).
    fn iteration(&self) -> usize;
    /// The controller to execute next.
    fn policy(&self) -> &LinGaussPolicy;
    /// Nothing more to learn.
    fn done(&self) -> bool;
    /// Gain-table version of [`ServeLearner::policy`].
    fn version(&self) -> u64 {
        self.iteration() as u64 + 1
    }
    /// Lines 2–6 on the `noisy` episodes and the noise-free `eval` of
    /// [`ServeLearner::policy`], whose version's first sample arrived at `started`.
    fn update(
        &mut self,
        noisy: &[Episode],
        eval: &Episode,
        started: Option<Instant>,
    ) -> anyhow::Result<Self::Log>;
    /// Writes what `--resume` needs into `out`.
    fn checkpoint(&self, out: &Path) -> anyhow::Result<()>;
    /// Opens the per-iteration CSV in `out` for appending (`resumed`: a resumed run).
    fn open_csv(&self, out: &Path, resumed: bool) -> anyhow::Result<std::fs::File>;
    /// One CSV row, newline included.
    fn csv_row(&self, log: &Self::Log) -> anyhow::Result<String>;
    /// The progress line of an iteration.
    fn progress_line(log: &Self::Log) -> String;
    /// Task cost of the iteration's noise-free episode.
    fn eval_cost(log: &Self::Log) -> f64;
}

impl ServeLearner for ExpertLearner {
    type Log = IterationLog;
    const ALGO: &'static str = "expert";
    const TASK_SOURCE: &'static str = "this learner's config ([task])";
    const PROGRESS_HEADER: &'static str = IterationLog::PROGRESS_HEADER;
    fn task(&self) -> &TaskConfig {
        &self.config().task
    }
    fn sim_config(&self) -> &SimConfig {
        &self.config().sim
    }
    fn samples(&self) -> usize {
        self.config().samples
    }
    fn seed(&self) -> u64 {
        self.config().seed
    }
    fn iteration(&self) -> usize {
        ExpertLearner::iteration(self)
    }
    fn policy(&self) -> &LinGaussPolicy {
        ExpertLearner::policy(self)
    }
    fn done(&self) -> bool {
        ExpertLearner::done(self)
    }
    fn update(
        &mut self,
        noisy: &[Episode],
        eval: &Episode,
        started: Option<Instant>,
    ) -> anyhow::Result<IterationLog> {
        let (mut entry, _) = ExpertLearner::update(self, noisy, eval)?;
        if let Some(t0) = started {
            entry.seconds = t0.elapsed().as_secs_f64();
        }
        Ok(entry)
    }
    fn checkpoint(&self, out: &Path) -> anyhow::Result<()> {
        save_checkpoint(
            &out.join("checkpoint.npz"),
            self.policy(),
            self.iteration(),
            self.cost_random(),
            self.config().seed,
        )
    }
    fn open_csv(&self, out: &Path, _resumed: bool) -> anyhow::Result<std::fs::File> {
        let path = out.join("serve_log.csv");
        let new_csv = !path.exists();
        let mut csv = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        if new_csv {
            writeln!(csv, "{}", IterationLog::CSV_HEADER)?;
        }
        Ok(csv)
    }
    fn csv_row(&self, log: &IterationLog) -> anyhow::Result<String> {
        Ok(format!("{}\n", log.csv_row()))
    }
    fn progress_line(log: &IterationLog) -> String {
        log.progress_line()
    }
    fn eval_cost(log: &IterationLog) -> f64 {
        log.eval_cost
    }
}

impl ServeLearner for LqrGaifo {
    type Log = GaifoLog;
    const ALGO: &'static str = "lqr-gaifo";
    const TASK_SOURCE: &'static str = "the demonstrations";
    const PROGRESS_HEADER: &'static str = GaifoLog::PROGRESS_HEADER;
    fn task(&self) -> &TaskConfig {
        LqrGaifo::task(self)
    }
    fn sim_config(&self) -> &SimConfig {
        &self.config().sim
    }
    fn samples(&self) -> usize {
        self.config().samples
    }
    fn seed(&self) -> u64 {
        self.config().seed
    }
    fn iteration(&self) -> usize {
        LqrGaifo::iteration(self)
    }
    fn policy(&self) -> &LinGaussPolicy {
        LqrGaifo::policy(self)
    }
    fn done(&self) -> bool {
        LqrGaifo::done(self)
    }
    fn update(
        &mut self,
        noisy: &[Episode],
        eval: &Episode,
        started: Option<Instant>,
    ) -> anyhow::Result<GaifoLog> {
        let waited = started.map_or(0.0, |t0| t0.elapsed().as_secs_f64());
        Ok(self.learn(noisy, eval, waited)?)
    }
    fn checkpoint(&self, out: &Path) -> anyhow::Result<()> {
        LqrGaifo::checkpoint(self, out).map(|_| ())
    }
    fn open_csv(&self, out: &Path, resumed: bool) -> anyhow::Result<std::fs::File> {
        open_log(
            &out.join("gaifo_log.csv"),
            resumed.then_some(self.iteration()),
        )
    }
    fn csv_row(&self, log: &GaifoLog) -> anyhow::Result<String> {
        let mut row = Vec::new();
        write_csv_row(&mut row, log, self.config().seed, Self::ALGO)?;
        Ok(String::from_utf8(row)?)
    }
    fn progress_line(log: &GaifoLog) -> String {
        log.progress_line()
    }
    fn eval_cost(log: &GaifoLog) -> f64 {
        log.task_cost
    }
}

/// The learner's side of the run: files and the table in force.
struct Run<L> {
    learner: L,
    opts: ServeOptions,
    csv: std::fs::File,
    arrivals: u64,
}

impl<L: ServeLearner> Run<L> {
    /// Saves the checkpoint and the table of the controller to execute next; returns the table.
    fn save_current(&self) -> anyhow::Result<Box<GainTable>> {
        let out = &self.opts.out;
        let version = self.learner.version();
        let table = to_gain_table(self.learner.policy(), version);
        self.learner.checkpoint(out)?;
        let dt = self.learner.task().dt;
        save_table(
            &out.join("tables").join(format!("v{version:04}.npz")),
            &table,
            dt,
        )?;
        save_table(&out.join("latest_table.npz"), &table, dt)?;
        Ok(table)
    }

    fn record(&mut self, ep: &Episode, episode: u64, version: u64) -> anyhow::Result<()> {
        self.arrivals += 1;
        if !self.opts.record_episodes {
            return Ok(());
        }
        let name = format!("{:06}_e{episode:06}_v{version:04}.npz", self.arrivals);
        let origin = EpisodeOrigin {
            table_version: version,
            episode,
            seed: self.learner.seed(),
        };
        save_episode(
            &self.opts.out.join("episodes").join(name),
            ep,
            &origin,
            self.learner.task(),
        )?;
        Ok(())
    }
}

/// Checks what `serve` needs of the configuration.
fn validate(
    task: &TaskConfig,
    samples: usize,
    init_var: f64,
    opts: &ServeOptions,
) -> anyhow::Result<()> {
    task.validate()?;
    anyhow::ensure!(
        task.horizon <= MAX_HORIZON,
        "task.horizon = {} exceeds the gain table's MAX_HORIZON = {MAX_HORIZON}",
        task.horizon
    );
    anyhow::ensure!(
        samples >= 2,
        "samples = {samples} noisy episodes per iteration: the dynamics fit needs at least 2"
    );
    anyhow::ensure!(
        init_var > 0.0 && init_var.is_finite(),
        "init_var must be finite and > 0 (rad²)"
    );
    anyhow::ensure!(
        opts.wait_report_s.is_finite() && opts.wait_report_s > 0.0,
        "serve.wait_report_s = {} must be > 0 (s)",
        opts.wait_report_s
    );
    anyhow::ensure!(
        opts.task_tolerance.is_finite() && opts.task_tolerance > 0.0,
        "serve.task_tolerance = {} must be > 0",
        opts.task_tolerance
    );
    ServiceNames::new(&opts.prefix).learner_samples()?;
    Ok(())
}

/// Σ Δq·q̄̇ / Σ q̄̇² over the steps of `ep` (q̄̇ the mean joint velocity of a step's two ends):
/// about the control period for slow motion, larger for a fast servo; `None` without motion.
pub fn motion_per_step(ep: &Episode) -> Option<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..ep.horizon().saturating_sub(1) {
        let (a, b) = (ep.state(t), ep.state(t + 1));
        for j in 0..DU {
            let v = 0.5 * (a[DU + j] + b[DU + j]);
            num += (b[j] - a[j]) * v;
            den += v * v;
        }
    }
    (den > 1e-12 && num.is_finite()).then(|| num / den)
}

/// The checks of the module docs ("The task must be the controller's and the arm's").
#[derive(Default)]
struct TaskCheck {
    /// The first state of the first complete episode (any version) was the task's.
    start_checked: bool,
    /// The first complete noisy episode of the learner's version moved as the task's dt does.
    dt_checked: bool,
    /// Length of the last partial episodes and how many in a row had it.
    short: (usize, u32),
}

impl TaskCheck {
    fn sample<L: ServeLearner>(&self, s: &StepSample, learner: &L) -> anyhow::Result<()> {
        let t_len = learner.task().horizon;
        anyhow::ensure!(
            (s.t as usize) < t_len,
            "the controller runs episodes longer than the task's T = {t_len} steps (episode {} \
             has step t = {}): run rt-controller and hil-sim with [task] horizon = {t_len}, as in {}",
            s.episode,
            s.t,
            L::TASK_SOURCE
        );
        Ok(())
    }

    fn partial<L: ServeLearner>(&mut self, have: usize, learner: &L) -> anyhow::Result<()> {
        self.short = if self.short.0 == have {
            (have, self.short.1 + 1)
        } else {
            (have, 1)
        };
        anyhow::ensure!(
            self.short.1 < 3,
            "the controller's episodes end after {have} steps (3 in a row), the task has T = {} \
             steps: run rt-controller and hil-sim with [task] horizon = {}, as in {}",
            learner.task().horizon,
            learner.task().horizon,
            L::TASK_SOURCE
        );
        Ok(())
    }

    /// On every complete episode (table `version`).
    fn episode<L: ServeLearner>(
        &mut self,
        ep: &Episode,
        version: u64,
        learner: &L,
        tolerance: f64,
    ) -> anyhow::Result<()> {
        self.short = (0, 0);
        let check_dt = !self.dt_checked && ep.noisy && version == learner.version();
        if self.start_checked && !check_dt {
            return Ok(());
        }
        let task = learner.task();
        let mut sim = Ur5Sim::new(learner.sim_config().clone(), task.dt)
            .map_err(|e| anyhow::anyhow!("the learner's model of the arm: {e}"))?;
        if !self.start_checked {
            // Joint angles and end effector minus goal (velocities: sensor noise only).
            let want = sim
                .reset(task.start_q, task.goal)
                .map_err(|e| anyhow::anyhow!("the learner's model of the arm: {e}"))?
                .state(&task.goal);
            let parts = |s: &[f64; DX]| [s[0], s[1], s[2], s[6], s[7], s[8]];
            let (got, want) = (parts(&ep.state(0)), parts(&want));
            let diff = (0..6).map(|i| (got[i] - want[i]).abs()).fold(0.0, f64::max);
            anyhow::ensure!(
                diff <= tolerance,
                "the controller's episodes start at joint angles {:.4?} rad with end effector \
                 minus goal {:.4?} m; the task's start is {:.4?} rad, {:.4?} m (start_q {:?}, \
                 goal {:?}): they differ by {diff:.3e} > serve.task_tolerance = {tolerance}; run \
                 rt-controller and hil-sim with the [task] start_q and goal of {}",
                &got[..3],
                &got[3..],
                &want[..3],
                &want[3..],
                task.start_q,
                task.goal,
                L::TASK_SOURCE
            );
            self.start_checked = true;
        }
        if check_dt {
            let table = to_gain_table(learner.policy(), version);
            let mut noise = Noise::new(learner.seed(), version, 0);
            let replay = run_episode(&mut sim, task, &table, Some(&mut noise))
                .map_err(|e| anyhow::anyhow!("replaying the first episode in process: {e}"))?;
            if let (Some(a), Some(b)) = (motion_per_step(ep), motion_per_step(&replay)) {
                let ratio = a / b;
                anyhow::ensure!(
                    (0.5..=2.0).contains(&ratio),
                    "the arm moves {ratio:.2}x as far per step as the task's control period \
                     dt = {} s gives on the learner's model of the arm (allowed 1/2 to 2): the \
                     arm or the controller runs another dt (or, in real time, the arm cannot \
                     keep up with its clock); run both with the [task] dt of {}",
                    task.dt,
                    L::TASK_SOURCE
                );
            }
            self.dt_checked = true;
        }
        Ok(())
    }
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
    let el = match &opts.resume {
        Some(dir) => {
            let path = dir.join("checkpoint.npz");
            let (pol, iteration, cost_random) = load_checkpoint(&path)
                .with_context(|| format!("resuming from {}", path.display()))?;
            anyhow::ensure!(
                pol.t == cfg.task.horizon,
                "{} holds a controller of T = {}, the task has T = {}",
                path.display(),
                pol.t,
                cfg.task.horizon
            );
            ExpertLearner::resume(cfg, pol, iteration, cost_random)
        }
        None => ExpertLearner::new(cfg, None),
    };
    serve_loop(el, opts, progress)
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
    let task = TaskConfig {
        dt: demos.dt,
        horizon: demos.horizon,
        start_q: demos.start_q,
        goal: demos.goal,
    };
    validate(&task, cfg.samples, cfg.init_var, &opts)
        .context("the demonstrations' task or the settings")?;
    let run = match &opts.resume {
        Some(dir) => LqrGaifo::resume(cfg, demos, dir)?,
        None => LqrGaifo::new(cfg, demos)?,
    };
    serve_loop(run, opts, progress)
}

/// The one serve loop (module docs) around `learner`.
fn serve_loop<L: ServeLearner>(
    learner: L,
    opts: ServeOptions,
    mut progress: impl FnMut(&L::Log),
) -> anyhow::Result<ServeSummary<L::Log>> {
    let out = opts.out.clone();
    for d in [out.clone(), out.join("tables"), out.join("episodes")] {
        std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    }
    let csv = learner.open_csv(&out, opts.resume.is_some())?;
    let mut run = Run {
        learner,
        opts,
        csv,
        arrivals: 0,
    };

    // Setup: every port before anything runs.
    let ports = Ports::create(&run.opts.prefix)?;
    let start_version = run.learner.version();
    let table = run.save_current()?;
    ports.publish(&table)?;
    let (n, t_len) = (run.learner.samples(), run.learner.task().horizon);
    eprintln!(
        "learner serve ({}): prefix `{}`, published gain table version {start_version}{}; waiting for {n} noisy + 1 noise-free episodes of T = {t_len} per version",
        L::ALGO,
        run.opts.prefix,
        if run.opts.resume.is_some() { " (resumed)" } else { "" },
    );
    eprintln!("{}", L::PROGRESS_HEADER);

    let mut asm = Assembler::new(t_len);
    let mut batch = Batch {
        noisy: Vec::with_capacity(n),
        eval: None,
    };
    let mut check = TaskCheck::default();
    let mut counts = Counts::default();
    let mut log = Vec::new();
    let mut best: Option<(LinGaussPolicy, f64)> = None;
    let mut finishing = run.learner.done();
    let report = Duration::from_secs_f64(run.opts.wait_report_s);
    let idle = Duration::from_micros(run.opts.idle_sleep_us.max(1));
    let mut last_sample = Instant::now();
    let mut last_report = Instant::now();
    let mut version_started: Option<Instant> = None;
    let mut newer_reported = 0u64;

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
            if s.table_version == run.learner.version() && version_started.is_none() {
                version_started = Some(Instant::now());
            }
            for a in asm.push(&s) {
                let (episode, version, ep) = match a {
                    Assembled::Complete {
                        episode,
                        version,
                        ep,
                    } => (episode, version, ep),
                    Assembled::Partial { episode, have } => {
                        counts.partial += 1;
                        eprintln!(
                            "learner serve: discarded episode {episode}: {have} of {t_len} steps"
                        );
                        check.partial(have, &run.learner)?;
                        continue;
                    }
                    Assembled::Mixed { episode } => {
                        counts.mixed += 1;
                        eprintln!("learner serve: discarded episode {episode}: table version or noise flag changed inside it");
                        continue;
                    }
                };
                counts.episodes += 1;
                run.record(&ep, episode, version)?;
                check.episode(&ep, version, &run.learner, run.opts.task_tolerance)?;
                let current = run.learner.version();
                if version < current {
                    counts.old_version += 1;
                } else if version > current {
                    counts.newer_version += 1;
                    if version != newer_reported {
                        newer_reported = version;
                        eprintln!(
                            "learner serve: the controller runs table version {version}, newer than this learner's {current}: \
                             another learner published it; restart this one with --resume <its out dir> to continue from there"
                        );
                    }
                } else if finishing {
                    // The controller took the last table: nothing more to learn.
                    break 'outer ServeExit::Done;
                } else if batch.offer(ep, n) {
                    counts.used += 1;
                } else {
                    counts.surplus += 1;
                }
            }
            if batch.full(n) {
                let eval = batch.eval.take().expect("full batch");
                let cost = eval.task_cost();
                if best.as_ref().is_none_or(|(_, c)| cost < *c) {
                    best = Some((run.learner.policy().clone(), cost));
                }
                let entry = run
                    .learner
                    .update(&batch.noisy, &eval, version_started.take())?;
                batch.noisy.clear();
                let table = run.save_current()?;
                ports.publish(&table)?;
                let row = run.learner.csv_row(&entry)?;
                run.csv.write_all(row.as_bytes())?;
                eprintln!("{}", L::progress_line(&entry));
                progress(&entry);
                log.push(entry);
                finishing = run.learner.done();
                if finishing {
                    eprintln!(
                        "learner serve: learning done ({} iterations); published the last table, version {}; \
                         exiting once the controller runs it",
                        run.learner.iteration(),
                        run.learner.version()
                    );
                }
            }
        }
        if got {
            last_sample = Instant::now();
            continue;
        }
        // Idle: deliver the table (history) to a controller that connected late.
        let _ = ports.gains.update_connections();
        if last_sample.elapsed() >= report && last_report.elapsed() >= report {
            last_report = Instant::now();
            eprintln!(
                "learner serve: waiting for episodes of table version {} on prefix `{}`: no sample for {:.0} s \
                 (is rt-controller running with --prefix {}?)",
                run.learner.version(),
                run.opts.prefix,
                last_sample.elapsed().as_secs_f64(),
                run.opts.prefix
            );
        }
        if ports.node.wait(idle).is_err() {
            break ServeExit::Stopped;
        }
    };

    if let Some((pol, _)) = &best {
        save_table(
            &out.join("best_table.npz"),
            &to_gain_table(pol, run.learner.version()),
            run.learner.task().dt,
        )?;
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

/// Units and files, shown after `learner serve --help`.
pub const HELP_UNITS: &str = "Units: angles rad (actions are goal joint angles), positions m (arm base frame), \
times s (task.dt is the control period; progress `sec` (expert) and `sim_ms` (lqr-gaifo) are wall-clock from the \
version's first sample to its update), task cost C(τ) = d_T + Σ (i/T) d_i in m; init_var rad². Every option lives \
in the TOML file (an ExpertConfig as for `learner expert --config`, or with --algo lqr-gaifo a GaifoConfig as for \
`learner train --config`, plus a [serve] table with algo, demos, prefix, out, resume, record_episodes, \
wait_report_s, idle_sleep_us, task_tolerance); the flags above override it. The controller must run with the \
same seed, task (lqr-gaifo: the demonstrations' goal, start_q, horizon, dt), noisy_episodes = samples and \
eval_episodes = 1; the learner checks the task on the sample stream and stops with an error naming the \
setting. Files in --out: episodes/*.npz, tables/v*.npz, latest_table.npz, best_table.npz; expert: \
checkpoint.npz, serve_log.csv; lqr-gaifo: iter_NNN_table.npz + iter_NNN_critic.json, gaifo_log.csv (the \
columns of `learner train`). --resume restores the controller (and LQR+GAIfO's critic exactly); the GMM \
dynamics prior, the step size and the previous controller are not checkpointed and start afresh.";

/// Arguments of `learner serve`.
#[derive(clap::Args, Debug)]
#[command(after_help = HELP_UNITS)]
pub struct ServeArgs {
    /// Learner: `expert` (true task cost; default) or `lqr-gaifo` (imitation from --demos);
    /// overrides the config's [serve] algo.
    #[arg(long, value_enum)]
    pub algo: Option<ServeAlgo>,
    /// Demonstrations (.npz from `learner expert`) for --algo lqr-gaifo; their task (goal,
    /// start pose, T, dt) is the one rt-controller and hil-sim must run.
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// TOML file: an `ExpertConfig` (as for `learner expert`) or, for lqr-gaifo, a
    /// `GaifoConfig` (as for `learner train`), plus an optional `[serve]` table.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// iceoryx2 service prefix (rt-controller and hil-sim must use the same).
    #[arg(long)]
    pub prefix: Option<String>,
    /// Output folder (episodes, tables, checkpoints, per-iteration CSV).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue from the checkpoint in DIR of an earlier (e.g. killed) run (expert:
    /// checkpoint.npz; lqr-gaifo: the latest iter_NNN_table.npz + iter_NNN_critic.json):
    /// re-publishes its table version and continues learning from that controller.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// Seed of the run (must be the controller's `seed`); overrides the config.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Largest number of iterations (counted from the first, across resumes); overrides the config.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
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
    let (rest, mut opts) = match &args.config {
        Some(p) => read_config(p)?,
        None => (toml::Table::new(), ServeOptions::default()),
    };
    let path = args.config.clone().unwrap_or_default();
    if let Some(a) = args.algo {
        opts.algo = a;
    }
    if args.demos.is_some() {
        opts.demos = args.demos;
    }
    if let Some(p) = args.prefix {
        opts.prefix = p;
    }
    if let Some(o) = args.out {
        opts.out = o;
    }
    if args.resume.is_some() {
        opts.resume = args.resume;
    }
    match opts.algo {
        ServeAlgo::Expert => {
            anyhow::ensure!(
                opts.demos.is_none(),
                "--demos is for --algo lqr-gaifo; the expert learns on the true task cost"
            );
            let mut cfg: ExpertConfig = settings(rest, &path, "expert")?;
            if let Some(s) = args.seed {
                cfg.seed = s;
            }
            if let Some(i) = args.iterations {
                cfg.iterations = i;
            }
            finish(&serve(cfg, opts, |_| {})?, args.json)
        }
        ServeAlgo::LqrGaifo => {
            let Some(demos_path) = opts.demos.clone() else {
                anyhow::bail!(
                    "--algo lqr-gaifo needs --demos FILE (or [serve] demos): the demonstrations \
                     to imitate, from `learner expert`"
                );
            };
            let demos = Demos::load(&demos_path)
                .with_context(|| format!("loading demonstrations {}", demos_path.display()))?;
            let mut cfg: GaifoConfig = settings(rest, &path, "LQR+GAIfO")?;
            if let Some(s) = args.seed {
                cfg.seed = s;
            }
            if let Some(i) = args.iterations {
                cfg.iterations = i;
            }
            finish(&serve_gaifo(cfg, demos, opts, |_| {})?, args.json)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let mut pol = crate::expert::init_hold(&task, 0.05);
        pol.gain.data[7] = 0.25;
        let path = dir.join("checkpoint.npz");
        save_checkpoint(&path, &pol, 4, Some(2.5), 3).unwrap();
        let (back, it, cr) = load_checkpoint(&path).unwrap();
        assert_eq!((back, it, cr), (pol, 4, Some(2.5)));

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
        let episode = |task: &TaskConfig, k: u64| {
            let mut sim = Ur5Sim::new(SimConfig::default(), task.dt).unwrap();
            run_episode(&mut sim, task, &table, Some(&mut Noise::new(0, 1, k))).unwrap()
        };
        let check = |ep: &Episode| TaskCheck::default().episode(ep, 1, &el, 0.01);
        // The same task (another episode of the version than the replayed k = 0 included).
        check(&episode(&cfg.task, 0)).unwrap();
        check(&episode(&cfg.task, 3)).unwrap();
        let mut physical = SimConfig::default();
        physical.perturbation = ur5_shared::config::Perturbation::physical_stand_in(1);
        let mut sim = Ur5Sim::new(physical, cfg.task.dt).unwrap();
        let ep = run_episode(&mut sim, &cfg.task, &table, Some(&mut Noise::new(0, 1, 2))).unwrap();
        check(&ep).unwrap();
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
