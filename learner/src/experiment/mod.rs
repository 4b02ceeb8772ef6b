//! `learner experiment <name>`: the paper's experiments, one command each.
//!
//! | name | what | default |
//! |---|---|---|
//! | `comparison` | LQR+GAIfO vs GAIfO (PPO) on the default goal (paper: "learning rate comparison"), PPO also with a converged budget; the summary adds episodes to normalised 0.9 and to 1 cm; on request also the baselines BCO(α), GAIfO (TD3) and the mean path ([`BASELINES`]) on the same arm, demonstrations and episodes per iteration; with `comparison_workspace_goals`, every algorithm on the five [`goals::WORKSPACE_GOALS`] with the steady-precision outputs and the summary over the goals | 10 seeds × 100 iterations each |
//! | `generalisation` | demonstrations from k of the 8 square points, target the unseen centre (paper: "multi-point") | k = 1…8, 5 seeds, 15 iterations |
//! | `stability` | LQR+GAIfO far beyond the paper's 100 iterations: does it degrade, and does a stronger critic make it? | 100 and 1000 critic steps per iteration, 5 seeds × 200 iterations |
//! | `ablation` | LQR+GAIfO's defaults against the same with one decision for precision undone (docs/design.md §5 D25, D36), or candidates ([`PRECISION_VARIANTS`]); with `ablation_workspace_goals`, on the five [`goals::WORKSPACE_GOALS`] with the steady-precision outputs | [`ABLATION_VARIANTS`], 5 seeds × 50 iterations |
//! | `multi-goal` | one MDGPS policy from the 8 square points vs the centre's LQR+GAIfO controller, at never-demonstrated goals ([`multi_goal`]) | 3 seeds × 20 iterations |
//! | `shapes` | every LASA handwriting shape imitated from its drawings, measured by the path ([`shapes`]) | 26 shapes × 5 seeds × 30 iterations |
//!
//! The simulated-vs-"physical" experiment runs over IPC: see [`ipc`].
//!
//! Every run is a set of independent jobs (variant × seed), run on a rayon pool of
//! `threads` workers (0 = all cores). A job's result depends only on its own seed and
//! settings, never on the thread count or on the other jobs: the CSV (bar the wall-time
//! columns) is the same with 1 thread or 8.
//!
//! Outputs in `--out` (default `runs/experiments/<name>`):
//! - `<name>.csv`: one row per (variant, seed, iteration): `experiment,variant,` followed by
//!   the columns of [`crate::io::log::CSV_HEADER`] (iteration, seed, algorithm, normalised
//!   performance, task cost, final distance, critic loss, Wasserstein estimate, KL, η, step
//!   multiplier, wall time per phase, learner CPU time);
//! - `<name>.png`: normalised performance of the noise-free episode per iteration, mean ±
//!   standard error over seeds, one curve per variant;
//! - `summary.txt` / `summary.json`: the table printed at the end;
//! - a pose task (`[expert.task] joints = 6` with a `goal_pose`; the layout is the task's) adds
//!   its measure of the orientation: the CSV's last column `final_orientation_error_deg`, a
//!   table of the final orientation error in the summary and a third panel in the figure;
//! - the demonstrations used (`demos.npz`, or `experts/` for the generalisation experiment).

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use imitation::demos::Demos;

mod error;

pub use ablation::{ablation_variant, ABLATION_VARIANTS, PRECISION_VARIANTS};
pub use error::ExperimentError;

use crate::error::ensure;
use imitation::expert::ExpertConfig;
use imitation::gaifo::{GaifoConfig, GaifoLog};
use imitation::ppo::gaifo_ppo::GaifoPpoConfig;

mod ablation;
pub mod goals;
pub mod ipc;
pub mod multi_goal;
pub mod pilqr;
pub mod scheduler;
pub mod shapes;
pub mod shard;
mod spec;
pub mod summary;

pub use spec::{baseline, Spec, BASELINES};

pub use summary::{csv_header, summarise, summary_text, write_outputs, SummaryRow};

mod demos;

use demos::demos_for;
pub use demos::{combine_demos, expert_demos, experts_at, generalisation_demos, subset};

