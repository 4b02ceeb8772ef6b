//! `learner record`: demonstrations taught by hand, from a UR's RTDE stream
//! ([`crate::record`]). The RTDE client is the shared one (`ur_protocol::client`), used as an
//! observer: no program is sent.

use std::io::Write;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Args, ValueEnum};
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::kinematics::{Joints6, UrKinematics};
use ur5_shared::UrModel;

use ur_protocol::client::{check_modes, Client, ClientError};
use ur_protocol::clock::ClockWatch;
use ur_protocol::dashboard::Dashboard;
use ur_protocol::modes::{robot_mode_name, safety_mode_name};
use ur_protocol::{OutputRecipe, RobotMode, RobotState, SafetyMode};

use crate::record::{steps_checked, to_recorded_demos, Event, Sample, Segmenter};

/// Output formats of `learner record`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RecordFormat {
    /// `OUT/demos.npz`, as `learner expert` writes.
    Npz,
    /// A LeRobot v3.0 dataset in `OUT/` (as `learner dataset export` writes).
    Lerobot,
}

/// Arguments of `learner record`.
#[derive(Args, Debug)]
pub struct RecordArgs {
    /// The robot controller's IPv4 address (or ur-sim's, 127.0.0.1).
    #[arg(long)]
    pub ur: String,
    /// RTDE port of the robot.
    #[arg(long, default_value_t = 30004)]
    pub rtde_port: u16,
    /// The robot's dashboard-server port: the recorder asks the robot's model there and refuses
    /// another than the one it records for (its kinematics give the end-effector point).
    #[arg(long, default_value_t = 29999)]
    pub dashboard_port: u16,
    /// Record without asking the robot's model (a robot whose dashboard server cannot be
    /// reached): the kinematics are --model's, unchecked.
    #[arg(long)]
    pub no_check_model: bool,
    /// Demonstrations to record; recording stops after the last.
    #[arg(long, default_value_t = 5)]
    pub episodes: usize,
    /// Output folder.
    #[arg(long, default_value = "runs/record")]
    pub out: PathBuf,
    /// The arm model: its kinematics turn joint angles into the end-effector point (default:
    /// the config's `[sim] model`, else ur5).
    #[arg(long)]
    pub model: Option<UrModel>,
    /// TOML file with optional [task] (dt, horizon: the steps a demonstration is cut to;
    /// joints = 6 records the whole arm, the wrist free to move) and [sim] (model, wrist_q,
    /// ee_offset) tables; start_q and goal come from the recording.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// A pose goal: the mean of the demonstrations' last tool poses, and three tool points in
    /// the state (needs `[task] joints = 6`); without it the goal is their mean end point.
    #[arg(long)]
    pub pose: bool,
    /// Output format.
    #[arg(long, value_enum, default_value = "npz")]
    pub format: RecordFormat,
    /// Stop after this much time (s) without all the demonstrations, arm time (the robot's
    /// clock) or wall time, whichever passes first (0: never); the finished demonstrations are
    /// kept, and the exit is an error.
    #[arg(long, default_value_t = 0.0)]
    pub max_time_s: f64,
    /// Print a one-line JSON summary at the end (stdout).
    #[arg(long)]
    pub json: bool,
}

/// The config file of `learner record`.
#[derive(Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct RecordConfig {
    task: TaskConfig,
    sim: SimConfig,
}

fn load_config(args: &RecordArgs) -> anyhow::Result<RecordConfig> {
    let cfg = match (&args.config, args.model) {
        (None, m) => {
            let m = m.unwrap_or_default();
            RecordConfig {
                task: TaskConfig::for_model(m),
                sim: SimConfig::for_model(m),
            }
        }
        (Some(p), m) => {
            let mut c: RecordConfig = ur5_shared::config::from_toml_file(p)?;
            anyhow::ensure!(
                c.task.goal_pose.is_none(),
                "{}: [task] goal_pose: a recording's goal is where its demonstrations end (the \
                 mean end point, or with --pose and joints = 6 the mean last tool pose); drop \
                 goal_pose",
                p.display()
            );
            // The start pose comes from the recording; a whole-arm task without one gets the
            // wrist's angles after the arm's three so that the settings validate.
            if c.task.joints == 6 && c.task.start_q.len() == 3 {
                c.task.start_q = c.task.start_q.extended(&c.sim.wrist_q)?;
            }
            if let Some(m) = m {
                anyhow::ensure!(
                    c.sim.model == m,
                    "--model {m} but {} names model {} in [sim]: drop one or make them agree",
                    p.display(),
                    c.sim.model
                );
            }
            c
        }
    };
    cfg.task.validate()?;
    cfg.sim.validate()?;
    Ok(cfg)
}

