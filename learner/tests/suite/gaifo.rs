//! LQR+GAIfO end to end on the simulated arm: expert → demonstrations → imitation from the
//! states alone.

use imitation::expert::ExpertConfig;
use imitation::gaifo::GaifoConfig;
use learner::run::train;
use learner::run::{demos as record_demos, expert as train_expert};

/// The default expert, then 12 iterations of LQR+GAIfO on its 5 state-only demonstrations:
/// the imitator's noise-free episode must reach normalised performance ≥ 0.8 (the
/// acceptance asks it within 20 iterations on average over 5 seeds; the README has that run).
#[test]
fn lqr_gaifo_imitates_the_expert_from_states_only() {
    let ecfg = ExpertConfig {
        iterations: 12,
        ..ExpertConfig::default()
    };
    let expert = train_expert(&ecfg, |_| {}).unwrap();
    let demos = record_demos(&ecfg, &expert).unwrap();
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
fn short_demos() -> imitation::demos::Demos {
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
    record_demos(&ecfg, &expert).unwrap()
}

/// The critic's terminal pairs (docs/design.md §5 D44) enter its training: the same run with
/// them differs in the critic's statistics from iteration 0 on and repeats bit for bit.
#[test]
fn the_critics_terminal_pairs_change_its_training_and_repeat_bit_for_bit() {
    let demos = short_demos();
    let run = |pairs: usize| {
        let cfg = GaifoConfig {
            iterations: 2,
            critic_terminal_pairs: pairs,
            ..GaifoConfig::default()
        };
        train(&cfg, demos.clone(), None, |_| {}).unwrap()
    };
    let stats = |logs: &[imitation::iteration_log::GaifoLog]| -> Vec<u64> {
        logs.iter()
            .flat_map(|l| [l.critic_loss, l.wasserstein, l.task_cost])
            .map(f64::to_bits)
            .collect()
    };
    let (off, on, again) = (run(0), run(5), run(5));
    assert_ne!(stats(&off[..1]), stats(&on[..1]));
    assert_eq!(stats(&on), stats(&again));
}

/// `iterate` is `execute` + `learn`: learning on episodes executed outside (as `learner serve`
/// does with the controller's) gives the same logs and controllers bit for bit.
#[test]
fn learning_on_executed_episodes_equals_iterate() {
    use imitation::gaifo::LqrGaifo;
    use imitation::learn::{iterate, LinGaussLearn};
    use imitation::rollout::execute;
    use learner::arm::SimArm;
    let demos = short_demos();
    let cfg = GaifoConfig {
        seed: 5,
        ..GaifoConfig::default()
    };
    let mut a = LqrGaifo::new(cfg.clone(), demos.clone()).unwrap();
    let mut b = LqrGaifo::new(cfg.clone(), demos).unwrap();
    let arm_a = SimArm::new(cfg.sim.clone(), a.task().dt).unwrap();
    let sim = SimArm::new(cfg.sim.clone(), b.task().dt).unwrap();
    for i in 0..3 {
        let (la, ea) = iterate(&mut a, &arm_a).unwrap();
        let task = b.task().clone();
        let (noisy, eval) = execute(&sim, &task, &*b.table(), b.version(), 5, 5).unwrap();
        assert_eq!(ea, [eval.clone()]);
        let lb = b.learn(&noisy, &eval, 0.0).unwrap();
        let key = |l: &imitation::gaifo::GaifoLog| {
            [l.task_cost, l.critic_loss, l.wasserstein, l.kl, l.eta].map(f64::to_bits)
        };
        assert_eq!((la.iteration, key(&la)), (i, key(&lb)));
        assert_eq!(a.policy(), b.policy());
    }
    let e = b
        .learn(&[], &iterate(&mut a, &arm_a).unwrap().1[0], 0.0)
        .unwrap_err();
    assert!(e.to_string().contains("needs 5 noisy episodes"), "{e}");
}

/// The episodes of an iteration run in parallel, each on its own fresh arm
/// (docs/design.md §5 D29), so the thread count changes no bit: the expert (its demonstrations),
/// 3 iterations of LQR+GAIfO and 2 of the GAIfO (PPO) baseline with 1, 2 and 3 worker threads
/// give the same demonstrations, logged figures, controllers and noise-free episodes.
#[test]
fn results_do_not_depend_on_the_thread_count() {
    use imitation::gaifo::LqrGaifo;
    use imitation::learn::{iterate, LinGaussLearn};
    use imitation::ppo::gaifo_ppo::{GaifoPpo, GaifoPpoConfig};
    use learner::run::arm_for;
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
    let key = |l: &imitation::gaifo::GaifoLog| {
        [
            l.task_cost,
            l.critic_loss,
            l.wasserstein,
            l.kl,
            l.eta,
            l.performance,
        ]
        .map(f64::to_bits)
    };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let demos = short_demos();
            let mut out = vec![bits(&demos.states), bits(&[demos.cost_random])];
            let cfg = GaifoConfig {
                seed: 3,
                ..GaifoConfig::default()
            };
            let mut lqr = LqrGaifo::new(cfg, demos.clone()).unwrap();
            let arm = arm_for(&lqr).unwrap();
            for _ in 0..3 {
                let (log, eval) = iterate(&mut lqr, &arm).unwrap();
                out.push(key(&log).to_vec());
                out.push(bits(&eval[0].x));
            }
            out.push(vec![lqr.table().compute_checksum()]);
            let cfg = GaifoPpoConfig {
                seed: 3,
                ..GaifoPpoConfig::default()
            };
            let mut ppo = GaifoPpo::new(cfg, demos).unwrap();
            let arm = arm_for(&ppo).unwrap();
            for _ in 0..2 {
                let (log, eval) = iterate(&mut ppo, &arm).unwrap();
                out.push(key(&log).to_vec());
                out.push(bits(&eval[0].x));
            }
            out
        })
    };
    let one = run(1);
    assert_eq!(run(2), one, "2 threads");
    assert_eq!(run(3), one, "3 threads");
}

