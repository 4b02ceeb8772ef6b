//! `hil-sim ur-sim`: the simulated UR5 behind the interfaces of a real UR controller
//! (docs/design.md §3.10), so that a UR driver can be tested against the plant.
//!
//! - **RTDE server** ([`rtde`], default port 30004): protocol v2 and v1, controller version
//!   (5.x for an e-Series, 3.x for a CB3), output recipes with NOT_FOUND, input recipes with
//!   IN_USE between connections, text messages, START / PAUSE, a data package per arm cycle
//!   (2 ms e-Series, 8 ms CB3; fewer if the client asked a lower frequency). robot_mode is
//!   RUNNING; safety_mode NORMAL until a joint-limit violation raises a protective stop.
//! - **Secondary interface** ([`program`], default port 30002): accepts this project's
//!   external_control program (recognised by its marker, `ur_protocol::script`) and then does
//!   what that program does: connects to the reverse port named in the program, applies SERVOJ
//!   targets of the three active joints through the sim's position servo (the wrist joints stay
//!   locked), and on a receive timeout stops the arm (`stopj`: decelerate, hold) and ends the
//!   program. Any other script is not run; every RTDE client gets a text message saying so.
//! - **Clock**: real time (the physics advance one arm cycle per cycle of wall time, divided by
//!   `time_compression`), or **lockstep**: each reverse command advances exactly one arm cycle,
//!   and that cycle's data package follows; nothing moves between commands. Lockstep makes a
//!   cross-process test deterministic: command n is always applied to the state of package n.
//!   The program's receive timeout counts wall time in both modes (divided by the compression
//!   in real time): it is the watchdog for a dead controller. A `stopj` in lockstep runs its
//!   cycles back to back; clients may then see only the newest of them.
//! - **Dashboard server** ([`dashboard`], default port 29999 from the command line; none in the
//!   library unless [`UrSimConfig::dashboard_port`] asks): the model, serial number and
//!   version, the robot, safety and program state, and power on / off, brake release, unlock
//!   protective stop, stop, play and load, as a real controller answers them. With
//!   [`UrSimConfig::start_powered_off`] the arm starts in POWER_OFF, for a driver's bring-up.
//!   In lockstep, an arm in a protective stop with no program running follows a real-time clock
//!   (arm time passes, the arm holds, packages flow), so that the 5 s before a protective stop
//!   can be unlocked pass; nothing else moves the lockstep clock.
//! - **Fault injection** ([`Faults`]): what Universal Robots' own client tests inject, and a
//!   broken robot's stream (a frozen or backwards clock, NaN or impossible joint angles, a
//!   robot that only sends text messages).
//! - **Playback** ([`playback`], `--playback FILE.csv`): the arm moved as by hand in freedrive
//!   through a file's joint angles, in arm time from the first RTDE connection; real time only (in lockstep nothing would
//!   advance the arm without a program's commands), so `time_compression` plays it faster.
//!
//! Only loopback addresses are used: the listeners and the reverse connection refuse others.

pub mod dashboard;
pub mod plant;
pub mod playback;
pub mod playback_motions;
pub mod program;
pub mod rtde;

use std::net::{Ipv4Addr, SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::Serialize;
use ur5_shared::config::{ActionMode, SimConfig, TaskConfig};
use ur_protocol::rtde::{level, ControllerVersion};

use crate::{SimError, Ur5Sim};
use plant::{Arm, Plant, Violation};
use rtde::Outlet;

/// Which controller generation to imitate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Series {
    /// e-Series: 500 Hz, controller 5.x.
    E,
    /// CB3: 125 Hz, controller 3.x.
    Cb3,
}

impl Series {
    /// Arm cycle (s).
    pub fn cycle_s(self) -> f64 {
        match self {
            Series::E => 0.002,
            Series::Cb3 => 0.008,
        }
    }

    /// Control and RTDE rate (Hz).
    pub fn rate_hz(self) -> f64 {
        1.0 / self.cycle_s()
    }

