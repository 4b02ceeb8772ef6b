//! `learner experiment shapes`: every LASA handwriting shape (docs/design.md §4.18) × seeds,
//! imitated from its seven drawings at the same episodes per iteration, measured by the path
//! (docs/design.md §4.15, §5 D39): per shape, the noise-free episode's path RMSE at the last
//! iteration against the drawings' own spread, and its final distance.
//!
//! Jobs are shape × algorithm × seed, in that order. Each finished job is written at once to
//! `OUT/runs/<shape>_<algorithm>_s<seed>.json` (with a hash of its settings); a job whose file
//! is there with the same hash is not run again, so an interrupted experiment resumes where
//! it stopped. `--shard K/N` runs jobs K, K + N, … of the list; shards may write into one
//! folder, or into their own whose `runs/` are then copied together: any run of the command
//! (all jobs done: none is run) writes the tables from every job file of its list present in
//! `OUT/runs/`, saying how many are missing.
//!
//! Outputs: `OUT/demos/<shape>.csv` (the placed drawings, a tool-path file `--demos` takes),
//! `OUT/runs/*.json` (each with the last iteration's noise-free tool path), `OUT/shapes.txt`
//! (the table), `OUT/shapes.json` and per algorithm the picture `OUT/shapes_<algorithm>.png`:
//! a panel a shape, in its plane, the drawings as the arm is given them in grey, every seed's
//! last noise-free episode in colour, the goal ringed ([`crate::plot_paths`]). Like the
//! tables, the pictures are written from the job files, so a run of the command whose jobs are
//! all done redraws them.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use imitation::demos::Demos;
use imitation::gaifo::{GaifoLog, LqrGaifo};
use imitation::learn::Learn;
use imitation::settings::PathSettings;
use imitation::tool_path::{mean_frames, orientation_rmse, tool_frames, tool_paths, Frame, Point};

use super::shard::Shard;
use super::{baseline, pool, ExperimentConfig, ExperimentError, Job, Spec, BASELINES};
use crate::error::ensure;
use crate::io::lasa;
use ur5_shared::config::SimConfig;

/// Algorithms the experiment runs ([`ShapesExperimentConfig::algorithms`]): LQR+GAIfO with
/// `lqr_gaifo`'s settings (whose `[path]` defaults to [`PathSettings::for_motions`] here), the
/// same with the paper's cost (no `[path]` term), and GAIfO (PPO); the baselines
/// ([`BASELINES`]) run too.
pub const SHAPE_ALGORITHMS: [&str; 3] = ["lqr-gaifo", "lqr-gaifo-paper", "gaifo-ppo"];

/// Settings of `learner experiment shapes` (`[shapes]` of its config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShapesExperimentConfig {
    /// Shapes (names of `learner dataset lasa`); empty: all 26.
    pub shapes: Vec<String>,
    /// Algorithms, of [`SHAPE_ALGORITHMS`].
    pub algorithms: Vec<String>,
    /// Plane of the drawings: `facing`, `xz`, `yz` or `xy` (`learner dataset lasa --plane`).
    pub plane: String,
    /// The shapes' larger extent (m).
    pub size: f64,
    /// The drawings' mean duration (s).
    pub duration: f64,
    /// The arm's active joints: 3 (the wrist locked, the drawings' tool point alone) or 6 (the
    /// whole arm holding the tool at [`Self::rotation`] along every drawing, a pose goal).
    #[serde(skip_serializing_if = "is_three")]
    pub joints: usize,
    /// With six joints, the tool's orientation (rotation vector, rad, base frame); none: the
    /// orientation the three-joint arm ends the drawing with ([`lasa::held_rotation`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f64; 3]>,
}

fn is_three(n: &usize) -> bool {
    *n == 3
}

impl Default for ShapesExperimentConfig {
    fn default() -> Self {
        Self {
            shapes: Vec::new(),
            algorithms: vec!["lqr-gaifo".into()],
            plane: "facing".into(),
            size: 0.2,
            duration: 10.0,
            joints: 3,
            rotation: None,
        }
    }
}

/// The experiment's defaults over `base`: 5 seeds × 30 iterations, LQR+GAIfO with the path
/// settings of a motion.
pub fn defaults(mut base: ExperimentConfig) -> ExperimentConfig {
    base.lqr_gaifo.path = PathSettings::for_motions();
    ExperimentConfig {
        seeds: 5,
        iterations: 30,
        ..base
    }
}

