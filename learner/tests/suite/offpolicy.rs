//! Off-policy GAIfO (TD3): a tiny run is the same for any thread count, resumes bit for bit
//! from a checkpoint at any iteration, through the library and through `learner train
//! --resume`, and `learner replay` redoes it. All fast (seconds).

use crate::common;

use std::path::{Path, PathBuf};

use imitation::demos::Demos;
use imitation::discriminator::Discriminator;
use imitation::learn::{iterate, Learn};
use imitation::offpolicy::td3::Td3Config;
use imitation::offpolicy::{CriticData, GaifoTd3, GaifoTd3Config, OffPolicyReward};
use learner::run::{arm_for, Checkpoint};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("td3-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Demonstrations of a short task (T = 20) of a 3-iteration expert.
fn short_demos(dir: &Path) -> (PathBuf, Demos) {
    let path = dir.join("demos.npz");
    common::save_short_demos(&path, 1);
    let d = learner::io::demos::load(&path).unwrap();
    (path, d)
}

/// N = 2, small nets, 3 TD3 steps per episode of minibatch 16 and a buffer of 50 rows, so that
/// it wraps in the second iteration (2 × 19 rows per iteration).
fn tiny_config() -> GaifoTd3Config {
    let mut cfg = GaifoTd3Config {
        samples: 2,
        iterations: 4,
        seed: 5,
        updates_per_episode: 3,
        buffer_capacity: 50,
        td3: Td3Config {
            pi_hidden: vec![8],
            q_hidden: vec![8],
            batch_size: 16,
            policy_delay: 2,
            ..Td3Config::default()
        },
        ..GaifoTd3Config::default()
    };
    cfg.discriminator.hidden = vec![8];
    cfg.discriminator.n_critic = 5;
    cfg
}

/// `iterations` iterations of `cfg` on `demos`: each log without its times, and the learner's
/// state at the end.
fn run(cfg: &GaifoTd3Config, demos: &Demos, iterations: usize) -> (Vec<String>, Vec<u8>) {
    let mut l = GaifoTd3::new(cfg.clone(), demos.clone()).unwrap();
    let arm = arm_for(&l).unwrap();
    let mut logs = Vec::new();
    for _ in 0..iterations {
        let (mut log, _) = iterate(&mut l, &arm).unwrap();
        (
            log.t_execute,
            log.t_critic,
            log.t_cost,
            log.t_lqr,
            log.cpu_learner,
        ) = (0.0, 0.0, 0.0, 0.0, 0.0);
        logs.push(format!("{log:?}"));
    }
    (logs, state_bytes(&l))
}

/// The learner state as the bytes of its state file.
fn state_bytes(l: &GaifoTd3) -> Vec<u8> {
    let dir = tmp(&format!("state-{}", l.iteration()));
    let p = dir.join("state.npz");
    learner::io::checkpoint::save_state(&p, &l.snapshot()).unwrap();
    let b = std::fs::read(&p).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    b
}

#[test]
fn a_tiny_td3_run_is_the_same_for_any_thread_count_and_learns_something() {
    let dir = tmp("threads");
    let (_, demos) = short_demos(&dir);
    let cfg = tiny_config();
    let with = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(&cfg, &demos, 3))
    };
    let one = with(1);
    assert!(one
        .0
        .iter()
        .all(|l| !l.contains("NaN") || l.contains("kl: NaN")));
    assert_eq!(with(2), one, "2 threads");
    assert_eq!(with(3), one, "3 threads");
    let mut other = cfg.clone();
    other.seed += 1;
    assert_ne!(run(&other, &demos, 3).1, one.1, "another seed, another run");
    // The actor moved away from holding the start pose.
    let mut l = GaifoTd3::new(cfg.clone(), demos.clone()).unwrap();
    let fresh = l.policy().flat();
    let arm = arm_for(&l).unwrap();
    iterate(&mut l, &arm).unwrap();
    assert_ne!(l.policy().flat(), fresh);
    assert_eq!(l.buffer().len(), 2 * 19);
    assert_eq!(l.td3().steps(), 2 * 3);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `cfg` run for 4 iterations equals, logs and final state bit for bit, the run checkpointed
