//! Exact resume over IPC: `learner serve --algo lqr-gaifo` against `hil-sim serve`
//! and `rt-controller run` (lockstep), the learner killed with SIGKILL at seeded random moments
//! and resumed with `--resume` each time (restarted with `--force` when the kill came before
//! its first checkpoint), while the controller and the arm run on. The finished run's tables,
//! learner states, critic checkpoints and CSV rows (timing columns aside) must equal the
//! in-process run with the same seed bit for bit, which `learning.rs` shows an uninterrupted
//! served run does. What makes it exact: the resumed learner publishes its version again with
//! a higher epoch, the controller restarts that version's episode count (the noise keys), and
//! the learner uses only episodes of the new publication (docs/design.md §3.6, "Exact resume").

use std::path::Path;
use std::time::Duration;

use integration_tests::{
    assert_same_checkpoint, checkpoint_file as file, cleanup_dead_nodes, json_summary,
    learned_columns, lqr_gaifo_in_process, scratch, serve_with_kills, spawn_sim_and_controller,
    unique_prefix, write_config, write_served_gaifo_config, Killed,
};
use learner::io::log::{write_csv_row, CSV_HEADER};
use learner::io::table::load_table;
use learner::serve::load_gaifo_config;
use ur5_shared::GainBounds;

const T: usize = 30;
const N: usize = 5;
const SEED: u64 = 11;
const ITERATIONS: usize = 10;
/// Kills before the run may finish.
const KILLS: usize = 6;
const LONG: Duration = Duration::from_secs(120);

#[test]
fn a_served_learner_killed_at_random_moments_resumes_bit_for_bit() {
    let prefix = unique_prefix("resume-ipc");
    let dir = scratch("resume-ipc");
    let (out, ref_out) = (dir.join("out"), dir.join("reference"));
    let ecfg = imitation::expert::ExpertConfig {
        task: ur5_shared::config::TaskConfig {
            horizon: T,
            ..Default::default()
        },
        samples: N,
        iterations: 4,
        random_episodes: 1,
        demos: 3,
        seed: SEED,
        ..Default::default()
    };
    let expert = learner::run::expert(&ecfg, |_| {}).unwrap();
    let demos = learner::run::demos(&ecfg, &expert).unwrap();
    let demos_path = dir.join("demos.npz");
    learner::io::demos::save(&demos, &demos_path).unwrap();
    let learner_cfg = write_served_gaifo_config(&dir, N, SEED, ITERATIONS);
    let sim_cfg = write_config(&dir, "sim.toml", &format!("[task]\nhorizon = {T}\n"));
    let ctl_cfg = write_config(
        &dir,
        "controller.toml",
        &format!("seed = {SEED}\nnoisy_episodes = {N}\neval_episodes = 1\n[task]\nhorizon = {T}\n"),
    );
    let (cfg, _) = load_gaifo_config(Path::new(&learner_cfg)).unwrap();
    let reference = {
        let ref_out = ref_out.clone();
        std::thread::spawn(move || lqr_gaifo_in_process(cfg, demos, ITERATIONS, &ref_out))
    };

    let (mut sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);
    let demos_arg = demos_path.display().to_string();
    let base = [
        "serve",
        "--config",
        &learner_cfg,
        "--prefix",
        &prefix,
        "--demos",
        &demos_arg,
        "--json",
    ];
    // The first KILLS runs are killed 50 to 800 ms after their start (a served iteration
    // takes about 0.2 s here, the whole run a few seconds); the next one finishes.
    let Killed {
        summary,
        kills,
        resumes,
        restarts,
    } = serve_with_kills(
        &dir,
        &base,
        &out,
        [&mut sim, &mut ctl],
        KILLS,
        23,
        (50, 750),
        LONG,
    );
    eprintln!("{kills} kills: {resumes} resumes, {restarts} restarts; then finished");
    assert!(resumes >= 1, "no kill landed after the first checkpoint");
    assert_eq!(summary["exit_reason"], "done", "{summary}");

    ctl.signal(libc::SIGTERM);
    let (code, cout) = ctl.wait(LONG);
    let clog = ctl.log();
    assert_eq!(code, Some(0), "controller log:\n{clog}");
    let cj = json_summary(&cout, &clog);
    assert_eq!(cj["rejected_total"], 0, "{cj}");
    sim.signal(libc::SIGTERM);
    sim.wait(LONG);

    let (tables, logs) = reference.join().unwrap();
    for (i, table) in tables.iter().enumerate() {
        let (got, _) = load_table(&file(&out, i, "table.npz"), &GainBounds::default()).unwrap();
        assert_eq!(got.checksum, table.checksum, "table of iteration {i}");
        assert_same_checkpoint(&out, &ref_out, i, &[]);
    }
    let csv = std::fs::read_to_string(out.join("gaifo_log.csv")).unwrap();
    let mut rows = csv.lines();
    assert_eq!(rows.next(), Some(CSV_HEADER));
    let rows: Vec<&str> = rows.collect();
    assert_eq!(rows.len(), ITERATIONS, "{csv}");
    for (i, (log, _)) in logs.iter().enumerate() {
        let mut want = Vec::new();
        write_csv_row(&mut want, log, SEED, "lqr-gaifo").unwrap();
        assert_eq!(
            learned_columns(rows[i]),
            learned_columns(std::str::from_utf8(&want).unwrap()),
            "iteration {i}: resumed IPC row vs in-process row"
        );
    }
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}
