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