/// Which experiment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExperimentName {
    /// LQR+GAIfO vs GAIfO (PPO), normalised performance per iteration.
    Comparison,
    /// Demonstrations from subsets of the 8 square points; reach the unseen centre.
    Generalisation,
    /// The same LQR+GAIfO run on the nominal and on the perturbed arm, over IPC in real time.
    SimVsPhysical,
    /// LQR+GAIfO for 200 iterations: late-iteration stability.
    Stability,
    /// LQR+GAIfO's defaults against variants with a decision undone (precision near the goal).
    Ablation,
    /// One MDGPS policy for many goals vs the centre's linear-Gaussian controller.
    MultiGoal,
    /// The KL-bounded LQR step against PILQR, nominal and perturbed arm.
    Pilqr,
    /// Every LASA handwriting shape × seeds, measured by the path.
    Shapes,
}

impl ExperimentName {
    /// File-name form (`comparison`, `sim-vs-physical`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Comparison => "comparison",
            Self::Generalisation => "generalisation",
            Self::SimVsPhysical => "sim-vs-physical",
            Self::Stability => "stability",
            Self::Ablation => "ablation",
            Self::MultiGoal => "multi-goal",
            Self::Pilqr => "pilqr",
            Self::Shapes => "shapes",
        }
    }
}

/// Settings of an experiment (TOML: `learner experiment <name> --config FILE`, layered over
/// that experiment's defaults, [`ExperimentConfig::defaults`]; unknown keys are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExperimentConfig {
    /// Seeds per variant: `first_seed, first_seed + 1, …`.
    pub seeds: usize,
    /// First seed.
    pub first_seed: u64,
    /// Iterations per run (overrides `lqr_gaifo.iterations` and `gaifo_ppo.iterations`).
    pub iterations: usize,
    /// Worker threads for the runs (seeds) and, inside each, the episodes of an iteration
    /// (one rayon pool, so never more threads in all); 0 = one per core.
    pub threads: usize,
    /// Algorithms of the comparison: `lqr-gaifo`, `gaifo-ppo` (the paper's budget, N =
    /// `gaifo_ppo.samples` episodes per iteration) and `gaifo-ppo-converged` (the same with
    /// N = `ppo_converged_samples`, a budget at which it converges); also the baselines
    /// [`BASELINES`] `bco`, `gaifo-td3` and `replay-mean`, on LQR+GAIfO's arm with its N
    /// ([`baseline`]).
    pub algorithms: Vec<String>,
    /// Comparison: noisy episodes per iteration of `gaifo-ppo-converged`. Ours: 40 (with it,
    /// one seed reached normalised 0.95 by iteration 55 with it).
    pub ppo_converged_samples: usize,
    /// The expert that records the demonstrations (its `task.goal` is the target; its
    /// `demos` is the number of demonstrations; the generalisation experiment trains one per
    /// square point and one at the centre for the normalisation).
    pub expert: ExpertConfig,
    /// LQR+GAIfO (its `seed` and `iterations` are set per run).
    pub lqr_gaifo: GaifoConfig,
    /// GAIfO (PPO) (its `seed` and `iterations` are set per run).
    pub gaifo_ppo: GaifoPpoConfig,
    /// Comparison: BCO(α) (its `sim`, `samples`, `seed` and `iterations` are set per run, the
    /// first two from `lqr_gaifo`).
    pub bco: imitation::bco::BcoConfig,
    /// Comparison: GAIfO (TD3) (the same four set per run as for `bco`).
    pub gaifo_td3: imitation::offpolicy::GaifoTd3Config,
    /// Generalisation: numbers of demonstrated square points, each a curve.
    pub subset_sizes: Vec<usize>,
    /// Generalisation: demonstrations per square point.
    pub demos_per_point: usize,
    /// Stability: one curve per number of critic (Adam) steps per iteration
    /// (`lqr_gaifo.discriminator.n_critic`), to probe the paper's guess that a critic which
    /// outpaces the controller causes the late degradation.
    pub critic_steps: Vec<usize>,
    /// Sim vs physical: the "physical" arm's perturbation (`hil-sim` knobs).
    pub physical: ur5_shared::config::Perturbation,
    /// Sim vs physical: iterations of the perturbed arm's expert, which only normalises that
    /// arm's curve (it stops early only when this is reached). Ours: 200 (on the default
    /// perturbation its noise-free cost falls to 1.2 % of the random policy's by then, the
    /// nominal expert's 0.6 % within 15; docs/design.md §5 D26).
    pub physical_expert_iterations: usize,
    /// Sim vs physical: simulated seconds per wall-clock second of the real-time loop.
    pub time_compression: f64,
    /// Ablation: the variants to run, each a curve (names from [`ABLATION_VARIANTS`]).
    pub ablation_variants: Vec<String>,
    /// Ablation: run every variant on the five [`goals::WORKSPACE_GOALS`] (each with its own
    /// expert's demonstrations) instead of `expert.task.goal`, and add the steady-precision
    /// outputs (`precision.txt`, `reach.txt`, `spread.csv`, [`goals`]).
    pub ablation_workspace_goals: bool,
    /// Comparison: run every algorithm on the five [`goals::WORKSPACE_GOALS`] (each with its
    /// own expert's demonstrations, the baselines on LQR+GAIfO's arm and episodes as at one
    /// goal) instead of `expert.task.goal`, and add the steady-precision outputs and the
    /// summary over the goals ([`goals::write_precision`]). Left out of the settings file
    /// when off, so earlier settings hash as before ([`shard::settings_hash`]).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub comparison_workspace_goals: bool,
    /// Multi-goal: the global policy and its S-step (MDGPS's per-condition settings are
    /// `lqr_gaifo`'s, so it uses LQR+GAIfO's N episodes per condition).
    pub mdgps_policy: imitation::mlp_policy::opt::PolicyOptConfig,
    /// Multi-goal: MDGPS's C-step KL bound, nats per time step (`MdgpsConfig::kl_step`; the
    /// centre's LQR+GAIfO keeps `lqr_gaifo.algorithm.kl_step`).
    pub mdgps_kl_step: f64,
    /// Multi-goal: seeded evaluation goals inside the square (besides the centre). Ours: 8.
    pub eval_inside: usize,
    /// Multi-goal: evaluation goals just outside the square. Ours: 4, one per edge.
    pub eval_outside: usize,
    /// Multi-goal: how far outside the square those are (m). Ours: 0.03.
    pub eval_outside_margin: f64,
    /// Multi-goal: seed of the evaluation goals (fixed across run seeds, so every seed is
    /// evaluated at the same goals).
    pub eval_seed: u64,
    /// PILQR: learners, arms, methods and goals compared ([`pilqr`]).
    pub pilqr: pilqr::PilqrExperimentConfig,
    /// Shapes: which LASA shapes, algorithms and placement ([`shapes`]).
    pub shapes: shapes::ShapesExperimentConfig,
}

