//! The `ur` arm's setup (docs/design.md §3.10; issue 13): RTDE handshake, controller version,
//! output recipe, START and the mode checks, then the project's URScript program sent headless
//! to the secondary interface and its reverse connection accepted. Allocates, blocks and fails
//! with [`UrSetupError`]s that say what is wrong and what to do. The loop side (states from the
//! packages, servoj targets on the reverse socket) is not written yet.

use std::io::{Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use ur_protocol::modes::{robot_mode_name, safety_mode_name};
use ur_protocol::rtde::{ControllerVersion, PackageType, Protocol};
use ur_protocol::script::{self, ScriptParams};
use ur_protocol::{
    ClientMessage, FrameDecoder, OutputRecipe, RobotMessage, RobotMode, RobotState, SafetyMode,
};

use serde::Serialize;
use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ArmLimits;
use ur5_shared::kinematics::{Joints6, Ur5Kinematics};
use ur5_shared::layout::N_JOINTS;
use ur5_shared::{ArmCommand, ArmFaults, ArmState, ArmStatus, CommandKind};
use ur_protocol::state::runtime_state;
use ur_protocol::{ControlMode, ReverseCommand};

use super::{ArmBackend, ArmIoError};
use crate::config::{ServoTarget, UrConfig, UrSeries};
use crate::error::SetupError;
use crate::stats::{Histogram, Percentiles};

/// The project's robot-side program (placeholders filled in by [`script::render`]).
pub const PROGRAM: &str = include_str!("../../urscript/external_control.script");

/// The outputs the driver asks for (issue 13: at least these).
pub const OUTPUTS: &str =
    "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state,speed_scaling";

pub use crate::error::UrSetupError;

/// A UR controller after setup: RTDE streaming the recipe, the program connected back.
pub struct UrSession {
    /// The RTDE connection (blocking, with the setup timeout, until the loop side takes it).
    pub rtde: TcpStream,
    /// Its decoder (frames left over from setup included).
    pub decoder: Box<FrameDecoder<8192>>,
    /// Negotiated protocol.
    pub protocol: Protocol,
    /// The controller's version.
    pub version: ControllerVersion,
    /// The arm cycle (s): 0.002 (e-Series) or 0.008 (CB3).
    pub cycle_s: f64,
    /// The accepted output recipe.
    pub recipe: OutputRecipe,
    /// The newest state seen during setup (RUNNING, NORMAL).
    pub state: RobotState,
    /// The program's reverse connection.
    pub reverse: TcpStream,
    /// Text messages the robot sent during setup.
    pub texts: Vec<String>,
}

struct Rtde {
    s: TcpStream,
    dec: Box<FrameDecoder<8192>>,
    protocol: Protocol,
    texts: Vec<String>,
}

/// A frame copied out of the decoder (setup only).
struct Owned(PackageType, Vec<u8>);

impl Owned {
    fn decode(
        &self,
        protocol: Protocol,
        during: &'static str,
    ) -> Result<RobotMessage<'_>, UrSetupError> {
        let f = ur_protocol::Frame {
            kind: self.0,
            payload: &self.1,
        };
        RobotMessage::decode(&f, protocol).map_err(|why| UrSetupError::Decode { during, why })
    }
}

impl Rtde {
    fn send(&mut self, m: ClientMessage<'_>, during: &'static str) -> Result<(), UrSetupError> {
        let mut buf = [0u8; 1024];
        let n = m
            .encode(&mut buf)
            .expect("the driver's requests fit in 1 KB");
        self.s
            .write_all(&buf[..n])
            .map_err(|why| UrSetupError::Io { during, why })
    }

    /// The next frame that is not a text message (texts are kept).
    fn next(&mut self, during: &'static str) -> Result<Owned, UrSetupError> {
        loop {
            let frame = self
                .dec
                .next_frame()
                .map_err(|why| UrSetupError::Frame { during, why })?
                .map(|f| Owned(f.kind, f.payload.to_vec()));
            if let Some(Owned(kind, payload)) = frame {
                if kind == PackageType::TextMessage {
                    let f = ur_protocol::Frame {
                        kind,
                        payload: &payload,
                    };
                    let text = match RobotMessage::decode(&f, self.protocol) {
                        Ok(RobotMessage::TextMessage(t)) => format!("{t:?}"),
                        _ => "(undecodable text message)".into(),
                    };
                    self.texts.push(text);
                    continue;
                }
                return Ok(Owned(kind, payload));
            }
            match self.s.read(self.dec.spare()) {
                Ok(0) => return Err(UrSetupError::Closed(during)),
                Ok(n) => self.dec.commit(n),
                Err(why) => return Err(UrSetupError::Io { during, why }),
            }
        }
    }

