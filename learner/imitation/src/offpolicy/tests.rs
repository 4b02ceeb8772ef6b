//! TD3's targets, losses and gradients on tiny nets against values computed by hand from the
//! nets' formulas, the gradients against central differences, Polyak averaging, and the
//! absorbing-state rows.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::layout::{DU, DX};

use super::replay::{ReplayBuffer, RowKind};
use super::td3::{smoothing_noise, Minibatch, Td3, Td3Config};
use super::{add_episode, EpisodeEnd, GaifoTd3Config};
use crate::discriminator::Normalizer;
use crate::rollout::Episode;
use ur5_shared::config::ActionMode;

const BOUND: [f64; DU] = [0.5, 1.0, 2.0];

/// TD3 with one hidden unit per net, the normalisation `u = (s − 0.1) / 2`, and every weight
/// drawn from `seed` (so that nothing is zero).
fn tiny(cfg: Td3Config, seed: u64) -> Td3 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let norm = Normalizer {
        mean: vec![0.1; DX],
        std: vec![2.0; DX],
    };
    let mut t = Td3::new(
        cfg,
        ur5_shared::StateLayout::REACH3,
        ur5_shared::joints::Joints::from(BOUND),
        norm,
        0.3,
        &mut rng,
    );
    let mut draw = |p: &mut [f64]| p.iter_mut().for_each(|v| *v = rng.random_range(-0.8..0.8));
    for k in 0..2 {
        draw(t.q[k].params_mut());
        draw(t.q_target[k].params_mut());
    }
    for pol in [&mut t.actor, &mut t.actor_target] {
        let n = pol.net().n_params();
        let mut theta = vec![0.0; n];
        pol.net().read_params(&mut theta);
        draw(&mut theta[..n - DU]);
        pol.net_mut().write_params(&theta);
    }
    t
}

fn tiny_cfg() -> Td3Config {
    Td3Config {
        pi_hidden: vec![1],
        q_hidden: vec![1],
        ..Td3Config::default()
    }
}

/// `w1 tanh(w0 · x + b0) + b1` of a net with one hidden unit, parameters `[w0, b0, w1, b1]`.
fn one_unit(p: &[f64], x: &[f64]) -> f64 {
    let n = x.len();
    let a: f64 = p[..n].iter().zip(x).map(|(w, x)| w * x).sum::<f64>() + p[n];
    p[n + 1] * a.tanh() + p[n + 2]
}

/// μ_j(s) of a tiny actor, by hand: u = (s − 0.1)/2, then head j's one unit.
fn mu_by_hand(pol: &crate::mlp_policy::global::GlobalPolicy, s: &[f64; DX], j: usize) -> f64 {
    let u: Vec<f64> = s.iter().map(|v| (v - 0.1) / 2.0).collect();
    one_unit(pol.net().head(j).params(), &u)
}

fn q_by_hand(p: &[f64], s: Option<&[f64; DX]>, a: &[f64; DU]) -> f64 {
    let mut x = vec![0.0; DX + DU + 1];
    match s {
        Some(s) => {
            for i in 0..DX {
                x[i] = (s[i] - 0.1) / 2.0;
            }
            x[DX..DX + DU].copy_from_slice(a);
        }
        None => x[DX + DU] = 1.0,
    }
    one_unit(p, &x)
}

/// Three rows: a step, one into the absorbing state, the absorbing state's own.
fn batch(rng: &mut ChaCha8Rng) -> Minibatch {
    let mut b = Minibatch::default();
    for (absorbing, next_absorbing) in [(false, false), (false, true), (true, true)] {
        let s: Vec<f64> = (0..DX).map(|_| rng.random_range(-1.5..1.5)).collect();
        b.s.extend_from_slice(&s);
        b.s_next
            .extend((0..DX).map(|_| rng.random_range(-1.5..1.5)));
        b.a.extend((0..DU).map(|_| rng.random_range(-1.0..1.0)));
        b.absorbing.push(absorbing);
        b.next_absorbing.push(next_absorbing);
        b.r.push(rng.random_range(-2.0..2.0));
    }
    b
}

