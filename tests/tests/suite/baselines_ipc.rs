//! The baselines over IPC: `learner serve --algo bco` and `--algo gaifo-td3` publish their MLP
//! policy as a policy table per version, which `rt-controller run` runs on `hil-sim serve`
//! (lockstep) as it runs a gain table: N noisy episodes with the learner's seed's noise, then
//! the noise-free one. The served runs' checkpoints (learner states bit for bit, the in-process
//! arm's noise position aside, which a served run has no use for; BCO's policy files and
//! TD3's critic files byte for byte) and `gaifo_log.csv` rows (timing columns aside) are those
//! of `learner train` with the same settings and demonstrations: the controller ran the
//! policy's law, noise keys included, exactly as in process. The mean path
//! (`--algo replay-mean`), a gain table with K = 0, likewise.

use std::path::Path;
use std::time::Duration;

use imitation::controller::init_hold;
use imitation::expert::{record_demos, ExpertConfig};
use integration_tests::{
    assert_same_checkpoint, assert_served_done, checkpoint_file, learn_over_ipc, learned_columns,
    scratch, serve_killed_and_resumed, state_bits, unique_prefix, write_config, Proc,
};
use learner::arm::SimArm;

const T: usize = 12;
const N: usize = 3;
const SEED: u64 = 9;
const ITERATIONS: usize = 2;
/// BCO's small settings.
const BCO: &str = "[model]\nhidden = [8]\nsteps = 20\n[policy]\nhidden = [8]\nsteps = 20\n";

/// Demonstrations of the initial hold controller at the default goal (the run only has to be
/// reproducible, not good).
fn hold_demos(path: &Path) {
    let mut cfg = ExpertConfig::default();
    (cfg.task.horizon, cfg.demos) = (T, 2);
    let hold = init_hold(&cfg.task, 0.01);
    let arm = SimArm::new(cfg.sim.clone(), cfg.task.dt).unwrap();
    let mut d = record_demos(&cfg, &arm, &hold, 0.0).unwrap();
    d.cost_random = d.cost_expert + 1.0;
    learner::io::demos::save(&d, path).unwrap();
}