/// The comparison's algorithms ([`ExperimentConfig::algorithms`]).
pub const ALGORITHMS: [&str; 3] = ["lqr-gaifo", "gaifo-ppo", "gaifo-ppo-converged"];

impl Default for ExperimentConfig {
    fn default() -> Self {
        Self::defaults(ExperimentName::Comparison)
    }
}

impl ExperimentConfig {
    /// The defaults of experiment `name` (10 seeds × 100 iterations for the
    /// comparison; 15 iterations for the generalisation; 50 for sim vs physical).
    pub fn defaults(name: ExperimentName) -> Self {
        let base = Self {
            seeds: 10,
            first_seed: 0,
            iterations: 100,
            threads: 0,
            algorithms: ALGORITHMS.iter().map(|a| a.to_string()).collect(),
            ppo_converged_samples: 40,
            expert: ExpertConfig::default(),
            lqr_gaifo: GaifoConfig::default(),
            gaifo_ppo: GaifoPpoConfig::default(),
            bco: Default::default(),
            gaifo_td3: Default::default(),
            subset_sizes: (1..=8).collect(),
            demos_per_point: 5,
            critic_steps: vec![100, 1000],
            physical: ur5_shared::config::Perturbation::physical_stand_in(1),
            physical_expert_iterations: 200,
            time_compression: 10.0,
            ablation_variants: ABLATION_VARIANTS
                .iter()
                .map(|(n, _)| n.to_string())
                .collect(),
            ablation_workspace_goals: false,
            comparison_workspace_goals: false,
            mdgps_policy: Default::default(),
            mdgps_kl_step: imitation::mdgps::MdgpsConfig::default().kl_step,
            eval_inside: 8,
            eval_outside: 4,
            eval_outside_margin: 0.03,
            eval_seed: 14,
            pilqr: Default::default(),
            shapes: Default::default(),
        };
        match name {
            ExperimentName::Comparison => base,
            ExperimentName::Generalisation => Self {
                seeds: 5,
                iterations: 15,
                ..base
            },
            ExperimentName::SimVsPhysical => Self {
                seeds: 3,
                iterations: 50,
                ..base
            },
            ExperimentName::Stability => Self {
                seeds: 5,
                iterations: 200,
                ..base
            },
            ExperimentName::Ablation => Self {
                seeds: 5,
                iterations: 50,
                ..base
            },
            ExperimentName::MultiGoal => Self {
                seeds: 3,
                iterations: 20,
                ..base
            },
            ExperimentName::Pilqr => pilqr::defaults(base),
            ExperimentName::Shapes => shapes::defaults(base),
        }
    }

