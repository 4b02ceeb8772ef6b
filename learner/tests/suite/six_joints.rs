//! Every learner with an MLP policy at six joints and a pose goal (the whole arm, dX = 30,
//! dU = 6) on the simulated UR5e: a few iterations of GAIfO (PPO), BCO, GAIfO (TD3) and MDGPS
//! end to end, checking the dimensions of what each outputs, that its numbers are finite, that
//! the policy table and the policy file carry the layout and refuse another, and that a BCO
//! run resumes exactly. All fast (seconds).

use std::path::PathBuf;

use imitation::bco::{Bco, BcoConfig};
use imitation::controller::init_hold;
use imitation::demos::Demos;
use imitation::expert::{record_demos, ExpertConfig};
use imitation::learn::{iterate, Learn};
use imitation::mdgps::{Mdgps, MdgpsConfig};
use imitation::mlp_policy::global::{GlobalActor, GlobalPolicy};
use imitation::offpolicy::td3::Td3Config;
use imitation::offpolicy::{GaifoTd3, GaifoTd3Config};
use imitation::ppo::gaifo_ppo::{GaifoPpo, GaifoPpoConfig};
use imitation::rollout::{Episode, Policy};
use learner::arm::SimArm;
use learner::io::checkpoint::{load_state, save_state};
use learner::io::policy::{load_policy, save_policy, PolicyFile};
use learner::run::arm_for;
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};
use ur5_shared::{policy_action, PolicyBounds, PolicyScratch, StateLayout, UrModel};

/// The UR5e's flange pose at q = (0.293, −1.379, 2.092, −1.9, 1.3, 0.4) rad (the expert's
/// pose test).
pub(crate) const POSE: [f64; 6] = [-0.4383, -0.2993, 0.3748, 0.4667, -0.108, -0.8096];

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("six-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub(crate) fn sim() -> SimConfig {
    SimConfig::for_model(UrModel::Ur5e)
}

pub(crate) fn pose_task(horizon: usize) -> TaskConfig {
    TaskConfig {
        horizon,
        ..TaskConfig::pose_for_model(UrModel::Ur5e, POSE)
    }
}

/// Two demonstrations of T = `horizon` of the initial controller (it holds the start pose,
/// with noise): states of the pose task's layout, all a learner reads.
pub(crate) fn pose_demos(horizon: usize) -> Demos {
    let cfg = ExpertConfig {
        task: pose_task(horizon),
        sim: sim(),
        demos: 2,
        ..ExpertConfig::default()
    };
    let arm = SimArm::for_task(cfg.sim.clone(), &cfg.task).unwrap();
    let mut d = record_demos(&cfg, &arm, &init_hold(&cfg.task, 0.01), 0.0).unwrap();
    d.cost_random = d.cost_expert + 1.0;
    assert_eq!(d.layout(), StateLayout::POSE6);
    d
}

/// An evaluation episode of the pose task: its layout's dimensions, finite, with an orientation
/// error; returns (final distance m, orientation error °).
fn check_eval(ep: &Episode, task: &TaskConfig) -> (f64, f64) {
    let t = task.horizon;
    assert_eq!(ep.layout, StateLayout::POSE6);
    assert_eq!((ep.x.len(), ep.u.len()), (t * 30, t * 6));
    assert!(ep.x.iter().chain(&ep.u).all(|v| v.is_finite()));
    let o = ep
        .final_orientation_error(&task.targets())
        .expect("a pose task's orientation error");
    assert!(o.is_finite() && ep.final_distance().is_finite());
    (ep.final_distance(), o.to_degrees())
}