/// The folder of a recording, claimed before anything is recorded (so that a path that cannot
/// take it fails first, and a second recorder on one `--out` is refused rather than replacing
/// the first one's demonstrations): the claim is the file `OUT/.recording` (created
/// exclusively, naming the process), deleted when the recorder ends.
struct Claim {
    dir: PathBuf,
    file: PathBuf,
    /// Whether the recorder created `dir` (an empty one is removed again).
    created: bool,
}

/// The claim file's name inside `--out`.
const CLAIM: &str = ".recording";

impl Claim {
    fn take(dir: &Path, format: RecordFormat) -> anyhow::Result<Self> {
        let file = dir.join(CLAIM);
        let held = || -> anyhow::Error {
            let who = std::fs::read_to_string(&file).unwrap_or_default();
            let pid: Option<i32> = who.split_whitespace().nth(1).and_then(|p| p.parse().ok());
            // SAFETY: kill with signal 0 only asks whether the process exists.
            let alive = pid.is_some_and(|p| p > 0 && unsafe { libc::kill(p, 0) } == 0);
            if alive {
                anyhow::anyhow!(
                    "{} is being recorded into by another `learner record` ({}): two recorders \
                     on one --out would replace each other's demonstrations; choose another --out",
                    dir.display(),
                    who.trim()
                )
            } else {
                anyhow::anyhow!(
                    "{} holds {} ({}), left by a recorder that no longer runs (killed?): its \
                     demonstrations were not written; delete the file and record again",
                    dir.display(),
                    file.display(),
                    who.trim()
                )
            }
        };
        anyhow::ensure!(
            !dir.exists() || dir.is_dir(),
            "--out {} is a file: give a folder (the recording goes into it)",
            dir.display()
        );
        if file.exists() {
            return Err(held());
        }
        match format {
            RecordFormat::Npz => {
                let out = dir.join("demos.npz");
                anyhow::ensure!(
                    !out.exists(),
                    "{} exists: record into another --out (recordings are never overwritten)",
                    out.display()
                );
            }
            RecordFormat::Lerobot => super::dataset::check_lerobot_target(dir)?,
        }
        let created = !dir.exists();
        crate::io::create_dir(dir)?;
        let mut f = match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&file)
        {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Err(held()),
            Err(e) => {
                return Err(e).with_context(|| format!("creating {}", file.display()));
            }
        };
        let since = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        writeln!(f, "pid {} since Unix time {since}", std::process::id())
            .with_context(|| format!("writing {}", file.display()))?;
        Ok(Self {
            dir: dir.to_owned(),
            file,
            created,
        })
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        std::fs::remove_file(&self.file).ok();
        if self.created {
            // Only if nothing was written into it.
            std::fs::remove_dir(&self.dir).ok();
        }
    }
}

/// SIGINT or SIGTERM arrived: the recording stops and keeps its finished demonstrations.
static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// A status line at least this often while nothing happens (s of arm time).
const STATUS_EVERY_S: f64 = 5.0;

