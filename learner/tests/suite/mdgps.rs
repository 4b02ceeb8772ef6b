//! MDGPS (docs/design.md §6): the global policy's Jacobian against finite differences, the
//! S-step, the policy file, a tiny seeded MDGPS run, the evaluation goals and the command
//! line's errors. All fast (seconds).

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::learner;

use imitation::controller::init_hold;
use imitation::demos::Demos;
use imitation::expert::{record_demos, square_goals, ExpertConfig};
use imitation::mdgps::{Mdgps, MdgpsConfig, MdgpsLog};
use imitation::mlp_policy::global::{flat_len, GlobalPolicy};
use imitation::mlp_policy::opt::{PolicyOpt, PolicyOptConfig, Targets};
use learner::arm::SimArm;
use learner::experiment::multi_goal::eval_goals;
use learner::io::policy::{load_policy, save_policy, PolicyFile};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ur5_shared::config::{ActionMode, TaskConfig};
use ur5_shared::layout::{DU, DX};
use ur5_shared::{StateLayout, UrModel};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mdgps-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A policy with every parameter random (non-zero output layers, a non-trivial
/// normalisation), so that every term of the Jacobian is exercised.
fn random_policy(hidden: &[usize], seed: u64) -> GlobalPolicy {
    random_policy_of(StateLayout::REACH3, hidden, seed)
}

/// [`random_policy`] for the task of `layout`.
fn random_policy_of(layout: StateLayout, hidden: &[usize], seed: u64) -> GlobalPolicy {
    let dx = layout.dx();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let flat: Vec<f64> = (0..flat_len(dx, layout.du(), hidden))
        .map(|i| {
            if (dx..2 * dx).contains(&i) {
                rng.random_range(0.2..2.0)
            } else {
                rng.random_range(-0.6..0.6)
            }
        })
        .collect();
    GlobalPolicy::from_flat(layout, hidden, &flat).unwrap()
}

fn random_state(rng: &mut ChaCha8Rng) -> [f64; DX] {
    std::array::from_fn(|_| rng.random_range(-1.0..1.0))
}

#[test]
fn mean_action_jacobian_matches_central_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for (layout, hidden, mode) in [
        (StateLayout::REACH3, vec![16, 8], ActionMode::GoalAngles),
        (StateLayout::REACH3, vec![5], ActionMode::Torque),
        (StateLayout::REACH3, vec![64, 64], ActionMode::GoalAngles),
        (StateLayout::POSE6, vec![16, 8], ActionMode::GoalAngles),
        (StateLayout::POSE6, vec![5], ActionMode::Torque),
    ] {
        let (dx, du) = (layout.dx(), layout.du());
        let pol = random_policy_of(layout, &hidden, 11);
        let mut ws = pol.workspace();
        for _ in 0..5 {
            let s: Vec<f64> = (0..dx).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut jac = vec![0.0; du * dx];
            let a = pol.mean_action_jacobian(&s, mode, &mut ws, &mut jac);
            assert_eq!(a.len(), du);
            assert_eq!(
                a,
                pol.mean_action(&s, mode, &mut ws),
                "same mean either way"
            );
            let h = 1e-6;
            for i in 0..dx {
                let (mut sp, mut sm) = (s.clone(), s.clone());
                sp[i] += h;
                sm[i] -= h;
                let (ap, am) = (
                    pol.mean_action(&sp, mode, &mut ws),
                    pol.mean_action(&sm, mode, &mut ws),
                );
                for j in 0..du {
                    let fd = (ap[j] - am[j]) / (2.0 * h);
                    let err = (fd - jac[j * dx + i]).abs();
                    assert!(
                        err <= 1e-7 * (1.0 + fd.abs()),
                        "{layout} {hidden:?} {mode:?}: ∂a_{j}/∂s_{i} analytic {} vs central difference {fd}",
                        jac[j * dx + i]
                    );
                }
            }
        }
    }
}

/// Targets from a smooth function of the state with random SPD precisions.
fn synthetic_targets(n: usize, seed: u64) -> Targets {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a: [[f64; DX]; DU] =
        std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-0.3..0.3)));
    let mut t = Targets::new(DX, DU);
    for _ in 0..n {
        let s = random_state(&mut rng);
        let offset: [f64; DU] = std::array::from_fn(|j| {
            (0..DX).map(|i| a[j][i] * s[i]).sum::<f64>() + 0.2 * (2.0 * s[j]).sin()
        });
        // P = B Bᵀ + 0.5 I.
        let b: [[f64; DU]; DU] =
            std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-2.0..2.0)));
        let p: Vec<f64> = (0..DU * DU)
            .map(|ij| {
                let (i, j) = (ij / DU, ij % DU);
                (0..DU).map(|k| b[i][k] * b[j][k]).sum::<f64>() + if i == j { 0.5 } else { 0.0 }
            })
            .collect();
        t.push(&s, &offset, &p);
    }
    t
}

