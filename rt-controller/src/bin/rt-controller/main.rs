//! `rt-controller`: the real-time loop (docs/design.md §3.4). `run` executes gain tables on the arm,
//! `bench` measures the loop, `print-config` writes the default TOML.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use rt_controller::config::ArmKind;
use rt_controller::stats::Percentiles;
use rt_controller::{
    install_signal_handlers, ArmBackend, Controller, ControllerConfig, ExitReason, Mode, Pacing,
    Summary, STOP,
};
use ur5_shared::config::from_toml_file;

#[cfg(feature = "testkit")]
mod bench;
mod realtime;

const UNITS: &str = "Units: angles rad, joint velocities rad/s, torques N·m, positions m (arm base frame), times s \
(the control period task.dt is arm time; in real time the wall period is task.dt / time_compression); statistics are \
wall-clock and printed in µs (JSON: ns). Every option lives in the TOML file (`rt-controller print-config` shows all \
of them with their defaults); the flags below override it.";

#[derive(Parser)]
#[command(name = "rt-controller", version, about = "Real-time controller: executes the learner's gain tables on the arm (hil-sim over iceoryx2, or a UR robot over RTDE).", long_about = None, after_help = UNITS)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum ModeArg {
    /// Wait for the arm's answer to each command (the arm steps once per command).
    Lockstep,
    /// Real time at 1 / task.dt, optionally compressed.
    RealTime,
}

#[derive(Clone, Copy, ValueEnum)]
enum PacingArg {
    /// Sleep to absolute deadlines (clock_nanosleep, TIMER_ABSTIME).
    Deadline,
    /// Each new arm state starts a tick.
    Arm,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run episodes: reset the arm to task.start_q (rad), execute the newest gain table for
    /// task.horizon ticks of task.dt s, publish every step on learner/samples, take a new table
    /// only at the episode boundary. The arm is `hil-sim serve` over iceoryx2, a UR robot
    /// (`[arm] backend = "ur"`, `[arm.ur]`) or a UR behind ROS 2's driver (`[arm] backend =
    /// "ros2"`, `[arm.ros2]`); `[live_view] enabled = true` also publishes the goal, the
    /// end-effector point, the episode and the table version on ROS 2 topics for rviz2 or
    /// Foxglove. Exit codes: 0 done or stopped (SIGINT/SIGTERM),
    /// 2 setup error, 3 arm lost (stale for safety.give_up_after_s, its connection closed, or
    /// its stream not to be trusted: a frozen or backwards RTDE clock, a measured joint not
    /// finite or outside [limits]; arm.stream_fault says which), 4 no table (safety.no_table_timeout_s), 5 the arm stopped itself (a UR protective stop,
    /// safety mode not NORMAL, or its program ended), 6 learner and controller disagree (a
    /// table rejected for its horizon or action mode, or the learner stopped and
    /// said why; both print the same message).
    #[command(after_help = UNITS)]
    Run {
        /// TOML configuration file (all keys optional).
        #[arg(long)]
        config: Option<PathBuf>,
        /// iceoryx2 service prefix (the arm and the learner must use the same).
        #[arg(long)]
        prefix: Option<String>,
        /// Pacing mode.
        #[arg(long, value_enum)]
        mode: Option<ModeArg>,
        /// Real-time pacing.
        #[arg(long, value_enum)]
        pacing: Option<PacingArg>,
        /// Real time runs this many times faster than arm time (>= 1).
        #[arg(long)]
        time_compression: Option<f64>,
        /// Episodes to run (0 = until SIGINT/SIGTERM).
        #[arg(long)]
        episodes: Option<u64>,
        /// Seed of the exploration noise.
        #[arg(long)]
        seed: Option<u64>,
        /// The goal x,y,z (m, arm base frame): overrides task.goal. The state the controller
        /// builds holds ee − goal, so a policy table reaches the goal given here (a gain table
        /// was trained for one goal: give that one).
        #[arg(long, value_parser = parse_goal, allow_hyphen_values = true)]
        goal: Option<[f64; 3]>,
        /// Print a one-line JSON summary on stdout at the end.
        #[arg(long)]
        json: bool,
    },
    /// Benchmark the loop in-process against a kinematic arm and a learner stand-in over real
    /// iceoryx2 ports, with gain tables and then with policy tables (12-64-64-1 heads): compute
    /// per tick (law + clamp + publish), table swap and validation, IPC round trip state →
    /// command. Prints a table (µs). Needs a build with the `testkit`
    /// feature (`cargo build --release -p rt-controller --features testkit`). With
    /// `--real-time`, instead: the wake-up lateness of the period wait alone (sleep to absolute
    /// deadlines at --rate for --seconds), beside cyclictest's (rt-tests) run at the same time
    /// with the same rate, wake-ups and privileges when it is installed; needs no feature.
    #[command(after_help = UNITS)]
    Bench {
        /// Measure the wake-up lateness of the period wait (p50/p99/p99.9/max) instead of the
        /// loop, beside cyclictest when it is on PATH.
        #[arg(long)]
        real_time: bool,
        /// --real-time: wake-ups per second (Hz).
        #[arg(long, default_value_t = 1000.0)]
        rate: f64,
        /// --real-time: duration (s).
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// --real-time: SCHED_FIFO priority 1–99 for both loops (0: the normal scheduler).
        #[arg(long, default_value_t = 0)]
        fifo_priority: i32,
        /// --real-time: mlockall in both.
        #[arg(long)]
        mlockall: bool,
        /// --real-time: pin both to this CPU.
        #[arg(long)]
        cpu: Option<usize>,
        /// Episodes (each swaps in a new table at its boundary).
        #[arg(long, default_value_t = 200)]
        episodes: u64,
        /// Ticks per episode.
        #[arg(long, default_value_t = 100)]
        horizon: usize,
        /// Controller busy-poll budget per wait (ns) before it sleeps between polls.
        #[arg(long, default_value_t = 1_000_000)]
        spin_ns: u64,
        /// Also the `ros2` arm's round trip over DDS on the loopback (joint state → command),
        /// against a driver stand-in on this ROS domain.
        #[arg(long)]
        ros2_domain: Option<u16>,
        /// Print a one-line JSON summary on stdout at the end.
        #[arg(long)]
        json: bool,
    },
    /// Benchmark the `ur` arm's loop in real time against the robot (or `hil-sim ur-sim`) the
    /// configuration's `[arm.ur]` names, holding the arm where it is (no learner, no table):
    /// per RTDE package the decode + state build + reverse write, the handling's lateness
    /// against the arm's clock, and the state-to-tick latency. Prints a table (µs).
    #[command(after_help = UNITS)]
    BenchUr {
        /// TOML configuration file with `[arm] backend = "ur"` and `[arm.ur]`.
        #[arg(long)]
        config: PathBuf,
        /// How long to run (s).
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// iceoryx2 service prefix of the controller's (unused) learner ports.
        #[arg(long, default_value = "bench-ur")]
        prefix: String,
        /// Print a one-line JSON summary on stdout at the end.
        #[arg(long)]
        json: bool,
    },
    /// Print the default configuration as TOML (every option, with its default).
    PrintConfig,
}