    fn ask<T>(
        &mut self,
        m: ClientMessage<'_>,
        during: &'static str,
        pick: impl Fn(RobotMessage<'_>) -> Option<T>,
    ) -> Result<T, UrSetupError> {
        self.send(m, during)?;
        let frame = self.next(during)?;
        pick(frame.decode(self.protocol, during)?).ok_or(UrSetupError::Unexpected {
            during,
            got: frame.0,
        })
    }
}

/// The `ur` arm after the RTDE half of the setup: streaming the recipe, RUNNING and NORMAL,
/// the program not sent yet ([`UrRtde::start_program`] does that).
pub struct UrRtde {
    c: Rtde,
    version: ControllerVersion,
    rate_hz: f64,
    recipe: OutputRecipe,
    state: RobotState,
}

impl UrSession {
    /// Setup of the `ur` arm, in the order of docs/design.md §3.10: [`UrRtde::connect`], then
    /// [`UrRtde::start_program`]. Each wait is bounded by `timeout`.
    pub fn connect(cfg: &UrConfig, timeout: Duration) -> Result<Self, UrSetupError> {
        UrRtde::connect(cfg, timeout)?.start_program(cfg, timeout)
    }
}

impl UrRtde {
    /// RTDE v2 (v1 fallback), the controller version and series, the output recipe at the
    /// controller's rate, START, the first package (RUNNING and NORMAL or refuse).
    pub fn connect(cfg: &UrConfig, timeout: Duration) -> Result<Self, UrSetupError> {
        let host: Ipv4Addr = cfg
            .host
            .parse()
            .expect("validated by ControllerConfig::validate");
        let rtde_addr = SocketAddr::from((host, cfg.rtde_port));
        let s = TcpStream::connect_timeout(&rtde_addr, timeout).map_err(|why| {
            UrSetupError::Connect {
                what: "RTDE interface",
                addr: rtde_addr,
                why,
            }
        })?;
        s.set_read_timeout(Some(timeout)).map_err(io("setup"))?;
        s.set_nodelay(true).map_err(io("setup"))?;
        let mut c = Rtde {
            s,
            dec: Box::default(),
            protocol: Protocol::V1,
            texts: Vec::new(),
        };
        let mut negotiated = None;
        for (v, p) in [(2u16, Protocol::V2), (1, Protocol::V1)] {
            let accepted = c.ask(
                ClientMessage::RequestProtocolVersion(v),
                "protocol negotiation",
                |m| match m {
                    RobotMessage::ProtocolVersion { accepted } => Some(accepted),
                    _ => None,
                },
            )?;
            if accepted {
                negotiated = Some(p);
                break;
            }
        }
        c.protocol = negotiated.ok_or(UrSetupError::NoProtocol)?;
        let version = c.ask(
            ClientMessage::GetUrcontrolVersion,
            "controller version",
            |m| match m {
                RobotMessage::UrcontrolVersion(v) => Some(v),
                _ => None,
            },
        )?;
        let mismatch = match cfg.series {
            UrSeries::Auto => false,
            UrSeries::E => !version.is_e_series(),
            UrSeries::Cb3 => version.is_e_series(),
        };
        if mismatch {
            return Err(UrSetupError::SeriesMismatch {
                configured: cfg.series,
                reported: version,
            });
        }
        let rate_hz = version.max_frequency_hz();
        let protocol = c.protocol;
        let (recipe_id, types) = c.ask(
            ClientMessage::SetupOutputs {
                frequency: (protocol == Protocol::V2).then_some(rate_hz),
                names: OUTPUTS,
            },
            "output recipe",
            |m| match m {
                RobotMessage::SetupOutputs { recipe_id, types } => {
                    Some((recipe_id, types.to_owned()))
                }
                _ => None,
            },
        )?;
        let recipe = OutputRecipe::from_answer(OUTPUTS, recipe_id, &types)?;
        let started = c.ask(ClientMessage::Start, "START", |m| match m {
            RobotMessage::Start { accepted } => Some(accepted),
            _ => None,
        })?;
        if !started {
            return Err(UrSetupError::StartRefused);
        }
        let state = c.state(&recipe)?;
        check_modes(&state)?;
        Ok(Self {
            c,
            version,
            rate_hz,
            recipe,
            state,
        })
    }

    /// The newest state (setup).
    pub fn state(&self) -> &RobotState {
        &self.state
    }

