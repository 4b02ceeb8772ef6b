//! `learner bench`: one full learner update on an arm-sized synthetic problem (GMM prior
//! update, dynamics fit, η search), timed per piece; with `--vectors`, the same pieces redone
//! on the recorded inputs of a GPS reference-vectors file, for a like-for-like comparison with
//! GPS's numpy code.

use std::time::Instant;

use imitation::cpu::thread_cpu_s;

use crate::stats::{median, quantile};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use gps::algorithm::init_state::fit_x0;
use gps::algorithm::update::Learner;
use gps::algorithm::AlgorithmConfig;
use gps::conformance::rel_err;
use gps::dynamics::gmm::ClusterInit;
use gps::dynamics::lr_prior::{fit, FitWorkspace, LrPriorConfig};
use gps::dynamics::prior_gmm::{DynamicsPriorGmm, PriorGmmConfig};
use gps::dynamics::Dynamics;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::synthetic::random_problem;
use gps::traj_opt::lqr::{TrajOptConfig, TrajOptLqr};

/// What stopped a benchmark.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A GPS piece (dynamics fit, LQR step, step adjustment) failed.
    #[error(transparent)]
    Gps(#[from] gps::GpsError),
    /// A GPS reference-vectors file that cannot be read or does not follow the layout.
    #[error(transparent)]
    Vectors(#[from] gps::conformance::ConformanceError),
    /// The LQR+GAIfO run that is timed.
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    /// `iterations = 0`: nothing to time.
    #[error("no iterations: set iterations >= 1")]
    NoIterations,
}

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
    /// The EM's E- and M-step flops ([`em_flops`]) per second of the GMM prior update's CPU
    /// time, GFLOP/s.
    pub gmm_gflops: f64,
    /// One core's f64 multiply-add peak measured in the same run ([`fma_peak_gflops`]).
    pub fma_peak_gflops: f64,
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
) -> Result<BenchResult, BenchError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (sys, pol, truth) = random_problem(&mut rng, t, dx, du);
    let (x, u) = sys.rollout(&pol, n, &mut rng);
    let (mut g, mut f, mut e, mut tot) = (
        Samples::default(),
        Samples::default(),
        Samples::default(),
        Samples::default(),
    );
    let mut out = LinGaussPolicy::zeros(t, dx, du);
    let (mut k, mut its, mut calls, mut flops) = (0, 0, 0, 0.0);
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
        let (rep, gw, gc) = timed(|| l.update_prior(&x, &u, n));
        let rep = rep?;
        let (fitted, fw, fc) = timed(|| l.fit_dynamics(&x, &u, n));
        fitted?;
        l.info.cc.clone_from(&truth.cc);
        l.info.cv.copy_from(&truth.cv);
        l.info.cm.copy_from(&truth.cm);
        let (res, ew, ec) = timed(|| l.update_trajectories(&pol, &mut out));
        let res = res?;
        g.push(gw, gc);
        f.push(fw, fc);
        e.push(ew, ec);
        tot.push(gw + fw + ew, gc + fc + ec);
        k = rep.k;
        its = rep.ll_trace.len();
        flops = em_flops(&rep, 2 * dx + du);
        calls = res.trace.len();
        trace = res.trace.iter().map(|s| (s.eta_out, s.kl)).collect();
        kl_target = l.alg.kl_step * l.step_mult * t as f64;
    }
    let (g, f, e, tot) = (g.median(), f.median(), e.median(), tot.median());
    Ok(BenchResult {
        t,
        dx,
        du,
        n,
        reps,
        gmm_prior_update_s: g.wall_s,
        dynamics_fit_s: f.wall_s,
        eta_search_s: e.wall_s,
        total_s: tot.wall_s,
        total_cpu_s: tot.cpu_s,
        gmm_prior_update_cpu_s: g.cpu_s,
        dynamics_fit_cpu_s: f.cpu_s,
        eta_search_cpu_s: e.cpu_s,
        gmm_k: k,
        gmm_em_iterations: its,
        gmm_gflops: flops / g.cpu_s / 1e9,
        fma_peak_gflops: fma_peak_gflops(),
        dgd_backward_calls: calls,
        dgd_trace: trace,
        kl_target,
    })
}