    /// Checks the settings an experiment needs.
    pub fn validate(&self, name: ExperimentName) -> Result<(), ExperimentError> {
        ensure!(
            self.seeds >= 1,
            ExperimentError::Settings("seeds must be >= 1".into())
        );
        ensure!(
            self.iterations >= 1,
            ExperimentError::Settings("iterations must be >= 1".into())
        );
        for a in &self.algorithms {
            ensure!(
                ALGORITHMS.contains(&a.as_str()) || BASELINES.contains(&a.as_str()),
                ExperimentError::Settings(format!(
                    "algorithms: unknown `{a}`; known: {}, {}",
                    ALGORITHMS.join(", "),
                    BASELINES.join(", ")
                ))
            );
        }
        ensure!(
            (1..=GaifoConfig::MAX_COUNT).contains(&self.ppo_converged_samples),
            ExperimentError::Settings(format!(
                "ppo_converged_samples = {}: must be in 1..={}",
                self.ppo_converged_samples,
                GaifoConfig::MAX_COUNT
            ))
        );
        if name == ExperimentName::Comparison {
            ensure!(
                !self.algorithms.is_empty(),
                ExperimentError::Settings("algorithms is empty".into())
            );
        }
        if name == ExperimentName::Stability {
            ensure!(
                !self.critic_steps.is_empty() && self.critic_steps.iter().all(|&n| n >= 1),
                ExperimentError::Settings(format!(
                    "critic_steps must list numbers >= 1, got {:?}",
                    self.critic_steps
                ))
            );
        }
        if name == ExperimentName::Ablation {
            ensure!(
                !self.ablation_variants.is_empty(),
                ExperimentError::Settings("ablation_variants is empty".into())
            );
            for v in &self.ablation_variants {
                ablation_variant(v, &self.lqr_gaifo)?;
            }
        }
        if name == ExperimentName::MultiGoal {
            ensure!(
                self.demos_per_point >= 1,
                ExperimentError::Settings("demos_per_point must be >= 1".into())
            );
            ensure!(
                self.eval_outside_margin > 0.0 && self.eval_outside_margin <= 1.0,
                ExperimentError::Settings(format!(
                    "eval_outside_margin = {}: must be in (0, 1] m",
                    self.eval_outside_margin
                ))
            );
            ensure!(
                self.eval_inside <= 1000 && self.eval_outside <= 1000,
                ExperimentError::Settings(format!(
                    "eval_inside = {}, eval_outside = {}: each must be in 0..=1000",
                    self.eval_inside, self.eval_outside
                ))
            );
            imitation::mdgps::MdgpsConfig {
                lqr_gaifo: self.lqr_gaifo.clone(),
                kl_step: self.mdgps_kl_step,
                policy: self.mdgps_policy.clone(),
            }
            .validate()?;
        }
        if name == ExperimentName::Generalisation {
            ensure!(
                !self.subset_sizes.is_empty()
                    && self.subset_sizes.iter().all(|k| (1..=8).contains(k)),
                ExperimentError::Settings(format!(
                    "subset_sizes must be numbers of square points in 1..=8, got {:?}",
                    self.subset_sizes
                ))
            );
            ensure!(
                self.demos_per_point >= 1,
                ExperimentError::Settings("demos_per_point must be >= 1".into())
            );
        }
        ensure!(
            (1..=GaifoConfig::MAX_COUNT).contains(&self.physical_expert_iterations),
            ExperimentError::Settings(format!(
                "physical_expert_iterations = {}: must be in 1..={}",
                self.physical_expert_iterations,
                GaifoConfig::MAX_COUNT
            ))
        );
        ensure!(
            self.time_compression > 0.0 && self.time_compression.is_finite(),
            ExperimentError::Settings("time_compression must be > 0".into())
        );
        if self.algorithms.iter().any(|a| a == "bco") {
            self.bco.validate()?;
        }
        if self.algorithms.iter().any(|a| a == "gaifo-td3") {
            self.gaifo_td3.validate()?;
        }
        ensure!(
            self.expert.task.goal_pose.is_none()
                || !(self.comparison_workspace_goals || self.ablation_workspace_goals),
            ExperimentError::Settings(
                "comparison_workspace_goals and ablation_workspace_goals move the goal point to \
                 the five workspace goals; a pose task (expert.task.goal_pose) has a pose of its \
                 own: leave them off"
                    .into()
            )
        );
        self.expert.task.validate()?;
        self.expert.sim.validate()?;
        Ok(())
    }

