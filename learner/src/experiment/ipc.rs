//! `learner experiment sim-vs-physical` (paper: "comparison" of simulation and the physical
//! arm): the same LQR+GAIfO run on the nominal simulated arm and on the perturbed one (mass,
//! damping, friction, actuator and sensor noise, one-step latency: `ExperimentConfig::physical`,
//! default `Perturbation::physical_stand_in`), each over IPC with all three processes in real
//! time, compressed `time_compression` times:
//!
//! ```text
//! hil-sim serve (real time, arm clock)  <->  rt-controller run (real time)  <->  learner serve --algo lqr-gaifo
//! ```
//!
//! Both arms imitate the same demonstrations, recorded on the nominal arm (one variable
//! changes: the arm); each curve is normalised by its own arm's converged expert and random
//! policy, trained in process on that arm (docs/design.md §5 D26). Runs (arm ×
//! seed) execute `threads` at a time (0 = one per core), each on its own iceoryx2 prefix; the
//! binaries `hil-sim` and `rt-controller` are taken from the directory of the running
//! `learner` executable. Real time is not lockstep: episodes depend on scheduling, so these
//! runs are not bit-for-bit repeatable (the in-process experiments are).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use rayon::prelude::*;
use ur5_shared::config::Perturbation;

use super::summary::{summary_text, write_outputs, SummaryRow};
use super::ExperimentError;
use super::{expert_demos, pool, ExperimentConfig, ExperimentName, Run};
use crate::error::ensure;
use crate::io::log::read_gaifo_csv;
use crate::process::{sibling, Spawned};
use crate::progress::Progress;
use imitation::demos::Demos;

/// Time a process gets to stop on SIGTERM before it is killed.
const GRACE: Duration = Duration::from_secs(3);

/// `v` as a TOML value.
fn value<T: serde::Serialize>(v: &T) -> Result<toml::Value, ExperimentError> {
    Ok(toml::Value::try_from(v)?)
}

/// Everything one IPC run needs.
struct IpcRun<'a> {
    cfg: &'a ExperimentConfig,
    arm: &'a str,
    perturbation: &'a Perturbation,
    demos: &'a Path,
    seed: u64,
    dir: PathBuf,
}

/// Rows (iterations) in a `gaifo_log.csv` so far (0 when there is none yet).
fn csv_rows(path: &Path) -> u64 {
    std::fs::read(path).map_or(0, |b| {
        (b.iter().filter(|&&c| c == b'\n').count() as u64).saturating_sub(1)
    })
}