impl ShapesExperimentConfig {
    /// The shapes to run, checked.
    pub fn shape_list(&self) -> Result<Vec<String>, ExperimentError> {
        if self.shapes.is_empty() {
            return Ok(lasa::SHAPES.iter().map(|s| s.to_string()).collect());
        }
        for s in &self.shapes {
            ensure!(
                lasa::SHAPES.iter().any(|k| k.eq_ignore_ascii_case(s)),
                ExperimentError::Settings(format!(
                    "shapes.shapes: unknown `{s}`; known: {}",
                    lasa::SHAPES.join(", ")
                ))
            );
        }
        Ok(self.shapes.clone())
    }

    /// Where the drawings are placed on the arm of `sim`: ending at its model's default goal,
    /// with the tool's orientation at six joints.
    pub fn placement(&self, sim: &SimConfig) -> Result<lasa::Placement, ExperimentError> {
        let end = sim.model.default_goal();
        let rotation = match (self.joints, self.rotation) {
            (6, Some(r)) => Some(r),
            (6, None) => Some(
                lasa::held_rotation(sim.model, sim.ee_offset, end)
                    .map_err(ExperimentError::Settings)?,
            ),
            _ => None,
        };
        Ok(lasa::Placement {
            plane: self.plane()?,
            end,
            size: self.size,
            duration: self.duration,
            rotation,
        })
    }

    fn plane(&self) -> Result<lasa::Plane, ExperimentError> {
        <lasa::Plane as clap::ValueEnum>::from_str(&self.plane, true).map_err(|_| {
            ExperimentError::Settings(format!(
                "shapes.plane = `{}`: must be facing, xz, yz or xy",
                self.plane
            ))
        })
    }

    /// Checks the names and the placement.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        self.shape_list()?;
        self.plane()?;
        ensure!(
            !self.algorithms.is_empty(),
            ExperimentError::Settings("shapes.algorithms is empty".into())
        );
        for a in &self.algorithms {
            ensure!(
                SHAPE_ALGORITHMS.contains(&a.as_str()) || BASELINES.contains(&a.as_str()),
                ExperimentError::Settings(format!(
                    "shapes.algorithms: unknown `{a}`; known: {}, {}",
                    SHAPE_ALGORITHMS.join(", "),
                    BASELINES.join(", ")
                ))
            );
        }
        ensure!(
            matches!(self.joints, 3 | 6) && (self.joints == 6 || self.rotation.is_none()),
            ExperimentError::Settings(format!(
                "shapes.joints = {} with shapes.rotation {:?}: joints must be 3 or 6, and a \
                 rotation needs 6 (three joints keep the wrist locked)",
                self.joints, self.rotation
            ))
        );
        ensure!(
            self.rotation
                .is_none_or(|r| r.iter().all(|v| v.is_finite())),
            ExperimentError::Settings(format!(
                "shapes.rotation {:?} must be finite",
                self.rotation
            ))
        );
        ensure!(
            self.size > 0.0 && self.size <= 1.0 && self.duration > 0.0 && self.duration <= 100.0,
            ExperimentError::Settings(format!(
                "shapes.size = {} m and shapes.duration = {} s: must be in (0, 1] m and (0, 100] s",
                self.size, self.duration
            ))
        );
        Ok(())
    }
}

/// One finished job, as written to `OUT/runs/`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ShapeRun {
    /// The shape.
    pub shape: String,
    /// The algorithm ([`SHAPE_ALGORITHMS`]).
    pub algorithm: String,
    /// The seed.
    pub seed: u64,
    /// Hash of the job's settings (algorithm settings with seed and iterations, placement).
    pub settings_hash: String,
    /// Noisy episodes per iteration.
    pub episodes_per_iteration: usize,
    /// The drawings' own spread, path RMSE (m).
    pub spread_rmse_m: f64,
    /// Per iteration: the noise-free episode's path RMSE (m).
    pub path_rmse_m: Vec<f64>,
    /// Per iteration: its final distance (m).
    pub final_distance_m: Vec<f64>,
    /// Per iteration: its normalised performance (on the reaching task cost).
    pub performance: Vec<f64>,
    /// Wall time of the job (s).
    pub wall_s: f64,
    /// The last iteration's noise-free episode's tool path (m, base frame); empty in job
    /// files of earlier builds, which the pictures then leave out.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub path_m: Vec<Point>,
    /// With a pose goal (six joints): per iteration, the noise-free episode's final
    /// orientation error (degrees); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub final_orientation_error_deg: Vec<f64>,
    /// With a pose goal: the last iteration's noise-free episode's orientation RMSE over the
    /// steps against the drawings' mean orientation (degrees; `tool_path::orientation_rmse`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation_rmse_deg: Option<f64>,
}