    fn seed_list(&self) -> Vec<u64> {
        (0..self.seeds as u64)
            .map(|i| self.first_seed + i)
            .collect()
    }
}

/// One finished run: a variant (curve) and seed.
#[derive(Clone, Debug)]
pub struct Run {
    /// Curve label (algorithm, subset size, arm, …).
    pub variant: String,
    /// `lqr-gaifo` or `gaifo-ppo`.
    pub algorithm: String,
    /// Seed.
    pub seed: u64,
    /// Noisy (training) episodes per iteration N.
    pub episodes_per_iteration: usize,
    /// Steps per episode T.
    pub horizon: usize,
    /// One log per iteration.
    pub logs: Vec<GaifoLog>,
    /// Wall time of the whole run, s.
    pub wall_s: f64,
}

/// One independent unit of work: a variant at one seed on one demonstration set.
#[derive(Clone)]
pub struct Job {
    /// Curve label.
    pub variant: String,
    /// Algorithm and settings (seed and iterations included).
    pub spec: Spec,
    /// The demonstrations (state-only use) and the task.
    pub demos: Arc<Demos>,
}

impl Job {
    fn seed(&self) -> u64 {
        self.spec.seed()
    }

    fn algorithm(&self) -> &'static str {
        self.spec.algorithm()
    }

    /// Runs the job in this thread.
    pub fn run(&self) -> Result<Run, ExperimentError> {
        let t0 = Instant::now();
        let logs = self.spec.logs((*self.demos).clone())?;
        Ok(Run {
            variant: self.variant.clone(),
            algorithm: self.algorithm().into(),
            seed: self.seed(),
            episodes_per_iteration: self.spec.samples(),
            horizon: self.demos.horizon,
            logs,
            wall_s: t0.elapsed().as_secs_f64(),
        })
    }
}

/// A rayon pool of `threads` workers (0 = one per core).
pub fn pool(threads: usize) -> Result<rayon::ThreadPool, ExperimentError> {
    ensure!(
        threads <= MAX_THREADS,
        ExperimentError::Settings(format!(
            "--threads {threads}: must be 0 (one per core) to {MAX_THREADS}; this machine has {} \
         cores",
            std::thread::available_parallelism().map_or(1, |n| n.get())
        ))
    );
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(ExperimentError::from)
}

/// Most worker threads a pool may have (`--threads`, `threads`): far above any core count we
/// run on, low enough that a typo (100000) is refused at once instead of spawning threads
/// for minutes.
pub const MAX_THREADS: usize = 1024;

/// Runs every job on `pool`, printing one line per finished job; results in job order.
pub fn run_jobs(pool: &rayon::ThreadPool, jobs: &[Job]) -> Result<Vec<Run>, ExperimentError> {
    let done = AtomicUsize::new(0);
    let t0 = Instant::now();
    let total = jobs.len();
    let progress = crate::progress::Progress::new(total as u64, "runs");
    pool.install(|| {
        jobs.par_iter()
            .map(|job| {
                let run = job.run().map_err(|e| ExperimentError::Job {
                    label: format!("{} seed {} ({})", job.variant, job.seed(), job.algorithm()),
                    source: Box::new(e),
                })?;
                let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                let last = run.logs.last().map(|l| l.performance).unwrap_or(f64::NAN);
                progress.done_one(&format!(
                    "[{k:>3}/{total}] {:<18} seed {:>3}: {} iterations, final normalised performance {:>6.3} ({:.0} s; {:.0} s elapsed)",
                    run.variant,
                    run.seed,
                    run.logs.len(),
                    last,
                    run.wall_s,
                    t0.elapsed().as_secs_f64()
                ));
                Ok(run)
            })
            .collect()
    })
}

