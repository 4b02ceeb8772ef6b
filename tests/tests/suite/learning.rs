//! Learning over IPC: `hil-sim serve`, `rt-controller run` and `learner serve`, all three from
//! the built binaries, lockstep, on a fresh prefix per test. The outcome must equal the
//! in-process loop with the same seed bit for bit, for the expert (`imitation::expert`) and for
//! LQR+GAIfO (`imitation::gaifo::LqrGaifo`); a killed learner must leave the controller on its
//! table, and a restarted one (`--resume`) must continue. Assertions are on behaviour only,
//! never on latency.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use imitation::controller::to_gain_table;
use imitation::expert::{ExpertConfig, ExpertLearner, IterationLog};
use imitation::gaifo::GaifoLog;
use imitation::rollout::{execute, Episode};
use integration_tests::{
    assert_served_done, cleanup_dead_nodes, json_summary, learned_columns, lqr_gaifo_in_process,
    scratch, spawn_sim_and_controller, unique_prefix, write_config, write_served_gaifo_config,
    Proc,
};
use learner::arm::SimArm;
use learner::io::episode::load_episode;
use learner::io::log::{write_csv_row, LogRow, CSV_HEADER};
use learner::io::table::load_table;
use learner::run::{demos as record_demos, expert as train};
use learner::serve::{episode_from_samples, load_config, load_gaifo_config};
use ur5_shared::config::TaskConfig;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{GainBounds, GainTable, StepSample};

/// Episode length (steps of the default 0.1 s), noisy episodes per version, run seed.
const T: usize = 30;
const N: usize = 5;
const SEED: u64 = 7;
const LONG: Duration = Duration::from_secs(60);

/// The learner's config file (an `ExpertConfig` plus `[serve]`) for `iterations` iterations.
fn learner_toml(iterations: usize) -> String {
    format!(
        "samples = {N}\nseed = {SEED}\niterations = {iterations}\nrandom_episodes = 1\n\
         [task]\nhorizon = {T}\n[serve]\nwait_report_s = 1.0\nidle_sleep_us = 200\n"
    )
}

/// Writes the three config files; returns (learner, sim, controller) paths.
fn configs(dir: &Path, iterations: usize) -> (String, String, String) {
    (
        write_config(dir, "learner.toml", &learner_toml(iterations)),
        write_config(dir, "sim.toml", &format!("[task]\nhorizon = {T}\n")),
        write_config(
            dir,
            "controller.toml",
            &format!(
                "seed = {SEED}\nnoisy_episodes = {N}\neval_episodes = 1\n[task]\nhorizon = {T}\n"
            ),
        ),
    )
}

fn spawn_learner(
    cfg: &str,
    prefix: &str,
    out: &Path,
    extra: &[&str],
    dir: &Path,
    label: &str,
) -> Proc {
    let out = out.display().to_string();
    let mut args = vec![
        "serve", "--config", cfg, "--prefix", prefix, "--out", &out, "--json",
    ];
    args.extend_from_slice(extra);
    Proc::spawn("learner", label, &args, dir)
}

/// A passive second subscriber on `learner/samples`: sees exactly what the learner sees.
struct SampleMonitor {
    sub: Subscriber<ipc::Service, StepSample, ()>,
    received: Vec<StepSample>,
    _node: Node<ipc::Service>,
}

impl SampleMonitor {
    fn new(prefix: &str) -> Self {
        set_log_level_from_env_or(LogLevel::Error);
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .unwrap();
        let svc = services::LEARNER_SAMPLES_QOS
            .open_or_create_retrying::<StepSample>(
                &node,
                &ServiceNames::new(prefix).learner_samples,
            )
            .unwrap();
        let sub = svc
            .subscriber_builder()
            .buffer_size(services::LEARNER_SAMPLES_QOS.subscriber_buffer)
            .create()
            .unwrap();
        Self {
            sub,
            received: Vec::new(),
            _node: node,
        }
    }

    fn poll(&mut self) {
        while let Some(s) = self.sub.receive().unwrap() {
            self.received.push(*s);
        }
    }

