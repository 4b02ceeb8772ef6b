//! `learner`: the offline learner's command line.

use anyhow::Context;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "learner",
    about = "Offline learner: GMM-prior dynamics fit and KL-bounded LQR (GPS port)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Check every learner piece against a GPS reference-vectors file (gps-vectors layout);
    /// exits non-zero if any quantity fails its tolerance.
    Conformance {
        /// Path to a problem_*.json file.
        vectors: std::path::PathBuf,
        /// Print only a one-line JSON summary on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Train the expert on the true task cost (KL-bounded LQR with learned dynamics, in
    /// process), save its gain table, record demonstrations. Progress: one line per iteration.
    Expert(learner::expert_cli::ExpertArgs),
    /// The learner end of the three processes (hil-sim serve <-> rt-controller <-> learner):
    /// publishes gain tables on controller/gains, learns from the episodes on learner/samples
    /// (the expert's iteration on the true task cost, or LQR+GAIfO with --algo lqr-gaifo
    /// --demos FILE). Progress: one line per iteration.
    Serve(learner::serve::ServeArgs),
    /// Imitate state-only demonstrations: LQR+GAIfO (default) or the GAIfO (PPO) baseline;
    /// --resume DIR continues an LQR+GAIfO run. Progress: one line per iteration.
    Train(learner::train_cli::TrainArgs),
    /// Time one full learner update (GMM prior update, dynamics fit, η search) on a seeded
    /// synthetic linear problem; prints median wall-clock times in milliseconds.
    Bench {
        /// Horizon T (steps of 0.1 s).
        #[arg(long, default_value_t = 100)]
        t: usize,
        /// State dimension dX.
        #[arg(long, default_value_t = 12)]
        dx: usize,
        /// Action dimension dU.
        #[arg(long, default_value_t = 3)]
        du: usize,
        /// Samples per iteration N.
        #[arg(long, default_value_t = 5)]
        n: usize,
        /// Repetitions (the median is reported).
        #[arg(long, default_value_t = 21)]
        reps: usize,
        /// RNG seed of the synthetic problem.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print only a one-line JSON summary on stdout.
        #[arg(long)]
        json: bool,
    },
    /// The paper's experiments (comparison, generalisation, sim-vs-physical, stability): CSV,
    /// PNG plot and summary table in the output folder; seeds run in parallel.
    Experiment(learner::experiment::ExperimentArgs),
    /// Time LQR+GAIfO iterations on real demonstrations (issue goal: < 50 ms of learner time
    /// per iteration on one core); prints per-phase medians and the learner CPU time.
    BenchGaifo {
        /// Demonstrations (.npz from `learner expert`); without it the default expert is
        /// trained first (about 10 s) and its demonstrations are used.
        #[arg(long)]
        demos: Option<std::path::PathBuf>,
        /// TOML `GaifoConfig` (as for `learner train --config`).
        #[arg(long)]
        config: Option<std::path::PathBuf>,
        /// Iterations.
        #[arg(long, default_value_t = 20)]
        iterations: usize,
        /// Seed of the run.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Print only a one-line JSON summary on stdout.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Expert(args) => learner::expert_cli::run(args)?,
        Cmd::Train(args) => learner::train_cli::run(args)?,
        Cmd::Experiment(args) => learner::experiment::run_cli(args)?,
        Cmd::Serve(args) => learner::serve::run_cli(args)?,
        Cmd::Conformance { vectors, json } => {
            let f = vectors.to_string_lossy().to_string();
            let rep = learner::conformance::run_file(&f)
                .with_context(|| format!("conformance on {f}"))?;
            if json {
                println!("{}", rep.to_json());
            } else {
                print!("{}", rep.to_text());
            }
            if !rep.all_pass() {
                std::process::exit(1);
            }
        }
        Cmd::BenchGaifo {
            demos,
            config,
            iterations,
            seed,
            json,
        } => bench_gaifo(demos, config, iterations, seed, json)?,
        Cmd::Bench {
            t,
            dx,
            du,
            n,
            reps,
            seed,
            json,
        } => {
            let r = learner::bench::run(t, dx, du, n, reps.max(1), seed)?;
            if json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                println!(
                    "learner bench: T={} dX={} dU={} N={}, {} reps, medians, one thread",
                    r.t, r.dx, r.du, r.n, r.reps
                );
                println!("{:<22} {:>9} {:>9}", "piece", "wall ms", "cpu ms");
                let row = |name: &str, w: f64, c: f64, extra: String| {
                    println!("{:<22} {:>9.3} {:>9.3}   {}", name, w * 1e3, c * 1e3, extra);
                };
                row(
                    "GMM prior update",
                    r.gmm_prior_update_s,
                    r.gmm_prior_update_cpu_s,
                    format!("(K={}, {} EM iterations)", r.gmm_k, r.gmm_em_iterations),
                );
                row(
                    "dynamics fit + x0",
                    r.dynamics_fit_s,
                    r.dynamics_fit_cpu_s,
                    String::new(),
                );
                row(
                    "eta search",
                    r.eta_search_s,
                    r.eta_search_cpu_s,
                    format!("({} backward passes)", r.dgd_backward_calls),
                );
                row("total", r.total_s, r.total_cpu_s, String::new());
                let tr: Vec<String> = r
                    .dgd_trace
                    .iter()
                    .map(|(e, k)| format!("eta={e:.3e} kl={k:.3}"))
                    .collect();
                println!(
                    "eta search (target KL {:.1}): {}",
                    r.kl_target,
                    tr.join(", ")
                );
            }
        }
    }
    Ok(())
}

