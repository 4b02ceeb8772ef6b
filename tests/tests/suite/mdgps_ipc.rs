//! MDGPS's step 1 on the real-time controller (docs/design.md §3.3, "Episode plan"): every goal's
//! episodes travel with the table that runs them. After one in-process iteration of a tiny
//! two-goal MDGPS run, the test (as the learner) publishes, goal after goal, that goal's gain
//! table (its goal and noise stream in the table's plan) and then the global policy as a
//! noise-free policy table at that goal, each a new publication (epoch) of version 2;
//! `rt-controller run` (whose own goal is the task's default, neither of the two) runs them on
//! `hil-sim serve` in lockstep. Every episode the learner would use, N noisy per goal and the
//! policy's evaluation per goal, equals `Mdgps::execute`'s in-process episode bit for bit:
//! states, executed and computed actions.
//!
//! `learner serve --algo mdgps` publishes and collects that way itself: served against
//! `hil-sim serve` and `rt-controller run` (lockstep), its checkpoints (critic files byte for
//! byte, learner states bit for bit but the in-process arm's noise position, which a served
//! run has no use for) and `mdgps_log.csv` rows (timing columns aside) are those of `learner
//! train --algo mdgps` with the same seed and demonstrations, also when the learner is killed at
//! seeded moments and resumed each time.

use std::time::Duration;

