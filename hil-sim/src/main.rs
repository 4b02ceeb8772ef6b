//! `hil-sim`: the simulated UR arm (the UR5 unless `--model` or `[sim] model` names another).
//!
//! Subcommands:
//! - `demo`: moves the arm through a few goal angles and prints the trajectory;
//! - `inspect`: one JSON object describing the model at a given state (for debugging a URDF);
//! - `bench`: physics throughput;
//! - `serve`: the arm behind `arm/state` / `arm/command` over iceoryx2 (see `hil_sim::serve`);
//! - `ur-sim`: the arm as a UR controller: RTDE and the secondary interface (see
//!   `hil_sim::ur_sim`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use serde::{Deserialize, Serialize};
use ur5_shared::config::{
    from_toml_file, from_toml_file_over, parse_triple as parse3, SimConfig, TaskConfig,
};
use ur5_shared::UrModel;

use hil_sim::Ur5Sim;

mod inspect;
use inspect::{inspect, parse_joints, JointValues};

#[derive(Parser)]
#[command(
    name = "hil-sim",
    version,
    about = "Simulated UR arm (rapier3d multibody from a URDF) for LQR+GAIfO."
)]
struct Cli {
    /// Arm model: ur3, ur5, ur10, ur3e, ur5e, ur7e, ur10e, ur12e, ur16e, ur15, ur18, ur20 or ur30
    /// (default: the config's `[sim] model`, else ur5). Brings the model's URDF and its default
    /// start pose, goal, wrist lock, end-effector offset and servo gains (docs/ur.md); a config
    /// file that names another model is refused.
    #[arg(long, global = true)]
    model: Option<UrModel>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Move the arm through a few goal joint angles (rad) and print the trajectory, one line per
    /// control period: t (s), q (rad), ee (m, base frame), ee − goal distance (m).
    Demo {
        /// TOML file with optional [task] and [sim] tables (see README).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Goal joint angles, semicolon-separated triples "q1,q2,q3;q1,q2,q3" (rad); each is held
        /// for 2 s.
        #[arg(long, default_value = "0.5,-1.2,1.5;-0.4,-1.0,1.0;0.0,-2.0,2.4")]
        goals: String,
        /// Print a one-line JSON summary at the end.
        #[arg(long)]
        json: bool,
    },
    /// Print one JSON object: model, joints (3 or 6 active), q (rad, all six), ee_pos (m, the
    /// flange's: no end-effector offset unless the model's default has one), ee_vel (m/s),
    /// flange_pose (UR's p[x, y, z, rx, ry, rz] of the flange, wrist_3_link's frame: m and a
    /// rotation vector in rad, base frame, as the teach pendant shows it), qdd (rad/s², one
    /// physics substep under raw torques τ, servo bypassed, gravity on), wrist_q (rad),
    /// ee_link, urdf.
    Inspect {
        /// Joint angles (rad): q1,q2,q3 (wrist locked at the model's wrist_q) or q1,…,q6 (all
        /// six joints active).
        #[arg(long, value_parser = parse_joints, allow_hyphen_values = true)]
        q: JointValues,
        /// Joint velocities (rad/s), as many as --q (default: zeros).
        #[arg(long, value_parser = parse_joints, allow_hyphen_values = true)]
        qd: Option<JointValues>,
        /// Raw joint torques (N·m), as many as --q (default: zeros).
        #[arg(long, value_parser = parse_joints, allow_hyphen_values = true)]
        tau: Option<JointValues>,
        /// Physics substep (s) for qdd.
        #[arg(long, default_value_t = 1e-4)]
        substep: f64,
        /// URDF file (default: the model's bundled URDF, hil-sim/urdf/<model>.urdf).
        #[arg(long)]
        urdf: Option<PathBuf>,
    },
    /// Physics throughput: steps per second for 10 s of simulated time at the physics rate (best
    /// and median of --reps runs, as ../shared/tools/mujoco_ur5.py reports MuJoCo's best of 5),
    /// and 100-step episodes per second. Beside MuJoCo on a six-joint UR5e in one command:
    /// scripts/sim-reference/bench_mujoco.py.
    Bench {
        /// Active joints: 3 (wrist locked, merged into the forearm) or 6.
        #[arg(long, default_value_t = 3)]
        joints: usize,
        /// Episodes to time.
        #[arg(long, default_value_t = 5)]
        episodes: usize,
        /// Runs of 10 s simulated time.
        #[arg(long, default_value_t = 5)]
        reps: usize,
        /// Print a one-line JSON summary at the end.
        #[arg(long)]
        json: bool,
    },
    /// Serve the simulated arm over iceoryx2 (`{prefix}/arm/state` out, `{prefix}/arm/command`
    /// in) until SIGINT/SIGTERM. Lockstep: each command advances task.dt s of arm time (a reset
    /// teleports to the command's reset pose, rad) and is answered by one state. Real time: the
    /// arm's own clock publishes a state every serve.state_period_s s of arm time
    /// (wall: / time_compression) and holds the last command (zero-order hold); without a command
    /// for serve.command_timeout_s (wall s) it holds and reports a stale command. States: q (rad),
    /// q̇ (rad/s), ee (m, base frame), ee velocity (m/s), stamps CLOCK_MONOTONIC ns.
    Serve {
        /// TOML file with optional [task], [sim] and [serve] tables (every option).
        #[arg(long)]
        config: Option<PathBuf>,
        /// iceoryx2 service prefix (overrides serve.prefix); the controller must use the same.
        #[arg(long)]
        prefix: Option<String>,
        /// lockstep or real-time (overrides serve.mode).
        #[arg(long)]
        mode: Option<String>,
        /// Real time runs this many times faster than wall time (overrides serve.time_compression).
        #[arg(long)]
        time_compression: Option<f64>,
        /// Print a one-line JSON summary at the end.
        #[arg(long)]
        json: bool,
    },
    /// The simulated arm as a UR controller (docs/design.md §3.10): an RTDE server and the
    /// secondary interface, which runs this project's external_control program
    /// (rt-controller/urscript/external_control.script) and refuses other scripts. Prints one
    /// JSON line with the bound addresses on stdout, then serves until killed.
    UrSim(UrSimArgs),
    /// The simulated arm as Universal Robots' ROS 2 driver presents it, over DDS (docs/design.md
    /// §3.13): `/joint_states` at 500 Hz, `/forward_position_controller/commands` taken, the
    /// driver's robot and safety modes. Real time; serves until killed.
    Ros2Sim(Ros2SimArgs),
    /// Write a playback file for `ur-sim --playback` of human-like reaches: per reach a rest
    /// of at least 1 s at the start pose, a minimum-jerk reach of seeded duration (1.2–2 s)
    /// into the goal region (joint goal by IK of the model's kinematics) overshooting it by
    /// 2–6 %, a corrective submovement, a rest of at least 1 s there, a return to (within
    /// 2 mrad of) the start pose; a final rest. Tremor (8–12 Hz, 0.2 mrad) rides on the
    /// motions. With `[task] joints = 6` and `goal_pose` the whole arm reaches to the pose
    /// (the wrist moving and trembling too; orientation within 3 mrad per axis). Prints one
    /// JSON line: rows, duration, motions.
    PlaybackGen(PlaybackGenArgs),
}