    /// Blocks for the next data package (bounded by the setup timeout) and returns its state:
    /// an observer's read (tests watch the arm through a second RTDE connection with it).
    pub fn next_state(&mut self) -> Result<&RobotState, UrSetupError> {
        self.state = self.c.state(&self.recipe)?;
        Ok(&self.state)
    }

    /// The rest of the setup: the packages queued meanwhile read (the newest must still be
    /// RUNNING and NORMAL), a listener on `reverse_port` at the RTDE socket's local address,
    /// the program rendered with it and sent to the secondary port, its connection back.
    pub fn start_program(
        mut self,
        cfg: &UrConfig,
        timeout: Duration,
    ) -> Result<UrSession, UrSetupError> {
        self.catch_up()?;
        check_modes(&self.state)?;
        let c = &mut self.c;
        let host: Ipv4Addr = cfg
            .host
            .parse()
            .expect("validated by ControllerConfig::validate");
        // The program connects back to the address this PC has toward the robot.
        let local = c.s.local_addr().map_err(io("setup"))?;
        let IpAddr::V4(reverse_ip) = local.ip() else {
            return Err(UrSetupError::NotIpv4(local.ip()));
        };
        let reverse_addr = SocketAddr::from((reverse_ip, cfg.reverse_port));
        let listener = TcpListener::bind(reverse_addr).map_err(|why| UrSetupError::Listen {
            addr: reverse_addr,
            why,
        })?;
        let bound = listener.local_addr().map_err(io("setup"))?;
        let program = script::render(
            PROGRAM,
            &ScriptParams {
                reverse_ip,
                reverse_port: bound.port(),
                steptime_s: 1.0 / self.rate_hz,
            },
        );
        let sec_addr = SocketAddr::from((host, cfg.secondary_port));
        let mut sec = TcpStream::connect_timeout(&sec_addr, timeout).map_err(|why| {
            UrSetupError::Connect {
                what: "secondary interface",
                addr: sec_addr,
                why,
            }
        })?;
        sec.write_all(program.as_bytes())
            .map_err(UrSetupError::SendProgram)?;
        drop(sec);
        listener.set_nonblocking(true).map_err(io("setup"))?;
        let t0 = Instant::now();
        let reverse = loop {
            match listener.accept() {
                Ok((r, _)) => break r,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock && t0.elapsed() < timeout => {
                    std::thread::sleep(Duration::from_millis(2))
                }
                Err(_) => {
                    return Err(UrSetupError::NoCallback {
                        addr: bound,
                        timeout_s: timeout.as_secs_f64(),
                        texts: std::mem::take(&mut c.texts),
                    })
                }
            }
        };
        reverse.set_nonblocking(false).map_err(io("setup"))?;
        reverse.set_nodelay(true).map_err(io("setup"))?;
        let Self {
            c,
            version,
            rate_hz,
            recipe,
            state,
        } = self;
        Ok(UrSession {
            rtde: c.s,
            decoder: c.dec,
            protocol: c.protocol,
            version,
            cycle_s: 1.0 / rate_hz,
            recipe,
            state,
            reverse,
            texts: c.texts,
        })
    }