/// Jobs of the comparison: every algorithm × seed on `demos`.
pub fn comparison_jobs(cfg: &ExperimentConfig, demos: Arc<Demos>) -> Vec<Job> {
    let mut jobs = Vec::new();
    for a in &cfg.algorithms {
        for seed in cfg.seed_list() {
            let (variant, spec) = if let Some(spec) = baseline(cfg, a, seed) {
                (a.clone(), spec)
            } else if a.starts_with("gaifo-ppo") {
                let mut c = cfg.gaifo_ppo.clone();
                c.seed = seed;
                c.iterations = cfg.iterations;
                let mut label = a.clone();
                if a == "gaifo-ppo-converged" {
                    c.samples = cfg.ppo_converged_samples;
                    label = format!("gaifo-ppo-{}ep", c.samples);
                }
                (label, Spec::GaifoPpo(c))
            } else {
                let mut c = cfg.lqr_gaifo.clone();
                c.seed = seed;
                c.iterations = cfg.iterations;
                (a.clone(), Spec::LqrGaifo(c))
            };
            jobs.push(Job {
                variant,
                spec,
                demos: demos.clone(),
            });
        }
    }
    jobs
}

/// LQR+GAIfO jobs for one variant over every seed.
pub fn lqr_jobs(cfg: &ExperimentConfig, variant: &str, demos: Arc<Demos>) -> Vec<Job> {
    cfg.seed_list()
        .into_iter()
        .map(|seed| {
            let mut c = cfg.lqr_gaifo.clone();
            c.seed = seed;
            c.iterations = cfg.iterations;
            Job {
                variant: variant.into(),
                spec: Spec::LqrGaifo(c),
                demos: demos.clone(),
            }
        })
        .collect()
}

/// Runs an in-process experiment (`comparison`, `generalisation`, `stability`) and writes its
/// outputs; `demos` replaces training the expert (comparison and stability).
pub fn run(
    name: ExperimentName,
    cfg: &ExperimentConfig,
    out: &Path,
    demos: Option<&Path>,
) -> Result<(Vec<Run>, Vec<SummaryRow>), ExperimentError> {
    run_sharded(name, cfg, out, demos, None)
}