/// Options of `hil-sim ur-sim` (see `hil_sim::ur_sim`).
#[derive(clap::Args)]
struct UrSimArgs {
    /// TOML file with optional [task] and [sim] tables (start pose: task.start_q).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Listen address (loopback only).
    #[arg(long, default_value = "127.0.0.1")]
    host: std::net::Ipv4Addr,
    /// RTDE port (0: any free port).
    #[arg(long, default_value_t = 30004)]
    rtde_port: u16,
    /// Secondary-interface port (0: any free port).
    #[arg(long, default_value_t = 30002)]
    secondary_port: u16,
    /// Dashboard-server port (0: any free port).
    #[arg(long, default_value_t = 29999)]
    dashboard_port: u16,
    /// Start with the robot powered off (robot mode POWER_OFF) until the dashboard's
    /// `power on` and `brake release` (to test a driver's bring-up).
    #[arg(long)]
    start_powered_off: bool,
    /// Controller generation: e (e-Series, 500 Hz, 5.x) or cb3 (125 Hz, 3.x). Default: the
    /// model's own (cb3 for ur3, ur5 and ur10, e for the others).
    #[arg(long)]
    series: Option<String>,
    /// servoj's tracking: ideal (the target is the servo's goal at once; lookahead_time and
    /// gain change nothing) or tracking (smoothing over lookahead_time, then proportional
    /// tracking at gain; docs/ur.md, "servoj").
    #[arg(long, default_value = "ideal")]
    servoj: String,
    /// Lockstep: each reverse command advances one arm cycle, then that cycle's data
    /// package is sent (deterministic tests).
    #[arg(long)]
    lockstep: bool,
    /// Real time runs this many times faster than wall time.
    #[arg(long, default_value_t = 1.0)]
    time_compression: f64,
    /// Fault: refuse RTDE protocol version 2.
    #[arg(long)]
    fault_refuse_v2: bool,
    /// Fault: refuse every protocol version.
    #[arg(long)]
    fault_refuse_versions: bool,
    /// Fault: a text message before every answer.
    #[arg(long)]
    fault_text_before_reply: bool,
    /// Fault: refuse START.
    #[arg(long)]
    fault_refuse_start: bool,
    /// Fault: per three data packages, one merged with a repeat of the previous in one
    /// write and one split over two writes.
    #[arg(long)]
    fault_merge_split: bool,
    /// Fault: every N-th data package is late by --fault-delay-ms.
    #[arg(long, default_value_t = 0)]
    fault_delay_every: u64,
    /// Fault: delay (ms) of a late package.
    #[arg(long, default_value_t = 50)]
    fault_delay_ms: u64,
    /// Fault: every N-th data package is dropped.
    #[arg(long, default_value_t = 0)]
    fault_drop_every: u64,
    /// Fault: close the RTDE connection after N data packages.
    #[arg(long, default_value_t = 0)]
    fault_disconnect_after: u64,
    /// Fault: a protective stop (as on a detected collision) after N arm cycles.
    #[arg(long, default_value_t = 0)]
    fault_protective_stop_after: u64,
    /// Fault: from the N-th data package on, the RTDE timestamp stops advancing.
    #[arg(long, default_value_t = 0)]
    fault_frozen_clock_after: u64,
    /// Fault: from the N-th data package on, the RTDE timestamp goes back one cycle per package.
    #[arg(long, default_value_t = 0)]
    fault_backwards_clock_after: u64,
    /// Fault: from the N-th data package on, the base joint's actual_q is NaN.
    #[arg(long, default_value_t = 0)]
    fault_nan_q_after: u64,
    /// Fault: from the N-th data package on, the base joint's actual_q reads 100 rad.
    #[arg(long, default_value_t = 0)]
    fault_q_out_of_limits_after: u64,
    /// Fault: answer every RTDE request with a text message only (and keep sending texts).
    #[arg(long)]
    fault_text_only: bool,
    /// Move the arm as by hand (freedrive) through the motions of a CSV file with the header
    /// `t,q0,q1,q2,q3,q4,q5` (arm time s from 0, six joint angles rad; docs/data.md): RTDE
    /// reports the file's joint angles and velocities, a program's servo targets are ignored,
    /// and after the last row the arm holds the last pose. Real time only (not --lockstep);
    /// --time-compression plays it faster.
    #[arg(long, value_name = "FILE.csv")]
    playback: Option<PathBuf>,
    /// Active joints: 3 (the wrist locked at the model's wrist_q; servoj's wrist targets are
    /// ignored with a warning) or 6 (servoj moves all six joints).
    #[arg(long, default_value_t = 3)]
    joints: usize,
}