/// A policy's table acts as the policy bit for bit at a state of the pose task, and the table
/// and the policy file both carry the layout (and refuse the three-joint one, naming both).
fn check_table_and_file(policy: &GlobalPolicy, demos: &Demos, name: &str) {
    assert_eq!(policy.layout(), StateLayout::POSE6);
    assert!(policy.flat().iter().all(|v| v.is_finite()));
    let table = policy.to_table(3, ActionMode::GoalAngles).unwrap();
    table.validate(&PolicyBounds::default()).unwrap();
    assert_eq!(table.dims(), (30, 6));
    table.check_layout(&StateLayout::POSE6).unwrap();
    let e = table
        .check_layout(&StateLayout::REACH3)
        .unwrap_err()
        .to_string();
    assert!(e.contains("dX = 30") && e.contains("dX = 12"), "{e}");
    let s = demos.state(1, 3);
    let eps = [0.3, -0.1, 0.2, 0.0, -0.4, 0.1];
    let (mut want, mut got) = ([f64::NAN; 6], [f64::NAN; 6]);
    let mut ws = policy.workspace();
    GlobalActor::new(policy, &mut ws).act(0, s, &eps, ActionMode::GoalAngles, &mut want);
    policy_action(&table, s, &eps, &mut PolicyScratch::default(), &mut got).unwrap();
    assert_eq!(want.map(f64::to_bits), got.map(f64::to_bits));
    let task = demos.task().unwrap();
    let file = PolicyFile {
        policy: policy.clone(),
        mode: ActionMode::GoalAngles,
        start_q: task.start_q,
        dt: task.dt,
        horizon: task.horizon,
        seed: 1,
        iterations: 2,
        model: UrModel::Ur5e,
    };
    let dir = tmp(name);
    let path = dir.join("policy.npz");
    save_policy(&file, &path).unwrap();
    let back = load_policy(&path).unwrap();
    assert_eq!(back, file);
    assert_eq!(back.start_q.len(), 6);
    back.check_layout(&StateLayout::POSE6).unwrap();
    let e = back
        .check_layout(&StateLayout::REACH3)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dX = 30, dU = 6") && e.contains("dX = 12, dU = 3"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn gaifo_ppo_runs_at_six_joints_and_a_pose() {
    let demos = pose_demos(10);
    let mut cfg = GaifoPpoConfig {
        sim: sim(),
        samples: 2,
        iterations: 2,
        ..GaifoPpoConfig::default()
    };
    cfg.ppo.pi_hidden = vec![8, 8];
    cfg.ppo.v_hidden = vec![8, 8];
    cfg.ppo.epochs = 2;
    cfg.discriminator.hidden = vec![8];
    cfg.discriminator.n_critic = 5;
    let mut r = GaifoPpo::new(cfg.clone(), demos.clone()).unwrap();
    let arm = arm_for(&r).unwrap();
    let task = r.task().clone();
    for i in 0..2 {
        let (log, evals) = iterate(&mut r, &arm).unwrap();
        let (d, o) = check_eval(&evals[0], &task);
        assert_eq!(log.final_distance, d);
        assert!(
            (log.final_orientation_error_deg - o).abs() < 1e-9,
            "{log:?}"
        );
        assert!(
            log.task_cost.is_finite() && log.critic_loss.is_finite(),
            "{i}: {log:?}"
        );
    }
    let pol = r.ppo().policy();
    assert_eq!((pol.dx(), pol.du(), pol.log_std().len()), (30, 6, 6));
    let ac = r.ppo().actor_critic();
    let mut theta = vec![f64::NAN; ac.n_params()];
    ac.read_params(&mut theta);
    assert!(theta.iter().all(|v| v.is_finite()));
    let file = ac.policy_file(&cfg.ppo.pi_hidden);
    assert_eq!((file.heads.len(), file.log_std.len()), (6, 6));
    assert_eq!(
        r.ppo().rollouts().states.len(),
        30 * r.ppo().rollouts().len()
    );
}

/// The BCO suite's small configuration on the UR5e with N = 2 and 3 iterations.
fn tiny_bco() -> BcoConfig {
    BcoConfig {
        sim: sim(),
        samples: 2,
        iterations: 3,
        ..super::bco::tiny_config()
    }
}