    /// Complete episodes of `version` in arrival order.
    fn episodes(&self, version: u64) -> Vec<Episode> {
        let mut out = Vec::new();
        let mut cur: Vec<StepSample> = Vec::new();
        for s in self.received.iter().filter(|s| s.table_version == version) {
            if s.t == 0 {
                cur.clear();
            }
            cur.push(*s);
            if cur.len() == T {
                out.push(episode_from_samples(&cur));
                cur.clear();
            }
        }
        out
    }
}

/// Every episode complete (t = 0 … T−1 in order, nothing lost), one table version per episode,
/// versions never decreasing and each new version first used at t = 0; the last episode may be
/// cut by SIGTERM.
fn check_stream(samples: &[StepSample]) {
    assert!(!samples.is_empty());
    assert_eq!((samples[0].episode, samples[0].t), (0, 0));
    for w in samples.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let next = (b.episode == a.episode && b.t == a.t + 1)
            || (b.episode == a.episode + 1 && b.t == 0 && a.t as usize == T - 1);
        assert!(
            next,
            "lost or out of order: {:?} then {:?}",
            (a.episode, a.t),
            (b.episode, b.t)
        );
        if b.episode == a.episode {
            assert_eq!(
                (b.table_version, b.noise),
                (a.table_version, a.noise),
                "version or noise flag changed inside episode {}",
                a.episode
            );
        } else {
            assert!(b.table_version >= a.table_version, "version went back");
        }
    }
}