/// Options of `hil-sim ros2-sim` (see `hil_sim::ros2_sim`).
#[derive(clap::Args)]
struct Ros2SimArgs {
    /// TOML file with optional [task] and [sim] tables (start pose: task.start_q).
    #[arg(long)]
    config: Option<PathBuf>,
    /// ROS_DOMAIN_ID.
    #[arg(long, default_value_t = 0)]
    domain_id: u16,
    /// DDS discovery: loopback (this machine only, unicast) or all (multicast on every
    /// interface).
    #[arg(long, default_value = "loopback")]
    network: String,
    /// Joint states per second (500: e-Series, 125: CB3).
    #[arg(long, default_value_t = 500.0)]
    rate: f64,
    /// A namespace before the driver's topics (`/ns` gives `/ns/joint_states` …); none by
    /// default, as the driver.
    #[arg(long, default_value = "")]
    namespace: String,
    /// Real time runs this many times faster than wall time.
    #[arg(long, default_value_t = 1.0)]
    time_compression: f64,
    /// Fault: a protective stop N arm cycles after the first command.
    #[arg(long, default_value_t = 0)]
    fault_protective_stop_after: u64,
    /// Fault: no joint states from N arm cycles after the first command on …
    #[arg(long, default_value_t = 0)]
    fault_silence_after: u64,
    /// … for this many cycles.
    #[arg(long, default_value_t = 0)]
    fault_silence_cycles: u64,
}

