//! LQR+GAIfO end to end on the simulated arm: expert → demonstrations → imitation from the
//! states alone.

use learner::expert::{record_demos, train as train_expert, ExpertConfig};
use learner::gaifo::{train, GaifoConfig};

/// The expert of issue 4, then 12 iterations of LQR+GAIfO on its 5 state-only demonstrations:
/// the imitator's noise-free episode must reach normalised performance ≥ 0.8 (the issue's
/// acceptance asks it within 20 iterations on average over 5 seeds; the README has that run).
#[test]
fn lqr_gaifo_imitates_the_expert_from_states_only() {
    let ecfg = ExpertConfig {
        iterations: 12,
        ..ExpertConfig::default()
    };
    let expert = train_expert(&ecfg, |_| {}).unwrap();
    let demos = record_demos(&ecfg, &expert.policy, expert.cost_random).unwrap();
    assert!(demos.cost_expert < 0.25 * demos.cost_random);
    let cfg = GaifoConfig {
        iterations: 12,
        ..GaifoConfig::default()
    };
    let logs = train(&cfg, demos, None, |l| {
        eprintln!(
            "iteration {}: performance {:.3}, task cost {:.3}, W1 {:.3}, kl {:.2}, eta {:.2e}",
            l.iteration, l.performance, l.task_cost, l.wasserstein, l.kl, l.eta
        )
    })
    .unwrap();
    let best = logs
        .iter()
        .map(|l| l.performance)
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(
        logs[0].performance < 0.3,
        "the first controller must not already imitate"
    );
    assert!(
        best >= 0.8,
        "best normalised performance {best:.3} < 0.8 in 12 iterations"
    );
}

/// Demonstrations of a short task (T = 30) from a 4-iteration expert: enough to imitate for a
/// few iterations, in a second.
fn short_demos() -> learner::io::demos::Demos {
    let ecfg = ExpertConfig {
        task: ur5_shared::config::TaskConfig {
            horizon: 30,
            ..Default::default()
        },
        iterations: 4,
        random_episodes: 2,
        demos: 3,
        ..ExpertConfig::default()
    };
    let expert = train_expert(&ecfg, |_| {}).unwrap();
    record_demos(&ecfg, &expert.policy, expert.cost_random).unwrap()
}

/// `iterate` is `execute` + `learn`: learning on episodes executed outside (as `learner serve`
/// does with the controller's) gives the same logs and controllers bit for bit.
#[test]
fn learning_on_executed_episodes_equals_iterate() {
    use learner::gaifo::LqrGaifo;
    use learner::iteration::execute;
    let demos = short_demos();
    let cfg = GaifoConfig {
        seed: 5,
        ..GaifoConfig::default()
    };
    let mut a = LqrGaifo::new(cfg.clone(), demos.clone()).unwrap();
    let mut b = LqrGaifo::new(cfg.clone(), demos).unwrap();
    let mut sim = hil_sim::Ur5Sim::new(cfg.sim.clone(), b.task().dt).unwrap();
    for i in 0..3 {
        let (la, ea) = a.iterate().unwrap();
        let task = b.task().clone();
        let (noisy, eval) = execute(&mut sim, &task, b.policy(), b.version(), 5, 5).unwrap();
        assert_eq!(ea, eval);
        let lb = b.learn(&noisy, &eval, 0.0).unwrap();
        let key = |l: &learner::gaifo::GaifoLog| {
            [l.task_cost, l.critic_loss, l.wasserstein, l.kl, l.eta].map(f64::to_bits)
        };
        assert_eq!((la.iteration, key(&la)), (i, key(&lb)));
        assert_eq!(a.policy(), b.policy());
    }
    let e = b.learn(&[], &a.iterate().unwrap().1, 0.0).unwrap_err();
    assert!(e.to_string().contains("needs 5 noisy episodes"), "{e}");
}