#[test]
fn td_targets_are_the_clipped_double_q_of_the_smoothed_target_action() {
    let cfg = Td3Config {
        target_noise: 0.4,
        target_noise_clip: 0.3,
        gamma: 0.9,
        ..tiny_cfg()
    };
    let mut t = tiny(cfg, 1);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let b = batch(&mut rng);
    // Large noise, so that both clips act on some entries.
    let eps = [1.5, -0.2, 0.1, -2.0, 0.7, 3.0, 0.0, 0.0, 0.0];
    let mut y = Vec::new();
    t.targets(&b, &eps, &mut y);
    let gamma = 0.9;
    // Row 0: a step row.
    let s1: [f64; DX] = b.s_next[..DX].try_into().unwrap();
    let a: [f64; DU] = std::array::from_fn(|j| {
        let mu = mu_by_hand(&t.actor_target, &s1, j) / BOUND[j];
        (mu + (0.4 * eps[j]).clamp(-0.3, 0.3)).clamp(-1.0, 1.0)
    });
    let q =
        |k: usize, s: Option<&[f64; DX]>, a: &[f64; DU]| q_by_hand(t.q_target[k].params(), s, a);
    let want0 = b.r[0] + gamma * q(0, Some(&s1), &a).min(q(1, Some(&s1), &a));
    // Rows 1 and 2 bootstrap from the absorbing state, whatever their s' and noise.
    let qa = q(0, None, &[0.0; DU]).min(q(1, None, &[0.0; DU]));
    let want = [want0, b.r[1] + gamma * qa, b.r[2] + gamma * qa];
    for i in 0..3 {
        assert!(
            (y[i] - want[i]).abs() < 1e-14,
            "row {i}: {} vs {}",
            y[i],
            want[i]
        );
    }
    // The same by hand with the online critics would differ: the targets use Q'.
    assert_ne!(
        q_by_hand(t.q[0].params(), None, &[0.0; DU]),
        q(0, None, &[0.0; DU])
    );
}

#[test]
fn critic_loss_and_gradient_match_the_formula_and_central_differences() {
    let mut t = tiny(tiny_cfg(), 3);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let b = batch(&mut rng);
    let y = vec![0.3, -1.1, 0.8];
    for k in 0..2 {
        let mut grad = Vec::new();
        let loss = t.critic_loss_gradient(k, &b, &y, &mut grad);
        let by_hand: f64 = (0..3)
            .map(|i| {
                let s: [f64; DX] = b.s[i * DX..(i + 1) * DX].try_into().unwrap();
                let a: [f64; DU] = b.a[i * DU..(i + 1) * DU].try_into().unwrap();
                let s = (!b.absorbing[i]).then_some(&s);
                let e = q_by_hand(t.q[k].params(), s, &a) - y[i];
                e * e / 3.0
            })
            .sum();
        assert!((loss - by_hand).abs() < 1e-14, "{loss} vs {by_hand}");
        let h = 1e-6;
        for p in 0..grad.len() {
            let base = t.q[k].params()[p];
            let mut scratch = Vec::new();
            t.q[k].params_mut()[p] = base + h;
            let up = t.critic_loss_gradient(k, &b, &y, &mut scratch);
            t.q[k].params_mut()[p] = base - h;
            let down = t.critic_loss_gradient(k, &b, &y, &mut scratch);
            t.q[k].params_mut()[p] = base;
            let fd = (up - down) / (2.0 * h);
            assert!(
                (grad[p] - fd).abs() < 1e-7 * (1.0 + fd.abs()),
                "critic {k} parameter {p}: {} vs {fd}",
                grad[p]
            );
        }
    }
}