#[test]
fn s_step_reduces_the_weighted_loss_and_is_deterministic_for_a_seed() {
    let data = synthetic_targets(300, 1);
    let cfg = PolicyOptConfig {
        hidden: vec![16, 16],
        steps: 300,
        batch_size: 32,
        ..PolicyOptConfig::default()
    };
    let fit = |seed: u64| {
        let mut pol = GlobalPolicy::new(
            StateLayout::REACH3,
            &cfg.hidden,
            0.2,
            &mut ChaCha8Rng::seed_from_u64(3),
        );
        let mut opt = PolicyOpt::new(cfg.clone(), &pol, seed);
        let r1 = opt.update(&mut pol, &data).unwrap();
        let r2 = opt.update(&mut pol, &data).unwrap();
        (pol, r1, r2)
    };
    let (pol, r1, r2) = fit(5);
    assert!(
        r1.loss_after < 0.3 * r1.loss_before && r2.loss_after < r1.loss_after,
        "loss {} -> {} -> {}",
        r1.loss_before,
        r1.loss_after,
        r2.loss_after
    );
    let mut ws = pol.workspace();
    assert_eq!(PolicyOpt::loss(&pol, &data, &mut ws), r2.loss_after);
    // σ² = 1 / mean (P)_jj.
    for j in 0..DU {
        let m = (0..data.len())
            .map(|i| data.precision(i)[j * DU + j])
            .sum::<f64>()
            / data.len() as f64;
        assert!((pol.std()[j] - (1.0 / m).sqrt()).abs() < 1e-12);
    }
    let (again, a1, _) = fit(5);
    assert_eq!(
        again.flat(),
        pol.flat(),
        "same seed, same policy bit for bit"
    );
    assert_eq!(a1, r1);
    let (other, _, _) = fit(6);
    assert_ne!(other.flat(), pol.flat(), "the seed orders the minibatches");
}

fn policy_file() -> PolicyFile {
    PolicyFile {
        policy: random_policy(&[8, 4], 2),
        mode: ActionMode::GoalAngles,
        start_q: [0.0, -2.0, 2.4].into(),
        dt: 0.1,
        horizon: 100,
        seed: u64::MAX - 3,
        iterations: 20,
        model: UrModel::Ur5,
    }
}

#[test]
fn policy_file_round_trips_exactly() {
    let dir = tmp("roundtrip");
    let p = dir.join("policy.npz");
    let f = policy_file();
    save_policy(&f, &p).unwrap();
    assert_eq!(load_policy(&p).unwrap(), f);
    std::fs::remove_dir_all(&dir).ok();
}

/// Rewrites `src` with array `name` replaced (`None`: removed) through the npz writer.
fn edit(src: &Path, dst: &Path, name: &str, new: Option<(&[u64], &[f64])>) {
    use learner::io::npz::{NpzFile, NpzWriter};
    let f = NpzFile::open(src).unwrap();
    let mut w = NpzWriter::create(dst).unwrap();
    for n in f.names() {
        if n == name {
            if let Some((shape, v)) = new {
                w.f64(&n, shape, v).unwrap();
            }
            continue;
        }
        match n.as_str() {
            "state_names" | "action_names" | "action_mode" | "model" => {
                let s = f.strings(&n).unwrap();
                let r: Vec<&str> = s.iter().map(String::as_str).collect();
                w.strings(&n, &r).unwrap();
            }
            "seed" | "horizon" | "iterations" => {
                w.u64(&n, &[], &[f.u64_scalar(&n).unwrap()]).unwrap()
            }
            _ => {
                let (shape, v) = f.f64(&n).unwrap();
                w.f64(&n, &shape, &v).unwrap();
            }
        }
    }
    w.finish().unwrap();
}

