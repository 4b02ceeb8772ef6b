//! `learner bench`, `learner bench-gaifo` and `learner conformance`: timings and the GPS
//! reference check.

use std::path::{Path, PathBuf};

use anyhow::Context;
use imitation::gaifo::GaifoConfig;

use crate::bench::PieceTime;

use super::CommonArgs;

/// Arguments of `learner conformance`.
#[derive(clap::Args, Debug)]
pub struct ConformanceArgs {
    /// Path to a problem_*.json file.
    pub vectors: PathBuf,
    /// Print only a one-line JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `learner conformance`: exits with status 1 if any quantity fails.
pub fn conformance(args: ConformanceArgs) -> anyhow::Result<()> {
    let f = args.vectors.to_string_lossy().to_string();
    let rep = gps::conformance::run_file(&f).with_context(|| format!("conformance on {f}"))?;
    if args.json {
        println!("{}", rep.to_json());
    } else {
        print!("{}", rep.to_text());
    }
    if !rep.all_pass() {
        std::process::exit(1);
    }
    Ok(())
}

/// Arguments of `learner bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Horizon T (steps of 0.1 s).
    #[arg(long, default_value_t = 100)]
    pub t: usize,
    /// State dimension dX.
    #[arg(long, default_value_t = 12)]
    pub dx: usize,
    /// Action dimension dU.
    #[arg(long, default_value_t = 3)]
    pub du: usize,
    /// Samples per iteration N.
    #[arg(long, default_value_t = 5)]
    pub n: usize,
    /// Repetitions (the median is reported).
    #[arg(long, default_value_t = 21)]
    pub reps: usize,
    /// RNG seed of the synthetic problem.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Instead of the synthetic problem, redo GPS's work on the recorded inputs of a GPS
    /// reference-vectors file (e.g. `../shared/gps-vectors/problem_B.json`): per recorded
    /// iteration its GMM prior update (GPS's cluster assignment or warm start, so the same EM
    /// iterations), dynamics fit and η search (from GPS's start η and KL target), checked against
    /// GPS's recorded outputs. --t, --dx, --du, --n and --seed are then the file's.
    #[arg(long, value_name = "FILE.json")]
    pub vectors: Option<PathBuf>,
    /// Print only a one-line JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Prints the timing table of `learner bench`: one row per piece (milliseconds), then a
/// `total` row; the text after a row's figures says what work it did.
fn print_pieces(rows: &[(&str, PieceTime, String)]) {
    println!("{:<22} {:>9} {:>9}", "piece", "wall ms", "cpu ms");
    for (name, p, extra) in rows {
        println!(
            "{:<22} {:>9.3} {:>9.3}   {}",
            name,
            p.wall_s * 1e3,
            p.cpu_s * 1e3,
            extra
        );
    }
}

/// The GMM's arithmetic rate beside the peak measured in the same run.
fn print_gflops(gmm: f64, peak: f64) {
    println!(
        "GMM EM arithmetic: {gmm:.1} GFLOP/s of CPU time over the whole GMM prior update (E- and M-step flops), one-core f64 FMA peak measured now {peak:.1} GFLOP/s: {:.0} %",
        100.0 * gmm / peak
    );
}

/// Runs `learner bench`.
pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    if let Some(file) = &args.vectors {
        return run_vectors(file, args.reps.max(1), args.json);
    }
    let r = crate::bench::run(
        args.t,
        args.dx,
        args.du,
        args.n,
        args.reps.max(1),
        args.seed,
    )?;
    if args.json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    println!(
        "learner bench: T={} dX={} dU={} N={}, {} reps, medians, one thread",
        r.t, r.dx, r.du, r.n, r.reps
    );
    let piece = |wall_s, cpu_s| PieceTime { wall_s, cpu_s };
    print_pieces(&[
        (
            "GMM prior update",
            piece(r.gmm_prior_update_s, r.gmm_prior_update_cpu_s),
            format!("(K={}, {} EM iterations)", r.gmm_k, r.gmm_em_iterations),
        ),
        (
            "dynamics fit + x0",
            piece(r.dynamics_fit_s, r.dynamics_fit_cpu_s),
            String::new(),
        ),
        (
            "eta search",
            piece(r.eta_search_s, r.eta_search_cpu_s),
            format!("({} backward passes)", r.dgd_backward_calls),
        ),
        ("total", piece(r.total_s, r.total_cpu_s), String::new()),
    ]);
    print_gflops(r.gmm_gflops, r.fma_peak_gflops);
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
    Ok(())
}