/// `x,y,z` (m) → [x, y, z].
fn parse_goal(s: &str) -> std::result::Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("`{p}`: {e}")))
        .collect::<std::result::Result<_, _>>()?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("`{s}`: give three finite numbers x,y,z in metres")),
    }
}

fn main() {
    match real_main() {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            // One line with the cause chain; a stack backtrace only on RUST_LIB_BACKTRACE=1.
            eprintln!(
                "rt-controller: error: {}",
                ur5_shared::report::error_line(e.chain())
            );
            if std::env::var_os("RUST_LIB_BACKTRACE").is_some_and(|v| v != "0") {
                eprintln!("{}", e.backtrace());
            }
            std::process::exit(2);
        }
    }
}

/// A benchmark's table: one row of percentiles per measure, in µs.
fn print_table(rows: &[(&str, Percentiles)]) {
    let us = |v: u64| v as f64 / 1e3;
    println!("| measure (µs) | n | p50 | p99 | p99.9 | max |");
    println!("|---|---|---|---|---|---|");
    for (name, p) in rows {
        println!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.2} |",
            p.count,
            us(p.p50_ns),
            us(p.p99_ns),
            us(p.p999_ns),
            us(p.max_ns)
        );
    }
}

/// The loop phase of any arm; the summary.
fn run_loop<A: ArmBackend>(mut controller: Controller<A>) -> Summary {
    let reason = controller.run(&STOP);
    if reason == ExitReason::TaskMismatch {
        // Until the learner has read why (it exits on reading it), at most 2 s.
        controller
            .ports()
            .linger_for_status(std::time::Duration::from_secs(2));
    }
    controller.summary(reason)
}

