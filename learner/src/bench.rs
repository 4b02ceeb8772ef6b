//! `learner bench`: one full learner update on an arm-sized synthetic problem (GMM prior
//! update, dynamics fit, η search), timed per piece.

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::algorithm::update::Learner;
use crate::algorithm::AlgorithmConfig;
use crate::dynamics::lr_prior::LrPriorConfig;
use crate::dynamics::prior_gmm::PriorGmmConfig;
use crate::policy::lin_gauss::LinGaussPolicy;
use crate::synthetic::random_problem;
use crate::traj_opt::lqr::TrajOptConfig;

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

/// CPU time of the calling thread, s (excludes time the thread waits for a core, which on a
/// shared machine inflates wall-clock numbers).
pub fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_THREAD_CPUTIME_ID is always supported
    // on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
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