#[test]
fn actor_loss_and_gradient_match_the_formula_and_central_differences() {
    // Heads with large weights, so that some μ_j/b_j leave [−1, 1] and the penalty acts.
    let cfg = Td3Config {
        bound_penalty: 0.7,
        ..tiny_cfg()
    };
    let mut t = tiny(cfg, 5);
    let n = t.actor.net().n_params();
    let mut theta = vec![0.0; n];
    t.actor.net().read_params(&mut theta);
    for v in &mut theta[..n - DU] {
        *v *= 3.0;
    }
    t.actor.net_mut().write_params(&theta);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let mut b = batch(&mut rng);
    for v in &mut b.s {
        *v *= 2.0;
    }
    let mut grad = Vec::new();
    let loss = t.actor_loss_gradient(&b, &mut grad);
    // By hand: rows 0 and 1 (row 2 is the absorbing state, where the actor does not act).
    let mut by_hand = 0.0;
    let mut penalised = 0;
    for i in 0..2 {
        let s: [f64; DX] = b.s[i * DX..(i + 1) * DX].try_into().unwrap();
        let a: [f64; DU] = std::array::from_fn(|j| mu_by_hand(&t.actor, &s, j) / BOUND[j]);
        by_hand -= q_by_hand(t.q[0].params(), Some(&s), &a) / 2.0;
        for aj in a {
            let over = (aj.abs() - 1.0).max(0.0);
            penalised += usize::from(over > 0.0);
            by_hand += 0.7 * 0.5 * over * over / 2.0;
        }
    }
    assert!(
        penalised > 0 && penalised < 6,
        "{penalised} entries penalised"
    );
    assert!((loss - by_hand).abs() < 1e-13, "{loss} vs {by_hand}");
    let h = 1e-6;
    for p in 0..n {
        let mut scratch = Vec::new();
        let mut at = |v: f64, t: &mut Td3| {
            let mut th = theta.clone();
            th[p] = v;
            t.actor.net_mut().write_params(&th);
            t.actor_loss_gradient(&b, &mut scratch)
        };
        let fd = (at(theta[p] + h, &mut t) - at(theta[p] - h, &mut t)) / (2.0 * h);
        t.actor.net_mut().write_params(&theta);
        assert!(
            (grad[p] - fd).abs() < 1e-7 * (1.0 + fd.abs()),
            "actor parameter {p}: {} vs {fd}",
            grad[p]
        );
    }
    // σ is not trained.
    assert!(grad[n - DU..].iter().all(|&g| g == 0.0));
}

#[test]
fn a_step_updates_the_critics_every_time_and_the_actor_and_targets_every_d_steps() {
    let cfg = Td3Config {
        policy_delay: 2,
        tau: 0.25,
        ..tiny_cfg()
    };
    let mut t = tiny(cfg, 7);
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let b = batch(&mut rng);
    let params = |t: &Td3| {
        (
            [t.q[0].params().to_vec(), t.q[1].params().to_vec()],
            [
                t.q_target[0].params().to_vec(),
                t.q_target[1].params().to_vec(),
            ],
            t.actor.flat(),
            t.actor_target.flat(),
        )
    };
    let before = params(&t);
    // The step draws its smoothing noise first: redo its targets by hand.
    let mut noise_rng = ChaCha8Rng::seed_from_u64(9);
    let mut copy_rng = noise_rng.clone();
    let eps = smoothing_noise(&mut copy_rng, b.len() * DU);
    let mut y = Vec::new();
    t.targets(&b, &eps, &mut y);
    let st = t.step(&b, &mut noise_rng);
    assert_eq!(noise_rng, copy_rng, "the step draws m·dU normals");
    assert!((st.mean_target - y.iter().sum::<f64>() / 3.0).abs() < 1e-15);
    assert!(st.actor_loss.is_nan(), "no actor step at step 1 of d = 2");
    let one = params(&t);
    assert_ne!(one.0, before.0, "critics stepped");
    assert_eq!(one.1, before.1, "targets kept");
    assert_eq!(one.2, before.2, "actor kept");
    t.step(&b, &mut noise_rng);
    let two = params(&t);
    assert_ne!(two.2, before.2, "actor stepped at step 2");
    // θ' = τ θ + (1 − τ) θ'_before, with θ the nets after step 2.
    for k in 0..2 {
        for ((tp, p), old) in two.1[k].iter().zip(&two.0[k]).zip(&before.1[k]) {
            assert_eq!(*tp, 0.25 * p + 0.75 * old);
        }
    }
    // The actor's target: the heads' parameters averaged, its normalisation and σ as they were.
    let heads = 2 * DX..two.3.len() - DU;
    for ((tp, p), old) in two.3[heads.clone()]
        .iter()
        .zip(&two.2[heads.clone()])
        .zip(&before.3[heads])
    {
        assert_eq!(*tp, 0.25 * p + 0.75 * old);
    }
    assert_eq!(two.3[..2 * DX], before.3[..2 * DX]);
    assert_eq!(two.2[two.2.len() - DU..], before.2[before.2.len() - DU..]);
}

