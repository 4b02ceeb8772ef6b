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
//! table version are in, runs one [`ExpertLearner::update`] (the same code as the in-process
//! [`crate::expert::train`]) and publishes the next version.
//!
//! # Same episodes as in process
//! The controller draws the noise of the k-th episode of a table version from
//! `Noise::new(seed, version, k)`, episodes k = 0 … N−1 of a version with noise and k = N
//! without (`noisy_episodes = N`, `eval_episodes = 1`), exactly the order of
//! [`crate::iteration::execute`]. With the same seed, task and arm (lockstep), the episodes over
//! IPC equal the in-process ones bit for bit, and so does everything learned from them. The
//! dynamics are fitted on the executed actions (`StepSample::a_sent`, after the clamp).
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
//! - `checkpoint.npz`: the controller to execute next (all GPS policy arrays), its iteration,
//!   the random-policy cost; written before the table is published;
//! - `serve_log.csv`: one row per iteration (appended across resumes); `best_table.npz` at exit.
//!
//! # Peers that die
//! A dead or absent controller: the learner keeps waiting and says so every `wait_report_s`.
//! A restarted learner: `--resume DIR` continues from `DIR/checkpoint.npz` and publishes that
//! table version again (the controller already runs it and ignores the duplicate), then waits
//! for N + 1 fresh episodes of it. The GPS learner state (dynamics prior, step size) is not
//! checkpointed and starts afresh. Without `--resume` a new learner starts at version 1,
//! which a controller running a newer version rejects: the learner then reports the newer
//! version it sees in the samples and keeps waiting.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use ur5_shared::layout::{DU, DX, MAX_HORIZON};
use ur5_shared::services::{self, Qos, ServiceNames};
use ur5_shared::{GainTable, StepSample};

use crate::expert::{to_gain_table, ExpertConfig, ExpertLearner, IterationLog};
use crate::io::episode::{save_episode, EpisodeOrigin};
use crate::io::npz::{NpzFile, NpzWriter};
use crate::io::table::save_table;
use crate::linalg::MatSeq;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::rollout::Episode;

/// Options of `learner serve` (the `[serve]` table of the config file; the rest of the file is
/// an [`ExpertConfig`], as for `learner expert`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServeOptions {
    /// iceoryx2 service prefix; the controller and the arm must use the same.
    pub prefix: String,
    /// Output folder.
    pub out: PathBuf,
    /// Continue from `DIR/checkpoint.npz` of an earlier run (see the module docs).
    pub resume: Option<PathBuf>,
    /// Record every complete episode to `out/episodes/`.
    pub record_episodes: bool,
    /// While no sample arrives, say so every this many seconds (wall clock).
    pub wait_report_s: f64,
    /// Sleep between polls when idle (µs).
    pub idle_sleep_us: u64,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            prefix: String::new(),
            out: PathBuf::from("runs/serve"),
            resume: None,
            record_episodes: true,
            wait_report_s: 5.0,
            idle_sleep_us: 500,
        }
    }
}