    /// Reads every package queued since the last read (non-blocking) into the newest state.
    fn catch_up(&mut self) -> Result<(), UrSetupError> {
        let during = "reading the queued packages";
        self.c.s.set_nonblocking(true).map_err(io(during))?;
        let result = loop {
            match self.c.s.read(self.c.dec.spare()) {
                Ok(0) => break Err(UrSetupError::Closed(during)),
                Ok(n) => {
                    self.c.dec.commit(n);
                    while let Some(f) = self
                        .c
                        .dec
                        .next_frame()
                        .map_err(|why| UrSetupError::Frame { during, why })?
                    {
                        let m = RobotMessage::decode(&f, self.c.protocol)
                            .map_err(|why| UrSetupError::Decode { during, why })?;
                        self.state
                            .update(&self.recipe, &m)
                            .map_err(|why| UrSetupError::Decode { during, why })?;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break Ok(()),
                Err(why) => break Err(UrSetupError::Io { during, why }),
            }
        };
        self.c.s.set_nonblocking(false).map_err(io(during))?;
        result
    }
}

fn io(during: &'static str) -> impl Fn(std::io::Error) -> UrSetupError {
    move |why| UrSetupError::Io { during, why }
}

impl Rtde {
    /// The next data package decoded into a state.
    fn state(&mut self, recipe: &OutputRecipe) -> Result<RobotState, UrSetupError> {
        let during = "first data package";
        loop {
            let frame = self.next(during)?;
            let m = frame.decode(self.protocol, during)?;
            let mut s = RobotState::default();
            if s.update(recipe, &m)
                .map_err(|why| UrSetupError::Decode { during, why })?
            {
                return Ok(s);
            }
        }
    }
}

// ------------------------------------------------------------------------------ the loop side

/// A reset to the start pose counts as done when every joint is this close (rad) …
pub const RESET_TOL_Q: f64 = 2e-3;
/// … and this slow (rad/s).
pub const RESET_TOL_QD: f64 = 1e-2;
/// After the reset motion ends, the arm has this long (s of arm time) to settle; then the
/// reset is acknowledged where the arm is.
pub const RESET_SETTLE_MAX_S: f64 = 3.0;
/// Shortest reset motion (s).
const RESET_MIN_S: f64 = 0.5;

/// What the program is servoing to.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Motion {
    /// The controller's goal (or a hold), as [`ServoTarget`] says.
    Servo,
    /// A quintic joint-space move from `from` to `to` starting at arm time `t0` (s), lasting
    /// `duration` (s); acknowledged with `seq` once settled.
    Reset {
        from: Joints6,
        to: Joints6,
        t0: f64,
        duration: f64,
        seq: u64,
    },
}

/// What the `ur` arm did in the loop (the summary's `arm` field).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct UrReport {
    /// RTDE data packages read.
    pub packages: u64,
    /// States handed to the controller (one per control period, and resets' acknowledgements).
    pub states: u64,
    /// Reverse commands written.
    pub commands_written: u64,
    /// Of those, written because no package (or no answer from the controller) came within
    /// half the program's receive timeout.
    pub keepalives: u64,
    /// Commands the controller sent that were not sendable to the arm (non-finite, outside
    /// the joint limits, or torques): replaced by a hold.
    pub commands_refused: u64,
    /// Resets completed.
    pub resets: u64,
    /// Resets acknowledged after [`RESET_SETTLE_MAX_S`] without settling.
    pub resets_unsettled: u64,
    /// Text messages from the robot on RTDE.
    pub texts: u64,
    /// The last of them (truncated to 256 bytes).
    pub last_text: String,
    /// RTDE packages that did not decode (framing lost: the buffer is dropped).
    pub decode_errors: u64,
    /// Why the robot stopped the run, if it did: the robot, safety and runtime modes.
    pub robot_stop: Option<String>,
    /// Why the arm is gone, if it is (connection closed).
    pub lost: Option<&'static str>,
    /// Per package: decode + state build (FK) + reverse write, ns.
    pub cycle: Percentiles,
    /// Real time only: when a package was handled, against the arm's clock (its timestamps),
    /// ns: (wall − wall₀) − (ts − ts₀)/time_compression, minus its minimum over the first
    /// [`LATENESS_BASELINE`] packages (the network's fixed delay is not known). Includes the
    /// robot's and this PC's clock drift (µs per s on real hardware; none against ur-sim).
    pub lateness: Option<Percentiles>,
}

/// Packages that set the lateness baseline.
pub const LATENESS_BASELINE: u64 = 100;

/// Counters of the loop (no allocation; [`UrReport`] at the end).
#[derive(Clone, Copy, Debug, Default)]
struct Counts {
    packages: u64,
    states: u64,
    writes: u64,
    keepalives: u64,
    refused: u64,
    resets: u64,
    unsettled: u64,
    texts: u64,
    decode_errors: u64,
}

/// The `ur` arm in the loop: RTDE packages in (non-blocking), one reverse command out per
/// package, one [`ArmState`] per control period of arm time (docs/design.md §3.10).
struct Live {
    rtde: TcpStream,
    reverse: TcpStream,
    dec: Box<FrameDecoder<8192>>,
    protocol: Protocol,
    recipe: OutputRecipe,
    robot: RobotState,
    kin: Ur5Kinematics,
    /// Arm cycle (s).
    cycle_s: f64,
    /// Control period (s of arm time).
    period_s: f64,
    motion: Motion,
    /// The goal in force (six joints, rad) and, for `ramp`, the target it ramps from and the
    /// arm time (s) of the package it answered.
    goal: Joints6,
    ramp_from: Joints6,
    goal_ts: f64,
    /// Arm time (s) of the next control-period state.
    next_emit_ts: f64,
    /// An emitted state the controller has not answered yet (the write for its package waits).
    awaiting_answer: bool,
    state_seq: u64,
    last_command_seq: u64,
    episode: u64,
    last_write_ns: u64,
    last_text: heapless::String<256>,
    robot_stop: Option<(i32, i32, u32)>,
    /// The program has been seen running (runtime state PLAYING).
    program_seen: bool,
    lost: Option<&'static str>,
    counts: Counts,
    cycle_ns: Histogram,
    /// Real time: the time compression, the first package's (wall ns, arm s), the baseline
    /// offset (ns) and the histogram.
    lateness: Option<Lateness>,
}

/// The lateness measurement of [`UrReport::lateness`].
struct Lateness {
    compression: f64,
    first: Option<(u64, f64)>,
    baseline_ns: i64,
    hist: Histogram,
}

impl Lateness {
    fn record(&mut self, package: u64, wall_ns: u64, ts: f64) {
        let (w0, t0) = *self.first.get_or_insert((wall_ns, ts));
        let offset = (wall_ns - w0) as i64 - ((ts - t0) * 1e9 / self.compression) as i64;
        if package <= LATENESS_BASELINE {
            self.baseline_ns = if package == 1 { offset } else { self.baseline_ns.min(offset) };
        } else {
            self.hist.record((offset - self.baseline_ns).max(0) as u64);
        }
    }
}

/// The `ur` arm backend: [`UrRtde::connect`] in [`ArmBackend::wait_ready`], the program
/// started in [`ArmBackend::connect`] (after the learner showed up, so the program's first
/// read does not time out meanwhile), then the loop side.
pub struct UrArm {
    cfg: UrConfig,
    limits: ArmLimits,
    /// Control period (s of arm time): `task.dt`.
    period_s: f64,
    /// Real time: the time compression (lateness is measured); lockstep: `None`.
    real_time: Option<f64>,
    timeout: Duration,
    rtde: Option<UrRtde>,
    live: Option<Live>,
}

impl UrArm {
    /// The arm of `cfg.arm.ur`, not connected yet.
    pub fn new(cfg: &crate::config::ControllerConfig) -> Self {
        Self {
            cfg: cfg.arm.ur.clone(),
            limits: cfg.limits.clone(),
            period_s: cfg.task.dt,
            real_time: (cfg.mode == crate::config::Mode::RealTime).then_some(cfg.time_compression),
            timeout: Duration::from_secs_f64(cfg.setup_timeout_s),
            rtde: None,
            live: None,
        }
    }

