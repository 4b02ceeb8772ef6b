//! MDGPS's step 1 on the real-time controller (docs/design.md §3.3, "Episode plan"): every goal's
//! episodes travel with the table that runs them. After one in-process iteration of a tiny
//! two-goal MDGPS run, the test (as the learner) publishes, goal after goal, that goal's gain
//! table (its goal and noise stream in the table's plan) and then the global policy as a
//! noise-free policy table at that goal, each a new publication (epoch) of version 2;
//! `rt-controller run` (whose own goal is the task's default, neither of the two) runs them on
//! `hil-sim serve` in lockstep. Every episode the learner would use, N noisy per goal and the
//! policy's evaluation per goal, equals `Mdgps::execute`'s in-process episode bit for bit:
//! states, executed and computed actions.

use std::time::Duration;

use imitation::controller::init_hold;
use imitation::demos::Demos;
use imitation::expert::{record_demos, square_goals, ExpertConfig};
use imitation::learn::iterate;
use imitation::mdgps::{Mdgps, MdgpsConfig};
use imitation::rollout::Episode;
use integration_tests::{
    json_summary, scratch, spawn_sim_and_controller, unique_prefix, write_config, TestLearner,
};
use learner::arm::SimArm;
use learner::serve::episode_from_samples;
use ur5_shared::config::TaskConfig;
use ur5_shared::StepSample;

const T: usize = 12;
const N: usize = 3;
const SEED: u64 = 9;

/// Demonstrations of the initial hold controller at `goal` (the run only has to be
/// reproducible, not good).
fn hold_demos(goal: [f64; 3]) -> Demos {
    let mut cfg = ExpertConfig::default();
    (cfg.task.horizon, cfg.task.goal, cfg.demos) = (T, goal, 2);
    let hold = init_hold(&cfg.task, 0.01);
    let arm = SimArm::new(cfg.sim.clone(), cfg.task.dt).unwrap();
    let mut d = record_demos(&cfg, &arm, &hold, 0.0).unwrap();
    d.cost_random = d.cost_expert + 1.0;
    d
}

/// The complete episodes (t = 0 … T−1, one publication, one noise flag) of publication
/// (`version`, `epoch`) with noise flag `noisy` among `samples`, in episode order.
fn episodes(samples: &[StepSample], version: u64, epoch: u32, noisy: bool) -> Vec<Episode> {
    let mut out = Vec::new();
    let mut ids: Vec<u64> = samples.iter().map(|s| s.episode).collect();
    ids.dedup();
    for id in ids {
        let steps: Vec<StepSample> = samples
            .iter()
            .filter(|s| s.episode == id)
            .copied()
            .collect();
        let complete = steps.len() == T
            && steps.iter().enumerate().all(|(t, s)| {
                s.t as usize == t
                    && (s.table_version, s.table_epoch, s.is_noisy()) == (version, epoch, noisy)
            });
        if complete {
            out.push(episode_from_samples(&steps));
        }
    }
    out
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn mdgps_goals_run_on_the_controller_by_their_tables_plans_as_in_process() {
    let dir = scratch("mdgps-ipc");
    let prefix = unique_prefix("mdgps-ipc");
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos = vec![hold_demos(goals[0]), hold_demos(goals[4])];
    let mut cfg = MdgpsConfig::default();
    cfg.lqr_gaifo.samples = N;
    cfg.lqr_gaifo.seed = SEED;
    cfg.lqr_gaifo.discriminator.n_critic = 5;
    cfg.policy.hidden = vec![8];
    cfg.policy.steps = 20;
    let mut run = Mdgps::new(cfg.clone(), demos).unwrap();
    let arm = SimArm::new(cfg.lqr_gaifo.sim.clone(), run.task(0).dt).unwrap();
    // One iteration in process, so that the policy and the controllers are not the initial
    // holds; then the reference episodes of version 2.
    iterate(&mut run, &arm).unwrap();
    assert_eq!(run.version(), 2);
    let (samples, evals) = run.execute(&arm).unwrap();

    let sim_cfg = write_config(&dir, "sim.toml", &format!("[task]\nhorizon = {T}\n"));
    let ctl_cfg = write_config(
        &dir,
        "controller.toml",
        &format!("seed = {SEED}\nnoisy_episodes = {N}\neval_episodes = 1\n[task]\nhorizon = {T}\n"),
    );
    let mut learner = TestLearner::with_policy(&prefix);
    let (sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);
    let wait = Duration::from_secs(120);
    let mut epoch = 0;
    for m in 0..run.conditions() {
        assert_ne!(run.task(m).goal, TaskConfig::default().goal);
        // Goal m's N noisy episodes: its controller, its goal and noise stream in the plan.
        learner.publish(&run.gain_table(m, epoch));
        learner.poll_until(&mut ctl, wait, "the noisy episodes", |l| {
            episodes(&l.received, 2, epoch, true).len() >= N
        });
        let got = episodes(&learner.received, 2, epoch, true);
        for (k, (ipc, local)) in got.iter().zip(&samples[m]).enumerate() {
            assert!(
                same_bits(&ipc.x, &local.x),
                "goal {m}, noisy episode {k}: states"
            );
            assert!(
                same_bits(&ipc.u, &local.u),
                "goal {m}, noisy episode {k}: actions"
            );
            assert!(
                same_bits(&ipc.u_policy, &local.u_policy),
                "goal {m}, noisy episode {k}: the law's actions"
            );
        }
        // The policy's evaluation at goal m: a noise-free policy table with goal m's plan.
        epoch += 1;
        learner.publish_policy(&run.eval_table(m, epoch).unwrap());
        learner.poll_until(&mut ctl, wait, "the evaluation", |l| {
            !episodes(&l.received, 2, epoch, false).is_empty()
        });
        let eval = &episodes(&learner.received, 2, epoch, false)[0];
        assert!(
            same_bits(&eval.x, &evals[m].x),
            "goal {m}'s evaluation: states"
        );
        assert!(
            same_bits(&eval.u, &evals[m].u),
            "goal {m}'s evaluation: actions"
        );
        // Every episode of the evaluation table runs noise-free.
        assert!(
            episodes(&learner.received, 2, epoch, true).is_empty(),
            "a noisy episode of a noise-free table"
        );
        epoch += 1;
    }
    // The arm moved towards different goals: the evaluations' last states differ.
    assert_ne!(evals[0].state(T - 1), evals[1].state(T - 1));
    ctl.signal(libc::SIGTERM);
    let (code, out) = ctl.wait(wait);
    let log = ctl.log();
    assert_eq!(code, Some(0), "controller:\n{log}");
    let summary = json_summary(&out, &log);
    assert_eq!(summary["rejected_total"], 0, "{summary}");
    assert_eq!(summary["episodes_aborted"], 0, "{summary}");
    drop(sim);
    std::fs::remove_dir_all(&dir).ok();
}