fn real_main() -> Result<i32> {
    // iceoryx2 warns about running without its config file; IOX2_LOG_LEVEL=Warn shows it.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    match Cli::parse().cmd {
        Cmd::Run {
            config,
            prefix,
            mode,
            pacing,
            time_compression,
            episodes,
            seed,
            goal,
            json,
        } => {
            let mut cfg: ControllerConfig = match &config {
                Some(p) => {
                    from_toml_file(p).with_context(|| format!("--config {}", p.display()))?
                }
                None => ControllerConfig::default(),
            };
            if let Some(p) = prefix {
                cfg.prefix = p;
            }
            if let Some(m) = mode {
                cfg.mode = match m {
                    ModeArg::Lockstep => Mode::Lockstep,
                    ModeArg::RealTime => Mode::RealTime,
                };
            }
            if let Some(p) = pacing {
                cfg.pacing = match p {
                    PacingArg::Deadline => Pacing::Deadline,
                    PacingArg::Arm => Pacing::Arm,
                };
            }
            if let Some(c) = time_compression {
                cfg.time_compression = c;
            }
            if let Some(e) = episodes {
                cfg.episodes = e;
            }
            if let Some(s) = seed {
                cfg.seed = s;
            }
            if let Some(g) = goal {
                cfg.task.goal = g;
            }
            install_signal_handlers();
            let summary = match cfg.arm.backend {
                ArmKind::Iceoryx2 => run_loop(Controller::setup(cfg)?),
                ArmKind::Ur => run_loop(Controller::setup_ur(cfg)?),
                ArmKind::Ros2 => run_loop(Controller::setup_ros2(cfg)?),
            };
            if json {
                println!("{}", serde_json::to_string(&summary)?);
            }
            Ok(match summary.exit_reason {
                ExitReason::EpisodesDone | ExitReason::Stopped => 0,
                ExitReason::ArmLost => 3,
                ExitReason::NoTable => 4,
                ExitReason::ArmStopped => 5,
                ExitReason::TaskMismatch | ExitReason::LearnerStopped => 6,
            })
        }
        Cmd::BenchUr {
            config,
            seconds,
            prefix,
            json,
        } => {
            let mut cfg: ControllerConfig = from_toml_file(&config)
                .with_context(|| format!("--config {}", config.display()))?;
            anyhow::ensure!(
                cfg.arm.backend == ArmKind::Ur,
                "--config {}: bench-ur needs [arm] backend = \"ur\"",
                config.display()
            );
            anyhow::ensure!(
                seconds.is_finite() && seconds > 0.0,
                "--seconds {seconds} must be > 0"
            );
            cfg.prefix = prefix;
            cfg.mode = Mode::RealTime;
            cfg.pacing = Pacing::Arm;
            cfg.wait_for_learner = false;
            cfg.episodes = 0;
            cfg.safety.no_table_timeout_s = seconds;
            install_signal_handlers();
            let mut controller = Controller::setup_ur(cfg)?;
            let reason = controller.run(&STOP);
            let summary = controller.summary(reason);
            let r = controller.arm().report();
            println!(
                "rt-controller bench-ur: {seconds} s, real time, arm held (no table); {} packages, {} commands written, {} keepalives; exit {:?}",
                r.packages, r.commands_written, r.keepalives, reason
            );
            let mut rows = vec![("package: decode + state (FK) + reverse write", r.cycle)];
            if let Some(l) = r.lateness {
                rows.push(("package handled, late against the arm's clock", l));
            }
            rows.push(("state → controller tick (arm pacing)", summary.wake));
            print_table(&rows);
            if json {
                println!("{}", serde_json::to_string(&summary)?);
            }
            Ok(if r.lost.is_some() || r.robot_stop.is_some() { 3 } else { 0 })
        }
        Cmd::Bench {
            real_time: true,
            rate,
            seconds,
            fifo_priority,
            mlockall,
            cpu,
            json,
            ..
        } => {
            let setup = rt_controller::config::RtSetup {
                mlockall,
                fifo_priority,
                cpu,
            };
            let r = realtime::run(rate, seconds, &setup)?;
            if json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                realtime::print(&r, &setup);
            }
            Ok(0)
        }
        #[cfg(not(feature = "testkit"))]
        Cmd::Bench { .. } => anyhow::bail!(
            "this rt-controller was built without the in-process arm and learner the benchmark runs against; build it with `cargo build --release -p rt-controller --features testkit`"
        ),
        #[cfg(feature = "testkit")]
        Cmd::Bench {
            episodes,
            horizon,
            spin_ns,
            ros2_domain,
            json,
            ..
        } => {
            let reach = ur5_shared::config::TaskConfig::default;
            let r = bench::run(episodes, horizon, spin_ns, bench::Kind::Gains, reach())?;
            let ros2 = ros2_domain
                .map(|d| bench::run_ros2(episodes, horizon, spin_ns, d))
                .transpose()?;
            let p = bench::run(episodes, horizon, spin_ns, bench::Kind::Policy, reach())?;
            let r6 = bench::run(episodes, horizon, spin_ns, bench::Kind::Gains, rt_controller::testkit::pose_task(horizon))?;
            let p6 = bench::run(episodes, horizon, spin_ns, bench::Kind::Policy, rt_controller::testkit::pose_task(horizon))?;
            let alone = bench::policy_action_alone(20_000);
            let law3 = bench::controller_action_alone(&ur5_shared::StateLayout::REACH3, 20_000);
            let law6 = bench::controller_action_alone(&ur5_shared::StateLayout::POSE6, 20_000);
            println!("rt-controller bench: {} + {} episodes × {} ticks, lockstep, kinematic arm in-process, iceoryx2 ipc; gain tables, then policy tables (heads 12-{}-1, {} parameters)", r.episodes, p.episodes, horizon,
                bench::POLICY_HIDDEN.map(|h| h.to_string()).join("-"), ur5_shared::policy::flat_len(ur5_shared::DX, ur5_shared::DU, &bench::POLICY_HIDDEN));
            print_table(&[
                ("gain table: tick compute (law + clamp + command + sample), 3 joints and a point", r.compute),
                ("gain table: tick compute, 6 joints and a pose (dX 30, dU 6)", r6.compute),
                ("gain table: swap (copy used part + flip)", r.swap),
                ("gain table: the law alone, 3 joints and a point (dX 12, dU 3)", law3),
                ("gain table: the law alone, 6 joints and a pose (dX 30, dU 6)", law6),
                ("gain table: validation", r.validate),
                ("gain table: intake (receive + copy + validate + flip)", r.intake),
                ("gain table: IPC round trip state → command", r.round_trip),
                ("policy: tick compute (MLP + clamp + command + sample), 3 joints and a point", p.compute),
                ("policy: tick compute, 6 joints and a pose (heads 30-64-64-1)", p6.compute),
                ("policy: policy_action alone, warm cache", alone),
                ("policy: swap (copy used part + flip)", p.swap),
                ("policy: validation", p.validate),
                ("policy: intake (receive + copy + validate + flip)", p.intake),
                ("policy: IPC round trip state → command", p.round_trip),
            ]);
            if let Some(d) = ros2 {
                println!("ros2 arm: real time, arm pacing, a driver stand-in over DDS (RustDDS) on the loopback");
                print_table(&[("gain table: DDS round trip joint state → command", d)]);
            }
            if json {
                println!("{}", serde_json::json!({"gains": r, "policy": p, "policy_action_alone": alone, "law_alone_reach3": law3, "law_alone_pose6": law6, "gains_pose6": r6, "policy_pose6": p6, "ros2_round_trip": ros2}));
            }
            Ok(0)
        }
        Cmd::PrintConfig => {
            // Every option written out, [limits] as the default model's own.
            let c = ControllerConfig::default();
            let c = ControllerConfig {
                limits: Some(c.limits()),
                ..c
            };
            // [arm.ur]'s keys a configuration carries only when set (so that other
            // configurations print and hash as before): written out under its header.
            let u = &c.arm.ur;
            let mut ur = toml::Table::new();
            ur.insert("model".into(), u.model.name().into());
            ur.insert("dashboard_port".into(), i64::from(u.dashboard_port).into());
            ur.insert("check_model".into(), u.check_model.into());
            ur.insert("bring_up".into(), u.bring_up.into());
            ur.insert(
                "recover_protective_stop".into(),
                u.recover_protective_stop.into(),
            );
            ur.insert(
                "servoj_lookahead_time_s".into(),
                u.servoj_lookahead_time_s.into(),
            );
            ur.insert("servoj_gain".into(), u.servoj_gain.into());
            let printed = toml::Value::try_from(u)?;
            ur.retain(|k, _| !printed.as_table().is_some_and(|t| t.contains_key(k)));
            let text = toml::to_string(&c)?.replacen(
                "[arm.ur]\n",
                &format!("[arm.ur]\n{}", toml::to_string(&ur)?),
                1,
            );
            print!("{text}");
            // The sections a configuration carries only when they differ from their defaults
            // (so that other configurations print and hash as before): written out here too.
            let mut arm = toml::Table::new();
            arm.insert("ros2".into(), toml::Value::try_from(&c.arm.ros2)?);
            let mut more = toml::Table::new();
            more.insert("arm".into(), arm.into());
            more.insert("live_view".into(), toml::Value::try_from(&c.live_view)?);
            print!("\n{}", toml::to_string(&more)?);
            Ok(0)
        }
    }
}
