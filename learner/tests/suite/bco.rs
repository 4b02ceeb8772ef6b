//! The baselines without a critic (docs/design.md §7): a tiny BCO(α) run reproducible bit for
//! bit and seeded, its exact resume (k iterations, stop, resume m == k + m iterations), the
//! naive mean path on the simulated arm, and both through `learner train`. All fast (seconds).

use crate::common;

use std::path::{Path, PathBuf};

use imitation::bco::{Bco, BcoConfig};
use imitation::demos::Demos;
use imitation::learn::{iterate, Learn, LinGaussLearn};
use imitation::replay_mean::{ReplayMean, ReplayMeanConfig};
use learner::arm::SimArm;
use learner::io::checkpoint::{load_state, save_state};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bco-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Demonstrations of a short task (T = 20) from a 3-iteration expert.
fn short_demos() -> Demos {
    let cfg = common::short_expert(20, 3);
    let run = learner::run::expert(&cfg, |_| {}).unwrap();
    learner::run::demos(&cfg, &run).unwrap()
}

/// N = 3, 4 iterations, α = 1/2, small nets and few steps.
pub(crate) fn tiny_config() -> BcoConfig {
    let mut cfg = BcoConfig {
        samples: 3,
        iterations: 4,
        pre_iterations: 2,
        seed: 5,
        ..BcoConfig::default()
    };
    cfg.model.hidden = vec![8];
    cfg.model.steps = 30;
    cfg.policy.hidden = vec![8];
    cfg.policy.steps = 30;
    cfg
}

/// `iterations` iterations of `run` on `arm`: the logs without their times.
fn logs(run: &mut Bco, arm: &SimArm, iterations: usize) -> Vec<String> {
    (0..iterations)
        .map(|_| {
            let (mut l, _) = iterate(run, arm).unwrap();
            (l.t_execute, l.t_dynamics, l.t_cost, l.t_lqr, l.cpu_learner) =
                (0.0, 0.0, 0.0, 0.0, 0.0);
            format!("{l:?}")
        })
        .collect()
}

#[test]
fn a_tiny_bco_run_is_reproducible_bit_for_bit_and_seeded() {
    let demos = short_demos();
    let run = |cfg: &BcoConfig| {
        let mut b = Bco::new(cfg.clone(), demos.clone()).unwrap();
        let arm = SimArm::new(cfg.sim.clone(), demos.dt).unwrap();
        let l = logs(&mut b, &arm, 4);
        (b.policy().flat(), l, b.last)
    };
    let cfg = tiny_config();
    let a = run(&cfg);
    // The pre-demonstration iterations hold the initial policy; the cloning starts at the
    // second, on the model fitted to 2 × 3 episodes of 19 transitions, then grows by 3 a time.
    assert_eq!(a.2.model.transitions, 4 * 3 * 19);
    assert_eq!(a.2.labelled, 2 * 19);
    assert!(a.2.clone_after < a.2.clone_before, "{:?}", a.2);
    assert!(a.1.iter().all(|l| l.contains("critic_loss: NaN")));
    let b = run(&cfg);
    assert_eq!(a.0, b.0, "policy");
    assert_eq!(a.1, b.1, "logs");
    let mut other = cfg.clone();
    other.seed += 1;
    assert_ne!(run(&other).0, a.0, "another seed, another run");
}

#[test]
fn a_bco_run_stopped_after_k_iterations_and_resumed_runs_the_same_m_more_bit_for_bit() {
    let demos = short_demos();
    let cfg = tiny_config();
    let arm = SimArm::new(cfg.sim.clone(), demos.dt).unwrap();
    let mut whole = Bco::new(cfg.clone(), demos.clone()).unwrap();
    let all = logs(&mut whole, &arm, 4);
    let dir = tmp("snapshot");
    for k in 0..4 {
        let mut first = Bco::new(cfg.clone(), demos.clone()).unwrap();
        let mut got = logs(&mut first, &arm, k);
        let path = dir.join(format!("state{k}.npz"));
        save_state(&path, &first.snapshot()).unwrap();
        drop(first);
        let mut resumed =
            Bco::from_snapshot(cfg.clone(), demos.clone(), &load_state(&path).unwrap()).unwrap();
        assert_eq!(resumed.iteration(), k);
        got.extend(logs(&mut resumed, &arm, 4 - k));
        assert_eq!(got, all, "stopped after {k}");
        assert_eq!(
            resumed.policy().flat(),
            whole.policy().flat(),
            "policy, stopped after {k}"
        );
        assert_eq!(
            format!("{:?}", resumed.snapshot()),
            format!("{:?}", whole.snapshot()),
            "whole state, stopped after {k}"
        );
    }
    // Another policy size cannot continue the run.
    let mut other = cfg.clone();
    other.policy.hidden = vec![9];
    let snap = load_state(&dir.join("state2.npz")).unwrap();
    let e = Bco::from_snapshot(other, demos, &snap)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("bco.policy"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The rows of a `gaifo_log.csv` without the timing columns.
fn rows(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !(header[i].starts_with("t_") || header[i].starts_with("cpu_")))
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
        })
        .collect()
}