    /// The version the controller driving `model` reports: a plausible release of each line
    /// (5.12, 3.15.8), or on the e-Series the first release that runs `model` when that is
    /// later (UR20 5.14, UR30 5.15, UR7e, UR12e and UR15 5.22, UR18 5.23: the minimum versions
    /// of URSim per model in URCL's `scripts/start_ursim.sh`).
    pub fn version(self, model: ur5_shared::UrModel) -> ControllerVersion {
        use ur5_shared::UrModel;
        match self {
            Series::E => ControllerVersion {
                major: 5,
                minor: match model {
                    UrModel::Ur20 => 14,
                    UrModel::Ur30 => 15,
                    UrModel::Ur7e | UrModel::Ur12e | UrModel::Ur15 => 22,
                    UrModel::Ur18 => 23,
                    _ => 12,
                },
                bugfix: 0,
                build: 0,
            },
            Series::Cb3 => ControllerVersion {
                major: 3,
                minor: 15,
                bugfix: 8,
                build: 0,
            },
        }
    }
}

/// Misbehaviour to inject (all off by default).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Faults {
    /// Answer "not accepted" to protocol version 2 (clients fall back to 1).
    pub refuse_v2: bool,
    /// Answer "not accepted" to every protocol version.
    pub refuse_versions: bool,
    /// Send a text message before every answer.
    pub text_before_reply: bool,
    /// Answer "not accepted" to START.
    pub refuse_start: bool,
    /// Per three data packages: one sent together with a repeat of the previous one in one
    /// write, one split over two writes 2 ms apart, one as usual.
    pub merge_split: bool,
    /// Every n-th data package is sent `delay_ms` late (0 = off).
    pub delay_every: u64,
    /// Delay of a delayed package (ms).
    pub delay_ms: u64,
    /// Every n-th data package is not sent (0 = off).
    pub drop_every: u64,
    /// Close the RTDE connection after this many data packages (0 = never).
    pub disconnect_after: u64,
    /// Raise a protective stop after this many arm cycles (0 = never): the robot stopping
    /// itself for a reason of its own, as on a detected collision.
    pub protective_stop_after: u64,
    /// From this data package of a connection on (1 = the first; 0 = off), `timestamp` stays
    /// at that package's value: a frozen arm clock.
    pub frozen_clock_after: u64,
    /// From this data package of a connection on (0 = off), `timestamp` goes back one arm
    /// cycle per package: a clock running backwards.
    pub backwards_clock_after: u64,
    /// From this data package of a connection on (0 = off), the base joint's `actual_q` is NaN.
    pub nan_q_after: u64,
    /// From this data package of a connection on (0 = off), the base joint's `actual_q` reads
    /// 100 rad: a measured state outside every joint limit.
    pub q_out_of_limits_after: u64,
    /// The RTDE server talks but never sets up: every request is answered by a text message
    /// only, and 8 text messages follow at least every 50 ms (arm cycles or not).
    pub text_only: bool,
}

/// Options of `hil-sim ur-sim`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UrSimConfig {
    /// Listen address (loopback only).
    pub host: Ipv4Addr,
    /// RTDE port (0: any free port).
    pub rtde_port: u16,
    /// Secondary-interface port (0: any free port).
    pub secondary_port: u16,
    /// Dashboard-server port (0: any free port; `None`: no dashboard server, the library's
    /// default so that tests do not compete for 29999; the command line's default is 29999).
    pub dashboard_port: Option<u16>,
    /// Start with the robot powered off (robot mode POWER_OFF): programs are refused until the
    /// dashboard's `power on` and `brake release`.
    pub start_powered_off: bool,
    /// Controller generation.
    pub series: Series,
    /// How servoj tracks its targets ([`plant::ServojModel`]).
    pub servoj: plant::ServojModel,
    /// Lockstep clock (see the module docs).
    pub lockstep: bool,
    /// Lockstep: the arm's clock runs (one cycle per `cycle / time_compression` of wall time)
    /// while it stands in a protective stop with no program, so that the 5 s before an unlock
    /// pass. `false` freezes it there too (a test of the refusal).
    pub stopped_clock: bool,
    /// Real time runs this many times faster than wall time (≥ 1).
    pub time_compression: f64,
    /// Misbehaviour to inject.
    pub faults: Faults,
    /// A playback file moving the arm as by hand (freedrive; [`playback`]); real time only.
    pub playback: Option<std::path::PathBuf>,
    /// Active joints of the simulated arm: 3 (the wrist locked at `sim.wrist_q`; servoj's wrist
    /// targets are ignored with a warning) or 6 (servoj moves all six). Left out when
    /// serialised at 3.
    #[serde(skip_serializing_if = "is_three")]
    pub joints: usize,
}