/// Options of `hil-sim playback-gen`.
#[derive(clap::Args)]
struct PlaybackGenArgs {
    /// TOML file with optional [task] and [sim] tables: the start pose (task.start_q), the
    /// goal region's centre (task.goal), or with joints = 6 a pose goal (task.goal_pose), the
    /// wrist lock and end-effector offset of [sim].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Reaches.
    #[arg(long, default_value_t = 5)]
    motions: usize,
    /// Seed: the same seed and settings give the same file, bit for bit.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Half side of the cubic goal region around task.goal (m) each reach aims into.
    #[arg(long, default_value_t = 0.005)]
    goal_half_side: f64,
    /// Rows per second of the file (Hz, 10 to 1000).
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Output file (new: an existing one is never replaced).
    #[arg(long, value_name = "FILE.csv")]
    out: PathBuf,
}

impl UrSimArgs {
    /// The options for an arm of `model`.
    fn config(&self, model: UrModel) -> Result<hil_sim::ur_sim::UrSimConfig> {
        use hil_sim::ur_sim::{Faults, Series, UrSimConfig};
        let series = match self.series.as_deref() {
            None if model.is_e_series() => Series::E,
            None => Series::Cb3,
            Some("e" | "e-series") => Series::E,
            Some("cb3") => Series::Cb3,
            Some(other) => anyhow::bail!("--series {other}: expected e or cb3"),
        };
        let servoj = match self.servoj.as_str() {
            "ideal" => hil_sim::ur_sim::plant::ServojModel::Ideal,
            "tracking" => hil_sim::ur_sim::plant::ServojModel::Tracking,
            other => anyhow::bail!("--servoj {other}: expected ideal or tracking"),
        };
        Ok(UrSimConfig {
            host: self.host,
            rtde_port: self.rtde_port,
            secondary_port: self.secondary_port,
            dashboard_port: Some(self.dashboard_port),
            start_powered_off: self.start_powered_off,
            servoj,
            series,
            lockstep: self.lockstep,
            stopped_clock: true,
            time_compression: self.time_compression,
            faults: Faults {
                refuse_v2: self.fault_refuse_v2,
                refuse_versions: self.fault_refuse_versions,
                text_before_reply: self.fault_text_before_reply,
                refuse_start: self.fault_refuse_start,
                merge_split: self.fault_merge_split,
                delay_every: self.fault_delay_every,
                delay_ms: self.fault_delay_ms,
                drop_every: self.fault_drop_every,
                disconnect_after: self.fault_disconnect_after,
                protective_stop_after: self.fault_protective_stop_after,
                frozen_clock_after: self.fault_frozen_clock_after,
                backwards_clock_after: self.fault_backwards_clock_after,
                nan_q_after: self.fault_nan_q_after,
                q_out_of_limits_after: self.fault_q_out_of_limits_after,
                text_only: self.fault_text_only,
            },
            playback: self.playback.clone(),
            joints: self.joints,
        })
    }
}