#[test]
fn bad_policy_files_are_refused_naming_file_and_array() {
    let dir = tmp("bad");
    let good = dir.join("good.npz");
    save_policy(&policy_file(), &good).unwrap();
    let n = flat_len(DX, DU, &[8, 4]) as u64;
    let mut nan = policy_file().policy.flat();
    nan[40] = f64::NAN;
    let mut neg = policy_file().policy.flat();
    neg[DX + 1] = -1.0;
    let mut huge = policy_file().policy.flat();
    huge[40] = 1e300;
    let cases: Vec<(&str, Option<(Vec<u64>, Vec<f64>)>, &str)> = vec![
        ("params", Some((vec![n - 1], vec![0.1; n as usize - 1]))),
        ("params", Some((vec![n], nan))),
        ("params", Some((vec![n], neg))),
        ("params", Some((vec![n], huge))),
        ("hidden", Some((vec![2], vec![8.0, 0.0]))),
        ("hidden", Some((vec![1, 2], vec![8.0, 4.0]))),
        ("schema_version", Some((vec![], vec![2.0]))),
        ("dt", Some((vec![], vec![0.0]))),
        ("dt", Some((vec![], vec![100.0]))),
        ("start_q", Some((vec![2], vec![0.0, 1.0]))),
        ("params", None),
    ]
    .into_iter()
    .zip([
        "expected [",
        "not finite",
        "r[1]",
        "max_abs_weight",
        "width 0",
        "expected (H,)",
        "this program reads 1",
        "supported are 10 Hz to 1 kHz",
        "100 s is a control rate of 0.01 Hz",
        "expected [3]",
        "no array `params`",
    ])
    .map(|((a, b), c)| (a, b, c))
    .collect();
    for (i, (name, new, why)) in cases.iter().enumerate() {
        let p = dir.join(format!("bad{i}.npz"));
        edit(
            &good,
            &p,
            name,
            new.as_ref().map(|(s, v)| (s.as_slice(), v.as_slice())),
        );
        let e = load_policy(&p).unwrap_err().to_string();
        assert!(
            e.contains(&p.display().to_string()) && e.contains(name) && e.contains(why),
            "{name}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Demonstrations of the initial controller (they need not be good: the run only has to be
/// reproducible) at `goal`, T = `horizon`.
fn tiny_demos(goal: [f64; 3], horizon: usize) -> Demos {
    let cfg = ExpertConfig {
        task: TaskConfig {
            horizon,
            goal,
            ..TaskConfig::default()
        },
        demos: 2,
        ..ExpertConfig::default()
    };
    let arm = SimArm::new(cfg.sim.clone(), cfg.task.dt).unwrap();
    let mut d = record_demos(&cfg, &arm, &init_hold(&cfg.task, 0.01), 0.0).unwrap();
    d.cost_random = d.cost_expert + 1.0;
    d
}

#[test]
fn a_tiny_mdgps_run_is_reproducible_bit_for_bit() {
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let mut cfg = tiny_config();
    let run = |cfg: &MdgpsConfig| {
        let mut m = Mdgps::new(cfg.clone(), demos.clone()).unwrap();
        let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
        let mut logs = Vec::new();
        for _ in 0..3 {
            let (samples, evals) = m.execute(&arm).unwrap();
            let mut l = m.learn(&samples, &evals, 0.0).unwrap();
            l.t_dynamics = 0.0;
            l.t_critic = 0.0;
            l.t_cost = 0.0;
            l.t_lqr = 0.0;
            l.t_policy = 0.0;
            logs.push(format!("{l:?}"));
        }
        let ctrl: Vec<_> = (0..m.conditions())
            .map(|c| m.controller(c).clone())
            .collect();
        (m.policy().flat(), ctrl, logs)
    };
    let a = run(&cfg);
    assert!(a.2.iter().all(|l| !l.contains("NaN")), "{:?}", a.2);
    let b = run(&cfg);
    assert_eq!(a.0, b.0, "policy");
    assert_eq!(a.1, b.1, "controllers");
    assert_eq!(a.2, b.2, "logs");
    cfg.lqr_gaifo.seed = 10;
    assert_ne!(run(&cfg).0, a.0, "another seed, another run");
}

#[test]
fn evaluation_goals_are_seeded_and_where_they_should_be() {
    let c = [-0.45, -0.25, 0.25];
    let g = eval_goals(c, 0.1, 8, 4, 0.03, 14);
    assert_eq!(g.len(), 1 + 8 + 4 + 8);
    assert_eq!(g[0].goal, c);
    let sq = square_goals(c, 0.1);
    for e in &g {
        let (dx, dy) = ((e.goal[0] - c[0]).abs(), (e.goal[1] - c[1]).abs());
        assert_eq!(e.goal[2], c[2]);
        match e.kind {
            "inside" => {
                assert!(dx < 0.1 && dy < 0.1);
                assert!(sq
                    .iter()
                    .all(|p| (p[0] - e.goal[0]).hypot(p[1] - e.goal[1]) >= 0.01));
            }
            "outside" => assert!((dx.max(dy) - 0.13).abs() < 1e-12, "{e:?}"),
            _ => {}
        }
    }
    let again = eval_goals(c, 0.1, 8, 4, 0.03, 14);
    assert!(g.iter().zip(&again).all(|(a, b)| a.goal == b.goal));
}

#[test]
fn command_line_errors_are_clear() {
    let (ok, e) = learner(&["policy", "eval", "--policy", "p.npz", "--goal", "1,2"]);
    assert!(!ok && e.contains("--goal"), "{e}");
    let (ok, e) = learner(&["policy", "eval", "--goal", "1,2,3"]);
    assert!(!ok && e.contains("--policy"), "{e}");
    let missing = tmp("cli").join("missing.npz");
    let (ok, e) = learner(&[
        "policy",
        "eval",
        "--policy",
        missing.to_str().unwrap(),
        "--goal",
        "-0.45,-0.25,0.25",
    ]);
    assert!(!ok && e.contains("missing.npz"), "{e}");
    let no_experts = tmp("cli").join("no-experts");
    let (ok, e) = learner(&[
        "experiment",
        "multi-goal",
        "--demos",
        no_experts.to_str().unwrap(),
        "--out",
        tmp("cli").join("out").to_str().unwrap(),
    ]);
    assert!(
        !ok && e.contains("no-experts/point_0.npz"),
        "a missing experts folder is named: {e}"
    );
    let (ok, e) = learner(&["experiment", "multi-goal", "--iterations", "0"]);
    assert!(!ok && e.contains("iterations"), "{e}");
}

#[test]
fn policy_eval_runs_a_saved_policy_to_a_goal() {
    let dir = tmp("eval");
    let p = dir.join("policy.npz");
    let mut f = policy_file();
    f.horizon = 5;
    // Zero heads: the policy holds the start pose, so the distance is the start's.
    let mut flat = f.policy.flat();
    for v in &mut flat[2 * DX..] {
        *v = 0.0;
    }
    f.policy = GlobalPolicy::from_flat(StateLayout::REACH3, &[8, 4], &flat).unwrap();
    save_policy(&f, &p).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(["policy", "eval", "--policy", p.to_str().unwrap()])
        .args(["--goal", "-0.45,-0.25,0.25", "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let d = v["result"]["final_distance_m"].as_f64().unwrap();
    assert!(d > 0.1 && d.is_finite(), "{v}");
    assert_eq!(v["result"]["steps"], 5);
    assert_eq!(v["result"]["model"], "ur5");
    // A policy of another arm runs on its own arm (its kinematics), said in the summary;
    // one whose model this build does not know is refused naming it.
    let p5e = dir.join("policy_ur5e.npz");
    save_policy(
        &PolicyFile {
            model: UrModel::Ur5e,
            ..f.clone()
        },
        &p5e,
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_learner"))
        .args(["policy", "eval", "--policy", p5e.to_str().unwrap()])
        .args(["--goal", "-0.45,-0.25,0.25", "--json"])
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["result"]["model"], "ur5e", "{v}");
    let d5e = v["result"]["final_distance_m"].as_f64().unwrap();
    assert!(
        (d5e - d).abs() > 1e-3,
        "the UR5e's kinematics: {d5e} vs {d}"
    );

    // Errors name their cause: one step (no task cost).
    let eval = |policy: &std::path::Path, extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_learner"))
            .args(["policy", "eval", "--policy", policy.to_str().unwrap()])
            .args(["--goal", "-0.45,-0.25,0.25"])
            .args(extra)
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = eval(&p, &["--steps", "1"]);
    assert!(
        e.contains("--steps 1: an episode needs at least 2 steps"),
        "{e}"
    );
    // (A gain table passed as a policy: learner/tests/suite/replay.rs.)
    std::fs::remove_dir_all(&dir).ok();
}

/// The tiny run of `a_tiny_mdgps_run_is_reproducible_bit_for_bit`, 4 iterations; with
/// MDGPS through the one driver interface ([`imitation::learn::iterate`]: `Learn::execute`,
/// its noisy episodes condition after condition, and `Learn::learn_goals`) is its own
/// `execute` and `learn` bit for bit; its goals are the conditions', and episodes of another
/// count are refused.
#[test]
fn mdgps_through_learn_is_its_own_execute_and_learn() {
    use imitation::learn::{iterate, Learn};
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let mut cfg = tiny_config();
    cfg.lqr_gaifo.iterations = 2;
    let untimed = |mut l: MdgpsLog| {
        (l.t_execute, l.t_dynamics, l.t_critic) = (0.0, 0.0, 0.0);
        (l.t_cost, l.t_lqr, l.t_policy) = (0.0, 0.0, 0.0);
        format!("{l:?}")
    };
    let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
    let mut a = Mdgps::new(cfg.clone(), demos.clone()).unwrap();
    let mut b = Mdgps::new(cfg.clone(), demos.clone()).unwrap();
    let tasks: Vec<[f64; 3]> = a.goal_tasks().iter().map(|t| t.goal).collect();
    assert_eq!(tasks, vec![goals[0], goals[4]]);
    while !Learn::done(&a) {
        let (la, ea) = iterate(&mut a, &arm).unwrap();
        let (samples, evals) = b.execute(&arm).unwrap();
        let lb = b.learn(&samples, &evals, 0.0).unwrap();
        assert_eq!(ea, evals);
        let mean = la.task_cost.iter().sum::<f64>() / 2.0;
        assert_eq!(Mdgps::eval_cost(&la).to_bits(), mean.to_bits());
        assert_eq!(untimed(la), untimed(lb));
    }
    assert_eq!((Learn::iteration(&a), Learn::version(&a)), (2, 3));
    assert_eq!(a.policy().flat(), b.policy().flat());
    for m in 0..2 {
        assert_eq!(a.controller(m), b.controller(m));
    }
    let (noisy, evals) = Learn::execute(&mut a, &arm).unwrap();
    assert_eq!((noisy.len(), evals.len()), (6, 2));
    let e = a.learn_goals(&noisy, &evals[..1], 0.0).unwrap_err();
    assert!(
        e.to_string()
            .contains("one evaluation episode per condition"),
        "{e}"
    );
    let e = a.learn_goals(&noisy[..5], &evals, 0.0).unwrap_err();
    assert!(e.to_string().contains("3 noisy episodes"), "{e}");
    assert_eq!(
        Learn::iteration(&a),
        2,
        "a refused iteration changes nothing"
    );
}

/// `stop = Some(i)` it is checkpointed after i iterations (learner state file and critic
/// file, as `learner train` writes them), dropped, and continued from the files.
fn tiny_run_resumed(
    cfg: &MdgpsConfig,
    demos: &[Demos],
    stop: Option<usize>,
) -> (Vec<f64>, Vec<String>, Vec<String>) {
    let mut m = Mdgps::new(cfg.clone(), demos.to_vec()).unwrap();
    let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
    let mut logs = Vec::new();
    for i in 0..4 {
        if stop == Some(i) {
            let dir = tmp(&format!("resume-{i}"));
            let (state, critic) = (dir.join("state.npz"), dir.join("critic.json"));
            learner::io::checkpoint::save_state(&state, &m.snapshot()).unwrap();
            m.critic().save(&critic).unwrap();
            drop(m);
            let snap = learner::io::checkpoint::load_state(&state).unwrap();
            let disc = imitation::discriminator::Discriminator::load(&critic, 24).unwrap();
            m = Mdgps::from_snapshot(cfg.clone(), demos.to_vec(), &snap, disc).unwrap();
            assert_eq!(m.iteration(), i);
            std::fs::remove_dir_all(&dir).unwrap();
        }
        let (samples, evals) = m.execute(&arm).unwrap();
        let mut l = m.learn(&samples, &evals, 0.0).unwrap();
        (l.t_dynamics, l.t_critic, l.t_cost, l.t_lqr, l.t_policy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        logs.push(format!("{l:?}"));
    }
    let ctrl = (0..m.conditions())
        .map(|c| format!("{:?}", m.controller(c)))
        .collect();
    (m.policy().flat(), ctrl, logs)
}

/// A tiny run of 4 iterations as the app runs it: `learner::run`'s checkpoint files
/// (`iter_NNN_critic.json`, then `iter_NNN_state.npz`) written into `dir` before every
/// iteration and after the last. With `kill = Some(i)` the process is taken as killed after
/// checkpoint i and the critic file of checkpoint i + 1 (a kill between its two files), and the
/// run continued from `dir` by `learner::run::resume_mdgps`.
fn app_run(
    cfg: &MdgpsConfig,
    demos: &[Demos],
    dir: &Path,
    kill: Option<usize>,
) -> (Vec<f64>, Vec<String>, Vec<String>) {
    use imitation::learn::iterate;
    use learner::run::Checkpoint;
    let _ = std::fs::remove_dir_all(dir);
    let mut m = Mdgps::new(cfg.clone(), demos.to_vec()).unwrap();
    let mut arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
    let mut logs = Vec::new();
    for i in 0..=4 {
        m.checkpoint(dir, Some(&arm)).unwrap();
        if kill == Some(i) {
            m.critic()
                .save(&dir.join(format!("iter_{:03}_critic.json", i + 1)))
                .unwrap();
            drop(m);
            let (resumed, noise) =
                learner::run::resume_mdgps(cfg.clone(), demos.to_vec(), dir).unwrap();
            m = resumed;
            assert_eq!(m.iteration(), i, "the latest complete checkpoint");
            arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
            arm.sim_mut()
                .set_noise_position(noise.expect("the arm's noise position"));
        }
        if i == 4 {
            break;
        }
        let (mut l, _) = iterate(&mut m, &arm).unwrap();
        (l.t_execute, l.t_dynamics, l.t_critic) = (0.0, 0.0, 0.0);
        (l.t_cost, l.t_lqr, l.t_policy) = (0.0, 0.0, 0.0);
        logs.push(format!("{l:?}"));
    }
    let ctrl = (0..m.conditions())
        .map(|c| format!("{:?}", m.controller(c)))
        .collect();
    (m.policy().flat(), ctrl, logs)
}

#[test]
fn an_mdgps_run_killed_at_any_checkpoint_and_resumed_by_the_app_is_the_same_bit_for_bit() {
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let cfg = tiny_config();
    let dir = tmp("app-resume");
    let whole = app_run(&cfg, &demos, &dir, None);
    assert_eq!(whole.2.len(), 4);
    assert!(dir.join("iter_004_state.npz").is_file());
    for kill in 0..4 {
        let resumed = app_run(&cfg, &demos, &dir, Some(kill));
        assert_eq!(resumed.0, whole.0, "policy, killed after checkpoint {kill}");
        assert_eq!(
            resumed.1, whole.1,
            "controllers, killed after checkpoint {kill}"
        );
        assert_eq!(resumed.2, whole.2, "logs, killed after checkpoint {kill}");
    }
    let mut other = cfg.clone();
    other.lqr_gaifo.seed += 1;
    let e = learner::run::resume_mdgps(other, demos.clone(), &dir)
        .err()
        .expect("another seed refused");
    let e = learner::error::line(&e);
    assert!(e.contains("iter_004_state.npz"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The tiny run's settings: 2 goals, N = 3, a critic of 5 steps, a policy of one hidden
/// layer of 8 and 20 S-step steps.
fn tiny_config() -> MdgpsConfig {
    let mut cfg = MdgpsConfig::default();
    cfg.lqr_gaifo.samples = 3;
    cfg.lqr_gaifo.seed = 9;
    cfg.lqr_gaifo.discriminator.n_critic = 5;
    cfg.policy.hidden = vec![8];
    cfg.policy.steps = 20;
    cfg
}

#[test]
fn a_tiny_mdgps_run_resumed_at_any_iteration_boundary_is_the_same_bit_for_bit() {
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let cfg = tiny_config();
    let whole = tiny_run_resumed(&cfg, &demos, None);
    for stop in 0..4 {
        let resumed = tiny_run_resumed(&cfg, &demos, Some(stop));
        assert_eq!(
            resumed.0, whole.0,
            "policy, resumed after {stop} iterations"
        );
        assert_eq!(resumed.1, whole.1, "controllers, resumed after {stop}");
        assert_eq!(resumed.2, whole.2, "logs, resumed after {stop}");
    }
}

#[test]
fn an_mdgps_resume_that_cannot_be_exact_is_refused() {
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let cfg = tiny_config();
    let mut m = Mdgps::new(cfg.clone(), demos.clone()).unwrap();
    let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
    let (samples, evals) = m.execute(&arm).unwrap();
    m.learn(&samples, &evals, 0.0).unwrap();
    let (snap, disc) = (m.snapshot(), m.critic().discriminator().clone());
    let refuse = |cfg: &MdgpsConfig, demos: &[Demos], snap: &gps::snapshot::Snapshot| {
        match Mdgps::from_snapshot(cfg.clone(), demos.to_vec(), snap, disc.clone()) {
            Ok(_) => panic!("resumed"),
            Err(e) => e.to_string(),
        }
    };
    // One goal fewer than the checkpoint's.
    let e = refuse(&cfg, &demos[..1], &snap);
    assert!(e.contains("more conditions"), "{e}");
    // Another policy size.
    let mut other = cfg.clone();
    other.policy.hidden = vec![9];
    let e = refuse(&other, &demos, &snap);
    assert!(e.contains("mdgps.policy"), "{e}");
    // Another horizon.
    let short = vec![tiny_demos(goals[0], 10), tiny_demos(goals[4], 10)];
    let e = refuse(&cfg, &short, &snap);
    assert!(e.contains("condition 0"), "{e}");
    // Another seed: the critic is refused.
    let mut seed = cfg.clone();
    seed.lqr_gaifo.seed = 10;
    let e = refuse(&seed, &demos, &snap);
    assert!(e.contains("seed 10"), "{e}");
    // A damaged state: the S-step's RNG missing.
    let mut damaged = snap.clone();
    damaged.words.remove("s_step.rng");
    let e = refuse(&cfg, &demos, &damaged);
    assert!(e.contains("s_step.rng"), "{e}");
}

/// `[traj_opt] method = "pilqr"` reaches MDGPS's C-step: a tiny run goes through without an
/// error or a NaN in its logs, keeps LQR's feedback gains at the first C-step and ends with
/// other controllers than the LQR run.
#[test]
fn a_tiny_mdgps_run_with_pilqr_runs_and_differs_from_lqr() {
    use gps::traj_opt::pilqr::TrajOptMethod;
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let run = |method, iterations| {
        let mut cfg = tiny_config();
        cfg.lqr_gaifo.traj_opt.method = method;
        let mut m = Mdgps::new(cfg.clone(), demos.clone()).unwrap();
        let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
        let mut logs = Vec::new();
        for _ in 0..iterations {
            let (samples, evals) = m.execute(&arm).unwrap();
            logs.push(format!("{:?}", m.learn(&samples, &evals, 0.0).unwrap()));
        }
        let ctrl: Vec<_> = (0..m.conditions())
            .map(|c| m.controller(c).clone())
            .collect();
        (ctrl, logs)
    };
    let (first_lqr, first_pilqr) = (run(TrajOptMethod::Lqr, 1).0, run(TrajOptMethod::Pilqr, 1).0);
    for (a, b) in first_lqr.iter().zip(&first_pilqr) {
        assert_eq!(a.gain, b.gain);
        assert_ne!(a.k, b.k);
    }
    let (lqr, pilqr) = (run(TrajOptMethod::Lqr, 3), run(TrajOptMethod::Pilqr, 3));
    assert!(pilqr.1.iter().all(|l| !l.contains("NaN")), "{:?}", pilqr.1);
    assert_ne!(lqr.0, pilqr.0);
}

/// The inputs of a tiny `learner train --algo mdgps` in `root`: a folder of two goals'
/// demonstrations (`tiny_demos`) and the config file of `tiny_config`.
fn command_inputs(root: &Path) -> (PathBuf, PathBuf) {
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = root.join("demos");
    std::fs::create_dir_all(&demos).unwrap();
    for (k, g) in [goals[0], goals[4]].into_iter().enumerate() {
        learner::io::demos::save(&tiny_demos(g, 12), &demos.join(format!("goal_{k}.npz"))).unwrap();
    }
    let config = root.join("mdgps.toml");
    std::fs::write(&config, toml::to_string(&tiny_config()).unwrap()).unwrap();
    (demos, config)
}

/// The MDGPS run folders `a` and `b` of `iterations` iterations hold the same checkpoint files
/// 0 … `iterations` byte for byte and the same `mdgps_log.csv` rows without their timing
/// columns (t_*_s, the last six).
fn assert_same_mdgps_run(a: &Path, b: &Path, iterations: usize) {
    for i in 0..=iterations {
        for kind in ["critic.json", "state.npz"] {
            let name = format!("iter_{i:03}_{kind}");
            assert!(
                std::fs::read(a.join(&name)).unwrap() == std::fs::read(b.join(&name)).unwrap(),
                "{name} differs"
            );
        }
    }
    let rows = |dir: &Path| -> Vec<String> {
        std::fs::read_to_string(dir.join("mdgps_log.csv"))
            .unwrap()
            .lines()
            .map(|l| l.split(',').take(11).collect::<Vec<_>>().join(","))
            .collect()
    };
    assert_eq!(
        rows(a).len(),
        iterations + 1,
        "header and a row per iteration"
    );
    assert_eq!(rows(b), rows(a));
}

/// `learner train --algo mdgps` on a folder of two goals' demonstrations, its folder then put
/// in the state a kill during the third iteration leaves (checkpoints 0 to 2, the next
/// checkpoint's critic file cut short, a row cut short) and resumed with `--resume`, ends with
/// the checkpoint files and `mdgps_log.csv` rows (timing columns aside) of the uninterrupted
/// command, bit for bit.
#[test]
fn train_mdgps_killed_and_resumed_through_the_command_is_the_uninterrupted_run() {
    let root = tmp("train-cmd");
    let (demos, config) = command_inputs(&root);
    let args = |out: &Path| {
        vec![
            "train".to_string(),
            "--algo".into(),
            "mdgps".into(),
            "--demos".into(),
            demos.display().to_string(),
            "--config".into(),
            config.display().to_string(),
            "--iterations".into(),
            "4".into(),
            "--out".into(),
            out.display().to_string(),
        ]
    };
    let whole = root.join("whole");
    let a = args(&whole);
    let (ok, err) = learner(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    // Killed during the third iteration: what it wrote after checkpoint 2 is gone or cut.
    let killed = root.join("killed");
    let k = args(&killed);
    let (ok, err) = learner(&k.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    for i in 3..=4 {
        for kind in ["critic.json", "state.npz"] {
            std::fs::remove_file(killed.join(format!("iter_{i:03}_{kind}"))).unwrap();
        }
    }
    std::fs::write(killed.join("iter_003_critic.json"), "{\"format\": ").unwrap();
    let csv = killed.join("mdgps_log.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let kept: Vec<&str> = text.split_inclusive('\n').take(3).collect();
    std::fs::write(&csv, format!("{}2,9,0.5", kept.concat())).unwrap();
    let mut resume = args(&killed);
    resume.extend(["--resume".to_string(), killed.display().to_string()]);
    let (ok, err) = learner(&resume.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    assert_same_mdgps_run(&whole, &killed, 4);
    // A complete run resumes to nothing; another seed is refused.
    let (ok, err) = learner(&resume.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    let mut other = resume.clone();
    other.extend(["--seed".to_string(), "10".into()]);
    let (ok, err) = learner(&other.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!ok && err.contains("another run"), "{err}");
    std::fs::remove_dir_all(&root).unwrap();
}

/// `learner train --algo mdgps --record-episodes` records every goal's episodes, and `learner
/// replay` redoes the run's learning from them: every recorded critic and learner state
/// (policy, S-step and each goal's LQR state) equal to the replay's, bit for bit.
#[test]
fn a_recorded_mdgps_run_replays_bit_for_bit() {
    let root = tmp("replay-cmd");
    let (demos, config) = command_inputs(&root);
    let out = root.join("run");
    let (d, c, o) = (
        demos.display().to_string(),
        config.display().to_string(),
        out.display().to_string(),
    );
    let (ok, err) = learner(&[
        "train",
        "--algo",
        "mdgps",
        "--demos",
        &d,
        "--config",
        &c,
        "--iterations",
        "3",
        "--record-episodes",
        "--out",
        &o,
    ]);
    assert!(ok, "{err}");
    // 2 goals × (3 noisy + 1 evaluation) per iteration.
    let episodes = std::fs::read_dir(out.join("episodes")).unwrap().count();
    assert_eq!(episodes, 3 * 2 * 4);
    let (ok, json, err) = common::learner_output(&["replay", &o, "--json"]);
    assert!(ok, "{err}");
    let r: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert!(r["difference"].is_null(), "{r}");
    assert_eq!(r["iterations"], 3, "{r}");
    assert_eq!(r["critics_checked"], 4, "{r}");
    assert_eq!(r["policies_checked"], 4, "{r}");
    assert_eq!(r["episodes_used"], 3 * 2 * 4, "{r}");
    std::fs::remove_dir_all(&root).unwrap();
}

/// A tampered MDGPS checkpoint is refused by `learner::run::resume_mdgps` with a typed error
/// that names the file and what is wrong, as the other learners' are: a state whose iteration
/// is not its name's, a non-finite policy parameter, a goal's LQR state without an entry, a
/// state file with bytes changed, and a malformed critic file.
#[test]
fn a_tampered_mdgps_checkpoint_is_refused_naming_file_and_entry() {
    use imitation::learn::iterate;
    use learner::io::checkpoint::{load_state, save_state};
    use learner::run::{resume_mdgps, Checkpoint, RunError};
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let cfg = tiny_config();
    let root = tmp("tampered");
    let good = root.join("good");
    let mut m = Mdgps::new(cfg.clone(), demos.clone()).unwrap();
    let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), 0.1).unwrap();
    m.checkpoint(&good, Some(&arm)).unwrap();
    iterate(&mut m, &arm).unwrap();
    m.checkpoint(&good, Some(&arm)).unwrap();
    let state = "iter_001_state.npz";
    // The untouched folder resumes.
    assert_eq!(
        resume_mdgps(cfg.clone(), demos.clone(), &good)
            .unwrap()
            .0
            .iteration(),
        1
    );
    // A copy of the run with its latest state edited by `edit`.
    let tampered = |name: &str, edit: &dyn Fn(&mut gps::snapshot::Snapshot)| -> RunError {
        let dir = root.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        for f in std::fs::read_dir(&good).unwrap() {
            let f = f.unwrap();
            std::fs::copy(f.path(), dir.join(f.file_name())).unwrap();
        }
        let mut snap = load_state(&dir.join(state)).unwrap();
        edit(&mut snap);
        save_state(&dir.join(state), &snap).unwrap();
        match resume_mdgps(cfg.clone(), demos.clone(), &dir) {
            Ok(_) => panic!("{name}: resumed"),
            Err(e) => e,
        }
    };
    let line = |e: &RunError| learner::error::line(e);
    // Renamed or edited: iteration 3 in the file of iteration 1.
    let e = tampered("iteration", &|s| s.put_words("mdgps.iteration", &[3]));
    assert!(
        matches!(
            e,
            RunError::Iteration {
                at: 3,
                named: 1,
                ..
            }
        ),
        "{}",
        line(&e)
    );
    assert!(line(&e).contains(state), "{}", line(&e));
    // A NaN in the policy's parameters.
    let e = tampered("nan-policy", &|s| {
        let (shape, mut data) = s.reals["mdgps.policy"].clone();
        data[30] = f64::NAN;
        s.put("mdgps.policy", &shape, &data);
    });
    let msg = line(&e);
    assert!(matches!(e, RunError::Restore { .. }), "{msg}");
    assert!(
        msg.contains(state) && msg.contains("mdgps.policy") && msg.contains("parameter 30"),
        "{msg}"
    );
    // A goal's LQR state without its controller's gains.
    let e = tampered("missing-entry", &|s| {
        assert!(s.reals.remove("condition1.policy.K").is_some());
    });
    let msg = line(&e);
    assert!(matches!(e, RunError::Restore { .. }), "{msg}");
    assert!(
        msg.contains(state) && msg.contains("condition 1") && msg.contains("policy.K"),
        "{msg}"
    );
    // The S-step's Adam moments of another size.
    let e = tampered("short-moments", &|s| {
        let key = s
            .reals
            .keys()
            .find(|k| k.starts_with("s_step."))
            .expect("the S-step's arrays")
            .clone();
        let (_, data) = s.reals[&key].clone();
        s.put(&key, &[data.len() - 1], &data[1..]);
    });
    let msg = line(&e);
    assert!(matches!(e, RunError::Restore { .. }), "{msg}");
    assert!(msg.contains(state) && msg.contains("s_step."), "{msg}");
    // Bytes of the state file changed on disk (inside an array's data).
    let dir = root.join("bytes");
    std::fs::create_dir_all(&dir).unwrap();
    for f in std::fs::read_dir(&good).unwrap() {
        let f = f.unwrap();
        std::fs::copy(f.path(), dir.join(f.file_name())).unwrap();
    }
    let mut bytes = std::fs::read(dir.join(state)).unwrap();
    let at = bytes.len() / 2;
    bytes[at] ^= 0x40;
    std::fs::write(dir.join(state), &bytes).unwrap();
    let e = resume_mdgps(cfg.clone(), demos.clone(), &dir)
        .err()
        .expect("refused");
    let msg = line(&e);
    assert!(
        matches!(e, RunError::Io(_) | RunError::Restore { .. }),
        "{msg}"
    );
    assert!(msg.contains(state), "{msg}");
    // A malformed critic file.
    std::fs::copy(good.join(state), dir.join(state)).unwrap();
    std::fs::write(dir.join("iter_001_critic.json"), "{\"format\": ").unwrap();
    let e = resume_mdgps(cfg.clone(), demos.clone(), &dir)
        .err()
        .expect("refused");
    let msg = line(&e);
    assert!(matches!(e, RunError::Critic { .. }), "{msg}");
    assert!(
        msg.contains("iter_001_critic.json") && msg.contains("not a valid critic file"),
        "{msg}"
    );
    std::fs::remove_dir_all(&root).ok();
}

/// The multi-goal experiment's MDGPS (`multi_goal::run_mdgps`) runs through `learn::Learn` with
/// checkpoints: its seed folder holds the checkpoint files and CSV rows (timing columns aside)
/// of `learner::run::train_mdgps` with the same settings bit for bit, its saved policy is that
/// run's, and the folder resumes (`train_mdgps_resumed`) to more iterations.
#[test]
fn the_multi_goal_experiments_mdgps_writes_the_checkpoints_of_train_mdgps() {
    use learner::experiment::multi_goal::{mdgps_config, run_mdgps, EvalGoal};
    use learner::experiment::ExperimentConfig;
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![tiny_demos(goals[0], 12), tiny_demos(goals[4], 12)];
    let tiny = tiny_config();
    let cfg = ExperimentConfig {
        iterations: 2,
        lqr_gaifo: tiny.lqr_gaifo.clone(),
        mdgps_policy: tiny.policy.clone(),
        ..ExperimentConfig::default()
    };
    let seed = 9;
    let root = tmp("multi-goal-ckpt");
    let eval: Vec<EvalGoal> = [goals[0], goals[2]]
        .iter()
        .map(|&goal| EvalGoal {
            kind: "inside",
            goal,
        })
        .collect();
    let progress = learner::progress::Progress::new(2, "iterations");
    let r = run_mdgps(&cfg, seed, &demos, &eval, &demos, &root, &progress).unwrap();
    drop(progress);
    assert_eq!((r.evals.len(), r.mdgps_logs.len()), (3, 2));
    let exp = root.join(format!("mdgps_seed{seed}"));
    let train = root.join("train");
    let c = mdgps_config(&cfg, seed);
    learner::run::train_mdgps(&c, demos.clone(), &train, |_| {}).unwrap();
    assert_same_mdgps_run(&train, &exp, 2);
    let saved = load_policy(&root.join(format!("policy_seed{seed}.npz"))).unwrap();
    let (resumed, _) = learner::run::resume_mdgps(c.clone(), demos.clone(), &exp).unwrap();
    assert_eq!(resumed.iteration(), 2);
    assert_eq!(saved.policy.flat(), resumed.policy().flat());
    // The experiment's folder continues as a `learner train --algo mdgps` folder does.
    let mut longer = c.clone();
    longer.lqr_gaifo.iterations = 3;
    let more = learner::run::train_mdgps_resumed(&longer, demos.clone(), &exp, |_| {}).unwrap();
    assert_eq!(more.len(), 1);
    assert!(exp.join("iter_003_state.npz").is_file());
    std::fs::remove_dir_all(&root).ok();
}