fn bench_gaifo(
    demos: Option<std::path::PathBuf>,
    config: Option<std::path::PathBuf>,
    iterations: usize,
    seed: u64,
    json: bool,
) -> anyhow::Result<()> {
    use learner::gaifo::GaifoConfig;
    let mut cfg: GaifoConfig = match &config {
        Some(p) => ur5_shared::config::from_toml_file(p)?,
        None => GaifoConfig::default(),
    };
    cfg.iterations = iterations.max(1);
    cfg.seed = seed;
    let demos = match &demos {
        Some(p) => learner::io::demos::Demos::load(p)
            .with_context(|| format!("loading demonstrations {}", p.display()))?,
        None => {
            eprintln!("no --demos: training the default expert first");
            let ecfg = learner::expert::ExpertConfig::default();
            let run = learner::expert::train(&ecfg, |_| {})?;
            learner::expert::record_demos(&ecfg, &run.policy, run.cost_random)?
        }
    };
    let r = learner::bench::gaifo(&cfg, demos)?;
    if json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    println!(
        "LQR+GAIfO bench: {} iterations, seed {}, N = {} + 1 episodes, final normalised performance {:.3}",
        r.iterations, r.seed, cfg.samples, r.final_performance
    );
    println!("{:<34} {:>9}", "learner CPU per iteration", "ms");
    println!("{:<34} {:>9.1}", "  median", 1e3 * r.cpu_learner_median_s);
    println!(
        "{:<34} {:>9.1}",
        "  90th percentile",
        1e3 * r.cpu_learner_p90_s
    );
    println!("{:<34} {:>9.1}", "  largest", 1e3 * r.cpu_learner_max_s);
    println!("{:<34} {:>9}", "phase (median wall)", "ms");
    for (name, v) in [
        ("  dynamics (GMM prior + fit)", r.dynamics_s),
        ("  critic (WGAN-GP steps)", r.critic_s),
        ("  composite cost + Hessians", r.cost_s),
        ("  KL-bounded LQR", r.lqr_s),
        ("  episodes (simulator, not learner)", r.execute_s),
    ] {
        println!("{:<34} {:>9.1}", name, 1e3 * v);
    }
    Ok(())
}