/// A config file for hil-sim: both tables optional.
#[derive(Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct FileConfig {
    task: TaskConfig,
    sim: SimConfig,
}

/// A failed command prints one line, `hil-sim: error: ` and the cause chain, without a stack
/// backtrace even where `RUST_BACKTRACE` is set; `RUST_LIB_BACKTRACE=1` asks for one.
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "hil-sim: error: {}",
                ur5_shared::report::error_line(e.chain())
            );
            if std::env::var_os("RUST_LIB_BACKTRACE").is_some_and(|v| v != "0") {
                eprintln!("{}", e.backtrace());
            }
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let cli = Cli::parse();
    let model = cli.model;
    match cli.cmd {
        Cmd::Demo {
            config,
            goals,
            json,
        } => demo(config, model, &goals, json),
        Cmd::Inspect {
            q,
            qd,
            tau,
            substep,
            urdf,
        } => inspect(model.unwrap_or_default(), q, qd, tau, substep, urdf),
        Cmd::Bench {
            joints,
            episodes,
            reps,
            json,
        } => bench(model.unwrap_or_default(), joints, episodes, reps, json),
        Cmd::Serve {
            config,
            prefix,
            mode,
            time_compression,
            json,
        } => serve(config, model, prefix, mode, time_compression, json),
        Cmd::UrSim(args) => ur_sim(args, model),
        Cmd::Ros2Sim(args) => ros2_sim(args, model),
        Cmd::PlaybackGen(args) => playback_gen(args, model),
    }
}

fn playback_gen(args: PlaybackGenArgs, model: Option<UrModel>) -> Result<()> {
    use hil_sim::ur_sim::playback::{generate, GenConfig};
    let file = load(args.config.clone(), model)?;
    anyhow::ensure!(
        file.task.joints == 3 || file.task.goal_pose.is_some(),
        "[task] joints = 6 without goal_pose: playback-gen's whole-arm reaches go to a pose; \
         give [task] goal_pose = [x, y, z, rx, ry, rz] (or joints = 3 for reaches to a point)"
    );
    let six = file.task.start_six(&file.sim.wrist_q);
    let cfg = GenConfig {
        model: file.sim.model,
        start_q: file.task.start_arm_joints(),
        // A pose goal's start pose has its own wrist angles.
        wrist_q: [six[3], six[4], six[5]],
        ee_offset: file.sim.ee_offset,
        goal: file.task.goal,
        goal_pose: file.task.goal_pose,
        goal_half_side: args.goal_half_side,
        motions: args.motions,
        rate_hz: args.rate,
        seed: args.seed,
    };
    // Checked before generating (a file, a FIFO or a device is never replaced), and again by
    // the write itself (another process may create it meanwhile).
    let exists = |out: &std::path::Path| {
        anyhow::anyhow!(
            "--out {} exists: playback-gen writes a new file and never replaces one (a file, a \
             FIFO, a device); delete it or choose another --out",
            out.display()
        )
    };
    if std::fs::symlink_metadata(&args.out).is_ok() {
        return Err(exists(&args.out));
    }
    let p = generate(&cfg)?;
    match ur5_shared::atomic_file::write_new(&args.out, p.to_csv().as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Err(exists(&args.out)),
        r => r.with_context(|| format!("writing {}", args.out.display()))?,
    }
    println!(
        "{}",
        serde_json::json!({"command": "playback-gen", "model": cfg.model, "rows": p.t.len(),
            "duration_s": p.duration(), "motions": cfg.motions, "seed": cfg.seed, "out": args.out})
    );
    Ok(())
}