fn job_file(out: &Path, shape: &str, algo: &str, seed: u64) -> PathBuf {
    out.join("runs")
        .join(format!("{shape}_{algo}_s{seed}.json"))
}

/// The shape's drawings placed by the experiment's settings, written to `OUT/demos/` and
/// loaded as demonstrations on the arm of `cfg.lqr_gaifo.sim`.
fn shape_demos(cfg: &ExperimentConfig, shape: &str, out: &Path) -> Result<Demos, ExperimentError> {
    let sim = &cfg.lqr_gaifo.sim;
    let placement = cfg.shapes.placement(sim)?;
    let paths = lasa::place(&lasa::shape(shape)?, &placement).map_err(ExperimentError::Settings)?;
    let dir = out.join("demos");
    crate::io::create_dir(&dir)?;
    let file = dir.join(format!("{shape}.csv"));
    lasa::write_csv(&paths, &file)?;
    Ok(crate::io::demos::load_checked(&file, sim)?)
}

/// The job of `algo` at `seed` on `demos`, and its settings hash.
fn job(
    cfg: &ExperimentConfig,
    shape: &str,
    algo: &str,
    seed: u64,
    demos: Arc<Demos>,
) -> Result<(Job, String), ExperimentError> {
    let spec = match algo {
        b if BASELINES.contains(&b) => baseline(cfg, b, seed).expect("a baseline's name"),
        "gaifo-ppo" => {
            let mut c = cfg.gaifo_ppo.clone();
            c.seed = seed;
            c.iterations = cfg.iterations;
            Spec::GaifoPpo(c)
        }
        _ => {
            let mut c = cfg.lqr_gaifo.clone();
            c.seed = seed;
            c.iterations = cfg.iterations;
            if algo == "lqr-gaifo-paper" {
                c.path = PathSettings::default();
            }
            Spec::LqrGaifo(c)
        }
    };
    let settings = match &spec {
        Spec::LqrGaifo(c) => serde_json::to_string(c)?,
        Spec::GaifoPpo(c) => serde_json::to_string(c)?,
        Spec::Bco(c) => serde_json::to_string(c)?,
        Spec::GaifoTd3(c) => serde_json::to_string(c)?,
        Spec::ReplayMean(c) => serde_json::to_string(c)?,
    };
    let s = &cfg.shapes;
    // The whole arm's settings join the hash only when used, so three-joint job files of
    // earlier builds stay done.
    let arm = match s.joints {
        6 => format!("|6|{:?}", s.rotation),
        _ => String::new(),
    };
    let hash = crate::io::files::fnv1a64(
        format!(
            "{shape}|{algo}|{settings}|{}|{}|{}{arm}",
            s.plane, s.size, s.duration
        )
        .as_bytes(),
    );
    Ok((
        Job {
            variant: format!("{shape} {algo}"),
            spec,
            demos,
        },
        hash,
    ))
}