fn is_three(n: &usize) -> bool {
    *n == 3
}

impl Default for UrSimConfig {
    fn default() -> Self {
        Self {
            host: Ipv4Addr::LOCALHOST,
            rtde_port: 30004,
            secondary_port: 30002,
            dashboard_port: None,
            start_powered_off: false,
            series: Series::E,
            servoj: plant::ServojModel::Ideal,
            lockstep: false,
            stopped_clock: true,
            time_compression: 1.0,
            faults: Faults::default(),
            playback: None,
            joints: 3,
        }
    }
}

/// Errors starting `ur-sim`.
#[derive(Debug, thiserror::Error)]
pub enum UrSimError {
    /// The simulator could not be built.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Invalid configuration.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    /// A port could not be bound.
    #[error("cannot listen on {addr} for {what}: {source}; pick another port (0 = any free port)")]
    Bind {
        /// What the port is for.
        what: &'static str,
        /// Address.
        addr: SocketAddr,
        /// I/O error.
        source: std::io::Error,
    },
    /// A non-loopback address.
    #[error("ur-sim listens on loopback addresses only; {0} is not one")]
    NotLoopback(Ipv4Addr),
    /// The sim is in torque mode.
    #[error("ur-sim needs sim.mode = \"goal_angles\" (servoj drives the position servo)")]
    TorqueMode,
    /// Bad time compression.
    #[error("time_compression {0}")]
    TimeCompression(String),
    /// A playback file that cannot be played.
    #[error(transparent)]
    Playback(#[from] playback::PlaybackError),
    /// Two of its servers given one port.
    #[error("{a} and {b} are both port {port}: each server needs its own (0 takes any free port)")]
    SamePort {
        /// One server's option.
        a: &'static str,
        /// The other's.
        b: &'static str,
        /// The port.
        port: u16,
    },
    /// A playback in lockstep.
    #[error(
        "--playback needs the real-time clock: in lockstep the arm moves only on a program's \
         commands; drop --lockstep (use --time-compression to play faster)"
    )]
    PlaybackLockstep,
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct UrSimSummary {
    /// Always "ur-sim".
    pub command: &'static str,
    /// RTDE connections accepted.
    pub rtde_connections: u64,
    /// Data packages sent (all connections).
    pub packages: u64,
    /// Reverse commands received.
    pub commands: u64,
    /// Programs of this project started.
    pub programs: u64,
    /// Scripts refused (not this project's program, or not runnable now).
    pub refused_scripts: u64,
    /// Programs ended by a receive timeout.
    pub receive_timeouts: u64,
    /// Protective stops.
    pub protective_stops: u64,
    /// Arm cycles simulated.
    pub cycles: u64,
}

#[derive(Default)]
pub(crate) struct Stats {
    rtde_connections: AtomicU64,
    packages: AtomicU64,
    commands: AtomicU64,
    programs: AtomicU64,
    refused_scripts: AtomicU64,
    receive_timeouts: AtomicU64,
    protective_stops: AtomicU64,
}

impl Stats {
    fn add(c: &AtomicU64) {
        c.fetch_add(1, Ordering::Relaxed);
    }
}

/// The program the dashboard's `load` and `play` act on.
#[derive(Default)]
pub(crate) struct ProgramStore {
    /// The last external_control program sent to the secondary interface.
    pub script: Option<String>,
    /// The name `load` gave it.
    pub loaded: Option<String>,
}