/// Reads a config file: an [`ExpertConfig`] at the top level plus an optional `[serve]` table.
pub fn load_config(path: &Path) -> anyhow::Result<(ExpertConfig, ServeOptions)> {
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
    let cfg = toml::Value::Table(value)
        .try_into()
        .with_context(|| format!("expert settings in {}", path.display()))?;
    Ok((cfg, serve))
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
pub struct ServeSummary {
    /// Always "serve".
    pub command: &'static str,
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
    pub log: Vec<IterationLog>,
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

/// The learner's side of the run: files and the table in force.
struct Run {
    cfg: ExpertConfig,
    opts: ServeOptions,
    el: ExpertLearner,
    csv: std::fs::File,
    arrivals: u64,
}

impl Run {
    /// Saves the checkpoint and the table of the controller to execute next; returns the table.
    fn save_current(&self) -> anyhow::Result<Box<GainTable>> {
        let out = &self.opts.out;
        let version = self.el.version();
        let table = to_gain_table(self.el.policy(), version);
        save_checkpoint(
            &out.join("checkpoint.npz"),
            self.el.policy(),
            self.el.iteration(),
            self.el.cost_random(),
            self.cfg.seed,
        )?;
        save_table(
            &out.join("tables").join(format!("v{version:04}.npz")),
            &table,
            self.cfg.task.dt,
        )?;
        save_table(&out.join("latest_table.npz"), &table, self.cfg.task.dt)?;
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
            seed: self.cfg.seed,
        };
        save_episode(
            &self.opts.out.join("episodes").join(name),
            ep,
            &origin,
            &self.cfg.task,
        )?;
        Ok(())
    }
}

/// Checks what `serve` needs of the configuration.
fn validate(cfg: &ExpertConfig, opts: &ServeOptions) -> anyhow::Result<()> {
    cfg.task.validate()?;
    anyhow::ensure!(
        cfg.task.horizon <= MAX_HORIZON,
        "task.horizon = {} exceeds the gain table's MAX_HORIZON = {MAX_HORIZON}",
        cfg.task.horizon
    );
    anyhow::ensure!(
        cfg.samples >= 2,
        "samples = {} noisy episodes per iteration: the dynamics fit needs at least 2",
        cfg.samples
    );
    anyhow::ensure!(
        cfg.init_var > 0.0 && cfg.init_var.is_finite(),
        "init_var must be finite and > 0 (rad²)"
    );
    anyhow::ensure!(
        opts.wait_report_s.is_finite() && opts.wait_report_s > 0.0,
        "serve.wait_report_s = {} must be > 0 (s)",
        opts.wait_report_s
    );
    ServiceNames::new(&opts.prefix).learner_samples()?;
    Ok(())
}

/// Runs the learner end until the learning is done or SIGINT/SIGTERM. `progress` receives each
/// iteration's log (`seconds`: from the first sample of the version to the end of its update).
pub fn serve(
    cfg: ExpertConfig,
    opts: ServeOptions,
    mut progress: impl FnMut(&IterationLog),
) -> anyhow::Result<ServeSummary> {
    validate(&cfg, &opts)?;
    let out = opts.out.clone();
    for d in [out.clone(), out.join("tables"), out.join("episodes")] {
        std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    }
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
            ExpertLearner::resume(cfg.clone(), pol, iteration, cost_random)
        }
        None => ExpertLearner::new(cfg.clone(), None),
    };
    let csv_path = out.join("serve_log.csv");
    let new_csv = !csv_path.exists();
    let mut csv = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&csv_path)
        .with_context(|| format!("opening {}", csv_path.display()))?;
    if new_csv {
        writeln!(csv, "{}", IterationLog::CSV_HEADER)?;
    }
    let mut run = Run {
        cfg,
        opts,
        el,
        csv,
        arrivals: 0,
    };

    // Setup: every port before anything runs.
    let ports = Ports::create(&run.opts.prefix)?;
    let start_version = run.el.version();
    let table = run.save_current()?;
    ports.publish(&table)?;
    eprintln!(
        "learner serve: prefix `{}`, published gain table version {start_version}{}; waiting for {} noisy + 1 noise-free episodes of T = {} per version",
        run.opts.prefix,
        if run.opts.resume.is_some() { " (resumed)" } else { "" },
        run.cfg.samples,
        run.cfg.task.horizon
    );
    eprintln!("{}", IterationLog::PROGRESS_HEADER);

    let n = run.cfg.samples;
    let mut asm = Assembler::new(run.cfg.task.horizon);
    let mut batch = Batch {
        noisy: Vec::with_capacity(n),
        eval: None,
    };
    let mut counts = Counts::default();
    let mut log = Vec::new();
    let mut finishing = run.el.done();
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
            if s.table_version == run.el.version() && version_started.is_none() {
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
                            "learner serve: discarded episode {episode}: {have} of {} steps",
                            run.cfg.task.horizon
                        );
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
                let current = run.el.version();
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
                let (mut entry, _) = run.el.update(&batch.noisy, &eval)?;
                batch.noisy.clear();
                if let Some(t0) = version_started.take() {
                    entry.seconds = t0.elapsed().as_secs_f64();
                }
                let table = run.save_current()?;
                ports.publish(&table)?;
                writeln!(run.csv, "{}", entry.csv_row())?;
                eprintln!("{}", entry.progress_line());
                progress(&entry);
                log.push(entry);
                finishing = run.el.done();
                if finishing {
                    eprintln!(
                        "learner serve: learning done ({} iterations); published the last table, version {}; \
                         exiting once the controller runs it",
                        run.el.iteration(),
                        run.el.version()
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
                run.el.version(),
                run.opts.prefix,
                last_sample.elapsed().as_secs_f64(),
                run.opts.prefix
            );
        }
        if ports.node.wait(idle).is_err() {
            break ServeExit::Stopped;
        }
    };

    let best = run.el.best().map(|(p, e)| (p.clone(), e.task_cost()));
    if let Some((pol, _)) = &best {
        save_table(
            &out.join("best_table.npz"),
            &to_gain_table(pol, run.el.version()),
            run.cfg.task.dt,
        )?;
    }
    Ok(ServeSummary {
        command: "serve",
        exit_reason: exit,
        start_version,
        table_version: run.el.version(),
        iterations: log.len(),
        eval_costs: log.iter().map(|l| l.eval_cost).collect(),
        best_eval_cost: best.map(|(_, c)| c),
        log,
        counts,
        out,
    })
}