use imitation::controller::init_hold;
use imitation::demos::Demos;
use imitation::expert::{record_demos, square_goals, ExpertConfig};
use imitation::learn::iterate;
use imitation::mdgps::{Mdgps, MdgpsConfig};
use imitation::rollout::Episode;
use integration_tests::{
    assert_same_checkpoint, assert_served_done, checkpoint_file, json_summary, learn_over_ipc,
    scratch, serve_killed_and_resumed, spawn_sim_and_controller, state_bits, unique_prefix,
    write_config, Proc, TestLearner,
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

/// The `mdgps_log.csv` columns up to `s_loss_after` (the rest are timings).
fn learned_mdgps_columns(row: &str) -> Vec<String> {
    row.split(',').take(11).map(str::to_owned).collect()
}

/// The files of a served MDGPS run of `iterations` in `dir`: demonstrations of two goals
/// (`demos/`), the settings for `learner train` and, with a `[serve]` table, for `learner
/// serve` (plus `serve_extra` in its `[serve]` table), and the arm's and the controller's
/// configs. Starts `learner train --algo mdgps` (output `dir/reference`) and returns it with
/// the paths (serve, sim, controller).
fn served_run_files(
    dir: &std::path::Path,
    iterations: usize,
    serve_extra: &str,
) -> (Proc, [String; 3]) {
    let goals = square_goals(TaskConfig::default().goal, 0.1);
    let demos_dir = dir.join("demos");
    std::fs::create_dir_all(&demos_dir).unwrap();
    for (name, goal) in [("a.npz", goals[0]), ("b.npz", goals[4])] {
        learner::io::demos::save(&hold_demos(goal), &demos_dir.join(name)).unwrap();
    }
    let settings = format!(
        "[lqr_gaifo]\nsamples = {N}\nseed = {SEED}\niterations = {iterations}\n\
         [lqr_gaifo.discriminator]\nn_critic = 5\n[policy]\nhidden = [8]\nsteps = 20\n"
    );
    let train_cfg = write_config(dir, "train.toml", &settings);
    let demos_arg = demos_dir.display().to_string();
    let serve_cfg = write_config(
        dir,
        "serve.toml",
        &format!(
            "{settings}[serve]\nalgo = \"mdgps\"\ndemos = \"{demos_arg}\"\n\
             wait_report_s = 1.0\nidle_sleep_us = 200\n{serve_extra}"
        ),
    );
    let train = Proc::spawn(
        "learner",
        "train",
        &[
            "train",
            "--algo",
            "mdgps",
            "--config",
            &train_cfg,
            "--demos",
            &demos_arg,
            "--out",
            &dir.join("reference").display().to_string(),
        ],
        dir,
    );
    let sim_cfg = write_config(dir, "sim.toml", &format!("[task]\nhorizon = {T}\n"));
    let ctl_cfg = write_config(
        dir,
        "controller.toml",
        &format!("seed = {SEED}\nnoisy_episodes = {N}\neval_episodes = 1\n[task]\nhorizon = {T}\n"),
    );
    (train, [serve_cfg, sim_cfg, ctl_cfg])
}

/// The served run in `out` has the checkpoints and log rows of `learner train` (`train`,
/// into `dir/reference`): every learner state bit for bit (the in-process arm's noise position
/// aside), every critic file byte for byte, the rows' learned columns.
fn assert_train_equal(
    mut train: Proc,
    dir: &std::path::Path,
    out: &std::path::Path,
    iterations: usize,
) {
    let (code, _) = train.wait(Duration::from_secs(300));
    assert_eq!(code, Some(0), "learner train:\n{}", train.log());
    let ref_out = dir.join("reference");
    for i in 0..=iterations {
        assert_same_checkpoint(out, &ref_out, i, &["arm.noise_position"]);
    }
    // The run learned: its last state is not its first.
    let state = |i| state_bits(&checkpoint_file(out, i, "state.npz"));
    assert_ne!(state(0), state(iterations));
    let rows = |d: &std::path::Path| -> Vec<Vec<String>> {
        std::fs::read_to_string(d.join("mdgps_log.csv"))
            .unwrap()
            .lines()
            .map(learned_mdgps_columns)
            .collect()
    };
    let served = rows(out);
    assert_eq!(served.len(), iterations + 1, "{served:?}");
    assert_eq!(served, rows(&ref_out));
}

/// `learner replay OUT` redoes the served run from its recorded episodes (the ones
/// `learned.jsonl` lists, every goal's evaluation included) to the same checkpoints.
fn assert_replays(dir: &std::path::Path, out: &std::path::Path, iterations: usize) {
    let o = out.display().to_string();
    let mut p = Proc::spawn("learner", "replay", &["replay", &o, "--json"], dir);
    let (code, stdout) = p.wait(Duration::from_secs(300));
    let log = p.log();
    assert_eq!(code, Some(0), "replay log:\n{log}");
    let r = json_summary(&stdout, &log);
    assert!(r["difference"].is_null(), "{r}");
    assert_eq!(r["iterations"], iterations as u64, "{r}");
    assert_eq!(r["resumes"], 0, "{r}");
    assert_eq!(r["critics_checked"], iterations as u64 + 1, "{r}");
}

#[test]
fn served_mdgps_checkpoints_equal_learner_train_bit_for_bit() {
    const ITERATIONS: usize = 2;
    let dir = scratch("mdgps-serve");
    let prefix = unique_prefix("mdgps-serve");
    let (train, [serve_cfg, sim_cfg, ctl_cfg]) = served_run_files(&dir, ITERATIONS, "");
    let mut sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &sim_cfg, "--prefix", &prefix],
        &dir,
    );
    let wait = Duration::from_secs(300);
    let (lj, cj) = learn_over_ipc(
        &dir,
        &prefix,
        &serve_cfg,
        &ctl_cfg,
        "mdgps",
        wait,
        |_, _| {},
    );
    let out = dir.join("out-mdgps");
    assert_served_done(&lj, "mdgps", ITERATIONS);
    // Per iteration and goal: N noisy episodes and the evaluation.
    assert_eq!(
        lj["counts"]["used"],
        (ITERATIONS * 2 * (N + 1)) as u64,
        "{lj}"
    );
    // 2 goals × 2 publications per version, and the last version's first.
    assert_eq!(cj["swaps"], (ITERATIONS * 4 + 1) as u64, "{cj}");
    assert!(sim.running());
    assert_train_equal(train, &dir, &out, ITERATIONS);
    // learned.jsonl: every iteration's N noisy episodes per goal and each goal's evaluation.
    let events = learner::io::learned::read_events(&out.join("episodes"))
        .unwrap()
        .unwrap();
    assert_eq!(events.len(), ITERATIONS);
    for (i, e) in events.iter().enumerate() {
        let learner::io::learned::LearnedEvent::Learned {
            iteration,
            noisy,
            more_evals,
            ..
        } = e
        else {
            panic!("{e:?}")
        };
        assert_eq!(
            (*iteration, noisy.len(), more_evals.len()),
            (i + 1, 2 * N, 1)
        );
    }
    assert_replays(&dir, &out, ITERATIONS);
    drop(sim);
    std::fs::remove_dir_all(&dir).ok();
}

/// Exact resume over IPC, as `resume_ipc.rs` for LQR+GAIfO: the served MDGPS learner killed
/// with SIGKILL at seeded moments and resumed each time (every publication of the resumed
/// version above all earlier ones) ends with `learner train`'s checkpoints and rows.
#[test]
fn a_served_mdgps_learner_killed_and_resumed_equals_learner_train() {
    // A served iteration takes about 0.1 s here: kills 30 to 280 ms after each start land
    // in every part of an iteration.
    const ITERATIONS: usize = 12;
    let dir = scratch("mdgps-resume");
    let prefix = unique_prefix("mdgps-resume");
    // Without recording: a learner that records every episode falls behind a lockstep
    // controller whose episodes are this short, and its kills and restarts let the backlog
    // grow until samples of an episode it needs are lost (then it learns from later ones).
    let (train, [serve_cfg, sim_cfg, ctl_cfg]) =
        served_run_files(&dir, ITERATIONS, "record_episodes = false\n");
    let out = dir.join("out");
    let sim = serve_killed_and_resumed(&dir, &prefix, [&serve_cfg, &sim_cfg, &ctl_cfg], &out, 31);
    assert_train_equal(train, &dir, &out, ITERATIONS);
    drop(sim);
    std::fs::remove_dir_all(&dir).ok();
}