/// after `stop` = 1, 2, 3 iterations as `learner train` does (the arm's noise position with it)
/// and continued from the files in `dir/ck<stop>`.
fn resumed_at_any_iteration(dir: &Path, cfg: &GaifoTd3Config, demos: &Demos) {
    let zero = |mut log: imitation::iteration_log::GaifoLog| {
        (
            log.t_execute,
            log.t_critic,
            log.t_cost,
            log.t_lqr,
            log.cpu_learner,
        ) = (0.0, 0.0, 0.0, 0.0, 0.0);
        format!("{log:?}")
    };
    let whole = run(cfg, demos, 4);
    for stop in 1..4 {
        let mut l = GaifoTd3::new(cfg.clone(), demos.clone()).unwrap();
        let arm = arm_for(&l).unwrap();
        let mut logs = Vec::new();
        for _ in 0..stop {
            logs.push(zero(iterate(&mut l, &arm).unwrap().0));
        }
        let ck = dir.join(format!("ck{stop}"));
        let _ = std::fs::remove_dir_all(&ck);
        l.checkpoint(&ck, Some(&arm)).unwrap();
        drop(l);
        let (mut l, noise) = learner::run::resume_td3(cfg.clone(), demos.clone(), &ck).unwrap();
        assert_eq!(l.iteration(), stop);
        let mut arm = arm_for(&l).unwrap();
        arm.sim_mut().set_noise_position(noise.unwrap());
        for _ in stop..4 {
            logs.push(zero(iterate(&mut l, &arm).unwrap().0));
        }
        assert_eq!(logs, whole.0, "logs, resumed after {stop}");
        assert!(state_bytes(&l) == whole.1, "state, resumed after {stop}");
    }
}

#[test]
fn a_td3_run_checkpointed_and_resumed_at_any_iteration_is_the_same_bit_for_bit() {
    let dir = tmp("resume");
    let (_, demos) = short_demos(&dir);
    // Also with the critic trained on buffer rows and the diagnostic reward, which draw from
    // the learner's RNG too.
    let other_data = GaifoTd3Config {
        critic_data: CriticData::Buffer,
        reward: OffPolicyReward::TaskDistance,
        ..tiny_config()
    };
    resumed_at_any_iteration(&dir, &other_data, &demos);
    let cfg = tiny_config();
    resumed_at_any_iteration(&dir, &cfg, &demos);
    // Another seed's or another buffer size's resume is refused, naming the state file.
    let ck = dir.join("ck1");
    let mut other = cfg.clone();
    other.seed += 1;
    let e = learner::run::resume_td3(other, demos.clone(), &ck)
        .err()
        .unwrap();
    let e = learner::error::line(&e);
    assert!(e.contains("seed"), "{e}");
    let mut small = cfg.clone();
    small.buffer_capacity = 10;
    let e = learner::run::resume_td3(small, demos.clone(), &ck)
        .err()
        .unwrap();
    let e = learner::error::line(&e);
    assert!(
        e.contains("iter_001_state.npz") && e.contains("replay"),
        "{e}"
    );
    let _ = Discriminator::load(&ck.join("iter_001_critic.json"), 24).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `learner train --algo gaifo-td3` stopped after 2 iterations and continued with `--resume`
/// ends with the checkpoint files and CSV rows (timing columns aside) of the uninterrupted
/// command; `learner replay` redoes a recorded run bit for bit.
#[test]
fn train_gaifo_td3_resumes_through_the_command_and_replays() {
    let root = tmp("command");
    let (demos, _) = short_demos(&root);
    let config = root.join("td3.toml");
    std::fs::write(&config, toml::to_string(&tiny_config()).unwrap()).unwrap();
    let (d, c) = (demos.display().to_string(), config.display().to_string());
    let train = |out: &Path, iterations: &str, extra: &[&str]| {
        let o = out.display().to_string();
        let mut args = vec![
            "train",
            "--algo",
            "gaifo-td3",
            "--demos",
            &d,
            "--config",
            &c,
            "--iterations",
            iterations,
            "--out",
            &o,
        ];
        args.extend_from_slice(extra);
        let (ok, err) = common::learner(&args);
        assert!(ok, "{err}");
    };
    let (whole, parts) = (root.join("whole"), root.join("parts"));
    train(&whole, "3", &["--record-episodes"]);
    train(&parts, "2", &[]);
    train(&parts, "3", &["--resume", &parts.display().to_string()]);
    for i in 0..=3 {
        for kind in ["critic.json", "state.npz"] {
            let name = format!("iter_{i:03}_{kind}");
            assert!(
                std::fs::read(whole.join(&name)).unwrap()
                    == std::fs::read(parts.join(&name)).unwrap(),
                "{name} differs"
            );
        }
    }
    let rows = |dir: &Path| -> Vec<String> {
        std::fs::read_to_string(dir.join("gaifo_log.csv"))
            .unwrap()
            .lines()
            .map(|l| l.split(',').take(11).collect::<Vec<_>>().join(","))
            .collect()
    };
    assert_eq!(rows(&whole).len(), 4);
    assert!(rows(&whole)[1].contains("gaifo-td3"), "{:?}", rows(&whole));
    assert_eq!(rows(&parts), rows(&whole));
    let (ok, json, err) =
        common::learner_output(&["replay", &whole.display().to_string(), "--json"]);
    assert!(ok, "{err}");
    let r: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert!(r["difference"].is_null(), "{r}");
    assert_eq!(r["iterations"], 3, "{r}");
    std::fs::remove_dir_all(&root).unwrap();
}