/// Units and files, shown after `learner serve --help`.
pub const HELP_UNITS: &str = "Units: angles rad (actions are goal joint angles), positions m (arm base frame), \
times s (task.dt is the control period; progress `sec` is wall-clock from the version's first sample to the \
end of its update), task cost C(τ) = d_T + Σ (i/T) d_i in m; init_var rad². Every option lives in the TOML file \
(an ExpertConfig as for `learner expert --config`, plus a [serve] table with prefix, out, resume, \
record_episodes, wait_report_s, idle_sleep_us); the flags above override it. The controller must run with \
the same seed, task, noisy_episodes = samples and eval_episodes = 1. Files in --out: episodes/*.npz, \
tables/v*.npz, latest_table.npz, checkpoint.npz, serve_log.csv, best_table.npz.";

/// Arguments of `learner serve`.
#[derive(clap::Args, Debug)]
#[command(after_help = HELP_UNITS)]
pub struct ServeArgs {
    /// TOML file: an `ExpertConfig` (as for `learner expert`) plus an optional `[serve]` table.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// iceoryx2 service prefix (rt-controller and hil-sim must use the same).
    #[arg(long)]
    pub prefix: Option<String>,
    /// Output folder (episodes, tables, checkpoint, per-iteration CSV).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue from `DIR/checkpoint.npz` of an earlier (e.g. killed) run: re-publishes its
    /// table version and continues learning from that controller.
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

/// Runs `learner serve`.
pub fn run_cli(args: ServeArgs) -> anyhow::Result<()> {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let (mut cfg, mut opts) = match &args.config {
        Some(p) => load_config(p)?,
        None => (ExpertConfig::default(), ServeOptions::default()),
    };
    if let Some(p) = args.prefix {
        opts.prefix = p;
    }
    if let Some(o) = args.out {
        opts.out = o;
    }
    if args.resume.is_some() {
        opts.resume = args.resume;
    }
    if let Some(s) = args.seed {
        cfg.seed = s;
    }
    if let Some(i) = args.iterations {
        cfg.iterations = i;
    }
    let summary = serve(cfg, opts, |_| {})?;
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
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    }
    Ok(())
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
        std::fs::remove_dir_all(&dir).ok();
    }
}