/// The in-process loop: `execute` on an in-process arm, then `ExpertLearner::update`. Returns
/// the table of each version 1 … iterations + 1 and, per iteration, its episodes and log.
#[allow(clippy::type_complexity)]
fn in_process(
    cfg: &ExpertConfig,
) -> (
    Vec<Box<GainTable>>,
    Vec<(Vec<Episode>, Episode, IterationLog)>,
) {
    let sim = SimArm::new(cfg.sim.clone(), cfg.task.dt).unwrap();
    let mut el = ExpertLearner::new(cfg.clone(), None);
    let (mut tables, mut iterations) = (Vec::new(), Vec::new());
    while !el.done() {
        tables.push(to_gain_table(el.policy(), el.version()));
        let (noisy, eval) = execute(
            &sim,
            &cfg.task,
            &*to_gain_table(el.policy(), el.version()),
            el.version(),
            cfg.seed,
            cfg.samples,
        )
        .unwrap();
        let (log, _) = el.update(&noisy, &eval).unwrap();
        iterations.push((noisy, eval, log));
    }
    tables.push(to_gain_table(el.policy(), el.version()));
    (tables, iterations)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn same_episode(a: &Episode, b: &Episode) -> bool {
    a.noisy == b.noisy
        && bits(&a.x) == bits(&b.x)
        && bits(&a.u) == bits(&b.u)
        && bits(&a.u_policy) == bits(&b.u_policy)
}

/// Waits until `done()`, polling `monitor`; panics with the logs when a process exits or on
/// timeout.
fn wait_for(
    what: &str,
    procs: &mut [&mut Proc],
    monitor: &mut Option<&mut SampleMonitor>,
    mut done: impl FnMut() -> bool,
) {
    let t0 = Instant::now();
    loop {
        if let Some(m) = monitor.as_mut() {
            m.poll();
        }
        if done() {
            return;
        }
        for p in procs.iter_mut() {
            assert!(
                p.running(),
                "{} exited while waiting for {what}; its log:\n{}",
                p.name(),
                p.log()
            );
        }
        if t0.elapsed() > LONG {
            let logs: Vec<String> = procs
                .iter()
                .map(|p| format!("--- {}:\n{}", p.name(), p.log()))
                .collect();
            panic!("timed out waiting for {what}:\n{}", logs.join("\n"));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// `(episode, table version, done)` of each episode line in the controller's log.
fn controller_episodes(log: &str) -> Vec<(u64, u64, bool)> {
    log.lines()
        .filter_map(|l| {
            let rest = l.strip_prefix("rt-controller: episode ")?;
            let (ep, rest) = rest.split_once(' ')?;
            let done = rest.starts_with("done");
            let v = rest.split_once("(table v")?.1.split_once(',')?.0;
            Some((ep.parse().ok()?, v.parse().ok()?, done))
        })
        .collect()
}

/// Waits until the learner exits (learning done), polling `monitor`; then stops the
/// controller. Returns the learner's JSON summary and log and the controller's summary.
fn run_until_learned(
    learner: &mut Proc,
    sim: &mut Proc,
    ctl: &mut Proc,
    monitor: &mut SampleMonitor,
) -> (serde_json::Value, String, serde_json::Value) {
    let t0 = Instant::now();
    while learner.running() {
        monitor.poll();
        for p in [&mut *sim, &mut *ctl] {
            assert!(
                p.running(),
                "{} exited; log:\n{}\nlearner log:\n{}",
                p.name(),
                p.log(),
                learner.log()
            );
        }
        assert!(
            t0.elapsed() < LONG,
            "learner did not finish; its log:\n{}",
            learner.log()
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let (code, stdout) = learner.wait(LONG);
    let llog = learner.log();
    assert_eq!(code, Some(0), "learner log:\n{llog}");
    let lj = json_summary(&stdout, &llog);
    let (cj, _) = ctl.terminate_ok(LONG);
    monitor.poll();
    (lj, llog, cj)
}

#[test]
fn learning_over_ipc_equals_the_in_process_loop_bit_for_bit() {
    const ITERATIONS: usize = 3;
    let prefix = unique_prefix("learn-a");
    let dir = scratch("learn-a");
    let out = dir.join("out");
    let (learner_cfg, sim_cfg, ctl_cfg) = configs(&dir, ITERATIONS);
    let (cfg, _) = load_config(Path::new(&learner_cfg)).unwrap();
    // The reference runs in another thread while this one watches the processes.
    let reference = {
        let cfg = cfg.clone();
        std::thread::spawn(move || {
            let (tables, iterations) = in_process(&cfg);
            let trained = train(&cfg, |_| {}).unwrap();
            (tables, iterations, trained.log)
        })
    };

    let mut monitor = SampleMonitor::new(&prefix);
    let mut learner = spawn_learner(&learner_cfg, &prefix, &out, &[], &dir, "learner");
    let (mut sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);
    let (lj, llog, cj) = run_until_learned(&mut learner, &mut sim, &mut ctl, &mut monitor);

    // The learner: ITERATIONS updates, the last table taken, nothing discarded.
    assert_eq!(lj["exit_reason"], "done", "{lj}");
    assert_eq!(lj["iterations"], ITERATIONS as u64, "{lj}");
    assert_eq!(lj["table_version"], ITERATIONS as u64 + 1, "{lj}");
    assert_eq!(lj["counts"]["partial"], 0, "{lj}");
    assert_eq!(lj["counts"]["mixed"], 0, "{lj}");
    assert_eq!(lj["counts"]["used"], (ITERATIONS * (N + 1)) as u64, "{lj}");
    assert!(
        llog.contains(IterationLog::PROGRESS_HEADER),
        "progress lines: {llog}"
    );
    // The controller: every version taken once, at a boundary; no episode aborted.
    assert_eq!(cj["swaps"], ITERATIONS as u64 + 1, "{cj}");
    assert_eq!(cj["table_version"], ITERATIONS as u64 + 1, "{cj}");
    assert_eq!(cj["rejected_total"], 0, "{cj}");
    assert_eq!(cj["episodes_aborted"], 0, "{cj}");

    // The sample stream: nothing lost, versions change only between episodes.
    let samples = &monitor.received;
    check_stream(samples);
    assert_eq!(
        samples.len() as u64,
        cj["ticks"].as_u64().unwrap(),
        "every sample arrived"
    );
    // The learner recorded every complete episode it received, as it arrived.
    let mut files: Vec<PathBuf> = std::fs::read_dir(out.join("episodes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "npz"))
        .collect();
    files.sort();
    assert_eq!(
        files.len() as u64,
        lj["counts"]["episodes"].as_u64().unwrap()
    );

    let (tables, iterations, trained) = reference.join().unwrap();
    assert_eq!(iterations.len(), ITERATIONS);
    for (i, (noisy, eval, log)) in iterations.iter().enumerate() {
        let v = i as u64 + 1;
        // The first N + 1 episodes of version v over IPC are the in-process ones, bit for bit:
        // k = 0 … N−1 with noise, k = N without.
        let ipc = monitor.episodes(v);
        assert!(ipc.len() > N, "version {v}: {} episodes", ipc.len());
        for (k, e) in noisy.iter().chain([eval]).enumerate() {
            assert!(
                same_episode(e, &ipc[k]),
                "version {v}, episode k = {k} differs from the in-process one"
            );
        }
        // What the learner recorded is what it received.
        let first = files
            .iter()
            .find(|f| {
                f.file_name()
                    .unwrap()
                    .to_str()
                    .unwrap()
                    .ends_with(&format!("_v{v:04}.npz"))
            })
            .unwrap();
        let (rec, origin) = load_episode(first).unwrap();
        assert_eq!(origin.table_version, v);
        assert!(
            same_episode(&rec, &noisy[0]),
            "recorded episode {}",
            first.display()
        );
        // The learning outcome: the noise-free task cost per iteration …
        let ipc_cost = lj["eval_costs"][i].as_f64().unwrap();
        assert_eq!(
            ipc_cost.to_bits(),
            log.eval_cost.to_bits(),
            "iteration {i}: {ipc_cost} vs {}",
            log.eval_cost
        );
        // … equals `expert::train`'s too (the same code in process, after its random baseline).
        assert_eq!(
            trained[i].eval_cost.to_bits(),
            log.eval_cost.to_bits(),
            "train, iteration {i}"
        );
    }
    // … and every table the learner published.
    for (i, table) in tables.iter().enumerate() {
        let v = i as u64 + 1;
        let (got, _) = load_table(
            &learner::io::table::version_path(&out, v),
            &GainBounds::default(),
        )
        .unwrap();
        assert_eq!(got.version, v);
        assert_eq!(got.checksum, table.checksum, "table version {v}");
        assert!(
            got.used_values() == table.used_values(),
            "table version {v}"
        );
    }
    assert!(
        tables[ITERATIONS].used_values() != tables[0].used_values(),
        "the controller changed"
    );
    assert!(sim.running());
    assert_replays_equal(&out, &dir, ITERATIONS, 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// `learner replay OUT --json` on a served run: its learning redone from the recorded episodes
/// (the same `Learn::learn`) gives every published table (and, for LQR+GAIfO, every critic
/// checkpoint) bit for bit.
fn assert_replays_equal(
    out: &Path,
    dir: &Path,
    iterations: usize,
    critics: usize,
) -> serde_json::Value {
    let o = out.display().to_string();
    let mut p = Proc::spawn("learner", "replay", &["replay", &o, "--json"], dir);
    let (code, stdout) = p.wait(LONG);
    let log = p.log();
    assert_eq!(code, Some(0), "replay log:\n{log}");
    let r = json_summary(&stdout, &log);
    assert!(r["difference"].is_null(), "{r}");
    // Every file the run's record lists was there, unaltered.
    assert!(
        r["files_verified"].as_u64().unwrap() > iterations as u64,
        "{r}"
    );
    assert_eq!(r["iterations"], iterations as u64, "{r}");
    assert!(
        r["tables_checked"].as_u64().unwrap() > iterations as u64,
        "{r}"
    );
    assert_eq!(r["critics_checked"], critics as u64, "{r}");
    r
}

/// `learner replay OUT --json`: (exit code, report).
fn replay_report(out: &Path, dir: &Path, label: &str) -> (Option<i32>, serde_json::Value) {
    let o = out.display().to_string();
    let mut p = Proc::spawn("learner", label, &["replay", &o, "--json"], dir);
    let (code, stdout) = p.wait(LONG);
    let log = p.log();
    (code, json_summary(&stdout, &log))
}

/// `learner serve --algo lqr-gaifo`: ITERATIONS iterations of LQR+GAIfO over IPC, on
/// demonstrations of a short expert of the same task, equal `LqrGaifo::iterate` in process with
/// the same seed bit for bit: every noise-free episode, every table published, the logged
/// task cost, critic loss, Wasserstein estimate, KL, η of each iteration, and the critic
/// checkpoints byte for byte.
#[test]
fn lqr_gaifo_over_ipc_equals_the_in_process_run_bit_for_bit() {
    lqr_gaifo_over_ipc_equals_in_process("learn-g", TaskConfig::default());
}

/// The same with the whole arm and a pose goal: six joints commanded, three tool points in the
/// state (dX = 30, dU = 6), the arm's states and the controller's samples at that layout.
#[test]
fn lqr_gaifo_at_six_joints_and_a_pose_over_ipc_equals_the_in_process_run() {
    use ur5_shared::kinematics::UrKinematics;
    use ur5_shared::model::UrModel;
    let kin = UrKinematics::new(UrModel::Ur5, UrModel::Ur5.default_ee_offset());
    let goal = ur5_shared::pose::ur_pose(&kin.tool_pose(&[0.2, -1.8, 2.0, -1.7, -1.5, 0.3]));
    lqr_gaifo_over_ipc_equals_in_process("learn-p", TaskConfig::pose_for_model(UrModel::Ur5, goal));
}

/// LQR+GAIfO served over IPC on `task` (its horizon set to T) against the in-process run: the
/// noise-free episodes, the learned numbers, the tables and the critic checkpoints bit for bit.
fn lqr_gaifo_over_ipc_equals_in_process(tag: &str, task: TaskConfig) {
    const ITERATIONS: usize = 3;
    let task = TaskConfig { horizon: T, ..task };
    let reach = task.layout() == ur5_shared::StateLayout::REACH3;
    let prefix = unique_prefix(tag);
    let dir = scratch(tag);
    let (out, ref_out) = (dir.join("out"), dir.join("reference"));
    // Demonstrations of the task the arm and the controller run.
    let ecfg = ExpertConfig {
        task: task.clone(),
        samples: N,
        iterations: 4,
        random_episodes: 1,
        demos: 3,
        seed: SEED,
        ..ExpertConfig::default()
    };
    let expert = train(&ecfg, |_| {}).unwrap();
    let demos = record_demos(&ecfg, &expert).unwrap();
    let demos_path = dir.join("demos.npz");
    learner::io::demos::save(&demos, &demos_path).unwrap();
    let learner_cfg = write_served_gaifo_config(&dir, N, SEED, ITERATIONS);
    let (_, mut sim_cfg, mut ctl_cfg) = configs(&dir, ITERATIONS);
    if !reach {
        // The arm and the controller run the pose task too.
        let t = toml::to_string(&task).unwrap();
        sim_cfg = write_config(&dir, "sim.toml", &format!("[task]\n{t}"));
        ctl_cfg = write_config(
            &dir,
            "controller.toml",
            &format!("seed = {SEED}\nnoisy_episodes = {N}\neval_episodes = 1\n[task]\n{t}"),
        );
    }
    let (cfg, _) = load_gaifo_config(Path::new(&learner_cfg)).unwrap();
    let reference = {
        let (cfg, demos, ref_out) = (cfg.clone(), demos.clone(), ref_out.clone());
        std::thread::spawn(move || lqr_gaifo_in_process(cfg, demos, ITERATIONS, &ref_out))
    };

    let mut monitor = SampleMonitor::new(&prefix);
    let demos_arg = demos_path.display().to_string();
    let args: &[&str] = &["--demos", &demos_arg, "--mcap"];
    let mut learner = spawn_learner(&learner_cfg, &prefix, &out, args, &dir, "learner");
    let (mut sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);
    let (lj, llog, cj) = run_until_learned(&mut learner, &mut sim, &mut ctl, &mut monitor);

    assert_served_done(&lj, "lqr-gaifo", ITERATIONS);
    assert_eq!(lj["counts"]["used"], (ITERATIONS * (N + 1)) as u64, "{lj}");
    assert!(llog.contains(GaifoLog::PROGRESS_HEADER), "{llog}");
    assert_eq!(cj["swaps"], ITERATIONS as u64 + 1, "{cj}");
    assert_eq!(cj["rejected_total"], 0, "{cj}");
    assert_eq!(cj["episodes_aborted"], 0, "{cj}");
    check_stream(&monitor.received);

    let (tables, iterations) = reference.join().unwrap();
    let csv = std::fs::read_to_string(out.join("gaifo_log.csv")).unwrap();
    let mut rows = csv.lines();
    // A pose task's log adds its orientation column; a point task's is as it was.
    let header = GaifoLog::header(&task.layout());
    assert_eq!(reach, header == CSV_HEADER);
    assert_eq!(rows.next(), Some(header.as_str()));
    let rows: Vec<&str> = rows.collect();
    assert_eq!(rows.len(), ITERATIONS, "{csv}");
    for (i, (log, eval)) in iterations.iter().enumerate() {
        let v = i as u64 + 1;
        // The noise-free episode of version v over IPC is the in-process one.
        let ipc = monitor.episodes(v);
        assert!(ipc.len() > N, "version {v}: {} episodes", ipc.len());
        assert!(
            same_episode(eval, &ipc[N]),
            "version {v}: noise-free episode"
        );
        // The learned numbers, as the CSV writes them (f64 Display round-trips exactly).
        let mut want = Vec::new();
        log.write_row(&mut want, SEED, "lqr-gaifo", &task.layout())
            .unwrap();
        if reach {
            let mut old = Vec::new();
            write_csv_row(&mut old, log, SEED, "lqr-gaifo").unwrap();
            assert_eq!(old, want, "a point task's row as before");
        }
        assert_eq!(
            learned_columns(rows[i]),
            learned_columns(std::str::from_utf8(&want).unwrap()),
            "iteration {i}: IPC row vs in-process row"
        );
        assert!(log.kl > 0.0, "iteration {i} took a step");
    }
    for (i, table) in tables.iter().enumerate() {
        let v = i as u64 + 1;
        let (got, _) = load_table(
            &learner::io::table::version_path(&out, v),
            &GainBounds::default(),
        )
        .unwrap();
        assert_eq!(got.version, v);
        assert_eq!(got.checksum, table.checksum, "table version {v}");
        assert!(
            got.used_values() == table.used_values(),
            "table version {v}"
        );
        // The critic checkpoints: same bytes (weights, normalisation, Adam, RNG position).
        let name = format!("iter_{i:03}_critic.json");
        assert_eq!(
            std::fs::read(out.join(&name)).unwrap(),
            std::fs::read(ref_out.join(&name)).unwrap(),
            "{name}"
        );
    }
    assert!(tables[ITERATIONS].used_values() != tables[0].used_values());
    assert!(sim.running());
    if reach {
        assert_replays_equal(&out, &dir, ITERATIONS, ITERATIONS + 1);
        // --mcap: the run as one MCAP file (its reading back: learner/tests/suite/replay.rs).
        let mcap = std::fs::read(out.join("run.mcap")).unwrap();
        assert!(mcap.starts_with(b"\x89MCAP0\r\n") && mcap.ends_with(b"\x89MCAP0\r\n"));
    } else {
        // The pose run's MCAP file, complete, sized by its layout.
        let mcap = std::fs::read(out.join("run.mcap")).unwrap();
        assert!(mcap.starts_with(b"\x89MCAP0\r\n") && mcap.ends_with(b"\x89MCAP0\r\n"));
        let ipc = monitor.episodes(1);
        assert_eq!(
            ipc[0].layout,
            task.layout(),
            "the samples carry the pose layout"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_killed_learner_leaves_the_controller_on_its_table_and_a_resumed_one_continues() {
    let prefix = unique_prefix("learn-b");
    let dir = scratch("learn-b");
    let out = dir.join("out");
    let (learner_cfg, sim_cfg, ctl_cfg) = configs(&dir, 50);
    let mut learner = spawn_learner(&learner_cfg, &prefix, &out, &["--mcap"], &dir, "learner1");
    let (mut sim, mut ctl) = spawn_sim_and_controller(&sim_cfg, &ctl_cfg, &prefix, &dir);

    // Two updates, and the controller runs version 3.
    wait_for(
        "version 3 in use",
        &mut [&mut learner, &mut sim, &mut ctl],
        &mut None,
        || {
            controller_episodes(&ctl_log(&dir))
                .iter()
                .any(|&(_, v, _)| v == 3)
        },
    );
    learner.signal(libc::SIGKILL);
    let _ = learner.wait(LONG);
    let killed_at = controller_episodes(&ctl_log(&dir)).len();
    // run.mcap, streamed episode by episode, without its summary: a streaming reader reads
    // every recorded episode whole (the last one may have been recorded, not yet written).
    let recorded = npz_count(&out.join("episodes"));
    let (count, _) = mcap_topics(&std::fs::read(out.join("run.mcap")).unwrap(), true);
    let in_mcap = count.get("/episode").copied().unwrap_or(0);
    assert!(
        in_mcap + 1 >= recorded && in_mcap <= recorded && in_mcap > 0,
        "{in_mcap} episodes in run.mcap, {recorded} recorded: {count:?}"
    );
    assert_eq!(count["/state"], in_mcap * T, "{count:?}");
    // The controller finishes its episodes and keeps its table.
    wait_for(
        "5 episodes after the kill",
        &mut [&mut sim, &mut ctl],
        &mut None,
        || controller_episodes(&ctl_log(&dir)).len() >= killed_at + 5,
    );
    let after = controller_episodes(&ctl_log(&dir));
    let kept = after[killed_at].1;
    assert!(kept >= 3);
    for &(e, v, done) in &after[killed_at..] {
        assert!(done, "episode {e} aborted after the learner died");
        assert_eq!(v, kept, "episode {e} ran table v{v}: nobody published it");
    }

    // Restart from the checkpoint: the same version is published again with epoch 1 (the
    // controller takes it again and restarts its noise keys), then learning goes on.
    let mut resumed = spawn_learner(
        &learner_cfg,
        &prefix,
        &out,
        &["--resume", &out.display().to_string(), "--mcap"],
        &dir,
        "learner2",
    );
    wait_for(
        "two more versions",
        &mut [&mut resumed, &mut sim, &mut ctl],
        &mut None,
        || {
            controller_episodes(&ctl_log(&dir))
                .iter()
                .any(|&(_, v, _)| v >= kept + 2)
        },
    );
    resumed.signal(libc::SIGTERM);
    let (code, stdout) = resumed.wait(LONG);
    let rlog = resumed.log();
    assert_eq!(code, Some(0), "resumed learner log:\n{rlog}");
    let rj = json_summary(&stdout, &rlog);
    assert_eq!(rj["exit_reason"], "stopped", "{rj}");
    assert!(rj["start_version"].as_u64().unwrap() >= kept, "{rj}");
    assert!(rj["iterations"].as_u64().unwrap() >= 1, "{rj}");
    assert!(rlog.contains("(resumed; publication 1 of it)"), "{rlog}");

    ctl.signal(libc::SIGTERM);
    let (code, cout) = ctl.wait(LONG);
    let clog = ctl.log();
    assert_eq!(code, Some(0), "controller log:\n{clog}");
    let cj = json_summary(&cout, &clog);
    assert_eq!(cj["episodes_aborted"], 0, "{cj}");
    assert_eq!(
        cj["rejected_total"], 0,
        "the resumed learner's first table is the current one: {cj}"
    );
    assert!(cj["table_version"].as_u64().unwrap() >= kept + 2, "{cj}");
    assert!(cj["lost_peers"]["learner"].as_u64().unwrap() >= 1, "{cj}");
    // Versions advanced one at a time, each taken once.
    let versions: Vec<u64> = controller_episodes(&clog).iter().map(|e| e.1).collect();
    for w in versions.windows(2) {
        assert!(
            w[1] == w[0] || w[1] == w[0] + 1,
            "versions {} then {}",
            w[0],
            w[1]
        );
    }
    assert!(sim.running());
    // The resumed learner wrote run.mcap again from the recorded episodes, went on, and
    // finished it at exit: complete (summary, end magic), every recorded episode in it.
    let (count, cut) = mcap_topics(&std::fs::read(out.join("run.mcap")).unwrap(), false);
    assert!(!cut, "{count:?}");
    assert_eq!(
        count["/episode"],
        npz_count(&out.join("episodes")),
        "{count:?}"
    );
    assert_resumed_run_replays(&out, &dir, rj["table_version"].as_u64().unwrap());
    cleanup_dead_nodes();
    std::fs::remove_dir_all(&dir).ok();
}

/// A served run that was killed and resumed replays bit for bit: the replay learns
/// from the episodes each update learned from (`episodes/learned.jsonl`) and redoes the resume
/// as `--resume` did; a changed episode learned from after the resume is the first
/// difference, at that update; without the list, the replay takes the first episodes of each
/// version, which after the resume are not the ones learned from, and says why it differs.
fn assert_resumed_run_replays(out: &Path, dir: &Path, last_version: u64) {
    use learner::io::episode::{load_episode, load_episode_task, save_episode};
    use learner::io::learned::{read_events, LearnedEvent, LEARNED};
    let r = assert_replays_equal(out, dir, last_version as usize - 1, 0);
    assert_eq!(r["resumes"], 1, "{r}");
    // The edits below are the replay's to find by comparison, not by the run's record of
    // its files (learner/tests/suite/replay.rs): the run made as a build without the record.
    std::fs::remove_file(out.join(learner::io::files::FILES)).unwrap();
    let manifest = out.join("run.json");
    let mut m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    m.as_object_mut().unwrap().remove("files");
    std::fs::write(&manifest, serde_json::to_vec(&m).unwrap()).unwrap();
    assert_eq!(r["selection"], "learned.jsonl", "{r}");
    let episodes = out.join("episodes");
    let events = read_events(&episodes).unwrap().unwrap();
    let resumed = events
        .iter()
        .position(|e| {
            matches!(
                e,
                LearnedEvent::Resumed {
                    same_folder: true,
                    ..
                }
            )
        })
        .expect("a resume event");
    let (iteration, version, noisy, eval) = events[resumed..]
        .iter()
        .find_map(|e| match e {
            LearnedEvent::Learned {
                iteration,
                version,
                noisy,
                eval,
                ..
            } => Some((*iteration, *version, noisy.clone(), eval.clone())),
            LearnedEvent::Resumed { .. } => None,
        })
        .expect("an update after the resume");

    // Were the episodes learned after the resume the first of their version to arrive?
    let mut of_version: Vec<String> = std::fs::read_dir(&episodes)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(&format!("_v{version:04}.npz")))
        .collect();
    of_version.sort();
    let mut listed = noisy.clone();
    listed.push(eval);
    listed.sort();
    let first_arrivals = of_version[..listed.len()].to_vec();
    eprintln!(
        "resumed at iteration {iteration}: learned from {listed:?}; first arrivals of v{version}: \
         {first_arrivals:?}"
    );
    if first_arrivals != listed {
        // The case the list is for: without it the replay differs, and the report says why.
        let list = episodes.join(LEARNED);
        let kept = std::fs::read(&list).unwrap();
        std::fs::remove_file(&list).unwrap();
        let (code, r) = replay_report(out, dir, "replay-no-list");
        assert_ne!(code, Some(0), "{r}");
        assert_eq!(r["selection"], "arrival order", "{r}");
        assert!(r["note"].as_str().unwrap().contains("resumed"), "{r}");
        assert!(
            r["difference"]["iteration"].as_u64().unwrap() >= iteration as u64,
            "{r}"
        );
        std::fs::write(&list, kept).unwrap();
    }

    // Tamper with the first noisy episode learned from after the resume.
    let path = episodes.join(&noisy[0]);
    let (mut ep, origin) = load_episode(&path).unwrap();
    let task = load_episode_task(&path).unwrap();
    ep.x[4 * 12 + 3] += 1e-7;
    save_episode(&path, &ep, &origin, &task).unwrap();
    let (code, r) = replay_report(out, dir, "replay-tampered");
    assert_ne!(code, Some(0), "{r}");
    let d = &r["difference"];
    assert_eq!(d["iteration"], iteration as u64, "{r}");
    assert_eq!(d["version"], version + 1, "{r}");
    assert!(
        d["episodes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p.as_str() == path.to_str()),
        "the changed episode is among those learned from: {r}"
    );
}

/// The `.npz` files in `dir`.
fn npz_count(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "npz")
        })
        .count()
}

/// Messages per topic of an MCAP file, read as a stream (`cut_ok`: the file may lack its
/// summary and end magic), and whether the reader met an error.
fn mcap_topics(bytes: &[u8], cut_ok: bool) -> (std::collections::BTreeMap<String, usize>, bool) {
    let opts = if cut_ok {
        mcap::read::Options::IgnoreEndMagic.into()
    } else {
        Default::default()
    };
    let mut count = std::collections::BTreeMap::new();
    for m in mcap::MessageStream::new_with_options(bytes, opts).unwrap() {
        match m {
            Ok(m) => *count.entry(m.channel.topic.clone()).or_default() += 1,
            Err(_) => return (count, true),
        }
    }
    (count, false)
}

fn ctl_log(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("controller.log")).unwrap_or_default()
}
