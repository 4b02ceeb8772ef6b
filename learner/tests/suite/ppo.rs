//! The GAIfO (PPO) baseline: the PPO loss gradient against finite differences, GAE against a
//! hand-computed example, PPO on the true task cost improving the simulated arm, and bitwise
//! determinism of the imitation loop.

use imitation::demos::Demos;
use imitation::learn::iterate;
use imitation::ppo::gaifo_ppo::{GaifoPpo, GaifoPpoConfig};
use imitation::ppo::rollout::execute_mlp;
use imitation::ppo::{gae, ppo_loss_gradient, ActorCritic, Ppo, PpoConfig, Rollouts};
use imitation::rollout::Episode;
use learner::arm::SimArm;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};
use ur5_shared::layout::{DU, DX, EE_MINUS_GOAL};
use ur5_shared::StateLayout;

/// Small nets so that every parameter can be checked.
fn small_cfg() -> PpoConfig {
    PpoConfig {
        pi_hidden: vec![8, 6],
        v_hidden: vec![7, 5],
        ent_coef: 0.01,
        ..PpoConfig::default()
    }
}

/// A minibatch whose ratios are e^{−δ} for δ ∈ {±0.5, ±0.05}: two rows clipped (ρ = 1.65 with
/// Â > 0, ρ = 0.61 with Â < 0), the others away from the kinks at 1 ± 0.2.
fn batch(ac: &ActorCritic, rng: &mut ChaCha8Rng, m: usize) -> Rollouts {
    let mut ws = ac.workspace();
    let mut d = Rollouts::default();
    let shifts = [0.5, -0.5, 0.05, -0.05];
    for i in 0..m {
        let s: [f64; DX] = std::array::from_fn(|_| rng.random_range(-1.5..1.5));
        let delta: [f64; DU] = std::array::from_fn(|_| rng.random_range(-0.4..0.4));
        let mu = ac.policy.mean(&s, &mut ws.policy);
        let lp = ac.policy.log_prob_given_mean(&mu, &delta);
        d.states.extend_from_slice(&s);
        d.deltas.extend_from_slice(&delta);
        d.logp_old.push(lp + shifts[i % 4]);
        let a: f64 = rng.random_range(0.2..2.0);
        d.advantages.push(if i % 2 == 0 { -a } else { a });
        d.returns.push(rng.random_range(-3.0..3.0));
    }
    d
}

#[test]
fn ppo_loss_gradient_matches_finite_differences() {
    let cfg = small_cfg();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    // Output scale 1 so the mean heads matter; log σ = ln 0.3.
    let mut ac = ActorCritic::new(
        DX,
        DU,
        &cfg.pi_hidden,
        &cfg.v_hidden,
        0.3f64.ln(),
        1.0,
        &mut rng,
    );
    let m = 12;
    let data = batch(&ac, &mut rng, m);
    let idx: Vec<usize> = (0..m).collect();
    let mut ws = ac.workspace();
    let mut adv = Vec::new();
    let n = ac.n_params();
    let mut grad = vec![0.0; n];
    let parts = ppo_loss_gradient(&ac, &mut ws, &cfg, &data, &idx, &mut adv, &mut grad);
    assert!(parts.clip_fraction > 0.3 && parts.clip_fraction < 0.7);
    // Every ratio ≥ 0.03 away from the kinks at 0.8 and 1.2 (the finite differences move
    // log ρ by ~1e-5).
    let loss = |ac: &ActorCritic, ws: &mut imitation::ppo::ActorCriticWorkspace| {
        let (mut a, mut g) = (Vec::new(), vec![0.0; n]);
        ppo_loss_gradient(ac, ws, &cfg, &data, &idx, &mut a, &mut g).loss
    };
    let mut pws = ac.workspace();
    for (i, &lp_old) in data.logp_old.iter().enumerate() {
        let mu = ac.policy.mean(&data.state(i), &mut pws.policy);
        let r = (ac.policy.log_prob_given_mean(&mu, &data.delta(i)) - lp_old).exp();
        assert!(
            (r - 0.8).abs() > 0.03 && (r - 1.2).abs() > 0.03,
            "ratio {r} at a kink"
        );
    }
    let gmax = grad.iter().fold(0.0f64, |a, g| a.max(g.abs()));
    let mut worst = 0.0f64;
    let mut worst_k = 0;
    for k in 0..n {
        let th = ac.param(k);
        let h = 1e-5 * th.abs().max(1.0);
        ac.set_param(k, th + h);
        let lp = loss(&ac, &mut ws);
        ac.set_param(k, th - h);
        let lm = loss(&ac, &mut ws);
        ac.set_param(k, th);
        let fd = (lp - lm) / (2.0 * h);
        let rel = (fd - grad[k]).abs() / grad[k].abs().max(fd.abs()).max(1e-3 * gmax);
        if rel > worst {
            worst = rel;
            worst_k = k;
        }
    }
    let np = ac.n_policy_params();
    eprintln!(
        "{n} parameters ({} policy incl. {DU} log σ), loss {:.6}, max |g| {gmax:.3e}, worst relative error {worst:.2e} at {worst_k}",
        np, parts.loss
    );
    assert!(
        worst <= 1e-6,
        "worst relative error {worst:.2e} at parameter {worst_k}"
    );
    // The log σ entries get the surrogate's, and the entropy's, gradient.
    assert!(grad[np - DU..np].iter().all(|g| g.abs() > 1e-6));
}

