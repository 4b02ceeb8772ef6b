//! Helpers for the cross-process integration tests in `tests/tests/`.
//!
//! # Running
//!
//! The tests spawn the real binaries `hil-sim` and `rt-controller` from the same target
//! directory as the test executable (`target/release/`, found from
//! `std::env::current_exe()`). `cargo test --release --workspace` builds every binary before it
//! runs any test; when running this crate alone, build them first:
//!
//! ```text
//! cargo build --release --workspace --bins && cargo test --release -p integration-tests
//! ```
//!
//! Every test uses its own iceoryx2 service prefix ([`unique_prefix`]), so tests run in
//! parallel and a crashed test leaves nothing that disturbs the next. No test asserts on a
//! latency: the machines are shared and stall now and then.

pub mod soak;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
pub use ur5_shared::services::unique_prefix;

use learner::process::Spawned;

use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{ArmCommand, GainTable, PolicyTable, StepSample, DU};

/// `target/release/<name>`, next to the directory of the test executable.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("current_exe");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("test executable lives in target/<profile>/deps");
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} not found: build the binaries first (`cargo build --release --workspace --bins`), or run \
         `cargo test --release --workspace`, which builds them before running tests",
        path.display()
    );
    path
}

/// A scratch directory for this test's config files and logs.
pub fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "ur5-it-{tag}-{}-{}",
        std::process::id(),
        unique_prefix("d").replace('/', "_")
    ));
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// A spawned binary ([`learner::process::Spawned`]: stdout piped for the `--json` line, stderr
/// to a log file), killed at once on drop; the methods panic with its log where a test would.
pub struct Proc(Spawned);

impl Proc {
    /// Spawns `bin(name)` with `args`; stderr goes to `dir/<label>.log`.
    pub fn spawn(name: &str, label: &str, args: &[&str], dir: &Path) -> Self {
        let log = dir.join(format!("{label}.log"));
        let p = Spawned::spawn(&bin(name), args, &log, Duration::ZERO)
            .unwrap_or_else(|e| panic!("spawn {name}: {e}"));
        Self(p.named(label))
    }

    /// What it is, for messages.
    pub fn name(&self) -> &str {
        &self.0.name
    }

    /// The process id.
    pub fn pid(&self) -> i32 {
        self.0.pid()
    }

    /// Sends a signal (e.g. `libc::SIGTERM`, `libc::SIGKILL`).
    pub fn signal(&self, sig: i32) {
        self.0.signal(sig)
    }

    /// Its stderr so far.
    pub fn log(&self) -> String {
        self.0.log()
    }

    /// Waits up to `timeout` for exit; returns (exit code, stdout). Panics with the log on
    /// timeout.
    pub fn wait(&mut self, timeout: Duration) -> (Option<i32>, String) {
        match self.0.wait(timeout) {
            Ok(r) => r,
            Err(e) => panic!("{e}; its log:\n{}", self.log()),
        }
    }

    /// True while running.
    pub fn running(&mut self) -> bool {
        self.0.running()
    }

    /// SIGTERM, then waits up to `timeout` for exit code 0 (panics with the log otherwise);
    /// returns its `--json` summary and log.
    pub fn terminate_ok(&mut self, timeout: Duration) -> (serde_json::Value, String) {
        self.signal(libc::SIGTERM);
        let (code, out) = self.wait(timeout);
        let log = self.log();
        assert_eq!(code, Some(0), "{} log:\n{log}", self.name());
        (json_summary(&out, &log), log)
    }
}

/// The last line of `stdout` parsed as JSON (the `--json` summary).
pub fn json_summary(stdout: &str, log: &str) -> serde_json::Value {
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON line in stdout {stdout:?}; log:\n{log}"));
    serde_json::from_str(line).unwrap_or_else(|e| panic!("bad JSON {line:?}: {e}"))
}

/// The test acting as the learner: publishes tables on `controller/gains`, receives samples on
/// `learner/samples`, and watches `arm/command` (a monitor, as a second subscriber).
pub struct TestLearner {
    gains: Publisher<ipc::Service, GainTable, ()>,
    /// `controller/policy`, when opened ([`TestLearner::with_policy`]).
    policy: Option<Publisher<ipc::Service, PolicyTable, ()>>,
    samples: Subscriber<ipc::Service, StepSample, ()>,
    commands: Option<Subscriber<ipc::Service, ArmCommand, ()>>,
    /// Every sample received so far, in arrival order.
    pub received: Vec<StepSample>,
    /// Every command seen so far.
    pub seen_commands: Vec<ArmCommand>,
    _node: Node<ipc::Service>,
}