    /// What the loop saw (allocates; after the loop).
    pub fn report(&self) -> UrReport {
        let Some(l) = &self.live else {
            return UrReport::default();
        };
        let c = l.counts;
        UrReport {
            packages: c.packages,
            states: c.states,
            commands_written: c.writes,
            keepalives: c.keepalives,
            commands_refused: c.refused,
            resets: c.resets,
            resets_unsettled: c.unsettled,
            texts: c.texts,
            last_text: l.last_text.as_str().to_owned(),
            decode_errors: c.decode_errors,
            robot_stop: l.robot_stop.map(|(r, s, p)| {
                format!(
                    "robot mode {} ({r}), safety mode {} ({s}), program {}",
                    robot_mode_name(r),
                    safety_mode_name(s),
                    if p == runtime_state::PLAYING { "running" } else { "not running" }
                )
            }),
            lost: l.lost,
            cycle: l.cycle_ns.summary(),
            lateness: l.lateness.as_ref().map(|x| x.hist.summary()),
        }
    }
}

impl ArmBackend for UrArm {
    fn wait_ready(&mut self, timeout_s: f64) -> Result<ArmState, SetupError> {
        let r = UrRtde::connect(&self.cfg, Duration::from_secs_f64(timeout_s))?;
        let kin = Ur5Kinematics::ur5(self.cfg.ee_offset);
        let s = state_from(&kin, r.state(), 0, 0, 0, ArmStatus::READY);
        self.rtde = Some(r);
        Ok(s)
    }

    fn connect(&mut self) -> Result<(), SetupError> {
        let r = self
            .rtde
            .take()
            .expect("wait_ready succeeded before connect");
        let session = r.start_program(&self.cfg, self.timeout)?;
        let setup = |why| SetupError::Ur(UrSetupError::Io { during: "setup", why });
        session.rtde.set_nonblocking(true).map_err(setup)?;
        let q = session.state.actual_q;
        let ts = session.state.timestamp;
        let mut live = Live {
            rtde: session.rtde,
            reverse: session.reverse,
            dec: session.decoder,
            protocol: session.protocol,
            recipe: session.recipe,
            robot: session.state,
            kin: Ur5Kinematics::ur5(self.cfg.ee_offset),
            cycle_s: session.cycle_s,
            period_s: self.period_s,
            motion: Motion::Servo,
            goal: q,
            ramp_from: q,
            goal_ts: ts,
            next_emit_ts: ts + self.period_s,
            awaiting_answer: false,
            state_seq: 0,
            last_command_seq: 0,
            episode: 0,
            last_write_ns: monotonic_ns(),
            last_text: heapless::String::new(),
            robot_stop: None,
            program_seen: false,
            lost: None,
            counts: Counts::default(),
            cycle_ns: Histogram::new(),
            lateness: self.real_time.map(|compression| Lateness {
                compression,
                first: None,
                baseline_ns: 0,
                hist: Histogram::new(),
            }),
        };
        // The program's first command: hold where the arm is.
        live.write(&self.cfg)
            .map_err(|_| setup(std::io::Error::other("the first reverse command could not be written")))?;
        self.live = Some(live);
        Ok(())
    }