/// Runs the experiment (or this `shard` of it) into `out`, skipping jobs already done, and
/// writes the tables; returns them as JSON.
pub fn run(
    cfg: &ExperimentConfig,
    out: &Path,
    shard: Option<Shard>,
) -> Result<serde_json::Value, ExperimentError> {
    cfg.shapes.validate()?;
    let shapes = cfg.shapes.shape_list()?;
    let pool = pool(cfg.threads)?;
    let t0 = Instant::now();
    crate::io::create_dir(&out.join("runs"))?;
    // Every job of the list: (index, shape, algorithm, seed).
    let mut list = Vec::new();
    for shape in &shapes {
        for algo in &cfg.shapes.algorithms {
            for s in 0..cfg.seeds {
                list.push((shape.clone(), algo.clone(), cfg.first_seed + s as u64));
            }
        }
    }
    let mine: Vec<usize> = (0..list.len())
        .filter(|&i| shard.is_none_or(|s| s.has(i)))
        .collect();
    // Demonstrations of the shapes this shard runs, and its jobs not done yet.
    let mut demos: Vec<(String, Arc<Demos>)> = Vec::new();
    let mut todo = Vec::new();
    for &i in &mine {
        let (shape, algo, seed) = &list[i];
        let d = match demos.iter().find(|(s, _)| s == shape) {
            Some((_, d)) => d.clone(),
            None => {
                let d = Arc::new(shape_demos(cfg, shape, out)?);
                demos.push((shape.clone(), d.clone()));
                d
            }
        };
        let (j, hash) = job(cfg, shape, algo, *seed, d)?;
        if read_done(out, shape, algo, *seed, &hash)?.is_none() {
            todo.push((shape.clone(), algo.clone(), j, hash));
        }
    }
    eprintln!(
        "experiment shapes: {} shape(s) × {:?} × {} seed(s) from {}, {} iterations: {} job(s) in \
         the list, {} this part's, {} to run on {} thread(s) -> {}",
        shapes.len(),
        cfg.shapes.algorithms,
        cfg.seeds,
        cfg.first_seed,
        cfg.iterations,
        list.len(),
        mine.len(),
        todo.len(),
        pool.current_num_threads(),
        out.display()
    );
    let progress = crate::progress::Progress::new(todo.len() as u64, "runs");
    pool.install(|| {
        todo.par_iter()
            .map(|(shape, algo, j, hash)| -> Result<(), ExperimentError> {
                let (run, last) = run_job(j).map_err(|e| ExperimentError::Job {
                    label: format!("{} seed {}", j.variant, j.seed()),
                    source: Box::new(e),
                })?;
                let spread =
                    imitation::iteration_log::demo_spread(&j.demos).map_or(f64::NAN, |s| s.rmse_m);
                let r = ShapeRun {
                    shape: shape.clone(),
                    algorithm: algo.clone(),
                    seed: run.seed,
                    settings_hash: hash.clone(),
                    episodes_per_iteration: run.episodes_per_iteration,
                    spread_rmse_m: spread,
                    path_rmse_m: run.logs.iter().map(|l| l.path_rmse).collect(),
                    final_distance_m: run.logs.iter().map(|l| l.final_distance).collect(),
                    performance: run.logs.iter().map(|l| l.performance).collect(),
                    wall_s: run.wall_s,
                    path_m: last.path,
                    final_orientation_error_deg: run
                        .logs
                        .iter()
                        .map(|l| l.final_orientation_error_deg)
                        .filter(|v| v.is_finite())
                        .collect(),
                    orientation_rmse_deg: last.orientation_rmse.map(f64::to_degrees),
                };
                let path = job_file(out, shape, algo, run.seed);
                ur5_shared::atomic_file::write(&path, &serde_json::to_vec_pretty(&r)?)?;
                progress.done_one(&format!(
                    "{:<16} {:<15} seed {:>3}: path RMSE {:.2} cm ({:.2} × spread), final \
                     distance {:.2} cm ({:.0} s)",
                    shape,
                    algo,
                    r.seed,
                    100.0 * r.path_rmse_m.last().copied().unwrap_or(f64::NAN),
                    r.path_rmse_m.last().copied().unwrap_or(f64::NAN) / spread,
                    100.0 * r.final_distance_m.last().copied().unwrap_or(f64::NAN),
                    r.wall_s
                ));
                Ok(())
            })
            .collect::<Result<Vec<()>, _>>()
    })?;
    drop(progress);
    // The tables, from every job of the list that is done.
    let mut done = Vec::new();
    let mut missing = 0;
    for (shape, algo, seed) in &list {
        let d = demos
            .iter()
            .find(|(s, _)| s == shape)
            .map(|(_, d)| d.clone());
        let d = match d {
            Some(d) => d,
            None => {
                let d = Arc::new(shape_demos(cfg, shape, out)?);
                demos.push((shape.clone(), d.clone()));
                d
            }
        };
        let (_, hash) = job(cfg, shape, algo, *seed, d)?;
        match read_done(out, shape, algo, *seed, &hash)? {
            Some(r) => done.push(r),
            None => missing += 1,
        }
    }
    let (text, json) = tables(&done, cfg.iterations, missing);
    std::fs::write(out.join("shapes.txt"), &text)?;
    std::fs::write(out.join("shapes.json"), serde_json::to_vec_pretty(&json)?)?;
    eprint!("{text}");
    pictures(cfg, &done, &demos, out)?;
    eprintln!(
        "experiment shapes done in {:.0} s; shapes.txt in {}",
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(json)
}

/// What a job keeps of its last iteration's noise-free episode: the tool path (m) and, with a
/// pose goal, its orientation RMSE against the drawings' mean orientation (rad).
struct LastEpisode {
    path: Vec<Point>,
    orientation_rmse: Option<f64>,
}

/// Runs job `j` as [`super::Job::run`] does (the same iterations, bit for bit), keeping the
/// last iteration's noise-free episode's measures.
fn run_job(j: &Job) -> Result<(super::Run, LastEpisode), ExperimentError> {
    fn go<R: Learn<Log = GaifoLog>>(
        mut run: R,
        iterations: usize,
        demos: &Demos,
    ) -> Result<(Vec<GaifoLog>, LastEpisode), ExperimentError> {
        let arm = crate::run::arm_for(&run)?;
        let targets = demos.task()?.targets();
        let (mut logs, mut path, mut frames) = (Vec::with_capacity(iterations), Vec::new(), None);
        for _ in 0..iterations {
            let (log, evals) = imitation::learn::iterate(&mut run, &arm)?;
            if let Some(e) = evals.first() {
                path = tool_paths(&e.x, &e.layout, e.horizon(), &demos.goal).swap_remove(0);
                frames = tool_frames(&e.x, &e.layout, e.horizon(), &targets)
                    .map(|mut f| f.swap_remove(0));
            }
            logs.push(log);
        }
        // Against the demonstrations' mean orientation, step by step.
        let shown = tool_frames(&demos.states, &demos.layout(), demos.horizon, &targets);
        let orientation_rmse = match (frames, shown) {
            (Some(f), Some(shown)) => {
                let refs: Vec<&[Frame]> = shown.iter().map(Vec::as_slice).collect();
                mean_frames(&refs)
                    .and_then(|mean| orientation_rmse(&f, &mean))
                    .ok()
            }
            _ => None,
        };
        Ok((
            logs,
            LastEpisode {
                path,
                orientation_rmse,
            },
        ))
    }
    use imitation::bco::Bco;
    use imitation::offpolicy::GaifoTd3;
    use imitation::ppo::gaifo_ppo::GaifoPpo;
    use imitation::replay_mean::ReplayMean;
    let t0 = Instant::now();
    let (d, demos) = ((*j.demos).clone(), &*j.demos);
    let (logs, last) = match &j.spec {
        Spec::LqrGaifo(c) => go(LqrGaifo::new(c.clone(), d)?, c.iterations, demos),
        Spec::GaifoPpo(c) => go(GaifoPpo::new(c.clone(), d)?, c.iterations, demos),
        Spec::Bco(c) => go(Bco::new(c.clone(), d)?, c.iterations, demos),
        Spec::GaifoTd3(c) => go(GaifoTd3::new(c.clone(), d)?, c.iterations, demos),
        Spec::ReplayMean(c) => go(ReplayMean::new(c.clone(), d)?, c.iterations, demos),
    }?;
    let run = super::Run {
        variant: j.variant.clone(),
        algorithm: j.algorithm().into(),
        seed: j.seed(),
        episodes_per_iteration: j.spec.samples(),
        horizon: j.demos.horizon,
        logs,
        wall_s: t0.elapsed().as_secs_f64(),
    };
    Ok((run, last))
}

/// Per algorithm, `OUT/shapes_<algorithm>.png` from the job files `done` (module docs): a
/// panel a shape with a run that kept its path, in cm along the shapes' plane from the goal.
fn pictures(
    cfg: &ExperimentConfig,
    done: &[ShapeRun],
    demos: &[(String, Arc<Demos>)],
    out: &Path,
) -> Result<(), ExperimentError> {
    let s = &cfg.shapes;
    let placement = cfg.shapes.placement(&cfg.lqr_gaifo.sim)?;
    let end = placement.end;
    let (u, v) = placement.axes().map_err(ExperimentError::Settings)?;
    let flat = |p: &Point| -> [f64; 2] {
        let d: [f64; 3] = core::array::from_fn(|k| p[k] - end[k]);
        let dot = |a: &[f64; 3]| 100.0 * (0..3).map(|k| a[k] * d[k]).sum::<f64>();
        [dot(&u), dot(&v)]
    };
    for algo in &s.algorithms {
        let mut panels = Vec::new();
        for (shape, d) in demos {
            let runs: Vec<&ShapeRun> = done
                .iter()
                .filter(|r| &r.shape == shape && &r.algorithm == algo && !r.path_m.is_empty())
                .collect();
            if runs.is_empty() {
                continue;
            }
            let ratio = runs
                .iter()
                .map(|r| r.path_rmse_m.last().copied().unwrap_or(f64::NAN) / r.spread_rmse_m)
                .sum::<f64>()
                / runs.len() as f64;
            panels.push(crate::plot_paths::PathPanel {
                title: format!("{shape}  {ratio:.2}× spread"),
                demos: tool_paths(&d.states, &d.layout(), d.horizon, &d.goal)
                    .iter()
                    .map(|p| p.iter().map(flat).collect())
                    .collect(),
                imitations: runs
                    .iter()
                    .map(|r| r.path_m.iter().map(flat).collect())
                    .collect(),
                goal: flat(&d.goal),
            });
        }
        if panels.is_empty() {
            eprintln!(
                "no picture for {algo}: its job files keep no tool path (written by an earlier \
                 build); run those jobs again to draw them"
            );
            continue;
        }
        let file = out.join(format!("shapes_{algo}.png"));
        crate::plot_paths::plot_path_grid(
            &file,
            &format!(
                "LASA shapes, {algo}, iteration {}: drawings grey, last noise-free episode per seed \
                 in colour, goal ringed (cm, {} plane)",
                cfg.iterations, s.plane
            ),
            "cm",
            &panels,
            6,
            300,
        )?;
        eprintln!("picture of {} shape(s) -> {}", panels.len(), file.display());
    }
    Ok(())
}

/// The job's file if it is there and was run with the settings of `hash`.
fn read_done(
    out: &Path,
    shape: &str,
    algo: &str,
    seed: u64,
    hash: &str,
) -> Result<Option<ShapeRun>, ExperimentError> {
    let path = job_file(out, shape, algo, seed);
    if !path.is_file() {
        return Ok(None);
    }
    let bytes = std::fs::read(&path)?;
    let r: ShapeRun = serde_json::from_slice(&bytes).map_err(|e| {
        ExperimentError::Settings(format!(
            "{}: not a shapes job file ({e}); delete it to run the job again",
            path.display()
        ))
    })?;
    Ok((r.settings_hash == hash).then_some(r))
}

/// Mean and largest of `v`.
fn mean_max(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (m, v.iter().copied().fold(f64::NEG_INFINITY, f64::max))
}

/// The table per shape and algorithm, at the last iteration of each run: seeds, the drawings'
/// spread, path RMSE (mean, largest), its ratio to the spread (mean, largest), seeds within 1×
/// and 2× of the spread, final distance (mean, largest) and seeds within 1 cm; then per
/// algorithm the shapes whose mean ratio is within 1× and 2× and whose every final distance is
/// within 1 cm.
pub fn tables(runs: &[ShapeRun], iterations: usize, missing: usize) -> (String, serde_json::Value) {
    let mut text = format!(
        "LASA shapes at iteration {iterations} (path RMSE of the noise-free episode against the \
         drawings' mean path; spread = the drawings' own, each against the mean of the others)\n\
         {:<16} {:<15} {:>5} {:>9} {:>13} {:>13} {:>5} {:>5} {:>13} {:>5}\n",
        "shape",
        "algorithm",
        "seeds",
        "spread_cm",
        "path_cm m/max",
        "ratio m/max",
        "<=1x",
        "<=2x",
        "final_cm m/max",
        "<=1cm"
    );
    // A pose goal (six joints): the orientation too.
    let posed = runs.iter().any(|r| r.orientation_rmse_deg.is_some());
    if posed {
        text.pop();
        text += &format!(" {:>13} {:>13}\n", "fin_deg m/max", "path_deg m/max");
    }
    let mut rows = Vec::new();
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in runs {
        let k = (r.shape.clone(), r.algorithm.clone());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    // Per algorithm: shapes, within 1×, within 2×, every final within 1 cm.
    let mut totals: Vec<(String, [usize; 4])> = Vec::new();
    for (shape, algo) in &keys {
        let rs: Vec<&ShapeRun> = runs
            .iter()
            .filter(|r| &r.shape == shape && &r.algorithm == algo)
            .collect();
        let last = |v: &Vec<f64>| v.last().copied().unwrap_or(f64::NAN);
        let path: Vec<f64> = rs.iter().map(|r| last(&r.path_rmse_m)).collect();
        let fin: Vec<f64> = rs.iter().map(|r| last(&r.final_distance_m)).collect();
        let spread = rs[0].spread_rmse_m;
        let ratio: Vec<f64> = path.iter().map(|p| p / spread).collect();
        let (pm, px) = mean_max(&path);
        let (rm, rx) = mean_max(&ratio);
        let (fm, fx) = mean_max(&fin);
        let within = |lim: f64| ratio.iter().filter(|r| **r <= lim).count();
        let near = fin.iter().filter(|d| **d <= 0.01).count();
        text += &format!(
            "{shape:<16} {algo:<15} {:>5} {:>9.2} {:>6.2}/{:<6.2} {:>6.2}/{:<6.2} {:>5} {:>5} {:>6.2}/{:<6.2} {:>5}\n",
            rs.len(),
            100.0 * spread,
            100.0 * pm,
            100.0 * px,
            rm,
            rx,
            within(1.0),
            within(2.0),
            100.0 * fm,
            100.0 * fx,
            near
        );
        let mut row = serde_json::json!({"shape": shape, "algorithm": algo, "seeds": rs.len(),
            "spread_rmse_m": spread, "path_rmse_mean_m": pm, "path_rmse_max_m": px,
            "ratio_mean": rm, "ratio_max": rx, "seeds_within_1x": within(1.0),
            "seeds_within_2x": within(2.0), "final_distance_mean_m": fm,
            "final_distance_max_m": fx, "seeds_within_1cm": near});
        if posed {
            let fin_deg: Vec<f64> = rs
                .iter()
                .map(|r| last(&r.final_orientation_error_deg))
                .collect();
            let path_deg: Vec<f64> = rs
                .iter()
                .map(|r| r.orientation_rmse_deg.unwrap_or(f64::NAN))
                .collect();
            let ((om, ox), (qm, qx)) = (mean_max(&fin_deg), mean_max(&path_deg));
            text.pop();
            text += &format!(" {om:>6.2}/{ox:<6.2} {qm:>6.2}/{qx:<6.2}\n");
            row["final_orientation_error_mean_deg"] = om.into();
            row["final_orientation_error_max_deg"] = ox.into();
            row["orientation_rmse_mean_deg"] = qm.into();
            row["orientation_rmse_max_deg"] = qx.into();
        }
        rows.push(row);
        let t = match totals.iter_mut().find(|(a, _)| a == algo) {
            Some(t) => t,
            None => {
                totals.push((algo.clone(), [0; 4]));
                totals.last_mut().expect("just pushed")
            }
        };
        t.1[0] += 1;
        t.1[1] += usize::from(rm <= 1.0);
        t.1[2] += usize::from(rx <= 2.0);
        t.1[3] += usize::from(fx <= 0.01);
    }
    let mut summary = Vec::new();
    for (algo, [n, one, two, cm]) in &totals {
        text += &format!(
            "{algo}: mean path RMSE within the spread on {one} of {n} shape(s); every seed within \
             2× on {two}; every final distance within 1 cm on {cm}\n"
        );
        summary.push(serde_json::json!({"algorithm": algo, "shapes": n,
            "shapes_mean_within_1x": one, "shapes_all_within_2x": two,
            "shapes_all_final_within_1cm": cm}));
    }
    if missing > 0 {
        text += &format!(
            "{missing} job(s) of the list not done yet (other shards, or not run): not in the \
             table\n"
        );
    }
    (
        text,
        serde_json::json!({"iterations": iterations, "rows": rows, "totals": summary,
            "jobs_missing": missing}),
    )
}