impl IpcRun<'_> {
    /// The run; `progress` counts its iterations as its learner logs them.
    fn run(&self, progress: &Progress) -> Result<Run, ExperimentError> {
        let t0 = Instant::now();
        let cfg = self.cfg;
        let dir = &self.dir;
        crate::io::create_dir(dir)?;
        let prefix =
            ur5_shared::services::unique_prefix(&format!("exp-{}-{}", self.arm, self.seed));
        let task = &cfg.expert.task;
        let mut sim = cfg.expert.sim.clone();
        sim.perturbation = self.perturbation.clone();
        let c = cfg.time_compression;
        let n = cfg.lqr_gaifo.samples;
        let table = |pairs: Vec<(&str, toml::Value)>| -> toml::Value {
            toml::Value::Table(pairs.into_iter().map(|(k, v)| (k.to_string(), v)).collect())
        };
        let write = |name: &str, v: toml::Value| -> Result<String, ExperimentError> {
            let p = dir.join(name);
            std::fs::write(&p, toml::to_string(&v)?)?;
            Ok(p.display().to_string())
        };
        let real_time = toml::Value::String("real_time".into());
        let sim_cfg = write(
            "sim.toml",
            table(vec![
                ("task", value(task)?),
                ("sim", value(&sim)?),
                (
                    "serve",
                    table(vec![
                        ("mode", real_time.clone()),
                        ("time_compression", toml::Value::Float(c)),
                    ]),
                ),
            ]),
        )?;
        let ctl_cfg = write(
            "controller.toml",
            table(vec![
                ("mode", real_time),
                ("pacing", toml::Value::String("deadline".into())),
                ("time_compression", toml::Value::Float(c)),
                ("seed", toml::Value::Integer(self.seed as i64)),
                ("noisy_episodes", toml::Value::Integer(n as i64)),
                ("eval_episodes", toml::Value::Integer(1)),
                ("action_mode", value(&sim.mode)?),
                ("task", value(task)?),
            ]),
        )?;
        let mut lcfg = cfg.lqr_gaifo.clone();
        lcfg.seed = self.seed;
        lcfg.iterations = cfg.iterations;
        lcfg.sim = sim.clone();
        let learner_cfg = write("learner.toml", value(&lcfg)?)?;
        let out = dir.join("learner");
        let s = |v: &str| v.to_string();
        let _sim = Spawned::spawn(
            &sibling("hil-sim")?,
            &[
                s("serve"),
                s("--config"),
                sim_cfg,
                s("--prefix"),
                prefix.clone(),
            ],
            &dir.join("sim.log"),
            GRACE,
        )?;
        let _ctl = Spawned::spawn(
            &sibling("rt-controller")?,
            &[
                s("run"),
                s("--config"),
                ctl_cfg,
                s("--prefix"),
                prefix.clone(),
            ],
            &dir.join("controller.log"),
            GRACE,
        )?;
        let mut learner = Spawned::spawn(
            &sibling("learner")?,
            &[
                s("serve"),
                s("--algo"),
                s("lqr-gaifo"),
                s("--demos"),
                self.demos.display().to_string(),
                s("--config"),
                learner_cfg,
                s("--prefix"),
                prefix,
                s("--out"),
                out.display().to_string(),
            ],
            &dir.join("learner.log"),
            GRACE,
        )?;
        // Arm time of one iteration (N + 1 episodes, one more for the table switch), in wall
        // time, and generous slack for learning and a loaded machine.
        let per_iter = (n + 2) as f64 * task.horizon as f64 * task.dt / c;
        let limit = Duration::from_secs_f64(120.0 + 3.0 * per_iter * cfg.iterations as f64);
        let (csv, mut logged) = (out.join("gaifo_log.csv"), 0);
        let status = loop {
            let now = csv_rows(&csv).min(cfg.iterations as u64);
            progress.inc(now.saturating_sub(logged));
            logged = logged.max(now);
            if let Some(st) = learner.try_wait()? {
                progress.inc((cfg.iterations as u64).saturating_sub(logged));
                break st;
            }
            ensure!(
                t0.elapsed() < limit,
                ExperimentError::Ipc(format!(
                    "{} seed {}: learner still running after {:.0} s (log: {})",
                    self.arm,
                    self.seed,
                    limit.as_secs_f64(),
                    dir.join("learner.log").display()
                ))
            );
            std::thread::sleep(Duration::from_millis(200));
        };
        ensure!(
            status.success(),
            ExperimentError::Ipc(format!(
                "{} seed {}: learner serve failed ({status}); log: {}",
                self.arm,
                self.seed,
                dir.join("learner.log").display()
            ))
        );
        let logs = read_gaifo_csv(&out.join("gaifo_log.csv"))?;
        ensure!(
            logs.len() >= cfg.iterations,
            ExperimentError::Ipc(format!(
                "{} seed {}: {} of {} iterations logged",
                self.arm,
                self.seed,
                logs.len(),
                cfg.iterations
            ))
        );
        Ok(Run {
            variant: self.arm.to_string(),
            algorithm: "lqr-gaifo".into(),
            seed: self.seed,
            episodes_per_iteration: n,
            horizon: task.horizon,
            logs,
            wall_s: t0.elapsed().as_secs_f64(),
        })
    }
}