#[test]
fn learner_train_runs_and_resumes_bco_exactly_and_runs_the_mean_path() {
    let dir = tmp("cli");
    let demos = dir.join("demos.npz");
    learner::io::demos::save(&short_demos(), &demos).unwrap();
    let config = dir.join("bco.toml");
    std::fs::write(
        &config,
        "samples = 3\npre_iterations = 2\n[model]\nhidden = [8]\nsteps = 30\n[policy]\nhidden = [8]\nsteps = 30\n",
    )
    .unwrap();
    let d = demos.to_str().unwrap();
    let c = config.to_str().unwrap();
    let (whole, part) = (dir.join("whole"), dir.join("part"));
    let train = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "train", "--algo", "bco", "--demos", d, "--config", c, "--seed", "3",
        ];
        args.extend_from_slice(extra);
        let (ok, err) = common::learner(&args);
        assert!(ok, "{} {err}", out.display());
    };
    let rec = "--record-episodes";
    train(
        &whole,
        &["--iterations", "4", "--out", whole.to_str().unwrap(), rec],
    );
    train(
        &part,
        &["--iterations", "2", "--out", part.to_str().unwrap(), rec],
    );
    train(
        &part,
        &["--iterations", "4", "--resume", part.to_str().unwrap()],
    );
    let (a, b) = (
        rows(&whole.join("gaifo_log.csv")),
        rows(&part.join("gaifo_log.csv")),
    );
    assert_eq!(a.len(), 4);
    assert!(a[0].contains(",bco"), "{}", a[0]);
    assert_eq!(a, b, "resumed rows");
    for f in ["iter_004_state.npz", "iter_004_policy.npz"] {
        assert_eq!(
            std::fs::read(whole.join(f)).unwrap(),
            std::fs::read(part.join(f)).unwrap(),
            "{f}"
        );
    }
    // The recorded runs' learning, redone from their episodes, is theirs bit for bit (the
    // resumed one's too).
    for run in [&whole, &part] {
        let (ok, err) = common::learner(&["replay", run.to_str().unwrap()]);
        assert!(ok, "{} {err}", run.display());
    }
    // The mean path: one evaluation row, its table; its replay redoes it.
    let mean = dir.join("mean");
    let (ok, err) = common::learner(&[
        "train",
        "--algo",
        "replay-mean",
        "--demos",
        d,
        "--out",
        mean.to_str().unwrap(),
        "--record-episodes",
    ]);
    assert!(ok, "{err}");
    let r = rows(&mean.join("gaifo_log.csv"));
    assert_eq!(r.len(), 1);
    assert!(r[0].contains(",replay-mean"), "{}", r[0]);
    assert!(mean.join("iter_001_table.npz").is_file());
    let (ok, err) = common::learner(&["replay", mean.to_str().unwrap()]);
    assert!(ok, "{err}");
    let (ok, err) = common::learner(&[
        "train",
        "--algo",
        "replay-mean",
        "--demos",
        d,
        "--resume",
        mean.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("nothing to resume"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_mean_path_commands_the_demonstrations_mean_joint_angles() {
    let demos = short_demos();
    let cfg = ReplayMeanConfig::default();
    let mut run = ReplayMean::new(cfg.clone(), demos.clone()).unwrap();
    let arm = SimArm::new(cfg.sim.clone(), demos.dt).unwrap();
    let table = run.table();
    let (log, evals) = iterate(&mut run, &arm).unwrap();
    assert!(run.done());
    let eval = &evals[0];
    let t_len = demos.horizon;
    for t in 0..t_len {
        let next = (t + 1).min(t_len - 1);
        for j in 0..3 {
            let mean = (0..demos.count)
                .map(|d| demos.state(d, next)[j])
                .sum::<f64>()
                / demos.count as f64;
            // The noise-free command is the mean path (the clamp leaves it: the demonstrations
            // moved no faster than it allows).
            assert_eq!(eval.u_policy[t * 3 + j], mean, "t {t} joint {j}");
        }
    }
    assert_eq!(table.horizon(), t_len);
    assert_eq!(log.final_distance, eval.final_distance());
    assert!(log.critic_loss.is_nan() && log.cpu_learner == 0.0);
}