/// [`run`], of only the jobs of `shard` when given ([`shard::select`]), noting them in
/// `out/shard.json` for [`shard::merge`].
pub fn run_sharded(
    name: ExperimentName,
    cfg: &ExperimentConfig,
    out: &Path,
    demos: Option<&Path>,
    shard: Option<shard::Shard>,
) -> Result<(Vec<Run>, Vec<SummaryRow>), ExperimentError> {
    cfg.validate(name)?;
    let pool = pool(cfg.threads)?;
    eprintln!(
        "experiment {}: {} seed(s) from {}, {} iterations, {} worker thread(s) -> {}",
        name.as_str(),
        cfg.seeds,
        cfg.first_seed,
        cfg.iterations,
        pool.current_num_threads(),
        out.display()
    );
    let t0 = Instant::now();
    let (jobs, title) = match name {
        ExperimentName::Comparison => {
            let sets = if cfg.comparison_workspace_goals {
                goals::workspace_goal_sets(cfg, demos, "comparison_workspace_goals", &pool)?
            } else {
                vec![(String::new(), Arc::new(demos_for(cfg, demos, out)?))]
            };
            (
                goals::at_goals(&sets, |d| comparison_jobs(cfg, d)),
                format!(
                    "LQR+GAIfO vs GAIfO (PPO): {} noisy episodes per iteration (PPO also {})",
                    cfg.lqr_gaifo.samples, cfg.ppo_converged_samples
                ),
            )
        }
        ExperimentName::Stability => {
            let d = Arc::new(demos_for(cfg, demos, out)?);
            let mut jobs = Vec::new();
            for &steps in &cfg.critic_steps {
                let mut c = cfg.clone();
                c.lqr_gaifo.discriminator.n_critic = steps;
                jobs.extend(lqr_jobs(&c, &format!("critic {steps} steps/it"), d.clone()));
            }
            (
                jobs,
                format!("LQR+GAIfO over {} iterations", cfg.iterations),
            )
        }
        ExperimentName::Ablation => {
            // One demonstration set per goal: the default goal's (or --demos), or one expert's
            // at each workspace goal.
            let sets: Vec<(String, Arc<Demos>)> = if cfg.ablation_workspace_goals {
                goals::workspace_goal_sets(cfg, demos, "ablation_workspace_goals", &pool)?
            } else {
                vec![(String::new(), Arc::new(demos_for(cfg, demos, out)?))]
            };
            let mut jobs = Vec::new();
            for (goal, d) in &sets {
                for v in &cfg.ablation_variants {
                    let mut c = cfg.clone();
                    c.lqr_gaifo = ablation_variant(v, &cfg.lqr_gaifo)?;
                    jobs.extend(lqr_jobs(&c, &format!("{v}{goal}"), d.clone()));
                }
            }
            (
                jobs,
                "LQR+GAIfO: defaults vs critic decisions undone (docs/design.md §5 D25)"
                    .to_string(),
            )
        }
        ExperimentName::Generalisation => {
            ensure!(
                demos.is_none(),
                ExperimentError::Settings(
                    "--demos does not apply to the generalisation experiment (it trains 9 experts)"
                        .into()
                )
            );
            let sets = generalisation_demos(cfg, &pool, out)?;
            let mut jobs = Vec::new();
            for (k, d) in sets {
                let label = format!("{k} point{}", if k == 1 { "" } else { "s" });
                jobs.extend(lqr_jobs(cfg, &label, Arc::new(d)));
            }
            (
                jobs,
                "Generalisation: demonstrations from k square points, target the centre"
                    .to_string(),
            )
        }
        ExperimentName::SimVsPhysical => {
            return Err(ExperimentError::Settings(
                "sim-vs-physical runs over IPC: learner::experiment::ipc::run".into(),
            )
            .into())
        }
        ExperimentName::MultiGoal => {
            return Err(ExperimentError::Settings(
                "multi-goal has its own outputs: learner::experiment::multi_goal::run".into(),
            )
            .into())
        }
        ExperimentName::Pilqr => {
            return Err(ExperimentError::Settings(
                "pilqr has its own outputs: learner::experiment::pilqr::run".into(),
            )
            .into())
        }
        ExperimentName::Shapes => {
            return Err(ExperimentError::Settings(
                "shapes has its own outputs: learner::experiment::shapes::run".into(),
            )
            .into())
        }
    };
    let total = jobs.len();
    let (indices, jobs) = shard::select(shard, jobs);
    // What makes the runs of one experiment (shards merge only with shards of the same).
    let settings_hash = shard::settings_hash(cfg, demos)?;
    if let (Some(s), true) = (shard, jobs.is_empty()) {
        // More shards than jobs: a valid part with nothing to do.
        crate::io::create_dir(out)?;
        shard::write_meta(
            out,
            name.as_str(),
            &title,
            s,
            total,
            &[],
            &[],
            settings_hash,
        )?;
        eprintln!(
            "experiment {}: shard {}/{} of {total} jobs holds none of them: nothing to do ({})",
            name.as_str(),
            s.k,
            s.n,
            out.join(shard::SHARD_FILE).display()
        );
        return Ok((Vec::new(), Vec::new()));
    }
    let runs = run_jobs(&pool, &jobs)?;
    let rows = write_outputs(name.as_str(), &title, &runs, out)?;
    if goals::at_several_goals(&runs) {
        eprint!("{}", goals::write_precision(&runs, out)?);
    }
    if let Some(s) = shard {
        shard::write_meta(
            out,
            name.as_str(),
            &title,
            s,
            total,
            &indices,
            &runs,
            settings_hash,
        )?;
    }
    eprint!("{}", summary_text(&rows));
    eprintln!(
        "experiment {} done in {:.0} s; {} and {} in {}",
        name.as_str(),
        t0.elapsed().as_secs_f64(),
        format_args!("{}.csv", name.as_str()),
        format_args!("{}.png", name.as_str()),
        out.display()
    );
    Ok((runs, rows))
}

#[cfg(test)]
mod tests {
    use super::summary::report_points;
    use super::*;

    #[test]
    fn subsets_spread_around_the_square() {
        assert_eq!(subset(1), vec![0]);
        assert_eq!(subset(2), vec![0, 4]);
        assert_eq!(subset(4), vec![0, 2, 4, 6]);
        assert_eq!(subset(8), (0..8).collect::<Vec<_>>());
        for k in 1..=8 {
            let s = subset(k);
            let mut u = s.clone();
            u.sort();
            u.dedup();
            assert_eq!(u.len(), k, "k = {k}: {s:?} has repeats");
        }
    }