/// Everything the threads share.
pub(crate) struct Ctx {
    pub plant: Plant,
    pub cfg: UrSimConfig,
    /// The simulated arm's model (the dashboard reports it).
    pub model: ur5_shared::UrModel,
    programs: Mutex<ProgramStore>,
    pub stop: AtomicBool,
    pub stats: Stats,
    /// Live RTDE connections, for text messages to all.
    outlets: Mutex<Vec<Weak<Outlet>>>,
    /// Input registers claimed, by connection id.
    pub inputs_in_use: Mutex<Vec<(ur_protocol::Input, u64)>>,
    next_conn: AtomicU64,
}

impl Ctx {
    /// Sends a text message to every RTDE client and logs it.
    pub fn broadcast(&self, message: &str, lvl: u8) {
        eprintln!("hil-sim ur-sim: {message}");
        let mut outlets = self.outlets.lock().unwrap_or_else(|e| e.into_inner());
        outlets.retain(|w| w.strong_count() > 0);
        for o in outlets.iter().filter_map(Weak::upgrade) {
            o.text(message, lvl);
        }
    }

    /// The dashboard's program (locked).
    pub fn program_store(&self) -> std::sync::MutexGuard<'_, ProgramStore> {
        self.programs.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn register(&self, o: &Arc<Outlet>) -> u64 {
        self.outlets
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(Arc::downgrade(o));
        Stats::add(&self.stats.rtde_connections);
        // A playback starts with the first client: the person teaches once someone listens.
        self.plant.lock().start_playback();
        self.next_conn.fetch_add(1, Ordering::Relaxed)
    }

    /// Under the arm's lock: applies `f`, then (if `step`) advances one arm cycle; a limit
    /// violation from either raises a protective stop. Then wakes the RTDE writers and reports.
    pub fn advance(&self, step: bool, f: impl FnOnce(&mut Arm) -> Result<(), Violation>) {
        let mut ended = None;
        let violation = {
            let mut arm = self.plant.lock();
            let mut v = f(&mut arm).err();
            if step {
                let stepped = arm.step();
                v = v.or(stepped);
                let after = self.cfg.faults.protective_stop_after;
                if after > 0 && arm.cycle == after {
                    v = v.or(Some(Violation(format!(
                        "a collision was detected (injected fault, after {after} arm cycles)"
                    ))));
                }
            }
            if let Some(m) = arm.playback_end_message() {
                ended = Some(m);
            }
            if v.is_some() && arm.safety == ur_protocol::SafetyMode::Normal {
                arm.protective_stop();
                Stats::add(&self.stats.protective_stops);
            } else {
                v = None; // already stopped: report once
            }
            v
        };
        self.plant.notify();
        if let Some(m) = ended {
            self.broadcast(&m, level::INFO);
        }
        if let Some(Violation(why)) = violation {
            self.broadcast(
                &format!("protective stop: {why}; the program stops the arm and ends (clear it on the dashboard, 5 s after the stop: `unlock protective stop`)"),
                level::ERROR,
            );
        }
    }

    fn summary(&self) -> UrSimSummary {
        let s = &self.stats;
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        UrSimSummary {
            command: "ur-sim",
            rtde_connections: g(&s.rtde_connections),
            packages: g(&s.packages),
            commands: g(&s.commands),
            programs: g(&s.programs),
            refused_scripts: g(&s.refused_scripts),
            receive_timeouts: g(&s.receive_timeouts),
            protective_stops: g(&s.protective_stops),
            cycles: self.plant.lock().cycle,
        }
    }
}

/// A running `ur-sim`: its bound addresses; [`UrSimHandle::stop`] ends it.
pub struct UrSimHandle {
    ctx: Arc<Ctx>,
    threads: Vec<JoinHandle<()>>,
    /// Where the RTDE server listens.
    pub rtde_addr: SocketAddr,
    /// Where the secondary interface listens.
    pub secondary_addr: SocketAddr,
    /// Where the dashboard server listens, if there is one.
    pub dashboard_addr: Option<SocketAddr>,
}