/// Flops of the E- and M-steps of one EM run (`gps::dynamics::em_kernels::estep_flops`,
/// `mstep_flops`) on points of dimension `d`: an E-step per recorded log-likelihood, an M-step
/// after each but the last unless EM ran out of iterations.
pub fn em_flops(rep: &gps::dynamics::gmm::EmReport, d: usize) -> f64 {
    use gps::dynamics::em_kernels::{estep_flops, mstep_flops};
    let e = rep.ll_trace.len();
    let m = if rep.stop == gps::dynamics::gmm::EmStop::MaxIterations {
        e
    } else {
        e.saturating_sub(1)
    };
    e as f64 * estep_flops(rep.n_points, d, rep.k) + m as f64 * mstep_flops(rep.n_points, d, rep.k)
}

/// One core's f64 fused multiply-add peak, GFLOP/s of thread CPU time: the best of 7 runs of
/// `gps::dynamics::em_kernels::fma_peak` (twelve independent 4-lane chains, AVX2+FMA where the
/// CPU has them).
pub fn fma_peak_gflops() -> f64 {
    (0..7)
        .map(|_| {
            let (flops, _, cpu) = timed(|| gps::dynamics::em_kernels::fma_peak(2_000_000));
            flops / cpu / 1e9
        })
        .fold(0.0, f64::max)
}

/// Wall and thread-CPU time of a closure, s.
fn timed<R>(f: impl FnOnce() -> R) -> (R, f64, f64) {
    let c0 = thread_cpu_s();
    let t0 = Instant::now();
    let r = f();
    let wall = t0.elapsed().as_secs_f64();
    (r, wall, thread_cpu_s() - c0)
}

/// Median wall and thread-CPU time of one piece over the repetitions, s.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct PieceTime {
    pub wall_s: f64,
    pub cpu_s: f64,
}

/// Per-repetition samples of one piece, s.
#[derive(Default)]
struct Samples {
    wall: Vec<f64>,
    cpu: Vec<f64>,
}

impl Samples {
    fn push(&mut self, wall: f64, cpu: f64) {
        self.wall.push(wall);
        self.cpu.push(cpu);
    }

    fn median(&mut self) -> PieceTime {
        PieceTime {
            wall_s: median(&mut self.wall),
            cpu_s: median(&mut self.cpu),
        }
    }
}

/// `learner bench --vectors`: the three GPS pieces of one recorded iteration of a vectors
/// file, redone on GPS's recorded inputs, timed, and compared with GPS's recorded outputs.
#[derive(Clone, Debug, serde::Serialize)]
pub struct VectorsIterationBench {
    /// Index of the iteration in the file.
    pub iteration: usize,
    /// Samples N of the iteration.
    pub n: usize,
    /// GMM prior update: append the samples, refit the GMM by EM (from GPS's cluster
    /// assignment, or warm-started from GPS's previous GMM, as GPS did).
    pub gmm_prior_update: PieceTime,
    /// Dynamics fit (prior evaluation + normal-inverse-Wishart regression per step) and x0 fit.
    pub dynamics_fit: PieceTime,
    /// KL-bounded LQR update: the η search from GPS's recorded dynamics, cost, previous
    /// controller, start η and KL target.
    pub eta_search: PieceTime,
    /// The three pieces (median of the per-repetition sums).
    pub total: PieceTime,
    /// Clusters and EM iterations (ours, GPS's).
    pub gmm_k: usize,
    pub gps_gmm_k: usize,
    pub em_iterations: usize,
    pub gps_em_iterations: usize,
    /// The EM's E- and M-step flops ([`em_flops`]) per second of the GMM prior update's CPU
    /// time, GFLOP/s.
    pub gmm_gflops: f64,
    /// Backward passes of the η search (ours, GPS's).
    pub backward_calls: usize,
    pub gps_backward_calls: usize,
    /// Relative error of the final η and largest of the new controller's arrays against GPS's
    /// (`gps::conformance::rel_err`).
    pub eta_rel_err: f64,
    pub controller_rel_err: f64,
}

