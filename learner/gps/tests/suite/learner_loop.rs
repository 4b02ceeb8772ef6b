//! The pieces chained as in GPS `AlgorithmTrajOpt.iteration` on a seeded linear plant: the
//! expected cost of the controller (Laplace estimate under the true dynamics) must go down.

use gps::algorithm::update::Learner;
use gps::algorithm::AlgorithmConfig;
use gps::dynamics::lr_prior::LrPriorConfig;
use gps::dynamics::prior_gmm::PriorGmmConfig;
use gps::policy::lin_gauss::LinGaussPolicy;
use gps::synthetic::random_problem;
use gps::traj_opt::lqr::{TrajOptConfig, TrajOptLqr};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[test]
fn iterations_reduce_expected_cost() {
    let (t, dx, du, n) = (20, 4, 2, 5);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let (sys, pol0, truth) = random_problem(&mut rng, t, dx, du);
    let mut l = Learner::new(
        AlgorithmConfig::default(),
        PriorGmmConfig::default(),
        LrPriorConfig::default(),
        TrajOptConfig::default(),
        t,
        dx,
        du,
        n,
        ChaCha8Rng::seed_from_u64(7),
    );
    let mut eval = TrajOptLqr::new(TrajOptConfig::default(), t, dx, du);
    let expected = |eval: &mut TrajOptLqr, p: &LinGaussPolicy| {
        let mut c = vec![0.0; t];
        eval.estimate_cost(p, &truth, &mut c).unwrap();
        c.iter().sum::<f64>()
    };
    let c0 = expected(&mut eval, &pol0);
    let mut pol = pol0.clone();
    let mut prev_pol: Option<LinGaussPolicy> = None;
    let mut new = LinGaussPolicy::zeros(t, dx, du);
    let mut costs = vec![c0];
    for _ in 0..5 {
        let (x, u) = sys.rollout(&pol, n, &mut rng);
        let rep = l.update_dynamics(&x, &u, n).unwrap();
        assert!(rep.k >= 2);
        l.info.cc.clone_from(&truth.cc);
        l.info.cv.copy_from(&truth.cv);
        l.info.cm.copy_from(&truth.cm);
        if let Some(pp) = prev_pol.as_ref() {
            let sa = l
                .update_step_size(pp, &pol)
                .unwrap()
                .expect("step adjust after the first iteration");
            assert!(sa.step_mult_after >= 0.01 && sa.step_mult_after <= 10.0);
        }
        let res = l.update_trajectories(&pol, &mut new).unwrap();
        assert!(res.converged, "{:?}", res.trace);
        prev_pol = Some(pol.clone());
        pol.copy_from(&new);
        costs.push(expected(&mut eval, &pol));
    }
    // Reference: plain LQR on the true model (η → 0 makes Σ → 0, the deterministic optimum).
    let mut opt = LinGaussPolicy::zeros(t, dx, du);
    eval.backward(&pol0, &truth, &mut [1e-9], &mut opt).unwrap();
    let c_opt = expected(&mut eval, &opt);
    let last = *costs.last().unwrap();
    let closed = (c0 - last) / (c0 - c_opt);
    assert!(
        closed > 0.8,
        "closed {closed:.3} of the gap to LQR {c_opt}: {costs:?}"
    );
    assert!(costs.windows(2).take(3).all(|w| w[1] < w[0]), "{costs:?}");
}