/// The files of a served run of `algo` with `settings` (its config, small and fast) and
/// `iterations` in `dir`: the demonstrations, the settings for `learner train` and, with a
/// `[serve]` table (plus `serve_extra`), for `learner serve`, and the arm's and the
/// controller's configs. Starts `learner train --algo ALGO` (output `dir/reference`) and
/// returns it with the paths (serve, sim, controller).
fn served_run_files(
    dir: &Path,
    algo: &str,
    settings: &str,
    iterations: usize,
    serve_extra: &str,
) -> (Proc, [String; 3]) {
    let demos = dir.join("demos.npz");
    hold_demos(&demos);
    let demos_arg = demos.display().to_string();
    let settings = format!("samples = {N}\nseed = {SEED}\niterations = {iterations}\n{settings}");
    let train_cfg = write_config(dir, "train.toml", &settings);
    // The same settings plus a [serve] table.
    let serve_cfg = write_config(
        dir,
        "serve.toml",
        &format!(
            "{settings}\n[serve]\nalgo = \"{algo}\"\ndemos = \"{demos_arg}\"\n\
             wait_report_s = 1.0\nidle_sleep_us = 200\n{serve_extra}"
        ),
    );
    let train = Proc::spawn(
        "learner",
        "train",
        &[
            "train",
            "--algo",
            algo,
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
    // One cycle per version: the lockstep controller waits for the learner's next table
    // instead of running on, so a learner slowed by a loaded machine loses no sample.
    let ctl_cfg = write_config(
        dir,
        "controller.toml",
        &format!(
            "seed = {SEED}\nnoisy_episodes = {N}\neval_episodes = 1\ncycles_per_table = 1\n\
             [task]\nhorizon = {T}\n"
        ),
    );
    (train, [serve_cfg, sim_cfg, ctl_cfg])
}

/// The served run in `out` has the checkpoints and log rows of `learner train` (`train`, into
/// `dir/reference`): every learner state bit for bit (the in-process arm's noise position
/// aside), the files `iter_NNN_{same_file}` byte for byte (TD3's `critic.json` through
/// [`assert_same_checkpoint`]), the rows' learned columns; and the run learned.
fn assert_train_equal(mut train: Proc, dir: &Path, out: &Path, same_file: &str, iterations: usize) {
    let (code, _) = train.wait(Duration::from_secs(300));
    assert_eq!(code, Some(0), "learner train:\n{}", train.log());
    let ref_out = dir.join("reference");
    for i in 0..=iterations {
        if same_file == "critic.json" {
            assert_same_checkpoint(out, &ref_out, i, &["arm.noise_position"]);
        } else {
            let bits = |d: &Path| {
                let mut b = state_bits(&checkpoint_file(d, i, "state.npz"));
                b.retain(|(name, _)| name != "arm.noise_position");
                b
            };
            assert_eq!(bits(out), bits(&ref_out), "learner state of iteration {i}");
        }
        let f = |d: &Path| std::fs::read(checkpoint_file(d, i, same_file)).unwrap();
        assert_eq!(f(out), f(&ref_out), "iter_{i:03}_{same_file}");
    }
    // The run learned: its last state is not its first.
    let state = |i| state_bits(&checkpoint_file(out, i, "state.npz"));
    assert_ne!(state(0), state(iterations));
    let rows = |d: &Path| -> Vec<Vec<String>> {
        std::fs::read_to_string(d.join("gaifo_log.csv"))
            .unwrap()
            .lines()
            .map(learned_columns)
            .collect()
    };
    let served = rows(out);
    assert_eq!(served.len(), iterations + 1, "{served:?}");
    assert_eq!(served, rows(&ref_out));
}

/// Serves `algo` with `settings` against `hil-sim serve` and `rt-controller run`, runs
/// `learner train --algo ALGO` beside it, and compares.
fn served_equals_train(algo: &str, settings: &str, same_file: &str) {
    let dir = scratch(&format!("{algo}-ipc"));
    let prefix = unique_prefix(&format!("{algo}-ipc"));
    let (train, [serve_cfg, sim_cfg, ctl_cfg]) =
        served_run_files(&dir, algo, settings, ITERATIONS, "");
    let sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", &sim_cfg, "--prefix", &prefix],
        &dir,
    );
    let wait = Duration::from_secs(300);
    let (lj, cj) = learn_over_ipc(&dir, &prefix, &serve_cfg, &ctl_cfg, algo, wait, |_, _| {});
    assert_served_done(&lj, algo, ITERATIONS);
    assert_eq!(lj["counts"]["used"], (ITERATIONS * (N + 1)) as u64, "{lj}");
    // One publication per version, the last version's included.
    assert_eq!(cj["swaps"], (ITERATIONS + 1) as u64, "{cj}");
    let out = dir.join(format!("out-{algo}"));
    assert_train_equal(train, &dir, &out, same_file, ITERATIONS);
    // Each version recorded as the table it published (a policy table for bco, gaifo-td3).
    for v in 1..=ITERATIONS as u64 + 1 {
        let f = learner::io::table::version_path(&out, v);
        assert_eq!(learner::io::table::stored_epoch(&f).unwrap(), 0, "{f:?}");
    }
    drop(sim);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn served_bco_checkpoints_equal_learner_train_bit_for_bit() {
    served_equals_train("bco", BCO, "policy.npz");
}

#[test]
fn served_td3_checkpoints_equal_learner_train_bit_for_bit() {
    served_equals_train(
        "gaifo-td3",
        "updates_per_episode = 5\n[discriminator]\nn_critic = 5\n\
         [td3]\npi_hidden = [8]\nq_hidden = [8]\nbatch_size = 16\n",
        "critic.json",
    );
}

/// The mean path over IPC: its gain table (K = 0) each version, the same evaluations and files
/// as in process.
#[test]
fn served_mean_path_equals_learner_train() {
    served_equals_train("replay-mean", "", "table.npz");
}

/// Exact resume over IPC of a learner that publishes policy tables, as `resume_ipc.rs` for
/// LQR+GAIfO: the served BCO learner killed with SIGKILL at seeded moments and resumed each
/// time (its version's policy table published again above every earlier publication, read
/// from the recorded policy table) ends with `learner train`'s checkpoints and rows.
#[test]
fn a_served_bco_learner_killed_and_resumed_equals_learner_train() {
    const ITERATIONS: usize = 12;
    let dir = scratch("bco-resume");
    let prefix = unique_prefix("bco-resume");
    let (train, [serve_cfg, sim_cfg, ctl_cfg]) =
        served_run_files(&dir, "bco", BCO, ITERATIONS, "record_episodes = false\n");
    let out = dir.join("out");
    let sim = serve_killed_and_resumed(&dir, &prefix, [&serve_cfg, &sim_cfg, &ctl_cfg], &out, 17);
    assert_train_equal(train, &dir, &out, "policy.npz", ITERATIONS);
    drop(sim);
    std::fs::remove_dir_all(&dir).ok();
}