/// Runs `learner record`.
pub fn run(args: RecordArgs) -> anyhow::Result<()> {
    let cfg = load_config(&args)?;
    let host: Ipv4Addr = args.ur.parse().map_err(|_| {
        anyhow::anyhow!(
            "--ur {}: give the robot's IPv4 address (e.g. 192.168.1.10)",
            args.ur
        )
    })?;
    anyhow::ensure!(args.episodes >= 1, "--episodes 0: record at least 1");
    anyhow::ensure!(
        args.max_time_s.is_finite() && args.max_time_s >= 0.0,
        "--max-time-s {}: a time in s (0: never)",
        args.max_time_s
    );
    anyhow::ensure!(
        !args.pose || cfg.task.joints == 6,
        "--pose: {}",
        crate::record::RecordError::PoseNeedsSixJoints(cfg.task.joints)
    );
    let claim = Claim::take(&args.out, args.format)?;
    let timeout = Duration::from_secs(10);
    if !args.no_check_model {
        check_model(
            std::net::SocketAddr::from((host, args.dashboard_port)),
            cfg.sim.model,
            timeout,
        )?;
    }
    let addr = std::net::SocketAddr::from((host, args.rtde_port));
    let mut rtde = Observer::connect(addr, timeout).map_err(|e| {
        let wrong_port = matches!(
            e,
            ClientError::Frame { .. }
                | ClientError::Decode { .. }
                | ClientError::Unexpected { .. }
                | ClientError::NoProtocol
        );
        anyhow::Error::new(e).context(if wrong_port {
            format!(
                "{addr} answers, but not in RTDE: wrong --rtde-port? (a UR's RTDE port is \
                 30004; 29999 is its dashboard server, 30001-30003 its primary and secondary \
                 interfaces)"
            )
        } else {
            format!("connecting to RTDE at {addr}")
        })
    })?;
    // The arm's package rate from its own clock: the median step of 25 consecutive packages'
    // timestamps, so that a package the controller skipped (a loaded machine, a busy network)
    // does not halve it.
    let mut clock = ClockWatch::new(rtde.state.timestamp);
    let rate = 1.0 / {
        let mut steps = Vec::with_capacity(25);
        let mut a = rtde.state.timestamp;
        for _ in 0..25 {
            let b = rtde.next_state()?.timestamp;
            clock.check(b)?;
            steps.push(b - a);
            a = b;
        }
        steps.sort_by(f64::total_cmp);
        steps[steps.len() / 2]
    };
    anyhow::ensure!(
        rate.is_finite() && rate > 0.0,
        "the robot's clock (RTDE timestamp) advanced by a median of {} s per package: its \
         packages cannot be timed (restart the robot's controller)",
        1.0 / rate
    );
    eprintln!(
        "recording {} demonstrations of T = {} steps of {} s from {host}:{} (packages at about \
         {rate:.0} Hz) into {}: rest at the start pose for {} s, move, rest at the end for {} s; \
         Ctrl-C stops and keeps the finished demonstrations",
        args.episodes,
        cfg.task.horizon,
        cfg.task.dt,
        args.rtde_port,
        args.out.display(),
        crate::record::REST_S,
        crate::record::REST_S
    );
    STOP.store(false, Ordering::Relaxed);
    // SAFETY: the handler only stores to an atomic.
    unsafe {
        libc::signal(
            libc::SIGINT,
            on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
        libc::signal(
            libc::SIGTERM,
            on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
    let kin = UrKinematics::new(cfg.sim.model, cfg.sim.ee_offset);
    let mut rec = Recording {
        seg: Segmenter::new(kin),
        kept: Vec::new(),
        skipped: 0,
    };
    let stopped = rec.run(&mut rtde, &mut clock, &args, &cfg).err();
    let finished = rec.kept.len();
    let Some(start) = rec.seg.start_pose().filter(|_| finished > 0) else {
        drop(claim);
        return Err(stopped
            .unwrap_or_else(|| anyhow::anyhow!("no demonstrations were recorded"))
            .context(format!(
                "no demonstration was finished, nothing written to {}",
                args.out.display()
            )));
    };
    let (demos, report) = to_recorded_demos(&rec.kept, &start, &cfg.task, &cfg.sim, args.pose)?;
    let written = match args.format {
        RecordFormat::Npz => {
            let f = args.out.join("demos.npz");
            crate::io::demos::save(&demos, &f)?;
            f
        }
        RecordFormat::Lerobot => {
            crate::io::lerobot::export(&crate::io::foreign::from_demos(&demos), &args.out)?;
            args.out.clone()
        }
    };
    drop(claim);
    eprintln!(
        "{}: {} demonstrations -> {}; start_q {:?} rad, goal ({:.4}, {:.4}, {:.4}) m (spread: \
         max {:.4} m, rms {:.4} m from it); C_expert {:.4}, C_random {:.4}; {} motions \
         not kept",
        if stopped.is_some() { "kept" } else { "done" },
        report.episodes,
        written.display(),
        report.start_q,
        report.goal[0],
        report.goal[1],
        report.goal[2],
        report.goal_spread_max_m,
        report.goal_spread_rms_m,
        report.cost_expert,
        report.cost_random,
        rec.skipped
    );
    if let Some(p) = report.goal_pose {
        eprintln!("goal pose p{p:.4?} (m, rotation vector)");
    }
    if args.json {
        println!(
            "{}",
            serde_json::json!({"command": "record", "model": cfg.sim.model, "out": written,
                "rate_hz": rate, "skipped": rec.skipped, "complete": stopped.is_none(),
                "report": report})
        );
    }
    match stopped {
        None => Ok(()),
        Some(e) => Err(e.context(format!(
            "the recording stopped after {finished} of {} demonstrations; the {finished} \
             finished ones are saved in {} (record the rest into another --out)",
            args.episodes,
            written.display()
        ))),
    }
}

/// Refuses a robot of another model than `model` (the one whose kinematics the recording
/// uses), asking its dashboard server at `addr` as the controller's `ur` arm does.
fn check_model(
    addr: std::net::SocketAddr,
    model: UrModel,
    timeout: Duration,
) -> anyhow::Result<()> {
    let id = Dashboard::connect(addr, timeout)
        .and_then(|mut d| d.identity())
        .with_context(|| {
            format!(
                "asking the robot's model (to check --model {model}): pass --dashboard-port (29999 \
                 on a UR), or --no-check-model to record with {model}'s kinematics unchecked"
            )
        })?;
    let found = id.model();
    anyhow::ensure!(
        found == Some(model),
        "recording for a {model} (--model or [sim] model), but the robot says it is a {} on {}, \
         that is {}: its end-effector points would be computed with the wrong kinematics; \
         record with --model {}",
        id.robot,
        id.polyscope,
        found.map_or(
            "a model this project does not know".to_string(),
            |m| format!("a {m}")
        ),
        found.map_or("<the robot's model>", UrModel::name)
    );
    Ok(())
}

/// A recording under way: the segmenter and what it has kept.
struct Recording {
    seg: Segmenter,
    /// The finished demonstrations, as T steps each.
    kept: Vec<Vec<(Joints6, Joints6)>>,
    /// Motions not kept.
    skipped: usize,
}

impl Recording {
    /// Reads packages until `args.episodes` demonstrations are kept; an error says why it
    /// stopped before (what was kept stays in `self`).
    fn run(
        &mut self,
        rtde: &mut Observer,
        clock: &mut ClockWatch,
        args: &RecordArgs,
        cfg: &RecordConfig,
    ) -> anyhow::Result<()> {
        let kin = UrKinematics::new(cfg.sim.model, cfg.sim.ee_offset);
        let t_begin = rtde.state.timestamp;
        let wall_begin = Instant::now();
        let mut said = (t_begin, self.seg.status().waiting);
        let mut stopped_since = None;
        while self.kept.len() < args.episodes {
            anyhow::ensure!(
                !STOP.load(Ordering::Relaxed),
                "interrupted (SIGINT or SIGTERM)"
            );
            let wall = wall_begin.elapsed().as_secs_f64();
            anyhow::ensure!(
                args.max_time_s == 0.0 || wall <= args.max_time_s,
                "{} s of wall time passed (--max-time-s) while the robot's clock advanced {:.1} \
                 s",
                args.max_time_s,
                rtde.state.timestamp - t_begin
            );
            let s = match rtde.next_state() {
                Ok(s) => s,
                Err(_) if STOP.load(Ordering::Relaxed) => {
                    anyhow::bail!("interrupted (SIGINT or SIGTERM)")
                }
                Err(e) => return Err(e).context("reading the robot's RTDE stream"),
            };
            clock.check(s.timestamp)?;
            anyhow::ensure!(
                args.max_time_s == 0.0 || s.timestamp - t_begin <= args.max_time_s,
                "{} s of arm time passed (--max-time-s)",
                args.max_time_s
            );
            let (robot, safety) = (s.robot_mode, s.safety_mode);
            if robot != RobotMode::Running.code() || safety != SafetyMode::Normal.code() {
                // The robot stopped the arm: a reach under way was cut short, not taught.
                let why = format!(
                    "the robot stopping the arm (robot mode {}, safety mode {})",
                    robot_mode_name(robot),
                    safety_mode_name(safety)
                );
                let t = s.timestamp;
                if let Some(Event::Discarded { at, why }) = self.seg.interrupt(t, &why) {
                    self.skipped += 1;
                    eprintln!("a motion at t = {at:.2} s is not a demonstration: {why}");
                }
                if stopped_since.is_none() {
                    eprintln!("t = {t:.2} s: {why}; waiting for RUNNING and NORMAL");
                    stopped_since = Some(t);
                }
                continue;
            }
            if let Some(t) = stopped_since.take() {
                eprintln!(
                    "t = {:.2} s: the robot runs again (stopped since t = {t:.2} s)",
                    s.timestamp
                );
            }
            let sample = Sample {
                t: s.timestamp,
                q: s.actual_q,
                qd: s.actual_qd,
            };
            sample.check(cfg.sim.model)?;
            let event = self.seg.push(sample);
            let status = self.seg.status();
            if event.is_some() {
                said = (sample.t, status.waiting);
            } else if status.waiting != said.1 || sample.t - said.0 >= STATUS_EVERY_S {
                eprintln!("t = {:.2} s: {status}", sample.t);
                said = (sample.t, status.waiting);
            }
            match event {
                None => {}
                Some(Event::StartPose(p)) => eprintln!(
                    "start pose at t = {:.2} s: {:?} rad; waiting for a motion from it",
                    sample.t,
                    p.map(|v| (v * 1e4).round() / 1e4)
                ),
                Some(Event::Discarded { at, why }) => {
                    self.skipped += 1;
                    eprintln!("a motion at t = {at:.2} s is not a demonstration: {why}");
                }
                Some(Event::Demonstration(d)) => match steps_checked(&d, &cfg.task, &cfg.sim) {
                    Ok(steps) => {
                        let (q, _) = steps.last().expect("T ≥ 2");
                        let ee = kin.ee_point(q);
                        self.kept.push(steps);
                        eprintln!(
                            "demonstration {}/{}: from t = {:.2} s, {} packages, ends at ({:.4}, \
                             {:.4}, {:.4}) m",
                            self.kept.len(),
                            args.episodes,
                            d.samples[0].t,
                            d.samples.len(),
                            ee[0],
                            ee[1],
                            ee[2]
                        );
                    }
                    Err(why) => {
                        self.skipped += 1;
                        eprintln!("skipped the motion from t = {:.2} s: {why}", d.samples[0].t);
                    }
                },
            }
        }
        Ok(())
    }
}

/// The outputs a recording reads (the modes for the check that the arm runs).
const OUTPUTS: &str = "timestamp,actual_q,actual_qd,robot_mode,safety_mode";

/// An RTDE observer: streaming [`OUTPUTS`] at the controller's rate, RUNNING and NORMAL.
struct Observer {
    c: Client,
    recipe: OutputRecipe,
    /// The newest state.
    state: RobotState,
    /// Bounds each read.
    timeout: Duration,
}

impl Observer {
    fn connect(addr: std::net::SocketAddr, timeout: Duration) -> Result<Self, ClientError> {
        let mut c = Client::connect(addr, timeout)?;
        let (_, recipe) = c.handshake(OUTPUTS)?;
        let state = c.state(&recipe)?;
        check_modes(&state)?;
        Ok(Self {
            c,
            recipe,
            state,
            timeout,
        })
    }

    /// Blocks for the next data package (at most `timeout`).
    fn next_state(&mut self) -> Result<&RobotState, ClientError> {
        self.c.restart_deadline(self.timeout);
        self.state = self.c.state(&self.recipe)?;
        Ok(&self.state)
    }
}
