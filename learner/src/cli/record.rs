//! `learner record`: demonstrations taught by hand, from a UR's RTDE stream
//! ([`crate::record`]). The RTDE client is the shared one (`ur_protocol::client`), used as an
//! observer: no program is sent.

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use serde::{Deserialize, Serialize};
use ur5_shared::config::{SimConfig, TaskConfig};
use ur5_shared::UrModel;

use ur_protocol::client::{check_modes, Client, ClientError};
use ur_protocol::{OutputRecipe, RobotState};

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
    /// TOML file with optional [task] (dt, horizon: the steps a demonstration is cut to) and
    /// [sim] (model, wrist_q, ee_offset) tables; start_q and goal come from the recording.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output format.
    #[arg(long, value_enum, default_value = "npz")]
    pub format: RecordFormat,
    /// Give up (with an error) after this much arm time (s) without all the demonstrations
    /// (0: never).
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
            let c: RecordConfig = ur5_shared::config::from_toml_file(p)?;
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
    let out_file = args.out.join("demos.npz");
    match args.format {
        RecordFormat::Npz => anyhow::ensure!(
            !out_file.exists(),
            "{} exists: record into another --out (recordings are never overwritten)",
            out_file.display()
        ),
        RecordFormat::Lerobot => anyhow::ensure!(
            !args.out.join("meta").exists(),
            "{} holds a dataset: record into another --out (recordings are never overwritten)",
            args.out.display()
        ),
    }
    let timeout = Duration::from_secs(10);
    let addr = std::net::SocketAddr::from((host, args.rtde_port));
    let mut rtde = Observer::connect(addr, timeout)
        .with_context(|| format!("connecting to RTDE at {host}:{}", args.rtde_port))?;
    // The arm's package rate from its own clock: the median step of 25 consecutive packages'
    // timestamps, so that a package the controller skipped (a loaded machine, a busy network)
    // does not halve it.
    let rate = 1.0 / {
        let mut steps = Vec::with_capacity(25);
        let mut a = rtde.state.timestamp;
        for _ in 0..25 {
            let b = rtde.next_state()?.timestamp;
            steps.push(b - a);
            a = b;
        }
        steps.sort_by(f64::total_cmp);
        steps[steps.len() / 2]
    };
    eprintln!(
        "recording {} demonstrations of T = {} steps of {} s from {host}:{} (packages at about \
         {rate:.0} Hz): rest at the start pose for {} s, move, rest at the end for {} s",
        args.episodes,
        cfg.task.horizon,
        cfg.task.dt,
        args.rtde_port,
        crate::record::REST_S,
        crate::record::REST_S
    );
    let mut seg = Segmenter::default();
    let mut kept = Vec::new();
    let mut skipped = 0usize;
    let t_begin = rtde.state.timestamp;
    while kept.len() < args.episodes {
        let s = rtde.next_state().with_context(|| {
            format!(
                "reading RTDE after {} of {} demonstrations",
                kept.len(),
                args.episodes
            )
        })?;
        if args.max_time_s > 0.0 && s.timestamp - t_begin > args.max_time_s {
            anyhow::bail!(
                "{} s of arm time passed with {} of {} demonstrations recorded (--max-time-s)",
                args.max_time_s,
                kept.len(),
                args.episodes
            );
        }
        let sample = Sample {
            t: s.timestamp,
            q: s.actual_q,
            qd: s.actual_qd,
        };
        match seg.push(sample) {
            None => {}
            Some(Event::StartPose(p)) => eprintln!(
                "start pose at t = {:.2} s: {:?} rad",
                sample.t,
                p.map(|v| (v * 1e4).round() / 1e4)
            ),
            Some(Event::Discarded { at, why }) => {
                skipped += 1;
                eprintln!("a motion at t = {at:.2} s is not a demonstration: {why}");
            }
            Some(Event::Demonstration(d)) => match steps_checked(&d, &cfg.task, &cfg.sim) {
                Ok(steps) => {
                    let (q, _) = steps.last().expect("T ≥ 2");
                    let kin =
                        ur5_shared::kinematics::UrKinematics::new(cfg.sim.model, cfg.sim.ee_offset);
                    let ee = kin.ee_point(q);
                    kept.push(steps);
                    eprintln!(
                        "demonstration {}/{}: from t = {:.2} s, {} packages, ends at ({:.4}, {:.4}, {:.4}) m",
                        kept.len(),
                        args.episodes,
                        d[0].t,
                        d.len(),
                        ee[0],
                        ee[1],
                        ee[2]
                    );
                }
                Err(why) => {
                    skipped += 1;
                    eprintln!("skipped the motion from t = {:.2} s: {why}", d[0].t);
                }
            },
        }
    }
    let start = seg
        .start_pose()
        .expect("a demonstration needs the start pose");
    let (demos, report) = to_recorded_demos(&kept, &start, &cfg.task, &cfg.sim)?;
    crate::io::create_dir(&args.out)?;
    let written = match args.format {
        RecordFormat::Npz => {
            crate::io::demos::save(&demos, &out_file)?;
            out_file
        }
        RecordFormat::Lerobot => {
            crate::io::lerobot::export(&crate::io::foreign::from_demos(&demos), &args.out)?;
            args.out.clone()
        }
    };
    eprintln!(
        "done: {} demonstrations -> {}; start_q {:?} rad, goal ({:.4}, {:.4}, {:.4}) m (spread: \
         max {:.4} m, rms {:.4} m from it); C_expert {:.4}, C_random {:.4}; {skipped} motions \
         not kept",
        report.episodes,
        written.display(),
        report.start_q,
        report.goal[0],
        report.goal[1],
        report.goal[2],
        report.goal_spread_max_m,
        report.goal_spread_rms_m,
        report.cost_expert,
        report.cost_random
    );
    if args.json {
        println!(
            "{}",
            serde_json::json!({"command": "record", "model": cfg.sim.model, "out": written,
                "rate_hz": rate, "skipped": skipped, "report": report})
        );
    }
    Ok(())
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