#[test]
fn bco_runs_at_six_joints_and_a_pose_and_resumes_exactly() {
    let demos = pose_demos(10);
    let cfg = tiny_bco();
    let arm = SimArm::for_task(cfg.sim.clone(), &demos.task().unwrap()).unwrap();
    let logs = |b: &mut Bco, n: usize| -> Vec<String> {
        (0..n)
            .map(|_| {
                let (mut l, evals) = iterate(b, &arm).unwrap();
                check_eval(&evals[0], b.task());
                (l.t_execute, l.t_dynamics, l.t_cost, l.t_lqr, l.cpu_learner) =
                    (0.0, 0.0, 0.0, 0.0, 0.0);
                format!("{l:?}")
            })
            .collect()
    };
    let mut whole = Bco::new(cfg.clone(), demos.clone()).unwrap();
    assert_eq!(*whole.layout(), StateLayout::POSE6);
    let all = logs(&mut whole, 3);
    // The model is fitted on 3 × 2 episodes of 9 transitions with six-joint actions; the
    // cloning ran and lowered its loss.
    assert_eq!(whole.last.model.transitions, 3 * 2 * 9);
    assert_eq!(whole.model().du(), 6);
    assert!(
        whole.last.clone_after < whole.last.clone_before,
        "{:?}",
        whole.last
    );
    check_table_and_file(whole.policy(), &demos, "bco");
    let table = whole.table().unwrap();
    assert_eq!(table.dims(), (30, 6));
    // Stopped after 2 iterations and resumed: the same third iteration, bit for bit.
    let dir = tmp("bco-resume");
    let mut first = Bco::new(cfg.clone(), demos.clone()).unwrap();
    let mut got = logs(&mut first, 2);
    let path = dir.join("state.npz");
    save_state(&path, &first.snapshot()).unwrap();
    drop(first);
    let mut resumed = Bco::from_snapshot(cfg, demos, &load_state(&path).unwrap()).unwrap();
    got.extend(logs(&mut resumed, 1));
    assert_eq!(got, all);
    assert_eq!(resumed.policy().flat(), whole.policy().flat());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn gaifo_td3_runs_at_six_joints_and_a_pose() {
    let demos = pose_demos(10);
    let mut cfg = GaifoTd3Config {
        sim: sim(),
        samples: 2,
        iterations: 2,
        seed: 5,
        updates_per_episode: 3,
        buffer_capacity: 50,
        td3: Td3Config {
            pi_hidden: vec![8],
            q_hidden: vec![8],
            batch_size: 16,
            ..Td3Config::default()
        },
        ..GaifoTd3Config::default()
    };
    cfg.discriminator.hidden = vec![8];
    cfg.discriminator.n_critic = 5;
    let mut l = GaifoTd3::new(cfg, demos.clone()).unwrap();
    let arm = arm_for(&l).unwrap();
    let task = l.task().clone();
    for _ in 0..2 {
        let (log, evals) = iterate(&mut l, &arm).unwrap();
        check_eval(&evals[0], &task);
        assert!(log.task_cost.is_finite(), "{log:?}");
    }
    assert_eq!(l.bound().len(), 6);
    assert!(l.td3().steps() > 0 && l.last_update.critic_loss.is_finite());
    let row = l.buffer().row(0);
    assert_eq!((row.s.len(), row.a.len(), row.s_next.len()), (30, 6, 30));
    assert_eq!(l.td3().critics()[0].sizes()[0], 30 + 6 + 1);
    check_table_and_file(l.policy(), &demos, "td3");
}

#[test]
fn mdgps_runs_at_six_joints_and_a_pose_and_refuses_many_goal_poses() {
    let demos = pose_demos(10);
    let mut cfg = MdgpsConfig::default();
    cfg.lqr_gaifo.sim = sim();
    cfg.lqr_gaifo.samples = 3;
    cfg.lqr_gaifo.seed = 9;
    cfg.lqr_gaifo.discriminator.n_critic = 5;
    cfg.policy.hidden = vec![8];
    cfg.policy.steps = 20;
    let mut m = Mdgps::new(cfg.clone(), vec![demos.clone()]).unwrap();
    assert_eq!(m.layout(), StateLayout::POSE6);
    let arm = SimArm::for_task(sim(), m.task(0)).unwrap();
    for _ in 0..2 {
        let (samples, evals) = m.execute(&arm).unwrap();
        check_eval(&evals[0], m.task(0));
        let log = m.learn(&samples, &evals, 0.0).unwrap();
        assert!(
            log.s_loss_after.is_finite() && log.kl.is_finite() && log.task_cost[0].is_finite(),
            "{log:?}"
        );
    }
    let c = m.controller(0);
    assert_eq!((c.dx, c.du), (30, 6));
    check_table_and_file(m.policy(), &demos, "mdgps");
    // Two goal poses: refused, saying why.
    let e = Mdgps::new(cfg, vec![demos.clone(), demos])
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("goal point, not a pose"), "{e}");
}