fn ur_sim(args: UrSimArgs, model: Option<UrModel>) -> Result<()> {
    use std::io::Write;
    let file = load(args.config.clone(), model)?;
    let cfg = args.config(file.sim.model)?;
    let handle = hil_sim::ur_sim::spawn(&file.task, &file.sim, &cfg)?;
    let dashboard = handle.dashboard_addr.map(|a| a.to_string());
    println!(
        "{}",
        serde_json::json!({"rtde": handle.rtde_addr.to_string(), "secondary": handle.secondary_addr.to_string(),
            "dashboard": dashboard, "model": file.sim.model.name(),
            "series": cfg.series, "lockstep": cfg.lockstep, "time_compression": cfg.time_compression})
    );
    std::io::stdout().flush()?;
    eprintln!(
        "hil-sim ur-sim: {} on a {:?} controller, RTDE on {}, secondary interface on {}, dashboard on {}, {}",
        file.sim.model,
        cfg.series,
        handle.rtde_addr,
        handle.secondary_addr,
        dashboard.as_deref().unwrap_or("-"),
        if cfg.lockstep {
            "lockstep".to_string()
        } else {
            format!("real time x{}", cfg.time_compression)
        }
    );
    handle.wait();
    Ok(())
}

fn ros2_sim(args: Ros2SimArgs, model: Option<UrModel>) -> Result<()> {
    use std::io::Write;
    let file = load(args.config.clone(), model)?;
    let network = match args.network.as_str() {
        "loopback" => ur5_ros2::Network::Loopback,
        "all" => ur5_ros2::Network::All,
        other => anyhow::bail!("--network {other}: loopback or all"),
    };
    let d = hil_sim::ros2_sim::Ros2SimConfig::default();
    let ns = args.namespace.trim_end_matches('/');
    let cfg = hil_sim::ros2_sim::Ros2SimConfig {
        domain_id: args.domain_id,
        network,
        joint_states_topic: format!("{ns}{}", d.joint_states_topic),
        command_topic: format!("{ns}{}", d.command_topic),
        robot_mode_topic: format!("{ns}{}", d.robot_mode_topic),
        safety_mode_topic: format!("{ns}{}", d.safety_mode_topic),
        rate_hz: args.rate,
        time_compression: args.time_compression,
        fault_protective_stop_after: args.fault_protective_stop_after,
        fault_silence_after: args.fault_silence_after,
        fault_silence_cycles: args.fault_silence_cycles,
        ..Default::default()
    };
    let handle = hil_sim::ros2_sim::spawn(&file.task, &file.sim, &cfg)?;
    println!(
        "{}",
        serde_json::json!({"domain_id": cfg.domain_id, "network": cfg.network,
            "joint_states": cfg.joint_states_topic, "commands": cfg.command_topic,
            "model": file.sim.model.name(), "rate_hz": cfg.rate_hz,
            "time_compression": cfg.time_compression})
    );
    std::io::stdout().flush()?;
    eprintln!(
        "hil-sim ros2-sim: {} on ROS domain {} ({:?}), {} at {} Hz, commands on {}, real time x{}",
        file.sim.model,
        cfg.domain_id,
        cfg.network,
        cfg.joint_states_topic,
        cfg.rate_hz,
        cfg.command_topic,
        cfg.time_compression
    );
    handle.wait();
    Ok(())
}

/// A config file of `T` (with `[task]` and `[sim]` tables) for `--model`: without `--model` the
/// file alone (its `[sim] model` brings that model's defaults); with it, the file layered over
/// `base(model)` and refused if it names another model.
fn load_for_model<T>(
    config: Option<&std::path::Path>,
    model: Option<UrModel>,
    base: impl Fn(UrModel) -> T,
    sim: impl Fn(&T) -> &SimConfig,
) -> Result<T>
where
    T: Serialize + serde::de::DeserializeOwned + Default,
{
    let Some(m) = model else {
        return Ok(match config {
            Some(p) => from_toml_file(p)?,
            None => T::default(),
        });
    };
    let Some(p) = config else {
        return Ok(base(m));
    };
    let cfg: T = from_toml_file_over(p, base(m))?;
    anyhow::ensure!(
        sim(&cfg).model == m,
        "--model {m} but {} names model {} in [sim]: drop one or make them agree",
        p.display(),
        sim(&cfg).model
    );
    Ok(cfg)
}