impl UrSimHandle {
    /// Stops every thread and returns what the run did.
    pub fn stop(self) -> UrSimSummary {
        self.ctx.stop.store(true, Ordering::Relaxed);
        self.ctx.plant.notify();
        for t in self.threads {
            let _ = t.join();
        }
        self.ctx.summary()
    }

    /// Blocks until the process is killed (the binary's foreground mode).
    pub fn wait(self) -> UrSimSummary {
        while !self.ctx.stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(200));
        }
        self.stop()
    }

    /// What the run did so far.
    pub fn summary(&self) -> UrSimSummary {
        self.ctx.summary()
    }
}

fn bind(host: Ipv4Addr, port: u16, what: &'static str) -> Result<TcpListener, UrSimError> {
    let addr = SocketAddr::from((host, port));
    let l = TcpListener::bind(addr).map_err(|source| UrSimError::Bind { what, addr, source })?;
    l.set_nonblocking(true)
        .map_err(|source| UrSimError::Bind { what, addr, source })?;
    Ok(l)
}

/// Accepts connections on `listener` until the stop flag, each served by `serve` on its own
/// thread.
fn accept_loop(ctx: Arc<Ctx>, listener: TcpListener, serve: fn(Arc<Ctx>, std::net::TcpStream)) {
    let mut conns: Vec<JoinHandle<()>> = Vec::new();
    while !ctx.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, peer)) if peer.ip().is_loopback() => {
                let _ = stream.set_nonblocking(false);
                let c = Arc::clone(&ctx);
                conns.push(std::thread::spawn(move || serve(c, stream)));
            }
            Ok((_, peer)) => {
                eprintln!("hil-sim ur-sim: refused a connection from {peer} (loopback only)")
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(5))
            }
            // SIGSTOP/SIGCONT of ur-sim: accept again.
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                eprintln!("hil-sim ur-sim: accept failed: {e}");
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        conns.retain(|t| !t.is_finished());
    }
    for t in conns {
        let _ = t.join();
    }
}

/// Real time: one arm cycle per `cycle / time_compression` of wall time (absolute deadlines;
/// after a long stall the clock restarts instead of catching up in a burst).
fn clock(ctx: Arc<Ctx>) {
    let period = Duration::from_secs_f64(ctx.cfg.series.cycle_s() / ctx.cfg.time_compression);
    let mut next = Instant::now() + period;
    while !ctx.stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > 10 * period {
            next = now;
        }
        next += period;
        ctx.advance(true, |_| Ok(()));
    }
}

/// Lockstep: while the arm stands in a protective stop with no program running, one arm
/// cycle per `cycle / time_compression` of wall time (the arm holds; see the module docs).
fn stopped_clock(ctx: Arc<Ctx>) {
    let period = Duration::from_secs_f64(ctx.cfg.series.cycle_s() / ctx.cfg.time_compression);
    while !ctx.stop.load(Ordering::Relaxed) {
        std::thread::sleep(period);
        let standing = {
            let arm = ctx.plant.lock();
            arm.phase == plant::Phase::Idle && arm.safety == ur_protocol::SafetyMode::ProtectiveStop
        };
        if standing {
            ctx.advance(true, |_| Ok(()));
        }
    }
}