impl TestLearner {
    /// Opens the services under `prefix` with the project's QoS, including the command monitor.
    pub fn new(prefix: &str) -> Self {
        Self::open(prefix, true)
    }

    /// Only the learner's two ports (no `arm/command` monitor, which would make this process
    /// look like an arm to the controller's peer monitor).
    pub fn learner_only(prefix: &str) -> Self {
        Self::open(prefix, false)
    }

    /// [`TestLearner::learner_only`] that also publishes policy tables on `controller/policy`
    /// ([`TestLearner::publish_policy`]).
    pub fn with_policy(prefix: &str) -> Self {
        let mut l = Self::open(prefix, false);
        let names = ServiceNames::new(prefix);
        let p = services::CONTROLLER_POLICY_QOS
            .open_or_create_retrying::<PolicyTable>(&l._node, &names.controller_policy)
            .unwrap();
        l.policy = Some(p.publisher_builder().create().unwrap());
        l
    }

    fn open(prefix: &str, monitor_commands: bool) -> Self {
        iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
        let names = ServiceNames::new(prefix);
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .unwrap();
        let g = services::CONTROLLER_GAINS_QOS
            .open_or_create_retrying::<GainTable>(&node, &names.controller_gains)
            .unwrap();
        let s = services::LEARNER_SAMPLES_QOS
            .open_or_create_retrying::<StepSample>(&node, &names.learner_samples)
            .unwrap();
        let c = services::ARM_COMMAND_QOS
            .open_or_create_retrying::<ArmCommand>(&node, &names.arm_command)
            .unwrap();
        Self {
            gains: g.publisher_builder().create().unwrap(),
            policy: None,
            samples: s.subscriber_builder().create().unwrap(),
            commands: monitor_commands.then(|| {
                c.subscriber_builder()
                    .buffer_size(services::ARM_COMMAND_QOS.subscriber_buffer)
                    .create()
                    .unwrap()
            }),
            received: Vec::new(),
            seen_commands: Vec::new(),
            _node: node,
        }
    }

    /// Publishes `table` as it is (sealed or not).
    pub fn publish(&self, table: &GainTable) {
        let mut slot = self.gains.loan_uninit().unwrap();
        table.copy_to_uninit(slot.payload_mut());
        // SAFETY: copy_to_uninit initialised the payload.
        unsafe { slot.assume_init() }.send().unwrap();
    }

    /// Publishes the policy `table` as it is; panics unless opened [`TestLearner::with_policy`].
    pub fn publish_policy(&self, table: &PolicyTable) {
        let publisher = self.policy.as_ref().expect("TestLearner::with_policy");
        let mut slot = publisher.loan_uninit().unwrap();
        PolicyTable::init_zeroed(slot.payload_mut()).copy_from(table);
        // SAFETY: init_zeroed and copy_from initialised the payload.
        unsafe { slot.assume_init() }.send().unwrap();
    }

    /// Takes what arrived; delivers the tables' history to late subscribers.
    pub fn poll(&mut self) {
        let _ = self.gains.update_connections();
        if let Some(p) = &self.policy {
            let _ = p.update_connections();
        }
        while let Some(s) = self.samples.receive().unwrap() {
            self.received.push(*s);
        }
        if let Some(commands) = &self.commands {
            while let Some(c) = commands.receive().unwrap() {
                self.seen_commands.push(*c);
            }
        }
    }

    /// Only delivers the gains history to late subscribers (a learner that never reads).
    pub fn poll_gains_only(&self) {
        let _ = self.gains.update_connections();
    }