fn load(config: Option<PathBuf>, model: Option<UrModel>) -> Result<FileConfig> {
    let cfg: FileConfig = load_for_model(
        config.as_deref(),
        model,
        |m| FileConfig {
            task: TaskConfig::for_model(m),
            sim: SimConfig::for_model(m),
        },
        |c| &c.sim,
    )?;
    cfg.task.validate()?;
    cfg.sim.validate()?;
    Ok(cfg)
}

fn demo(config: Option<PathBuf>, model: Option<UrModel>, goals: &str, json: bool) -> Result<()> {
    let cfg = load(config, model)?;
    let goals: Vec<[f64; 3]> = goals
        .split(';')
        .map(parse3)
        .collect::<Result<_, _>>()
        .map_err(anyhow::Error::msg)
        .context("--goals")?;
    let mut sim = Ur5Sim::new(cfg.sim.clone(), cfg.task.dt)?;
    let mut obs = sim.reset(cfg.task.start_arm_joints(), cfg.task.goal)?;
    let dist = |o: &hil_sim::Observation, g: [f64; 3]| {
        ((o.ee_pos[0] - g[0]).powi(2) + (o.ee_pos[1] - g[1]).powi(2) + (o.ee_pos[2] - g[2]).powi(2))
            .sqrt()
    };
    println!(
        "# t_s  q1 q2 q3 (rad)  goal1 goal2 goal3 (rad)  ee_x ee_y ee_z (m)  |ee-goal_point| (m)"
    );
    let steps_per_goal = (2.0 / cfg.task.dt).round() as usize;
    let mut t = 0.0;
    let mut worst_final = 0.0f64;
    for g in &goals {
        for _ in 0..steps_per_goal {
            obs = sim.step(*g);
            t += cfg.task.dt;
            println!(
                "{t:6.2}  {:+.4} {:+.4} {:+.4}  {:+.4} {:+.4} {:+.4}  {:+.4} {:+.4} {:+.4}  {:.4}",
                obs.q[0],
                obs.q[1],
                obs.q[2],
                g[0],
                g[1],
                g[2],
                obs.ee_pos[0],
                obs.ee_pos[1],
                obs.ee_pos[2],
                dist(&obs, cfg.task.goal)
            );
        }
        let err = (0..3).map(|j| (obs.q[j] - g[j]).abs()).fold(0.0, f64::max);
        eprintln!(
            "goal {g:?} rad: final joint error {err:.2e} rad after {:.1} s",
            steps_per_goal as f64 * cfg.task.dt
        );
        worst_final = worst_final.max(err);
    }
    if json {
        println!(
            "{}",
            serde_json::json!({"command": "demo", "goals": goals.len(), "sim_time_s": t,
                "worst_final_joint_error_rad": worst_final, "max_abs_torque_nm": sim.max_abs_torque()})
        );
    }
    Ok(())
}