    fn receive(&mut self) -> Result<Option<ArmState>, ArmIoError> {
        let Some(l) = self.live.as_mut() else {
            return Err(ArmIoError::Receive);
        };
        l.pump(&self.cfg)
    }

    fn send(&mut self, cmd: &ArmCommand) -> Result<(), ArmIoError> {
        let Some(l) = self.live.as_mut() else {
            return Err(ArmIoError::Send);
        };
        let ok = l.take_command(cmd, &self.limits, &self.cfg);
        l.awaiting_answer = false;
        let written = l.write(&self.cfg);
        if ok {
            written
        } else {
            Err(ArmIoError::Send)
        }
    }

    fn lost(&self) -> Option<&'static str> {
        self.live.as_ref().and_then(|l| l.lost)
    }

    fn report(&self) -> Option<super::ArmReport> {
        Some(super::ArmReport::Ur(UrArm::report(self)))
    }
}

/// The controller's [`ArmState`] from an RTDE state: the three active joints, the
/// end-effector point and velocity from all six measured joints (`ur5_shared::kinematics`).
fn state_from(
    kin: &Ur5Kinematics,
    r: &RobotState,
    seq: u64,
    last_command_seq: u64,
    episode: u64,
    status: ArmStatus,
) -> ArmState {
    let (ee_pos, ee_vel) = kin.ee_point_velocity(&r.actual_q, &r.actual_qd);
    let mut faults = ArmFaults::default();
    if r.robot_mode != RobotMode::Running.code() || r.safety_mode != SafetyMode::Normal.code() {
        faults.insert(ArmFaults::DRIVER);
    }
    ArmState {
        seq,
        stamp_ns: monotonic_ns(),
        episode,
        last_command_seq,
        q: [r.actual_q[0], r.actual_q[1], r.actual_q[2]],
        qd: [r.actual_qd[0], r.actual_qd[1], r.actual_qd[2]],
        ee_pos,
        ee_vel,
        status,
        faults,
    }
}