/// γ = 0.5, λ = 0.5, r = (1, 0, 2), V = (0.5, 1, −1), V(s_3) = 4:
/// δ = (1 + 0.5 − 0.5, 0 − 0.5 − 1, 2 + 2 + 1) = (1, −1.5, 5);
/// Â_2 = 5, Â_1 = −1.5 + 0.25·5 = −0.25, Â_0 = 1 + 0.25·(−0.25) = 0.9375.
#[test]
fn gae_matches_a_hand_computed_example() {
    let mut adv = [0.0; 3];
    gae(&[1.0, 0.0, 2.0], &[0.5, 1.0, -1.0], 4.0, 0.5, 0.5, &mut adv);
    assert_eq!(adv, [0.9375, -0.25, 5.0]);
    // With SB3's γ = 0.99, λ = 0.95 on one step: Â = r + γ V' − V.
    let mut one = [0.0];
    gae(&[-0.3], &[0.2], 0.1, 0.99, 0.95, &mut one);
    assert!((one[0] - (-0.3 + 0.099 - 0.2)).abs() < 1e-15);
}

/// r_t = −‖ee_{t+1} − goal‖ (m): the per-step distance of the task cost.
fn distance_rewards(episodes: &[Episode]) -> Vec<Vec<f64>> {
    episodes
        .iter()
        .map(|ep| {
            (1..ep.horizon())
                .map(|t| {
                    let e = &ep.state(t)[EE_MINUS_GOAL];
                    -(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
                })
                .collect()
        })
        .collect()
}

/// Runs `iterations` PPO iterations on the true distance reward; returns the noise-free task
/// cost before each iteration and the final one, and the final parameters.
fn ppo_on_task_cost(
    cfg: PpoConfig,
    task: &TaskConfig,
    samples: usize,
    iterations: usize,
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let sim = SimArm::new(SimConfig::default(), task.dt).unwrap();
    let mut ppo = Ppo::new(cfg, ActionMode::GoalAngles, StateLayout::REACH3, seed).unwrap();
    let mut costs = Vec::new();
    for it in 0..=iterations {
        let (pol, _) = ppo.policy_and_workspace();
        let (eps, eval) = execute_mlp(&sim, task, pol, it as u64 + 1, seed, samples).unwrap();
        costs.push(eval.task_cost());
        if it < iterations {
            let st = ppo.update(&eps, &distance_rewards(&eps));
            if it % 10 == 0 || it + 1 == iterations {
                eprintln!(
                    "it {it:>3}: eval cost {:.3}, final distance {:.3} m, mean reward {:.4}, kl {:.2e}, clip {:.2}, σ {:.3}, v_loss {:.3e}",
                    eval.task_cost(),
                    eval.final_distance(),
                    st.mean_reward,
                    st.approx_kl,
                    st.clip_fraction,
                    st.mean_std,
                    st.value_loss
                );
            }
        }
    }
    let mut theta = vec![0.0; ppo.actor_critic().n_params()];
    ppo.actor_critic().read_params(&mut theta);
    (costs, theta)
}

/// PPO on the true per-step distance, T = 30 (3 s), 15 noisy episodes per iteration, 45
/// iterations: the noise-free task cost must come down clearly (measured while writing this:
/// 3.7–4.2 → 2.7–3.0 after 40 iterations of 15 episodes on 3 seeds, this seed 3.71 → 2.83
/// (mean of the last 5), 20 s; with 5 episodes per
/// iteration it took 60 iterations to reach 3.0–3.2). Not fast, and that is the paper's point:
/// PPO needs many more samples than LQR+GAIfO. Reward normalisation is off: the true cost has a
/// fixed scale (m).
#[test]
fn ppo_on_the_true_task_cost_reduces_it() {
    let task = TaskConfig {
        horizon: 30,
        ..TaskConfig::default()
    };
    let cfg = PpoConfig {
        normalize_reward: false,
        ..PpoConfig::default()
    };
    let t0 = std::time::Instant::now();
    let iterations = 45;
    let (costs, _) = ppo_on_task_cost(cfg, &task, 15, iterations, 0);
    let first = costs[0];
    let last5 = costs[iterations - 4..].iter().sum::<f64>() / 5.0;
    eprintln!(
        "task cost (T = 30) noise-free: first {first:.3}, mean of the last 5 {last5:.3} ({:.0} %), {:.1} s",
        100.0 * last5 / first,
        t0.elapsed().as_secs_f64()
    );
    assert!(
        last5 < 0.85 * first,
        "PPO did not reduce the task cost: {costs:?}"
    );
}

#[test]
fn reward_normalisation_matches_two_pass_statistics() {
    use imitation::ppo::{normalize_rewards, RunningMeanStd};
    let mut rms = RunningMeanStd::default();
    let mut r = vec![vec![1.0, -2.0, 0.5], vec![3.0, 0.0]];
    normalize_rewards(&mut rms, 0.5, &mut r);
    // Discounted returns fed in order: 1, −1.5, −0.25 | 3, 1.5.
    let x = [1.0, -1.5, -0.25, 3.0, 1.5];
    let mean = x.iter().sum::<f64>() / 5.0;
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / 5.0;
    // The prior (count 1e-4, var 1) weighs 2e-5 of the total.
    assert!((rms.mean - mean).abs() < 1e-4 && (rms.var - var).abs() < 1e-4);
    assert!((rms.count - 5.0001).abs() < 1e-12);
    assert!((r[1][1] - 0.0).abs() < 1e-15);
    // Each reward is scaled by the statistics after its own return went in.
    let mut upto = RunningMeanStd::default();
    for v in &x[..4] {
        upto.update(*v);
    }
    assert_eq!(r[1][0], (3.0 / (upto.var + 1e-8).sqrt()).clamp(-10.0, 10.0));
}

#[test]
fn same_seed_same_run_bit_for_bit() {
    let task = TaskConfig {
        horizon: 15,
        ..TaskConfig::default()
    };
    let cfg = PpoConfig {
        pi_hidden: vec![16, 16],
        v_hidden: vec![16, 16],
        ..PpoConfig::default()
    };
    let (c1, p1) = ppo_on_task_cost(cfg.clone(), &task, 2, 3, 11);
    let (c2, p2) = ppo_on_task_cost(cfg.clone(), &task, 2, 3, 11);
    let (_, p3) = ppo_on_task_cost(cfg, &task, 2, 3, 12);
    assert_eq!(c1, c2);
    assert_eq!(p1, p2);
    assert_ne!(p1, p3, "another seed, another run");
}

/// Demonstrations stand-in: two episodes of a fresh noisy policy (the loop only needs states).
fn fake_demos(task: &TaskConfig) -> Demos {
    let sim = SimArm::new(SimConfig::default(), task.dt).unwrap();
    let mut ppo = Ppo::new(
        PpoConfig::default(),
        ActionMode::GoalAngles,
        StateLayout::REACH3,
        99,
    )
    .unwrap();
    let (pol, _) = ppo.policy_and_workspace();
    let (eps, _) = execute_mlp(&sim, task, pol, 1, 5, 2).unwrap();
    Demos {
        states: eps.iter().flat_map(|e| e.x.iter().copied()).collect(),
        actions: eps.iter().flat_map(|e| e.u.iter().copied()).collect(),
        model: ur5_shared::UrModel::Ur5,
        count: 2,
        horizon: task.horizon,
        goal: task.goal,
        goal_pose: None,
        tool_points: task.tool_points,
        start_q: task.start_q,
        dt: task.dt,
        seed: 5,
        cost_random: 5.0,
        cost_expert: 1.0,
    }
}

#[test]
fn gaifo_ppo_is_deterministic_and_logs_like_lqr_gaifo() {
    let task = TaskConfig {
        horizon: 12,
        ..TaskConfig::default()
    };
    let demos = fake_demos(&task);
    let cfg = GaifoPpoConfig {
        iterations: 2,
        ..GaifoPpoConfig::default()
    };
    let run = |cfg: &GaifoPpoConfig| {
        let mut r = GaifoPpo::new(cfg.clone(), demos.clone()).unwrap();
        let arm = learner::run::arm_for(&r).unwrap();
        let mut out = Vec::new();
        for _ in 0..cfg.iterations {
            let (log, eval) = iterate(&mut r, &arm).unwrap();
            out.push((
                log.task_cost,
                log.critic_loss,
                log.wasserstein,
                log.kl,
                eval,
            ));
        }
        let mut th = vec![0.0; r.ppo().actor_critic().n_params()];
        r.ppo().actor_critic().read_params(&mut th);
        (out, th, r.discriminator().params().to_vec())
    };
    let a = run(&cfg);
    let b = run(&cfg);
    assert_eq!(a.0.len(), 2);
    for (x, y) in a.0.iter().zip(&b.0) {
        assert_eq!(x.0.to_bits(), y.0.to_bits());
        assert_eq!(x.1.to_bits(), y.1.to_bits());
        assert_eq!(x.2.to_bits(), y.2.to_bits());
        assert_eq!(x.3.to_bits(), y.3.to_bits());
        assert_eq!(x.4, y.4);
    }
    assert_eq!(a.1, b.1);
    assert_eq!(a.2, b.2);
    // The CSV: LQR+GAIfO's header, algorithm gaifo-ppo.
    let dir = std::env::temp_dir().join(format!("ppo_test_csv_{}", std::process::id()));
    let logs = learner::run::train_ppo(&cfg, demos, Some(&dir), |_, _| {}).unwrap();
    assert_eq!(logs.len(), 2);
    let csv = std::fs::read_to_string(dir.join("gaifo_log.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), learner::io::log::CSV_HEADER);
    let row: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(row.len(), learner::io::log::CSV_HEADER.split(',').count());
    assert_eq!(row[2], "gaifo-ppo");
    assert!(dir.join("iter_002_policy.json").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