fn bench(model: UrModel, joints: usize, episodes: usize, reps: usize, json: bool) -> Result<()> {
    let task = TaskConfig::for_model(model);
    let mut sim = Ur5Sim::with_joints(SimConfig::for_model(model), task.dt, joints)?;
    let wrist = sim.model().wrist_q;
    // The goal of every joint at time t (s): the three-joint bench's goals, and at six joints
    // the wrist swinging ±0.3 rad about its rest angles.
    let goal = |t: f64| {
        let s = t.sin();
        [
            0.5 * s,
            -1.5 + 0.3 * s,
            1.8 - 0.3 * s,
            wrist[0] + 0.3 * s,
            wrist[1] - 0.3 * s,
            wrist[2] + 0.3 * s,
        ]
    };
    let start: Vec<f64> = {
        let s = task.start_q;
        [s[0], s[1], s[2], wrist[0], wrist[1], wrist[2]][..joints].to_vec()
    };
    let physics_dt = sim.config().physics_dt;
    // 10 s of simulated time, servo tracking a moving goal; the same run `reps` times.
    let steps = (10.0 / task.dt).round() as usize;
    let mut rates = Vec::with_capacity(reps.max(1));
    for _ in 0..reps.max(1) {
        sim.reset_all(&start, task.goal)?;
        let t0 = Instant::now();
        for i in 0..steps {
            sim.step_all(&goal(i as f64 * task.dt)[..joints]);
        }
        rates.push(10.0 / physics_dt / t0.elapsed().as_secs_f64());
    }
    rates.sort_by(f64::total_cmp);
    let steps_per_s = rates[rates.len() - 1];
    let median_steps_per_s = rates[rates.len() / 2];
    let rt_factor = steps_per_s * physics_dt;

    let t0 = Instant::now();
    for e in 0..episodes {
        sim.reset_all(&start, task.goal)?;
        for i in 0..task.horizon {
            sim.step_all(&goal((i + e) as f64 * task.dt)[..joints]);
        }
    }
    let ep_per_s = episodes as f64 / t0.elapsed().as_secs_f64();
    println!("| measure ({model}, {joints} active joints) | value |");
    println!("|---|---|");
    println!(
        "| physics steps/s (dt = {physics_dt} s, servo on), best of {} runs of 10 s | {steps_per_s:.0} |",
        rates.len()
    );
    println!("| physics steps/s, median of the runs | {median_steps_per_s:.0} |");
    println!("| real-time factor (best) | {rt_factor:.1}x |");
    println!("| {}-step episodes/s | {ep_per_s:.2} |", task.horizon);
    if json {
        println!(
            "{}",
            serde_json::json!({"command": "bench", "model": model.name(), "joints": joints,
                "physics_dt_s": physics_dt, "substeps": sim.config().substeps,
                "physics_steps_per_s": steps_per_s,
                "median_physics_steps_per_s": median_steps_per_s, "runs": rates.len(), "real_time_factor": rt_factor,
                "episodes_per_s": ep_per_s})
        );
    }
    Ok(())
}

fn serve(
    config: Option<PathBuf>,
    model: Option<UrModel>,
    prefix: Option<String>,
    mode: Option<String>,
    time_compression: Option<f64>,
    json: bool,
) -> Result<()> {
    use hil_sim::serve::{ServeFile, ServeMode};
    // iceoryx2 warns about running without its config file; IOX2_LOG_LEVEL=Warn shows it.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let mut cfg: ServeFile = load_for_model(
        config.as_deref(),
        model,
        |m| ServeFile {
            task: TaskConfig::for_model(m),
            sim: SimConfig::for_model(m),
            ..ServeFile::default()
        },
        |c| &c.sim,
    )?;
    if let Some(p) = prefix {
        cfg.serve.prefix = p;
    }
    if let Some(m) = mode {
        cfg.serve.mode = match m.as_str() {
            "lockstep" => ServeMode::Lockstep,
            "real-time" | "real_time" => ServeMode::RealTime,
            other => anyhow::bail!("--mode {other}: expected lockstep or real-time"),
        };
    }
    if let Some(c) = time_compression {
        cfg.serve.time_compression = c;
    }
    let never = std::sync::atomic::AtomicBool::new(false);
    let summary = hil_sim::serve::serve(&cfg.task, &cfg.sim, &cfg.serve, &never)?;
    eprintln!(
        "hil-sim serve: {} commands ({} resets, {} holds, {} rejected), {} states, {:.1} s simulated",
        summary.commands, summary.resets, summary.holds, summary.rejected_commands, summary.states, summary.sim_time_s
    );
    if json {
        println!("{}", serde_json::to_string(&summary)?);
    }
    Ok(())
}