    /// Polls until `done(self)` or `timeout`; panics with `what` and the controller's log on
    /// timeout or when the controller exits first.
    pub fn poll_until(
        &mut self,
        ctl: &mut Proc,
        timeout: Duration,
        what: &str,
        done: impl Fn(&Self) -> bool,
    ) {
        let t0 = Instant::now();
        loop {
            self.poll();
            if done(self) {
                return;
            }
            let exited = !ctl.running();
            if exited || t0.elapsed() > timeout {
                self.poll();
                if done(self) {
                    return;
                }
                panic!(
                    "{} waiting for {what} ({} samples so far); controller log:\n{}",
                    if exited {
                        "the controller exited"
                    } else {
                        "timed out"
                    },
                    self.received.len(),
                    ctl.log()
                );
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Highest episode number received, if any.
    pub fn last_episode(&self) -> Option<u64> {
        self.received.iter().map(|s| s.episode).max()
    }
}

/// A stable table around the goal angles `q_goal` (rad): a = q* + ½ (q − q*) + σ ε, i.e.
/// K = ½ on the joint angles, ŝ = q* on them, â = q*, L = σ I. The arm converges to q*.
pub fn reaching_table(
    version: u64,
    horizon: usize,
    q_goal: [f64; DU],
    sigma: f64,
) -> Box<GainTable> {
    let mut t = rt_controller::testkit::constant_goal_table(version, horizon, q_goal, sigma);
    for s in 0..horizon {
        let mut st = t.step_mut(s);
        for i in 0..DU {
            st.set_k(i, i, 0.5);
            st.s_hat[i] = q_goal[i];
        }
    }
    t.seal();
    t
}

/// Removes the iceoryx2 resources (shared memory, registrations) of processes that died, e.g.
/// ones a test killed, so repeated runs do not accumulate them. Live processes are untouched.
pub fn cleanup_dead_nodes() {
    let _ = Node::<ipc::Service>::try_cleanup_dead_nodes(Config::global_config());
}

/// Writes `text` to `dir/name` and returns the path as a string.
pub fn write_config(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write config");
    p.display().to_string()
}

/// `DIR/gaifo.toml`, the learner's config of a served LQR+GAIfO run of `iterations` iterations
/// with `samples` noisy episodes per iteration and `seed`; returns its path.
pub fn write_served_gaifo_config(
    dir: &Path,
    samples: usize,
    seed: u64,
    iterations: usize,
) -> String {
    write_config(
        dir,
        "gaifo.toml",
        &format!(
            "samples = {samples}\nseed = {seed}\niterations = {iterations}\n\
             [serve]\nalgo = \"lqr-gaifo\"\nwait_report_s = 1.0\nidle_sleep_us = 200\n"
        ),
    )
}

/// The in-process reference of a served LQR+GAIfO run: `iterations` calls of
/// [`imitation::learn::iterate`] with `cfg` on `demos` on the simulated arm, checkpointed into
/// `out` before each and after the last, as `learner serve` checkpoints before each publication.
/// Returns the tables of versions 1 … iterations + 1 and each iteration's log and noise-free
/// episode.
#[allow(clippy::type_complexity)]
pub fn lqr_gaifo_in_process(
    cfg: imitation::gaifo::GaifoConfig,
    demos: imitation::demos::Demos,
    iterations: usize,
    out: &Path,
) -> (
    Vec<Box<GainTable>>,
    Vec<(imitation::gaifo::GaifoLog, imitation::rollout::Episode)>,
) {
    use learner::run::Checkpoint;
    let mut run = imitation::gaifo::LqrGaifo::new(cfg, demos).unwrap();
    let arm = learner::run::arm_for(&run).unwrap();
    let (mut tables, mut logs) = (Vec::new(), Vec::new());
    for _ in 0..iterations {
        tables.push(imitation::controller::to_gain_table(
            run.policy(),
            run.version(),
        ));
        run.checkpoint(out, None).unwrap();
        let (log, mut evals) = imitation::learn::iterate(&mut run, &arm).unwrap();
        logs.push((log, evals.remove(0)));
    }
    tables.push(imitation::controller::to_gain_table(
        run.policy(),
        run.version(),
    ));
    run.checkpoint(out, None).unwrap();
    (tables, logs)
}

/// `learner serve --json` (config `learner_cfg`, output `DIR/out-LABEL`) and `rt-controller
/// run --json` (config `ctl_cfg`) on `prefix` against an arm already running; `during` runs
/// while they learn (given the learner and its output folder). Waits for the learner to
/// finish, then stops the controller (SIGTERM); both must exit 0, the controller with no
/// aborted episode and no rejected table. Returns both summaries (learner, controller).
pub fn learn_over_ipc(
    dir: &Path,
    prefix: &str,
    learner_cfg: &str,
    ctl_cfg: &str,
    label: &str,
    timeout: Duration,
    during: impl FnOnce(&mut Proc, &Path),
) -> (serde_json::Value, serde_json::Value) {
    let out = dir.join(format!("out-{label}"));
    let mut learner = Proc::spawn(
        "learner",
        &format!("learner-{label}"),
        &[
            "serve",
            "--config",
            learner_cfg,
            "--prefix",
            prefix,
            "--out",
            &out.display().to_string(),
            "--json",
        ],
        dir,
    );
    let mut ctl = Proc::spawn(
        "rt-controller",
        &format!("controller-{label}"),
        &["run", "--config", ctl_cfg, "--prefix", prefix, "--json"],
        dir,
    );
    during(&mut learner, &out);
    let (code, lout) = learner.wait(timeout);
    let log = learner.log();
    assert_eq!(
        code,
        Some(0),
        "learner ({label}):\n{log}\ncontroller:\n{}",
        ctl.log()
    );
    ctl.signal(libc::SIGTERM);
    let (code, cout) = ctl.wait(timeout);
    let clog = ctl.log();
    assert_eq!(code, Some(0), "controller ({label}):\n{clog}");
    let c = json_summary(&cout, &clog);
    assert_eq!(c["episodes_aborted"], 0, "{c}");
    assert_eq!(c["rejected_total"], 0, "{c}");
    (json_summary(&lout, &log), c)
}

/// `hil-sim serve` and `rt-controller run --json` with the given config files on `prefix`.
pub fn spawn_sim_and_controller(
    sim_cfg: &str,
    ctl_cfg: &str,
    prefix: &str,
    dir: &Path,
) -> (Proc, Proc) {
    let sim = Proc::spawn(
        "hil-sim",
        "sim",
        &["serve", "--config", sim_cfg, "--prefix", prefix],
        dir,
    );
    let ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &["run", "--config", ctl_cfg, "--prefix", prefix, "--json"],
        dir,
    );
    (sim, ctl)
}

/// splitmix64: the seeded kill moments of the resume tests.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `dir/iter_NNN_KIND`: a checkpoint file of iteration `i` (`table.npz`, `state.npz`,
/// `critic.json`).
pub fn checkpoint_file(dir: &Path, i: usize, kind: &str) -> PathBuf {
    dir.join(format!("iter_{i:03}_{kind}"))
}

/// The columns of a `gaifo_log.csv` row up to `step_mult` (the rest are timings).
pub fn learned_columns(row: &str) -> Vec<String> {
    row.trim_end()
        .split(',')
        .take(11)
        .map(str::to_owned)
        .collect()
}

/// Every number of a learner state file (`iter_NNN_state.npz`) as bits: the real arrays and
/// the words (RNG positions, counters), by name.
pub fn state_bits(path: &Path) -> Vec<(String, Vec<u64>)> {
    let s = learner::io::checkpoint::load_state(path).unwrap();
    s.reals
        .iter()
        .map(|(k, (_, v))| (k.clone(), v.iter().map(|x| x.to_bits()).collect()))
        .chain(s.words.clone())
        .collect()
}

/// What [`serve_with_kills`] did: the finishing run's `--json` summary, the kills, and how
/// many of them were followed by a resume or by a restart.
pub struct Killed {
    pub summary: serde_json::Value,
    pub kills: usize,
    pub resumes: usize,
    pub restarts: usize,
}

/// `rt-controller run --config cfg --prefix prefix --json --episodes episodes` in `dir`,
/// calling `poll` every 5 ms while it runs (for at most `limit`); returns its exit code,
/// standard output and log.
pub fn run_controller_polling(
    cfg: &str,
    prefix: &str,
    episodes: u64,
    dir: &Path,
    limit: Duration,
    mut poll: impl FnMut(),
) -> (Option<i32>, String, String) {
    let episodes = episodes.to_string();
    let mut ctl = Proc::spawn(
        "rt-controller",
        "controller",
        &[
            "run",
            "--config",
            cfg,
            "--prefix",
            prefix,
            "--json",
            "--episodes",
            &episodes,
        ],
        dir,
    );
    let t0 = Instant::now();
    while ctl.running() && t0.elapsed() < limit {
        poll();
        std::thread::sleep(Duration::from_millis(5));
    }
    let (code, out) = ctl.wait(limit);
    (code, out, ctl.log())
}

/// Runs `learner` with `base` (its arguments without `--out`, `--resume`, `--force`) into
/// `out` while `peers` (the arm and the controller) run on: the first `kills` runs are killed
/// with SIGKILL `window.0` to `window.0 + window.1` ms after their start (seeded by `seed`),
/// each followed by a resume (`--resume OUT --out OUT`) or, when the kill came before the
/// first checkpoint (`iter_000_state.npz`), a restart (`--out OUT --force`); the next run must
/// finish with exit code 0 within `timeout`.
pub fn serve_with_kills(
    dir: &Path,
    base: &[&str],
    out: &Path,
    peers: [&mut Proc; 2],
    kills: usize,
    mut seed: u64,
    window: (u64, u64),
    timeout: Duration,
) -> Killed {
    let o = out.display().to_string();
    let [sim, ctl] = peers;
    let (mut killed, mut resumes, mut restarts) = (0, 0, 0);
    let mut resume = false;
    let t0 = Instant::now();
    let summary = loop {
        assert!(
            t0.elapsed() < (kills as u32 + 1) * timeout,
            "no end after {killed} kills"
        );
        let args = if resume {
            [base, &["--resume", &o, "--out", &o]].concat()
        } else {
            [base, &["--out", &o, "--force"]].concat()
        };
        let mut p = Proc::spawn("learner", &format!("learner{killed}"), &args, dir);
        let at = Duration::from_millis(window.0 + splitmix64(&mut seed) % window.1);
        let started = Instant::now();
        let mut finished = None;
        while killed >= kills || started.elapsed() < at {
            for q in [&mut *sim, &mut *ctl] {
                assert!(q.running(), "{} exited; its log:\n{}", q.name(), q.log());
            }
            if !p.running() {
                finished = Some(p.wait(Duration::from_secs(1)));
                break;
            }
            assert!(
                started.elapsed() < timeout,
                "learner hangs; its log:\n{}",
                p.log()
            );
            std::thread::sleep(Duration::from_millis(2));
        }
        match finished {
            Some((code, stdout)) => {
                let log = p.log();
                assert_eq!(code, Some(0), "learner log:\n{log}");
                break json_summary(&stdout, &log);
            }
            None => {
                p.signal(libc::SIGKILL);
                p.wait(Duration::from_secs(10));
                killed += 1;
                resume = checkpoint_file(out, 0, "state.npz").is_file();
                resumes += usize::from(resume);
                restarts += usize::from(!resume);
                eprintln!("kill {killed} after {at:?}; resume: {resume}");
            }
        }
    };
    Killed {
        summary,
        kills: killed,
        resumes,
        restarts,
    }
}

/// A served learner (`learner serve --config SERVE`) with `hil-sim serve` and `rt-controller`
/// on `prefix`, the settings files `[serve, sim, controller]` in `dir`, writing into `out`:
/// killed 6 times 30 to 280 ms after its starts (seeded by `seed`) and resumed or restarted
/// ([`serve_with_kills`]). Asserts that a kill landed after the first checkpoint, that the last
/// run finished and that the controller rejected no table; returns the arm process, to be
/// dropped after the caller's checks.
pub fn serve_killed_and_resumed(
    dir: &Path,
    prefix: &str,
    [serve_cfg, sim_cfg, ctl_cfg]: [&str; 3],
    out: &Path,
    seed: u64,
) -> Proc {
    let (mut sim, mut ctl) = spawn_sim_and_controller(sim_cfg, ctl_cfg, prefix, dir);
    let base = ["serve", "--config", serve_cfg, "--prefix", prefix, "--json"];
    let killed = serve_with_kills(
        dir,
        &base,
        out,
        [&mut sim, &mut ctl],
        6,
        seed,
        (30, 250),
        Duration::from_secs(120),
    );
    eprintln!(
        "{} kills: {} resumes, {} restarts; then finished",
        killed.kills, killed.resumes, killed.restarts
    );
    assert!(
        killed.resumes >= 1,
        "no kill landed after the first checkpoint"
    );
    assert_eq!(killed.summary["exit_reason"], "done", "{}", killed.summary);
    let (cj, _) = ctl.terminate_ok(Duration::from_secs(120));
    assert_eq!(cj["rejected_total"], 0, "{cj}");
    sim
}

/// Asserts that checkpoint `i` in `out` is the one in `reference`: the learner state file
/// (`iter_NNN_state.npz`) bit for bit, its entries named in `ignore` aside, and the critic file
/// (`iter_NNN_critic.json`) byte for byte.
pub fn assert_same_checkpoint(out: &Path, reference: &Path, i: usize, ignore: &[&str]) {
    let bits = |dir: &Path| {
        let mut b = state_bits(&checkpoint_file(dir, i, "state.npz"));
        b.retain(|(name, _)| !ignore.contains(&name.as_str()));
        b
    };
    assert_eq!(bits(out), bits(reference), "learner state of iteration {i}");
    let name = format!("iter_{i:03}_critic.json");
    assert_eq!(
        std::fs::read(out.join(&name)).unwrap(),
        std::fs::read(reference.join(&name)).unwrap(),
        "{name}"
    );
}

/// Asserts that the `learner serve --json` summary `s` is of a run of `algorithm` that ran
/// `iterations` iterations to their end and discarded no episode.
pub fn assert_served_done(s: &serde_json::Value, algorithm: &str, iterations: usize) {
    assert_eq!(s["algorithm"], algorithm, "{s}");
    assert_eq!(s["exit_reason"], "done", "{s}");
    assert_eq!(s["iterations"], iterations as u64, "{s}");
    assert_eq!(s["table_version"], iterations as u64 + 1, "{s}");
    assert_eq!(s["counts"]["partial"], 0, "{s}");
    assert_eq!(s["counts"]["mixed"], 0, "{s}");
}