/// An episode of `t` states with distinct values.
fn episode(t: usize) -> Episode {
    Episode {
        layout: ur5_shared::StateLayout::REACH3,
        x: (0..t * DX).map(|i| 0.01 * i as f64).collect(),
        u: (0..t * DU).map(|i| 0.5 + 0.02 * i as f64).collect(),
        u_policy: vec![0.0; t * DU],
        eps: vec![0.0; t * DU],
        noisy: true,
    }
}

#[test]
fn episodes_become_rows_with_executed_offsets_and_dac_ends() {
    let ep = episode(4);
    let mut buf = ReplayBuffer::new(DX, DU, 100);
    add_episode(
        &mut buf,
        &ep,
        ActionMode::GoalAngles,
        &BOUND,
        EpisodeEnd::TimeLimit,
    );
    assert_eq!(buf.len(), 3, "T − 1 transitions");
    assert!((0..3).all(|i| buf.row(i).kind == RowKind::Step));
    let r = buf.row(1);
    assert_eq!(r.s, &ep.x[DX..2 * DX]);
    assert_eq!(r.s_next, &ep.x[2 * DX..3 * DX]);
    for j in 0..DU {
        // Goal-angle mode: the executed goal angle minus q = s[j], over the bound.
        assert_eq!(r.a[j], (ep.u[DU + j] - ep.x[DX + j]) / BOUND[j]);
    }
    let mut torque = ReplayBuffer::new(DX, DU, 100);
    add_episode(
        &mut torque,
        &ep,
        ActionMode::Torque,
        &BOUND,
        EpisodeEnd::TimeLimit,
    );
    assert_eq!(torque.row(1).a[2], ep.u[DU + 2] / BOUND[2]);

    let mut term = ReplayBuffer::new(DX, DU, 100);
    add_episode(
        &mut term,
        &ep,
        ActionMode::GoalAngles,
        &BOUND,
        EpisodeEnd::Terminated,
    );
    let kinds: Vec<RowKind> = (0..term.len()).map(|i| term.row(i).kind).collect();
    assert_eq!(
        kinds,
        [
            RowKind::Step,
            RowKind::Step,
            RowKind::ToAbsorbing,
            RowKind::Absorbing
        ]
    );
    let abs = term.row(3);
    assert_eq!((abs.s, abs.s_next), (&ep.x[3 * DX..], &ep.x[3 * DX..]));
    assert_eq!(abs.a, &[0.0; DU]);
}

#[test]
fn settings_that_cannot_work_are_refused_naming_the_setting() {
    assert!(GaifoTd3Config::default().validate().is_ok());
    let cases: Vec<(&str, Box<dyn Fn(&mut GaifoTd3Config)>)> = vec![
        ("samples", Box::new(|c| c.samples = 0)),
        ("buffer_capacity", Box::new(|c| c.buffer_capacity = 0)),
        (
            "updates_per_episode",
            Box::new(|c| c.updates_per_episode = 1_000_000_000),
        ),
        ("exploration_noise", Box::new(|c| c.exploration_noise = 0.0)),
        ("reward_scale", Box::new(|c| c.reward_scale = f64::NAN)),
        ("gamma", Box::new(|c| c.td3.gamma = 1.0)),
        ("tau", Box::new(|c| c.td3.tau = 0.0)),
        ("policy_delay", Box::new(|c| c.td3.policy_delay = 0)),
        ("batch_size", Box::new(|c| c.td3.batch_size = 0)),
        ("q_hidden", Box::new(|c| c.td3.q_hidden = vec![])),
        ("critic_adam", Box::new(|c| c.td3.critic_adam.lr = -1.0)),
        ("critic_updates", Box::new(|c| c.critic_updates = 0)),
    ];
    crate::error::assert_each_refused_naming(cases, GaifoTd3Config::validate);
}
