//! LQR+GAIfO end to end on the simulated arm: expert → demonstrations → imitation from the
//! states alone.

use imitation::expert::ExpertConfig;
use imitation::gaifo::GaifoConfig;
use learner::run::train;
use learner::run::{demos as record_demos, expert as train_expert};

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
        assert_eq!(ea, eval);
        let lb = b.learn(&noisy, &eval, 0.0).unwrap();
        let key = |l: &imitation::gaifo::GaifoLog| {
            [l.task_cost, l.critic_loss, l.wasserstein, l.kl, l.eta].map(f64::to_bits)
        };
        assert_eq!((la.iteration, key(&la)), (i, key(&lb)));
        assert_eq!(a.policy(), b.policy());
    }
    let e = b
        .learn(&[], &iterate(&mut a, &arm_a).unwrap().1, 0.0)
        .unwrap_err();
    assert!(e.to_string().contains("needs 5 noisy episodes"), "{e}");
}

/// Issue 16 goal 2: the episodes of an iteration run in parallel, each on its own fresh arm
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
                out.push(bits(&eval.x));
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
                out.push(bits(&eval.x));
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
    use imitation::cost::composite::D_IN;
    use imitation::discriminator::Discriminator;
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

    fn same_critic(a: &Discriminator, b: &Discriminator) -> bool {
        // Adam (step count, both moments) and the normaliser compare by value; all finite.
        bits(a.params()) == bits(b.params())
            && a.adam() == b.adam()
            && a.adam().steps() > 0
            && a.normalizer() == b.normalizer()
    }

    /// 4 iterations in one go vs 2 + `train_resumed` to 4. Not bit for bit overall (the GMM
    /// dynamics prior and the previous controller restart), but: the resumed run starts from
    /// the checkpointed table and critic (the uninterrupted run's at that point), numbers on
    /// from 2, appends to the CSV, and its first iteration — same episodes, same critic
    /// update — logs the uninterrupted run's task cost, critic loss and Wasserstein estimate
    /// bit for bit. Then the errors: nothing to resume, no checkpoint, a malformed critic, a
    /// different seed.
    #[test]
    fn a_resumed_run_continues_from_its_checkpoint() {
        let demos = short_demos();
        let root = scratch("a");
        let (full, split) = (root.join("full"), root.join("split"));
        let logs_full = train(&cfg(4), demos.clone(), Some(&full), |_| {}).unwrap();
        let logs_a = train(&cfg(2), demos.clone(), Some(&split), |_| {}).unwrap();
        assert_eq!(logs_a.len(), 2);

        // What the resumed run starts from: the checkpointed table and critic, which are the
        // uninterrupted run's after 2 iterations.
        let resumed = resume(cfg(4), demos.clone(), &split).unwrap();
        assert_eq!((resumed.iteration(), resumed.version()), (2, 3));
        let (table, dt) =
            load_table(&split.join("iter_002_table.npz"), &GainBounds::default()).unwrap();
        let (full_table, _) =
            load_table(&full.join("iter_002_table.npz"), &GainBounds::default()).unwrap();
        assert_eq!(dt, demos.dt);
        let first = to_gain_table(resumed.policy(), resumed.version());
        assert_eq!(first.version, 3);
        assert_eq!(first.checksum, table.checksum, "first table = checkpoint");
        assert_eq!(first.checksum, full_table.checksum);
        assert!(first.used_steps() == table.used_steps());
        let critic = Discriminator::load(split.join("iter_002_critic.json"), D_IN).unwrap();
        let full_critic = Discriminator::load(full.join("iter_002_critic.json"), D_IN).unwrap();
        assert!(same_critic(resumed.discriminator(), &critic));
        assert!(same_critic(&critic, &full_critic));
        drop(resumed);

        let logs_b = train_resumed(&cfg(4), demos.clone(), &split, |_| {}).unwrap();
        let numbers: Vec<usize> = logs_b.iter().map(|l| l.iteration).collect();
        assert_eq!(numbers, [2, 3], "numbering continues");
        let (b, f) = (&logs_b[0], &logs_full[2]);
        assert_eq!(b.task_cost.to_bits(), f.task_cost.to_bits());
        assert_eq!(b.critic_loss.to_bits(), f.critic_loss.to_bits());
        assert_eq!(b.wasserstein.to_bits(), f.wasserstein.to_bits());

        // The CSV: 2 rows of the first run, 2 appended; the first two are the uninterrupted
        // run's.
        let (split_rows, full_rows) = (rows(&split), rows(&full));
        assert_eq!(split_rows.len(), 4, "{split_rows:?}");
        for (i, r) in split_rows.iter().enumerate() {
            assert!(r.starts_with(&format!("{i},3,lqr-gaifo,")), "{r}");
        }
        for i in 0..2 {
            assert_eq!(learned(&split_rows[i]), learned(&full_rows[i]));
        }
        for i in 0..=4 {
            assert!(split.join(format!("iter_{i:03}_table.npz")).is_file());
            assert!(split.join(format!("iter_{i:03}_critic.json")).is_file());
        }

        // Rows written after the checkpoint resumed from (a run stopped between its CSV row
        // and its next checkpoint) are dropped, not duplicated.
        let stale = root.join("stale");
        std::fs::create_dir_all(&stale).unwrap();
        for f in [
            "iter_003_table.npz",
            "iter_003_critic.json",
            "gaifo_log.csv",
        ] {
            std::fs::copy(split.join(f), stale.join(f)).unwrap();
        }
        let logs_c = train_resumed(&cfg(4), demos.clone(), &stale, |_| {}).unwrap();
        assert_eq!(logs_c.len(), 1);
        let stale_rows = rows(&stale);
        assert_eq!(stale_rows.len(), 4, "{stale_rows:?}");
        assert!(stale_rows[3].starts_with("3,"));

        // Errors.
        let msg = |e: anyhow::Error| format!("{e:#}");
        let e = msg(train_resumed(&cfg(4), demos.clone(), &split, |_| {}).unwrap_err());
        assert!(e.contains("nothing to resume"), "{e}");
        let empty = root.join("empty");
        std::fs::create_dir_all(&empty).unwrap();
        let e = msg(train_resumed(&cfg(4), demos.clone(), &empty, |_| {}).unwrap_err());
        assert!(e.contains("no checkpoint"), "{e}");
        let e =
            msg(train_resumed(&cfg(4), demos.clone(), &root.join("missing"), |_| {}).unwrap_err());
        assert!(e.contains("cannot resume"), "{e}");
        std::fs::write(split.join("iter_004_critic.json"), "{\"format\": ").unwrap();
        let e = msg(train_resumed(&cfg(6), demos.clone(), &split, |_| {}).unwrap_err());
        assert!(
            e.contains("iter_004_critic.json") && e.contains("not a valid critic file"),
            "{e}"
        );
        let other_seed = GaifoConfig { seed: 4, ..cfg(6) };
        let e = msg(train_resumed(&other_seed, demos.clone(), &stale, |_| {}).unwrap_err());
        assert!(e.contains("another seed"), "{e}");
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
