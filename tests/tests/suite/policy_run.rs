//! A policy table in the real-time loop (docs/design.md §3.11): `learner policy
//! serve` publishes a saved MDGPS policy, `rt-controller run --goal x,y,z` runs it on `hil-sim
//! serve` (lockstep) to a goal given on the command line, and the episode equals the same
//! policy run in process on the same arm to the same goal: every noise-free action is the
//! policy's own (bit for bit) and the distance to the goal at the last step is the in-process
//! one. The policy is a seeded random perturbation of a fresh one (training one takes minutes);
//! what is tested is that the controller executes whatever policy it is given, to the goal it
//! is given.

use std::time::Duration;

use imitation::mlp_policy::global::{GlobalActor, GlobalPolicy};
use imitation::rollout::run_episode;
use integration_tests::{json_summary, scratch, unique_prefix, write_config, Proc};
use learner::arm::SimArm;
use learner::io::policy::{save_policy, PolicyFile};
use rand::{Rng, SeedableRng};
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};
use ur5_shared::layout::{DX, EE_MINUS_GOAL};

const T: usize = 40;

/// A policy that moves the arm: a fresh 64-64 one with every parameter perturbed (seeded).
fn moving_policy() -> GlobalPolicy {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let p = GlobalPolicy::new(ur5_shared::StateLayout::REACH3, &[64, 64], 0.05, &mut rng);
    let mut flat = p.flat();
    for v in flat.iter_mut().skip(2 * DX) {
        *v += rng.random_range(-0.05..0.05);
    }
    GlobalPolicy::from_flat(ur5_shared::StateLayout::REACH3, &[64, 64], &flat).unwrap()
}

#[test]
fn the_controller_runs_a_policy_table_to_a_goal_given_on_the_command_line() {
    let dir = scratch("policy-run");
    let prefix = unique_prefix("policy-run");
    let policy = moving_policy();
    let default = TaskConfig::default();
    let goal = [
        default.goal[0] + 0.05,
        default.goal[1] - 0.04,
        default.goal[2],
    ];
    let task = TaskConfig {
        horizon: T,
        goal,
        ..default
    };
    let file = dir.join("policy.npz");
    save_policy(
        &PolicyFile {
            policy: policy.clone(),
            mode: ActionMode::GoalAngles,
            start_q: task.start_q,
            dt: task.dt,
            horizon: T,
            seed: 21,
            iterations: 0,
            model: ur5_shared::UrModel::Ur5,
        },
        &file,
    )
    .unwrap();

    // In process: the same policy, arm and goal.
    let mut arm = SimArm::new(SimConfig::default(), task.dt).unwrap();
    let mut ws = policy.workspace();
    let ep = run_episode(
        &mut arm,
        &task,
        &mut GlobalActor::new(&policy, &mut ws),
        None,
    )
    .unwrap();
    let want: f64 = ep.state(T - 1)[EE_MINUS_GOAL]
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt();

    // Over IPC: the goal only on the controller's command line (the arm and the policy file
    // know nothing of it).
    let sim_cfg = write_config(&dir, "sim.toml", &format!("[task]\nhorizon = {T}\n"));
    let ctl_cfg = write_config(
        &dir,
        "controller.toml",
        &format!("episodes = 2\nnoisy_episodes = 1\neval_episodes = 1\n[task]\nhorizon = {T}\n"),
    );
    let goal_arg = format!("{},{},{}", goal[0], goal[1], goal[2]);
    let file_arg = file.display().to_string();
    let mut server = Proc::spawn(
        "learner",
        "policy-serve",
        &[
            "policy",
            "serve",
            "--policy",
            &file_arg,
            "--prefix",
            &prefix,
            "--episodes",
            "2",
            "--steps",
            &T.to_string(),
            "--json",
        ],
        &dir,
    );
    let sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &sim_cfg, "--prefix", &prefix],
        &dir,
    );
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &[
            "run", "--config", &ctl_cfg, "--prefix", &prefix, "--goal", &goal_arg, "--json",
        ],
        &dir,
    );
    let (code, out) = server.wait(Duration::from_secs(120));
    let log = server.log();
    assert_eq!(code, Some(0), "policy serve failed:\n{log}");
    let (ccode, cout) = ctl.wait(Duration::from_secs(60));
    assert_eq!(ccode, Some(0), "controller:\n{}", ctl.log());
    let summary = json_summary(&cout, &ctl.log());
    assert_eq!(summary["episodes_completed"], 2, "{summary}");
    assert_eq!(summary["table_version"], 1, "{summary}");
    assert_eq!(summary["rejected_total"], 0, "{summary}");
    drop(sim); // killed on drop

    let report = json_summary(&out, &log);
    let eps = report["episodes"].as_array().expect("episodes");
    assert_eq!(eps.len(), 2, "{report}");
    assert_eq!(eps[0]["noisy"], true, "{report}");
    let eval = &eps[1];
    assert_eq!(eval["noisy"], false, "{report}");
    assert_eq!(eval["steps"], T, "{report}");
    assert_eq!(eval["mismatched_actions"], 0, "{report}");
    let got = eval["distance_last_m"].as_f64().unwrap();
    assert_eq!(
        got.to_bits(),
        want.to_bits(),
        "distance at the last step over IPC {got} m, in process {want} m"
    );
    // The arm moved: the policy is not a hold.
    let d0: f64 = ep.state(0)[EE_MINUS_GOAL]
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt();
    assert!(
        (d0 - want).abs() > 1e-3,
        "the arm did not move ({d0} → {want} m)"
    );
}