/// Builds the arm at rest at `task.start_q`, binds the ports and starts serving.
pub fn spawn(
    task: &TaskConfig,
    sim_cfg: &SimConfig,
    cfg: &UrSimConfig,
) -> Result<UrSimHandle, UrSimError> {
    task.validate()?;
    sim_cfg.validate()?;
    if !cfg.host.is_loopback() {
        return Err(UrSimError::NotLoopback(cfg.host));
    }
    if sim_cfg.mode != ActionMode::GoalAngles {
        return Err(UrSimError::TorqueMode);
    }
    ur5_shared::config::check_time_compression(cfg.time_compression)
        .map_err(UrSimError::TimeCompression)?;
    let ports = [
        ("rtde_port (--rtde-port)", Some(cfg.rtde_port)),
        (
            "secondary_port (--secondary-port)",
            Some(cfg.secondary_port),
        ),
        ("dashboard_port (--dashboard-port)", cfg.dashboard_port),
    ];
    for (i, (a, pa)) in ports.iter().enumerate() {
        for (b, pb) in &ports[i + 1..] {
            if let (Some(port), Some(q)) = (*pa, *pb) {
                if port != 0 && port == q {
                    return Err(UrSimError::SamePort { a, b, port });
                }
            }
        }
    }
    let dt = cfg.series.cycle_s();
    let player = match &cfg.playback {
        Some(_) if cfg.lockstep => return Err(UrSimError::PlaybackLockstep),
        Some(path) => Some(playback::Player::new(
            playback::Playback::load(path, sim_cfg.model)?,
            sim_cfg.model,
            sim_cfg.ee_offset,
            path.display().to_string(),
        )),
        None => None,
    };
    // A task of six joints needs an arm of six.
    let sim = Ur5Sim::with_joints(sim_cfg.clone(), dt, cfg.joints.max(task.joints))?;
    let start_q = player.as_ref().map_or(
        task.start_six(&sim_cfg.wrist_q),
        playback::Player::start_pose,
    );
    let mut arm = Arm::new(sim, start_q, task.goal, dt)?;
    if let Some(p) = player {
        arm.load_playback(p);
    }
    if cfg.start_powered_off {
        arm.robot_mode = ur_protocol::RobotMode::PowerOff;
        arm.refresh();
    }
    let dash_l = cfg
        .dashboard_port
        .map(|p| bind(cfg.host, p, "the dashboard server"))
        .transpose()?;
    let dashboard_addr = dash_l
        .as_ref()
        .map(|l| {
            l.local_addr().map_err(|source| UrSimError::Bind {
                what: "the dashboard server",
                addr: SocketAddr::from((cfg.host, cfg.dashboard_port.unwrap_or(0))),
                source,
            })
        })
        .transpose()?;
    let rtde_l = bind(cfg.host, cfg.rtde_port, "RTDE")?;
    let sec_l = bind(cfg.host, cfg.secondary_port, "the secondary interface")?;
    let rtde_addr = rtde_l.local_addr().map_err(|source| UrSimError::Bind {
        what: "RTDE",
        addr: SocketAddr::from((cfg.host, cfg.rtde_port)),
        source,
    })?;
    let secondary_addr = sec_l.local_addr().map_err(|source| UrSimError::Bind {
        what: "the secondary interface",
        addr: SocketAddr::from((cfg.host, cfg.secondary_port)),
        source,
    })?;
    let ctx = Arc::new(Ctx {
        plant: Plant::new(arm),
        cfg: cfg.clone(),
        model: sim_cfg.model,
        programs: Mutex::new(ProgramStore::default()),
        stop: AtomicBool::new(false),
        stats: Stats::default(),
        outlets: Mutex::new(Vec::new()),
        inputs_in_use: Mutex::new(Vec::new()),
        next_conn: AtomicU64::new(1),
    });
    let mut threads = Vec::new();
    let c = Arc::clone(&ctx);
    threads.push(std::thread::spawn(move || {
        accept_loop(c, rtde_l, rtde::serve_connection)
    }));
    let c = Arc::clone(&ctx);
    threads.push(std::thread::spawn(move || {
        accept_loop(c, sec_l, program::serve_secondary)
    }));
    if let Some(l) = dash_l {
        let c = Arc::clone(&ctx);
        threads.push(std::thread::spawn(move || {
            accept_loop(c, l, dashboard::serve_dashboard)
        }));
    }
    let c = Arc::clone(&ctx);
    if cfg.lockstep {
        if cfg.stopped_clock {
            threads.push(std::thread::spawn(move || stopped_clock(c)));
        }
    } else {
        threads.push(std::thread::spawn(move || clock(c)));
    }
    Ok(UrSimHandle {
        ctx,
        threads,
        rtde_addr,
        secondary_addr,
        dashboard_addr,
    })
}