/// `learner bench --vectors FILE`: one table per recorded iteration; exits with an error if
/// any iteration did other work than GPS or reached another result.
fn run_vectors(file: &Path, reps: usize, json: bool) -> anyhow::Result<()> {
    let name = file.to_string_lossy();
    let r = crate::bench::vectors(&name, reps).with_context(|| format!("bench on {name}"))?;
    if json {
        println!("{}", serde_json::to_string(&r)?);
    } else {
        println!(
            "learner bench --vectors {}: T={} dX={} dU={}, GPS's recorded inputs, {} reps, medians, one thread",
            r.file, r.t, r.dx, r.du, r.reps
        );
        for it in &r.iterations {
            println!("iteration {} (N={}):", it.iteration, it.n);
            print_pieces(&[
                (
                    "GMM prior update",
                    it.gmm_prior_update,
                    format!(
                        "(K={}, {} EM iterations; GPS K={}, {})",
                        it.gmm_k, it.em_iterations, it.gps_gmm_k, it.gps_em_iterations
                    ),
                ),
                ("dynamics fit + x0", it.dynamics_fit, String::new()),
                (
                    "eta search",
                    it.eta_search,
                    format!(
                        "({} backward passes; GPS {})",
                        it.backward_calls, it.gps_backward_calls
                    ),
                ),
                ("total", it.total, String::new()),
            ]);
            println!(
                "against GPS's outputs: final eta rel. err {:.1e}, new controller max rel. err {:.1e} (tol {:.0e}): {}",
                it.eta_rel_err,
                it.controller_rel_err,
                gps::conformance::TOL_DET,
                if it.matches_gps() { "same work, same result" } else { "DIFFERS" }
            );
            print_gflops(it.gmm_gflops, r.fma_peak_gflops);
        }
    }
    anyhow::ensure!(
        r.iterations.iter().all(|it| it.matches_gps()),
        "{name}: the benchmark did other work than GPS or reached another result (see the table)"
    );
    Ok(())
}

/// Arguments of `learner bench-gaifo`.
#[derive(clap::Args, Debug)]
pub struct BenchGaifoArgs {
    /// Demonstrations (.npz from `learner expert`); without it the default expert is trained
    /// first (about 10 s) and its demonstrations are used.
    #[arg(long)]
    pub demos: Option<PathBuf>,
    /// Iterations.
    #[arg(long, default_value_t = 20)]
    pub iterations: usize,
    /// --config (a `GaifoConfig`), --seed (default 0), --json; --out is not used.
    #[command(flatten)]
    pub common: CommonArgs,
}

/// Runs `learner bench-gaifo`.
pub fn run_gaifo(args: BenchGaifoArgs) -> anyhow::Result<()> {
    let mut cfg: GaifoConfig = args.common.settings()?;
    cfg.iterations = args.iterations.max(1);
    cfg.seed = args.common.seed.unwrap_or(0);
    let demos = match &args.demos {
        Some(p) => crate::io::demos::load_checked(p, &cfg.sim)?,
        None => {
            eprintln!("no --demos: training the default expert first");
            let ecfg = imitation::expert::ExpertConfig::default();
            let run = crate::run::expert(&ecfg, |_| {})?;
            crate::run::demos(&ecfg, &run)?
        }
    };
    let r = crate::bench::gaifo(&cfg, demos)?;
    if args.common.json {
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