/// Runs the experiment and writes its outputs (`sim-vs-physical.csv`, `.png`, summary) into
/// `out`; `demos` replaces training the nominal arm's expert.
pub fn run(
    cfg: &ExperimentConfig,
    out: &Path,
    demos: Option<&Path>,
) -> Result<(Vec<Run>, Vec<SummaryRow>), ExperimentError> {
    let name = ExperimentName::SimVsPhysical;
    cfg.validate(name)?;
    let pool = pool(cfg.threads)?;
    crate::io::create_dir(out)?;
    eprintln!(
        "experiment sim-vs-physical: {} seed(s) from {}, {} iterations, real time x{} over IPC, {} run(s) at a time -> {}",
        cfg.seeds,
        cfg.first_seed,
        cfg.iterations,
        cfg.time_compression,
        pool.current_num_threads(),
        out.display()
    );
    let t0 = Instant::now();
    let arms = [
        ("simulated", Perturbation::default()),
        ("physical", cfg.physical.clone()),
    ];
    // The demonstrations: the nominal arm's expert, imitated on both arms (docs/design.md §5
    // D26). Each arm's curve is normalised by its own converged expert and random policy.
    let nominal_path = out.join("demos_simulated.npz");
    let nominal = match demos {
        Some(d) => crate::io::demos::load_checked(d, &cfg.expert.sim)?,
        None => expert_demos(&cfg.expert)?,
    };
    crate::io::demos::save(&nominal, &nominal_path)?;
    let mut e = cfg.expert.clone();
    e.sim.perturbation = cfg.physical.clone();
    e.iterations = cfg.physical_expert_iterations;
    e.patience = cfg.physical_expert_iterations;
    let own = expert_demos(&e)?;
    crate::io::demos::save(&own, &out.join("expert_physical.npz"))?;
    let physical = Demos {
        cost_expert: own.cost_expert,
        cost_random: own.cost_random,
        ..nominal.clone()
    };
    let physical_path = out.join("demos_physical.npz");
    crate::io::demos::save(&physical, &physical_path)?;
    eprintln!(
        "both arms imitate {}; the perturbed arm is normalised by its own expert ({} iterations): expert cost {:.4}, random {:.4}",
        nominal_path.display(),
        cfg.physical_expert_iterations,
        own.cost_expert,
        own.cost_random
    );
    let demo_paths = [nominal_path, physical_path];
    let mut jobs = Vec::new();
    for ((arm, p), d) in arms.iter().zip(&demo_paths) {
        for i in 0..cfg.seeds as u64 {
            let seed = cfg.first_seed + i;
            jobs.push(IpcRun {
                cfg,
                arm,
                perturbation: p,
                demos: d,
                seed,
                dir: out.join(format!("{arm}_seed{seed}")),
            });
        }
    }
    let done = AtomicUsize::new(0);
    let total = jobs.len();
    // A bar over all runs' iterations (ETA) on a terminal; the run lines either way.
    let progress = Progress::new((total * cfg.iterations) as u64, "iterations");
    let runs: Vec<Run> = pool.install(|| {
        jobs.par_iter()
            .map(|j| {
                let r = j.run(&progress)?;
                let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                progress.println(&format!(
                    "[{k:>3}/{total}] {:<10} seed {:>3}: {} iterations over IPC, final normalised performance {:>6.3} ({:.0} s)",
                    r.variant,
                    r.seed,
                    r.logs.len(),
                    r.logs.last().map(|l| l.performance).unwrap_or(f64::NAN),
                    r.wall_s
                ));
                Ok(r)
            })
            .collect::<Result<Vec<_>, ExperimentError>>()
    })?;
    drop(progress);
    let rows = write_outputs(
        name.as_str(),
        &format!(
            "LQR+GAIfO over IPC in real time (x{}): nominal vs perturbed arm",
            cfg.time_compression
        ),
        &runs,
        out,
    )?;
    eprint!("{}", summary_text(&rows));
    eprintln!(
        "experiment sim-vs-physical done in {:.0} s; outputs in {}",
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok((runs, rows))
}
