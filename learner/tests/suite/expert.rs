//! The default expert on the simulated arm: acceptance and reproducibility.

use imitation::expert::ExpertConfig;
use learner::io::table::load_table;
use learner::run::{demos as record_demos, expert as train, train_and_record};
use ur5_shared::GainBounds;

/// From the standard retracted pose to the default goal: final distance < 2 cm and task cost
/// < 25 % of the random policy's within 15 iterations (75 noisy episodes).
#[test]
fn expert_reaches_the_goal_within_15_iterations() {
    let cfg = ExpertConfig {
        iterations: 15,
        ..ExpertConfig::default()
    };
    let mut lines = Vec::new();
    let run = train(&cfg, |l| {
        lines.push((l.iteration, l.eval_cost, l.final_distance))
    })
    .unwrap();
    for (i, c, d) in &lines {
        eprintln!("iteration {i}: eval cost {c:.4}, final distance {d:.4} m");
    }
    let ratio = run.eval.task_cost() / run.cost_random;
    eprintln!(
        "best: cost {:.4} = {:.2} % of random {:.4}, final distance {:.5} m",
        run.eval.task_cost(),
        100.0 * ratio,
        run.cost_random,
        run.eval.final_distance()
    );
    assert!(run.log.len() <= 15);
    assert!(
        run.eval.final_distance() < 0.02,
        "final distance {} m",
        run.eval.final_distance()
    );
    assert!(ratio < 0.25, "cost ratio {ratio}");
    // Learning, not luck: the first controller (hold the start pose) is far from the goal.
    assert!(run.log[0].final_distance > 0.1);
}

/// The same seed gives the same demonstrations bit for bit; another seed does not.
#[test]
fn same_seed_same_demonstrations_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("expert-test-{}", std::process::id()));
    let mut cfg = ExpertConfig {
        iterations: 3,
        demos: 2,
        random_episodes: 2,
        ..ExpertConfig::default()
    };
    cfg.task.horizon = 30;
    let a = train_and_record(&cfg, &dir.join("a"), |_| {}).unwrap();
    let b = train_and_record(&cfg, &dir.join("b"), |_| {}).unwrap();
    let bytes = |p: &std::path::Path| std::fs::read(p).unwrap();
    assert_eq!(bytes(&a.demos), bytes(&b.demos), "demos.npz differ");
    assert_eq!(bytes(&a.table), bytes(&b.table), "expert_table.npz differ");
    let da = learner::io::demos::load(&a.demos).unwrap();
    assert_eq!(da.count, 2);
    assert_eq!(da.horizon, 30);
    assert_eq!(da.seed, cfg.seed);
    assert!(da.cost_random > da.cost_expert);
    let (table, dt) = load_table(&a.table, &GainBounds::default()).unwrap();
    assert_eq!((table.horizon(), dt), (30, cfg.task.dt));

    let other = ExpertConfig {
        seed: cfg.seed + 1,
        ..cfg.clone()
    };
    let run = train(&other, |_| {}).unwrap();
    let dc = record_demos(&other, &run).unwrap();
    assert_ne!(
        dc.states, da.states,
        "another seed must give other demonstrations"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// PILQR's step from the same first episodes as LQR's: the same feedback gains (PI2 changes
/// only the feed-forward terms and the covariances), other feed-forward terms and covariances,
/// a positive-definite covariance, and the same episodes bit for bit on a rerun.
#[test]
fn pilqr_keeps_the_lqr_gains_and_moves_the_feed_forward() {
    use gps::traj_opt::pilqr::TrajOptMethod;
    use imitation::expert::ExpertLearner;
    let mut cfg = ExpertConfig::default();
    cfg.task.horizon = 30;
    let arm = learner::arm::SimArm::new(cfg.sim.clone(), cfg.task.dt).unwrap();
    let step = |method| {
        let mut c = cfg.clone();
        c.traj_opt.method = method;
        let mut el = ExpertLearner::new(c, None);
        imitation::learn::iterate(&mut el, &arm).unwrap();
        el.policy().clone()
    };
    let (lqr, pilqr) = (step(TrajOptMethod::Lqr), step(TrajOptMethod::Pilqr));
    assert_eq!(lqr.gain, pilqr.gain);
    assert_ne!(lqr.k, pilqr.k);
    assert_ne!(lqr.pol_covar, pilqr.pol_covar);
    for t in 0..pilqr.t {
        let c = pilqr.pol_covar.slice(t);
        let r = pilqr.chol_pol_covar.slice(t);
        // Σ = Rᵀ R with R upper triangular, positive diagonal.
        for a in 0..3 {
            assert!(r[a * 3 + a] > 0.0);
            for b in 0..3 {
                let rtr: f64 = (0..3).map(|k| r[k * 3 + a] * r[k * 3 + b]).sum();
                assert!((rtr - c[a * 3 + b]).abs() <= 1e-12 * c[a * 3 + a].abs().max(1e-12));
            }
        }
    }
    assert_eq!(step(TrajOptMethod::Pilqr), pilqr);
}

/// The whole arm of a UR5e to a pose goal (six joints, three tool points, dX = 30): the expert
/// brings the tool within 5 mm and 1° of the pose in 12 iterations (from 22 cm and 44° away),
/// and its demonstrations keep the task through a file (six start angles, the pose, the tool
/// points) and pass the checks against the arm.
#[test]
fn the_expert_reaches_a_pose_with_six_joints_and_its_demonstrations_keep_the_task() {
    let model = ur5_shared::UrModel::Ur5e;
    // The flange pose of the UR5e at q = (0.293, −1.379, 2.092, −1.9, 1.3, 0.4) rad.
    let pose = [-0.4383, -0.2993, 0.3748, 0.4667, -0.108, -0.8096];
    let cfg = ExpertConfig {
        task: ur5_shared::config::TaskConfig::pose_for_model(model, pose),
        sim: ur5_shared::config::SimConfig::for_model(model),
        iterations: 12,
        demos: 2,
        ..ExpertConfig::default()
    };
    assert_eq!(cfg.task.layout(), ur5_shared::StateLayout::POSE6);
    let run = train(&cfg, |_| {}).unwrap();
    let targets = cfg.task.targets();
    let first = &run.log[0];
    assert!(first.final_distance > 0.1, "{}", first.final_distance);
    let (d, o) = (
        run.eval.final_distance(),
        run.eval
            .final_orientation_error(&targets)
            .unwrap()
            .to_degrees(),
    );
    eprintln!("pose expert: {d:.5} m, {o:.4}°");
    assert!(d < 0.005 && o < 1.0, "{d} m, {o}°");
    let demos = record_demos(&cfg, &run).unwrap();
    assert_eq!(demos.layout(), ur5_shared::StateLayout::POSE6);
    let dir = std::env::temp_dir().join(format!("pose-demos-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("demos.npz");
    learner::io::demos::save(&demos, &path).unwrap();
    let back = learner::io::demos::load_checked(&path, &cfg.sim).unwrap();
    assert_eq!(back, demos);
    assert_eq!(back.task().unwrap(), cfg.task);
    // The learners with an MLP policy take them at their layout too.
    let ppo = imitation::ppo::gaifo_ppo::GaifoPpo::new(Default::default(), back).unwrap();
    assert_eq!((ppo.ppo().policy().dx(), ppo.ppo().policy().du()), (30, 6));
    std::fs::remove_dir_all(&dir).ok();
}