impl VectorsIterationBench {
    /// The same work as GPS (clusters, EM iterations, backward passes) and the same result
    /// (η and controller within [`gps::conformance::TOL_DET`]).
    pub fn matches_gps(&self) -> bool {
        self.gmm_k == self.gps_gmm_k
            && self.em_iterations == self.gps_em_iterations
            && self.backward_calls == self.gps_backward_calls
            && self.eta_rel_err <= gps::conformance::TOL_DET
            && self.controller_rel_err <= gps::conformance::TOL_DET
    }
}

/// `learner bench --vectors` on a whole file.
#[derive(Clone, Debug, serde::Serialize)]
pub struct VectorsBenchResult {
    pub file: String,
    pub t: usize,
    pub dx: usize,
    pub du: usize,
    pub reps: usize,
    pub iterations: Vec<VectorsIterationBench>,
    /// One core's f64 multiply-add peak measured in the same run ([`fma_peak_gflops`]).
    pub fma_peak_gflops: f64,
}

/// Redoes, `reps` times, the GMM prior update, dynamics fit and η search of every recorded
/// iteration of the vectors file `file` on GPS's recorded inputs (one thread), and returns the
/// median timings with the comparison against GPS's recorded outputs.
pub fn vectors(file: &str, reps: usize) -> Result<VectorsBenchResult, BenchError> {
    let p = gps::conformance::recorded::load_file(file)?;
    let (t, dx, du) = (p.t, p.dx, p.du);
    let cfg = &p.settings;
    let mut iterations = Vec::with_capacity(p.iterations.len());
    for (index, it) in p.iterations.iter().enumerate() {
        let (mut g, mut f, mut e, mut tot) = (
            Samples::default(),
            Samples::default(),
            Samples::default(),
            Samples::default(),
        );
        let mut last = None;
        for _ in 0..reps.max(1) {
            // Outside the timing: the prior's dataset as GPS had it before this iteration, the
            // workspaces (built once per problem size).
            let mut prior = DynamicsPriorGmm::new(cfg.prior.clone(), t, dx, du);
            if it.earlier_n > 0 {
                prior.append(&it.earlier_x, &it.earlier_u, it.earlier_n)?;
            }
            if let Some(w) = &it.warm_start {
                prior
                    .gmm
                    .set_params(w.k, &w.mu, &w.sigma, &w.logmass, w.self_n);
            }
            let mut fit_ws = FitWorkspace::new(it.n, dx, du);
            let mut dynamics = Dynamics::zeros(t, dx, du);
            let mut opt = TrajOptLqr::new(cfg.opt.clone(), t, dx, du);
            let mut new_pol = LinGaussPolicy::zeros(t, dx, du);

            let (em, gw, gc) = timed(|| {
                prior.update(&it.x, &it.u, it.n, ClusterInit::Given(&it.init_cluster_idx))
            });
            let em = em?;
            let (fitted, fw, fc) = timed(|| -> Result<_, gps::GpsError> {
                fit(
                    &it.x,
                    &it.u,
                    it.n,
                    &mut prior,
                    &cfg.fit,
                    &mut fit_ws,
                    &mut dynamics,
                )?;
                let p0 = prior.initial_state();
                Ok(fit_x0(
                    &it.x,
                    it.n,
                    t,
                    dx,
                    cfg.alg.initial_state_var,
                    Some(&p0),
                ))
            });
            fitted?;
            let (dgd, ew, ec) =
                timed(|| opt.update(&it.prev, &it.info, it.eta_start, it.kl_step, &mut new_pol));
            let dgd = dgd?;
            g.push(gw, gc);
            f.push(fw, fc);
            e.push(ew, ec);
            tot.push(gw + fw + ew, gc + fc + ec);
            last = Some((em, dgd, new_pol));
        }
        let (em, dgd, new_pol) = last.expect("at least one repetition");
        let gpsc = &it.gps_new_controller;
        let controller_rel_err = [
            rel_err(&new_pol.gain.data, &gpsc.gain.data),
            rel_err(&new_pol.k.data, &gpsc.k.data),
            rel_err(&new_pol.pol_covar.data, &gpsc.pol_covar.data),
            rel_err(&new_pol.chol_pol_covar.data, &gpsc.chol_pol_covar.data),
            rel_err(&new_pol.inv_pol_covar.data, &gpsc.inv_pol_covar.data),
        ]
        .into_iter()
        .fold(0.0, f64::max);
        let gmm_prior_update = g.median();
        iterations.push(VectorsIterationBench {
            iteration: index,
            n: it.n,
            gmm_gflops: em_flops(&em, 2 * dx + du) / gmm_prior_update.cpu_s / 1e9,
            gmm_prior_update,
            dynamics_fit: f.median(),
            eta_search: e.median(),
            total: tot.median(),
            gmm_k: em.k,
            gps_gmm_k: it.gps_k,
            em_iterations: em.ll_trace.len(),
            gps_em_iterations: it.gps_em_iterations,
            backward_calls: dgd.trace.len(),
            gps_backward_calls: it.gps_backward_calls,
            eta_rel_err: rel_err(&[dgd.eta], &[it.gps_eta_final]),
            controller_rel_err,
        });
    }
    Ok(VectorsBenchResult {
        file: file.to_string(),
        t,
        dx,
        du,
        reps: reps.max(1),
        iterations,
        fma_peak_gflops: fma_peak_gflops(),
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
/// faer's own parallelism is off for the run (restored after), so that every matrix routine of
/// the learner runs on the thread whose CPU time is measured: with it on, faer hands parts of
/// its larger products to the episode threads' pool, which that clock does not see.
pub fn gaifo(
    cfg: &imitation::gaifo::GaifoConfig,
    demos: imitation::demos::Demos,
) -> Result<GaifoBenchResult, BenchError> {
    let par = faer::get_global_parallelism();
    faer::set_global_parallelism(faer::Par::Seq);
    let logs = crate::run::train(cfg, demos, None, |_| {});
    faer::set_global_parallelism(par);
    let logs = logs?;
    if logs.is_empty() {
        return Err(BenchError::NoIterations);
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The in-crate copies of the GPS reference vectors (as the gps crate's conformance tests).
    fn vectors_file(name: &str) -> String {
        format!(
            "{}/gps/tests/data/gps-vectors/{name}",
            env!("CARGO_MANIFEST_DIR")
        )
    }

    #[test]
    fn vectors_bench_redoes_gps_work_with_gps_results() {
        // (file, per iteration: clusters, EM iterations, backward passes), as GPS recorded them.
        for (name, expect) in [
            ("problem_A.json", [(2, 8, 7), (2, 3, 2)]),
            ("problem_B.json", [(5, 11, 5), (11, 36, 4)]),
        ] {
            let r = vectors(&vectors_file(name), 1).unwrap();
            assert_eq!(r.iterations.len(), 2, "{name}");
            for (it, (k, em, calls)) in r.iterations.iter().zip(expect) {
                assert!(it.matches_gps(), "{name}: {it:?}");
                assert_eq!(
                    (it.gmm_k, it.em_iterations, it.backward_calls),
                    (k, em, calls),
                    "{name} iteration {}",
                    it.iteration
                );
                for p in [it.gmm_prior_update, it.dynamics_fit, it.eta_search] {
                    assert!(p.wall_s >= 0.0 && p.cpu_s >= 0.0);
                }
            }
        }
    }

    #[test]
    fn vectors_bench_names_a_missing_file() {
        let e = vectors("/nonexistent/problem_X.json", 1).unwrap_err();
        assert!(e.to_string().contains("problem_X.json"), "{e}");
    }
}
