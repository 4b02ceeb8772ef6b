//! `learner bench`: one full learner update on an arm-sized synthetic problem (GMM prior
//! update, dynamics fit, η search), timed per piece.

use std::time::Instant;

use imitation::cpu::thread_cpu_s;

use crate::stats::{median, quantile};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use gps::algorithm::update::Learner;
use gps::algorithm::AlgorithmConfig;
use gps::dynamics::lr_prior::LrPriorConfig;
use gps::dynamics::prior_gmm::PriorGmmConfig;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::synthetic::random_problem;
use gps::traj_opt::lqr::TrajOptConfig;

/// Median timings (seconds) of the pieces of one update.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchResult {
    pub t: usize,
    pub dx: usize,
    pub du: usize,
    pub n: usize,
    pub reps: usize,
    pub gmm_prior_update_s: f64,
    pub dynamics_fit_s: f64,
    pub eta_search_s: f64,
    pub total_s: f64,
    /// Median thread CPU time of the whole update, s.
    pub total_cpu_s: f64,
    pub gmm_prior_update_cpu_s: f64,
    pub dynamics_fit_cpu_s: f64,
    pub eta_search_cpu_s: f64,
    pub gmm_k: usize,
    pub gmm_em_iterations: usize,
    pub dgd_backward_calls: usize,
    /// (η, KL) of each backward pass of the η search, and the KL target.
    pub dgd_trace: Vec<(f64, f64)>,
    pub kl_target: f64,
}

/// Runs `reps` full updates (each on a fresh learner, same seeded data) and returns medians.
pub fn run(
    t: usize,
    dx: usize,
    du: usize,
    n: usize,
    reps: usize,
    seed: u64,
) -> Result<BenchResult, crate::LearnerError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (sys, pol, truth) = random_problem(&mut rng, t, dx, du);
    let (x, u) = sys.rollout(&pol, n, &mut rng);
    let (mut g, mut f, mut e, mut tot) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut gc, mut fc, mut ec, mut totc) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut out = LinGaussPolicy::zeros(t, dx, du);
    let (mut k, mut its, mut calls) = (0, 0, 0);
    let mut trace = Vec::new();
    let mut kl_target = 0.0;
    for _ in 0..reps {
        let mut l = Learner::new(
            AlgorithmConfig::default(),
            PriorGmmConfig::default(),
            LrPriorConfig::default(),
            TrajOptConfig::default(),
            t,
            dx,
            du,
            n,
            ChaCha8Rng::seed_from_u64(seed.wrapping_add(1)),
        );
        let c0 = thread_cpu_s();
        let t0 = Instant::now();
        let rep = l.update_prior(&x, &u, n)?;
        let t1 = Instant::now();
        let c1 = thread_cpu_s();
        l.fit_dynamics(&x, &u, n)?;
        l.info.cc.clone_from(&truth.cc);
        l.info.cv.copy_from(&truth.cv);
        l.info.cm.copy_from(&truth.cm);
        let t2 = Instant::now();
        let c2 = thread_cpu_s();
        let res = l.update_trajectories(&pol, &mut out)?;
        let t3 = Instant::now();
        let c3 = thread_cpu_s();
        gc.push(c1 - c0);
        fc.push(c2 - c1);
        ec.push(c3 - c2);
        totc.push(c3 - c0);
        g.push((t1 - t0).as_secs_f64());
        f.push((t2 - t1).as_secs_f64());
        e.push((t3 - t2).as_secs_f64());
        tot.push((t3 - t0).as_secs_f64());
        k = rep.k;
        its = rep.ll_trace.len();
        calls = res.trace.len();
        trace = res.trace.iter().map(|s| (s.eta_out, s.kl)).collect();
        kl_target = l.alg.kl_step * l.step_mult * t as f64;
    }
    Ok(BenchResult {
        t,
        dx,
        du,
        n,
        reps,
        gmm_prior_update_s: median(&mut g),
        dynamics_fit_s: median(&mut f),
        eta_search_s: median(&mut e),
        total_s: median(&mut tot),
        total_cpu_s: median(&mut totc),
        gmm_prior_update_cpu_s: median(&mut gc),
        dynamics_fit_cpu_s: median(&mut fc),
        eta_search_cpu_s: median(&mut ec),
        gmm_k: k,
        gmm_em_iterations: its,
        dgd_backward_calls: calls,
        dgd_trace: trace,
        kl_target,
    })
}

/// `learner bench-gaifo`: LQR+GAIfO iterations (5 + 1 episodes, dynamics, critic steps,
/// Hessians, LQR) on real demonstrations; per-iteration learner time on one core.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GaifoBenchResult {
    pub iterations: usize,
    pub seed: u64,
    /// Learner thread-CPU time per iteration (everything but executing the episodes), s:
    /// median, 90th percentile and largest over the iterations.
    pub cpu_learner_median_s: f64,
    pub cpu_learner_p90_s: f64,
    pub cpu_learner_max_s: f64,
    /// Median wall time per phase, s.
    pub dynamics_s: f64,
    pub critic_s: f64,
    pub cost_s: f64,
    pub lqr_s: f64,
    pub execute_s: f64,
    /// Normalised performance of the last noise-free episode (that the run still learns).
    pub final_performance: f64,
}

/// Runs `cfg.iterations` LQR+GAIfO iterations on `demos` and summarises their timings.
pub fn gaifo(
    cfg: &imitation::gaifo::GaifoConfig,
    demos: imitation::demos::Demos,
) -> anyhow::Result<GaifoBenchResult> {
    let logs = crate::run::train(cfg, demos, None, |_| {})?;
    anyhow::ensure!(!logs.is_empty(), "no iterations");
    let col =
        |f: fn(&imitation::gaifo::GaifoLog) -> f64| -> Vec<f64> { logs.iter().map(f).collect() };
    let mut cpu = col(|l| l.cpu_learner);
    Ok(GaifoBenchResult {
        iterations: logs.len(),
        seed: cfg.seed,
        cpu_learner_median_s: median(&mut cpu.clone()),
        cpu_learner_p90_s: quantile(&mut cpu.clone(), 0.9),
        cpu_learner_max_s: quantile(&mut cpu, 1.0),
        dynamics_s: median(&mut col(|l| l.t_dynamics)),
        critic_s: median(&mut col(|l| l.t_critic)),
        cost_s: median(&mut col(|l| l.t_cost)),
        lqr_s: median(&mut col(|l| l.t_lqr)),
        execute_s: median(&mut col(|l| l.t_execute)),
        final_performance: logs.last().map(|l| l.performance).unwrap_or(f64::NAN),
    })
}