mod resume {
    use std::path::{Path, PathBuf};

    use super::short_demos;
    use imitation::controller::{policy_from_gain_table, to_gain_table};
    use imitation::gaifo::GaifoConfig;
    use learner::io::log::CSV_HEADER;
    use learner::io::table::load_table;
    use learner::run::{resume, train, train_resumed};
    use ur5_shared::config::TaskConfig;
    use ur5_shared::GainBounds;

    fn cfg(iterations: usize) -> GaifoConfig {
        GaifoConfig {
            iterations,
            seed: 3,
            ..GaifoConfig::default()
        }
    }

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("gaifo-resume-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn rows(dir: &Path) -> Vec<String> {
        let text = std::fs::read_to_string(dir.join("gaifo_log.csv")).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some(CSV_HEADER), "one header, first");
        lines.map(str::to_owned).collect()
    }

    /// The columns of a row up to `step_mult` (the rest are timings).
    fn learned(row: &str) -> Vec<&str> {
        row.split(',').take(11).collect()
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Files of checkpoint `i` in `dir`.
    fn ckpt(dir: &Path, i: usize, kind: &str) -> PathBuf {
        dir.join(format!("iter_{i:03}_{kind}"))
    }

    /// Where a `learner train` process may be killed after its checkpoint `k` is complete, and
    /// what it leaves behind (each write is atomic: temporary file, fsync, rename).
    #[derive(Clone, Copy, Debug)]
    enum Kill {
        /// While executing or learning iteration k: nothing of it written.
        Learning,
        /// While writing iteration k's CSV row: a row cut short, no newline.
        MidRow,
        /// While writing checkpoint k + 1's table: a `.partial` file.
        MidTable,
        /// While writing its critic: the table, and a `.tmp` critic.
        MidCritic,
        /// While writing its state: table, critic, and a `.partial` state.
        MidState,
        /// Right after checkpoint k + 1 (resumes from there).
        After,
    }

    const KILLS: [Kill; 6] = [
        Kill::Learning,
        Kill::MidRow,
        Kill::MidTable,
        Kill::MidCritic,
        Kill::MidState,
        Kill::After,
    ];

    /// Turns `dir`, a run stopped right after checkpoint k + 1, into what a kill at `kill`
    /// during iteration k would have left (`cut` picks where a file is cut short).
    fn unwind(dir: &Path, k: usize, kill: Kill, cut: f64) {
        let truncate_to = |from: &Path, to: &Path| {
            let bytes = std::fs::read(from).unwrap();
            std::fs::write(to, &bytes[..(bytes.len() as f64 * cut) as usize]).unwrap();
            std::fs::remove_file(from).unwrap();
        };
        let partial = |p: &Path, ext: &str| PathBuf::from(format!("{}.{ext}", p.display()));
        let (table, critic, state) = (
            ckpt(dir, k + 1, "table.npz"),
            ckpt(dir, k + 1, "critic.json"),
            ckpt(dir, k + 1, "state.npz"),
        );
        let remove = |ps: &[&PathBuf]| ps.iter().for_each(|p| std::fs::remove_file(p).unwrap());
        match kill {
            Kill::Learning | Kill::MidRow => {
                remove(&[&table, &critic, &state]);
                let csv = dir.join("gaifo_log.csv");
                let text = std::fs::read_to_string(&csv).unwrap();
                let body = text.trim_end_matches('\n');
                let last = body.rfind('\n').unwrap() + 1;
                assert!(body[last..].starts_with(&format!("{k},")));
                let keep = match kill {
                    Kill::Learning => last,
                    _ => last + 1 + ((body.len() - last - 2) as f64 * cut) as usize,
                };
                std::fs::write(&csv, &text[..keep]).unwrap();
            }
            Kill::MidTable => {
                remove(&[&critic, &state]);
                truncate_to(&table, &partial(&table, "partial"));
            }
            Kill::MidCritic => {
                remove(&[&state]);
                truncate_to(&critic, &partial(&critic, "tmp"));
            }
            Kill::MidState => truncate_to(&state, &partial(&state, "partial")),
            Kill::After => {}
        }
    }

    /// Every table, learner state and CSV row (timing columns aside) of `dir` is `full`'s, bit
    /// for bit, for iterations 0..=n.
    fn assert_same_run(dir: &Path, full: &Path, n: usize, what: &str) {
        use learner::io::checkpoint::load_state;
        for i in 0..=n {
            let (a, _) = load_table(&ckpt(dir, i, "table.npz"), &GainBounds::default()).unwrap();
            let (b, _) = load_table(&ckpt(full, i, "table.npz"), &GainBounds::default()).unwrap();
            assert_eq!(a.checksum, b.checksum, "{what}: table {i}");
            let (a, b) = (
                load_state(&ckpt(dir, i, "state.npz")).unwrap(),
                load_state(&ckpt(full, i, "state.npz")).unwrap(),
            );
            let bits = |s: &gps::snapshot::Snapshot| -> Vec<(String, Vec<u64>)> {
                let reals = s.reals.iter().map(|(k, (_, v))| (k.clone(), bits(v)));
                reals.chain(s.words.clone()).collect()
            };
            assert_eq!(bits(&a), bits(&b), "{what}: learner state {i}");
            let (a, b) = (
                std::fs::read(ckpt(dir, i, "critic.json")).unwrap(),
                std::fs::read(ckpt(full, i, "critic.json")).unwrap(),
            );
            assert!(a == b, "{what}: critic {i}");
        }
        let (a, b) = (rows(dir), rows(full));
        assert_eq!(a.len(), n, "{what}: {a:?}");
        for (ra, rb) in a.iter().zip(&b) {
            assert_eq!(learned(ra), learned(rb), "{what}");
        }
    }

    /// Exact resume: N iterations in one go vs runs stopped after a seeded random
    /// iteration k, at every moment of iteration k (learning, mid CSV row, mid table, mid critic,
    /// mid state write, just after the next checkpoint), then resumed to N, and once more
    /// stopped and resumed: every table, learner state, critic file and CSV row (timing columns
    /// aside) is the uninterrupted run's, bit for bit. The arm has sensor noise, so its noise
    /// stream's position must resume too.
    #[test]
    fn a_run_killed_anywhere_resumes_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        const N: usize = 6;
        let demos = short_demos();
        let noisy = |iterations: usize| {
            let mut c = cfg(iterations);
            c.sim.perturbation.sensor_noise_q_std = 1e-4;
            c.sim.perturbation.seed = 11;
            c
        };
        let root = scratch("exact");
        let full = root.join("full");
        train(&noisy(N), demos.clone(), Some(&full), |_| {}).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(15);
        for (case, kill) in KILLS.into_iter().enumerate() {
            let k = rng.random_range(0..N - 1);
            let cut = rng.random_range(0.05..0.95);
            let what = format!("kill at {kill:?} of iteration {k} (cut {cut:.2})");
            let dir = root.join(format!("case{case}"));
            train(&noisy(k + 1), demos.clone(), Some(&dir), |_| {}).unwrap();
            unwind(&dir, k, kill, cut);
            // A second stop on the way, after a whole checkpoint.
            let mid = rng.random_range(k + 1..=N);
            if mid < N {
                train_resumed(&noisy(mid), demos.clone(), &dir, |_| {}).unwrap();
            }
            let logs = train_resumed(&noisy(N), demos.clone(), &dir, |_| {}).unwrap();
            assert_eq!(logs.last().map(|l| l.iteration), Some(N - 1), "{what}");
            assert_same_run(&dir, &full, N, &what);
            eprintln!("{what}, second stop at {mid}: bit for bit");
        }
        std::fs::remove_dir_all(&root).ok();
    }

    /// What a resume refuses, by name: fewer iterations than done, no checkpoint (or only tables of a
    /// build before exact resume), a missing folder, a malformed critic, another seed, a
    /// learner state of another horizon.
    #[test]
    fn a_resume_that_cannot_be_exact_is_refused() {
        let demos = short_demos();
        let root = scratch("refused");
        let split = root.join("split");
        train(&cfg(2), demos.clone(), Some(&split), |_| {}).unwrap();
        let resumed = resume(cfg(4), demos.clone(), &split).unwrap().0;
        assert_eq!((resumed.iteration(), resumed.version()), (2, 3));
        drop(resumed);
        let msg = |e: learner::run::RunError| learner::error::line(&e);
        // A complete run resumes to nothing (a retried job); a shorter one is refused.
        let again = std::fs::read(split.join("gaifo_log.csv")).unwrap();
        assert!(train_resumed(&cfg(2), demos.clone(), &split, |_| {})
            .unwrap()
            .is_empty());
        assert_eq!(std::fs::read(split.join("gaifo_log.csv")).unwrap(), again);
        let e = msg(train_resumed(&cfg(1), demos.clone(), &split, |_| {}).unwrap_err());
        assert!(e.contains("never shortens"), "{e}");
        let empty = root.join("empty");
        std::fs::create_dir_all(&empty).unwrap();
        let e = msg(train_resumed(&cfg(4), demos.clone(), &empty, |_| {}).unwrap_err());
        assert!(e.contains("no checkpoint"), "{e}");
        std::fs::copy(ckpt(&split, 0, "table.npz"), ckpt(&empty, 0, "table.npz")).unwrap();
        std::fs::copy(
            ckpt(&split, 0, "critic.json"),
            ckpt(&empty, 0, "critic.json"),
        )
        .unwrap();
        let e = msg(train_resumed(&cfg(4), demos.clone(), &empty, |_| {}).unwrap_err());
        assert!(e.contains("before exact resume"), "{e}");
        let e =
            msg(train_resumed(&cfg(4), demos.clone(), &root.join("missing"), |_| {}).unwrap_err());
        assert!(e.contains("cannot resume"), "{e}");
        let other_seed = GaifoConfig { seed: 4, ..cfg(6) };
        let e = msg(train_resumed(&other_seed, demos.clone(), &split, |_| {}).unwrap_err());
        assert!(e.contains("another seed"), "{e}");
        // The same demonstrations one step longer (the last step repeated).
        let longer = |v: &[f64], w: usize| -> Vec<f64> {
            v.chunks(demos.horizon * w)
                .flat_map(|d| {
                    d.iter()
                        .chain(&d[d.len() - w..])
                        .copied()
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let longer = imitation::demos::Demos {
            states: longer(&demos.states, 12),
            actions: longer(&demos.actions, 3),
            horizon: demos.horizon + 1,
            ..demos.clone()
        };
        let e = msg(train_resumed(&cfg(6), longer, &split, |_| {}).unwrap_err());
        assert!(
            e.contains("iter_002_state.npz") && e.contains("policy.K"),
            "{e}"
        );
        std::fs::write(ckpt(&split, 2, "critic.json"), "{\"format\": ").unwrap();
        let e = msg(train_resumed(&cfg(6), demos.clone(), &split, |_| {}).unwrap_err());
        assert!(
            e.contains("iter_002_critic.json") && e.contains("not a valid critic file"),
            "{e}"
        );
        std::fs::remove_dir_all(&root).ok();
    }

    /// A gain table back to a controller: K, k and L (hence the table) exactly, Σ and Σ⁻¹ to
    /// rounding.
    #[test]
    fn policy_from_gain_table_inverts_to_gain_table() {
        let task = TaskConfig {
            horizon: 4,
            ..TaskConfig::default()
        };
        let mut pol = imitation::controller::init_hold(&task, 0.05);
        for t in 0..4 {
            pol.gain.slice_mut(t)[5] = -0.3 * t as f64;
            // Σ = R Rᵀ... here a full lower factor L (GPS keeps R = Lᵀ).
            let l = [[0.3, 0.0, 0.0], [0.1, 0.2, 0.0], [-0.05, 0.07, 0.25]];
            for i in 0..3 {
                for j in 0..3 {
                    pol.chol_pol_covar.slice_mut(t)[j * 3 + i] = if j <= i { l[i][j] } else { 0.0 };
                    pol.pol_covar.slice_mut(t)[i * 3 + j] = (0..3).map(|k| l[i][k] * l[j][k]).sum();
                }
            }
        }
        let table = to_gain_table(&pol, 7);
        let back = policy_from_gain_table(&table).unwrap();
        assert_eq!(to_gain_table(&back, 7).checksum, table.checksum);
        assert_eq!(back.gain, pol.gain);
        assert_eq!(back.k, pol.k);
        assert_eq!(back.chol_pol_covar, pol.chol_pol_covar);
        for t in 0..4 {
            let (s, si) = (back.pol_covar.slice(t), back.inv_pol_covar.slice(t));
            for i in 0..3 {
                for j in 0..3 {
                    assert!((s[i * 3 + j] - pol.pol_covar.slice(t)[i * 3 + j]).abs() < 1e-15);
                    let id: f64 = (0..3).map(|k| s[i * 3 + k] * si[k * 3 + j]).sum();
                    assert!((id - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12, "{id}");
                }
            }
        }
    }
}