    /// Episodes to a threshold: i·N for a seed that first reaches it at iteration i, mean ±
    /// s.e. over the seeds that reached it, and the count of those.
    #[test]
    fn reach_counts_the_training_episodes_before_the_first_reaching_iteration() {
        let log = |p: f64, d: f64| GaifoLog {
            performance: p,
            final_distance: d,
            ..GaifoLog::default()
        };
        let run = |seed: u64, curve: &[(f64, f64)]| Run {
            variant: "v".into(),
            algorithm: "lqr-gaifo".into(),
            seed,
            episodes_per_iteration: 5,
            horizon: 100,
            logs: curve.iter().map(|&(p, d)| log(p, d)).collect(),
            wall_s: 0.0,
        };
        let runs = [
            run(0, &[(0.1, 0.2), (0.5, 0.05), (0.95, 0.02), (0.8, 0.009)]),
            run(1, &[(0.9, 0.2), (0.99, 0.2), (0.99, 0.2), (0.99, 0.2)]),
            run(2, &[(0.2, 0.2), (0.3, 0.2), (0.3, 0.2), (0.3, 0.2)]),
        ];
        let rows = summarise(&runs);
        let r = &rows[0].to_performance_0_9;
        assert_eq!((r.seeds_reached, r.seeds), (2, 3));
        // Seeds 0 and 1: 2·5 = 10 and 0 episodes.
        assert!((r.episodes_mean - 5.0).abs() < 1e-12);
        assert!((r.episodes_se - 5.0).abs() < 1e-12);
        assert!((r.env_steps_mean - 500.0).abs() < 1e-9);
        let d = &rows[0].to_within_1cm;
        assert_eq!(d.seeds_reached, 1);
        assert!((d.episodes_mean - 15.0).abs() < 1e-12);
        let text = summary_text(&rows);
        assert!(text.contains("2/3") && text.contains("1/3"), "{text}");
    }

    /// A first variant that needed no episode (the mean path) is no reference for a ratio:
    /// the ratio column says "-", never NaN or infinity.
    #[test]
    fn no_ratio_to_a_reference_that_needed_no_episode() {
        let run = |variant: &str, d: [f64; 2]| Run {
            variant: variant.into(),
            algorithm: "x".into(),
            seed: 0,
            episodes_per_iteration: 5,
            horizon: 100,
            logs: d
                .iter()
                .map(|&d| GaifoLog {
                    performance: 1.0,
                    final_distance: d,
                    ..GaifoLog::default()
                })
                .collect(),
            wall_s: 0.0,
        };
        let rows = summarise(&[run("replay-mean", [0.001; 2]), run("b", [0.1, 0.005])]);
        assert_eq!(rows[1].to_within_1cm.episodes_mean, 5.0);
        let text = summary_text(&rows);
        assert!(!text.contains("NaN") && !text.contains("inf"), "{text}");
    }

    #[test]
    fn report_points_end_with_the_last_iteration() {
        assert_eq!(report_points(3), vec![0, 2]);
        assert_eq!(report_points(15), vec![0, 4, 9, 14]);
        assert_eq!(report_points(100).last(), Some(&99));
    }

    #[test]
    fn partial_config_keeps_the_experiments_defaults() {
        let base = ExperimentConfig::defaults(ExperimentName::Generalisation);
        let dir = std::env::temp_dir().join(format!("exp-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.toml");
        std::fs::write(&p, "seeds = 2\n[lqr_gaifo.discriminator]\nn_critic = 7\n").unwrap();
        let c: ExperimentConfig =
            ur5_shared::config::from_toml_file_over(&p, base.clone()).unwrap();
        assert_eq!(c.seeds, 2);
        assert_eq!(c.iterations, 15, "generalisation default kept");
        assert_eq!(c.lqr_gaifo.discriminator.n_critic, 7);
        assert_eq!(
            c.lqr_gaifo.discriminator.batch_size,
            base.lqr_gaifo.discriminator.batch_size
        );
        std::fs::write(&p, "seedz = 2\n").unwrap();
        let e = ur5_shared::config::from_toml_file_over(&p, base.clone()).unwrap_err();
        assert!(e.to_string().contains("seedz"), "{e}");
        // Unknown keys in the critic's tables are errors too (they were ignored before).
        for (text, key) in [
            ("[lqr_gaifo.discriminator]\nhiddn = [8]\n", "hiddn"),
            ("[lqr_gaifo.discriminator.adam]\nlrr = 1.0\n", "lrr"),
            ("[gaifo_ppo.discriminator]\npenalty = \"raw\"\n", "penalty"),
        ] {
            std::fs::write(&p, text).unwrap();
            let e = ur5_shared::config::from_toml_file_over(&p, base.clone()).unwrap_err();
            assert!(e.to_string().contains(key), "{text}: {e}");
        }
        std::fs::write(&p, "[lqr_gaifo.discriminator]\npenalty_space = \"raw\"\n").unwrap();
        let c: ExperimentConfig = ur5_shared::config::from_toml_file_over(&p, base).unwrap();
        assert_eq!(
            c.lqr_gaifo.discriminator.penalty_space,
            imitation::discriminator::PenaltySpace::Raw
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