/// Quintic time scaling: 0 → 1 with zero velocity and acceleration at both ends.
fn quintic(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

impl Live {
    /// Half the program's receive timeout in ns: with nothing to answer for this long, a
    /// command is written anyway so that the program's watchdog does not fire.
    fn keepalive_ns(cfg: &UrConfig) -> u64 {
        u64::from(cfg.receive_timeout_ms) * 500_000
    }

    /// Reads what RTDE delivered and answers each package with a command, until a state for
    /// the controller is due (returned; its package's command waits for the controller's
    /// answer), nothing more is queued, or the connection is gone.
    fn pump(&mut self, cfg: &UrConfig) -> Result<Option<ArmState>, ArmIoError> {
        if self.lost.is_some() {
            // Reported once (the read or write that found it); the loop asks `lost()`.
            return Ok(None);
        }
        let now = monotonic_ns();
        if self.awaiting_answer {
            if now.saturating_sub(self.last_write_ns) < Self::keepalive_ns(cfg) {
                return Ok(None);
            }
            // The controller did not answer: hold the goal in force.
            self.awaiting_answer = false;
            self.counts.keepalives += 1;
            self.write(cfg)?;
        }
        loop {
            let frame = match self.dec.next_frame() {
                Ok(f) => f,
                Err(_) => {
                    self.counts.decode_errors += 1;
                    self.dec.clear();
                    return Err(ArmIoError::Receive);
                }
            };
            let Some(frame) = frame else {
                match self.rtde.read(self.dec.spare()) {
                    Ok(0) => {
                        self.lost = Some("the robot closed the RTDE connection");
                        return Err(ArmIoError::Receive);
                    }
                    Ok(n) => {
                        self.dec.commit(n);
                        continue;
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        if now.saturating_sub(self.last_write_ns) >= Self::keepalive_ns(cfg) {
                            self.counts.keepalives += 1;
                            self.write(cfg)?;
                        }
                        return Ok(None);
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(_) => {
                        self.lost = Some("the RTDE connection failed");
                        return Err(ArmIoError::Receive);
                    }
                }
            };
            let t_frame = monotonic_ns();
            let message = match RobotMessage::decode(&frame, self.protocol) {
                Ok(m) => m,
                Err(_) => {
                    self.counts.decode_errors += 1;
                    continue;
                }
            };
            match message {
                RobotMessage::TextMessage(t) => {
                    self.counts.texts += 1;
                    self.last_text.clear();
                    let text = match t {
                        ur_protocol::TextMessage::V2 { message, .. } => message,
                        ur_protocol::TextMessage::V1(b) => core::str::from_utf8(b).unwrap_or("(v1 text, not UTF-8)"),
                    };
                    for ch in text.chars() {
                        if self.last_text.push(ch).is_err() {
                            break;
                        }
                    }
                    continue;
                }
                RobotMessage::DataPackage { .. } => {}
                _ => continue,
            }
            if self.robot.update(&self.recipe, &message).is_err() {
                self.counts.decode_errors += 1;
                continue;
            }
            self.counts.packages += 1;
            if let Some(l) = self.lateness.as_mut() {
                l.record(self.counts.packages, t_frame, self.robot.timestamp);
            }
            let emitted = self.on_package();
            if emitted.is_none() || !self.awaiting_answer {
                self.write(cfg)?;
                self.cycle_ns.record(monotonic_ns() - t_frame);
            }
            if let Some(s) = emitted {
                self.counts.states += 1;
                return Ok(Some(s));
            }
        }
    }

    /// One package: the program's state check, the reset's progress, and the control-period
    /// state if one is due.
    fn on_package(&mut self) -> Option<ArmState> {
        let period_s = self.period_s;
        let r = &self.robot;
        let ts = r.timestamp;
        // The program counts as ended once it was seen running and is no longer (packages
        // queued before it started say STOPPED).
        let playing = r.runtime_state == runtime_state::PLAYING;
        self.program_seen |= playing;
        let stopped = r.robot_mode != RobotMode::Running.code()
            || r.safety_mode != SafetyMode::Normal.code()
            || (self.program_seen && !playing);
        if stopped && self.robot_stop.is_none() {
            self.robot_stop = Some((r.robot_mode, r.safety_mode, r.runtime_state));
            // The controller hears of it at once, not at the next control period.
            self.awaiting_answer = true;
            return Some(self.emit(ArmStatus::READY));
        }
        let mut status = ArmStatus::READY;
        if let Motion::Reset {
            to,
            t0,
            duration,
            seq,
            ..
        } = self.motion
        {
            let settled = (0..6).all(|j| {
                (r.actual_q[j] - to[j]).abs() < RESET_TOL_Q && r.actual_qd[j].abs() < RESET_TOL_QD
            });
            let end = t0 + duration;
            if ts >= end && (settled || ts >= end + RESET_SETTLE_MAX_S) {
                self.counts.resets += 1;
                self.counts.unsettled += u64::from(!settled);
                self.motion = Motion::Servo;
                self.goal = to;
                self.ramp_from = to;
                self.goal_ts = ts;
                self.last_command_seq = seq;
                self.next_emit_ts = ts + period_s;
                self.awaiting_answer = true;
                return Some(self.emit(ArmStatus::READY));
            }
            status = ArmStatus::RESETTING;
        }
        // A state per control period of arm time (CB3: 12 or 13 cycles of 8 ms, 0.1 s on
        // average).
        if ts >= self.next_emit_ts - 0.49 * self.cycle_s {
            self.next_emit_ts += period_s;
            if self.next_emit_ts <= ts {
                self.next_emit_ts = ts + period_s;
            }
            // A reset's progress reports are not answered: its own commands go on.
            self.awaiting_answer = status != ArmStatus::RESETTING;
            return Some(self.emit(status));
        }
        None
    }

    fn emit(&mut self, status: ArmStatus) -> ArmState {
        self.state_seq += 1;
        let mut s = state_from(
            &self.kin,
            &self.robot,
            self.state_seq,
            self.last_command_seq,
            self.episode,
            status,
        );
        if self.robot_stop.is_some() {
            s.faults.insert(ArmFaults::DRIVER);
        }
        s
    }

    /// Takes a controller command; false if it could not be sent as it is (then the arm
    /// holds where it is).
    fn take_command(&mut self, cmd: &ArmCommand, limits: &ArmLimits, cfg: &UrConfig) -> bool {
        self.last_command_seq = cmd.seq;
        self.episode = cmd.episode;
        let here = self.robot.actual_q;
        let hold_here = Ur5Kinematics::six(&[here[0], here[1], here[2]], &cfg.wrist_q);
        let in_limits = |q: &[f64; N_JOINTS]| {
            (0..N_JOINTS).all(|j| q[j].is_finite() && q[j] >= limits.lower[j] && q[j] <= limits.upper[j])
        };
        let (goal, ok) = match cmd.kind() {
            Ok(CommandKind::GoalAngles) if in_limits(&cmd.values) => {
                (Ur5Kinematics::six(&cmd.values, &cfg.wrist_q), true)
            }
            Ok(CommandKind::Hold) => (hold_here, true),
            Ok(CommandKind::Reset) if in_limits(&cmd.reset_pose) => {
                let to = Ur5Kinematics::six(&cmd.reset_pose, &cfg.wrist_q);
                match &mut self.motion {
                    // The same reset again (the controller's retry): it goes on.
                    Motion::Reset { to: t, seq, .. } if *t == to => *seq = cmd.seq,
                    _ => {
                        let dist = (0..6).fold(0.0f64, |m, j| m.max((to[j] - here[j]).abs()));
                        // Peak speed of the quintic: 15/8 · distance / duration.
                        let duration = (1.875 * dist / cfg.reset_speed_rad_s).max(RESET_MIN_S);
                        self.motion = Motion::Reset {
                            from: here,
                            to,
                            t0: self.robot.timestamp,
                            duration,
                            seq: cmd.seq,
                        };
                    }
                }
                // Acknowledged when done ([`Self::on_package`]).
                self.last_command_seq = cmd.seq.saturating_sub(1);
                return true;
            }
            _ => (hold_here, false),
        };
        if !ok {
            self.counts.refused += 1;
        }
        self.ramp_from = self.target(cfg, self.robot.timestamp);
        self.motion = Motion::Servo;
        self.goal = goal;
        self.goal_ts = self.robot.timestamp;
        ok
    }

    /// The servo target for the cycle after the package of arm time `ts`.
    fn target(&self, cfg: &UrConfig, ts: f64) -> Joints6 {
        match self.motion {
            Motion::Reset {
                from,
                to,
                t0,
                duration,
                ..
            } => {
                let s = quintic((ts + self.cycle_s - t0) / duration);
                core::array::from_fn(|j| from[j] + s * (to[j] - from[j]))
            }
            Motion::Servo => match cfg.servo_target {
                ServoTarget::Hold => self.goal,
                ServoTarget::Ramp => {
                    let f = ((ts + self.cycle_s - self.goal_ts) / self.period_s).clamp(0.0, 1.0);
                    core::array::from_fn(|j| self.ramp_from[j] + f * (self.goal[j] - self.ramp_from[j]))
                }
            },
        }
    }

    /// Writes the servo target for the next cycle on the reverse socket.
    fn write(&mut self, cfg: &UrConfig) -> Result<(), ArmIoError> {
        let q = self.target(cfg, self.robot.timestamp);
        let cmd = ReverseCommand {
            timeout_ms: cfg.receive_timeout_ms as i32,
            q,
            mode: ControlMode::Servoj,
        };
        let bytes = cmd.encode().map_err(|_| ArmIoError::Send)?;
        self.last_write_ns = monotonic_ns();
        match self.reverse.write_all(&bytes) {
            Ok(()) => {
                self.counts.writes += 1;
                Ok(())
            }
            Err(_) => {
                self.lost = Some("the robot's program closed the reverse connection (it stopped: see the robot's log)");
                Err(ArmIoError::Send)
            }
        }
    }
}

/// Refuses to drive an arm that is not RUNNING with safety NORMAL.
pub fn check_modes(s: &RobotState) -> Result<(), UrSetupError> {
    let (robot, safety) = (s.robot_mode, s.safety_mode);
    if robot != RobotMode::Running.code() {
        return Err(UrSetupError::NotRunning {
            name: robot_mode_name(robot),
            code: robot,
        });
    }
    if safety != SafetyMode::Normal.code() {
        return Err(UrSetupError::NotNormal {
            name: safety_mode_name(safety),
            code: safety,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mode_check_names_the_mode() {
        let mut s = RobotState {
            robot_mode: RobotMode::Running.code(),
            safety_mode: SafetyMode::Normal.code(),
            ..RobotState::default()
        };
        check_modes(&s).unwrap();
        s.safety_mode = SafetyMode::ProtectiveStop.code();
        let e = check_modes(&s).unwrap_err().to_string();
        assert!(
            e.contains("PROTECTIVE_STOP") && e.contains("not NORMAL"),
            "{e}"
        );
        s.robot_mode = 3;
        let e = check_modes(&s).unwrap_err().to_string();
        assert!(e.contains("POWER_OFF") && e.contains("not RUNNING"), "{e}");
    }
}
