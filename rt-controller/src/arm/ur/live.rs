//! The `ur` arm in the loop (docs/design.md §3.10): RTDE packages in (non-blocking), one
//! servoj target per package on the reverse socket, one [`ArmState`] per control period of
//! arm time; resets as quintic joint moves; a robot stop or a closed connection reported.
//! Nothing here allocates after [`ArmBackend::connect`].

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

use ur_protocol::clock::ClockWatch;
use ur_protocol::modes::{robot_mode_name, safety_mode_name};
use ur_protocol::rtde::Protocol;
use ur_protocol::{FrameDecoder, OutputRecipe, RobotMessage, RobotState};

use serde::Serialize;
use ur5_shared::clock::monotonic_ns;
use ur5_shared::config::ArmLimits;
use ur5_shared::kinematics::Joints6;
use ur5_shared::{ArmCommand, ArmFaults, ArmState, ArmStatus};
use ur_protocol::state::runtime_state;
use ur_protocol::{ControlMode, ReverseCommand};

use crate::arm::servo::{state_due, ArmSensor, Servo};
use crate::arm::{ArmBackend, ArmIoError};
use crate::config::UrConfig;
use crate::error::SetupError;
use crate::stats::{Histogram, Percentiles};

use super::setup::{check_modes, StreamFault, UrRtde, UrSetupError};

mod lateness;
mod recover;

use lateness::Lateness;

// ------------------------------------------------------------------------------ the loop side

pub use crate::arm::servo::{RESET_SETTLE_MAX_S, RESET_TOL_Q, RESET_TOL_QD};
/// A measured active joint may be this far (rad) outside `[limits]` (a servo's overshoot at a
/// limit) before the state counts as a fault ([`StreamFault::OutsideLimits`]).
pub const MEASURED_LIMIT_MARGIN_RAD: f64 = 0.05;

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
    /// Protective stops unlocked and the program restarted (`recover_protective_stop`).
    pub protective_stops_recovered: u64,
    /// Why the arm is gone, if it is (connection closed, or its stream not to be trusted).
    pub lost: Option<&'static str>,
    /// What made the robot's stream untrustworthy, if anything did ([`StreamFault`]).
    pub stream_fault: Option<String>,
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
    texts: u64,
    decode_errors: u64,
    recoveries: u64,
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
    sensor: ArmSensor,
    /// Arm cycle (s).
    cycle_s: f64,
    /// Control period (s of arm time).
    period_s: f64,
    /// The goal in force, the reset in progress, the acknowledged command and episode.
    servo: Servo,
    /// Arm time (s) of the next control-period state.
    next_emit_ts: f64,
    /// An emitted state the controller has not answered yet (the write for its package waits).
    awaiting_answer: bool,
    /// The controller has nothing to command ([`ArmBackend::idle`]): writes are IDLE
    /// keepalives, which the program answers by holding and a lockstep ur-sim by not stepping
    /// (docs/ur.md, "Lockstep"); the next command ends it.
    idle: bool,
    state_seq: u64,
    last_write_ns: u64,
    last_text: heapless::String<256>,
    robot_stop: Option<(i32, i32, u32)>,
    /// The program has been seen running (runtime state PLAYING).
    program_seen: bool,
    /// The program was sent again after a protective stop: until it is seen running, the
    /// packages from before it (still in the stop) are not a new stop.
    restarted: bool,
    lost: Option<&'static str>,
    /// The program's reverse connection failed: no more writes; the queued packages are read
    /// for the robot's own report (its program ended, a stop) before the arm counts as lost.
    reverse_closed: bool,
    /// When it was found closed: wall time (ns) and arm time (s).
    reverse_closed_ns: u64,
    reverse_closed_ts: f64,
    /// The controller's joint limits (measured states are checked against them).
    limits: ArmLimits,
    /// The robot's clock over the packages ([`ur_protocol::clock`]).
    clock: ClockWatch,
    stream_fault: Option<StreamFault>,
    counts: Counts,
    cycle_ns: Histogram,
    /// Real time: the time compression, the first package's (wall ns, arm s), the baseline
    /// offset (ns) and the histogram.
    lateness: Option<Lateness>,
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
    /// The task's active joints and tool points as the arm reports them.
    sensor: ArmSensor,
    joints: usize,
}

impl UrArm {
    /// The arm of `cfg.arm.ur`, not connected yet.
    pub fn new(cfg: &crate::config::ControllerConfig) -> Self {
        Self {
            cfg: cfg.arm.ur.clone(),
            limits: cfg.limits(),
            period_s: cfg.task.dt,
            real_time: (cfg.mode == crate::config::Mode::RealTime).then_some(cfg.time_compression),
            timeout: Duration::from_secs_f64(cfg.setup_timeout_s),
            rtde: None,
            live: None,
            sensor: ArmSensor::new(cfg.arm.ur.model, cfg.arm.ur.ee_offset, &cfg.task),
            joints: cfg.task.joints,
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
            commands_refused: l.servo.refused,
            resets: l.servo.resets,
            resets_unsettled: l.servo.unsettled,
            texts: c.texts,
            last_text: l.last_text.as_str().to_owned(),
            decode_errors: c.decode_errors,
            robot_stop: l.robot_stop.map(|(r, s, p)| {
                format!(
                    "robot mode {} ({r}), safety mode {} ({s}), program {}",
                    robot_mode_name(r),
                    safety_mode_name(s),
                    if p == runtime_state::PLAYING {
                        "running"
                    } else {
                        "not running"
                    }
                )
            }),
            protective_stops_recovered: c.recoveries,
            lost: l.lost,
            stream_fault: l.stream_fault.map(|f| f.to_string()),
            cycle: l.cycle_ns.summary(),
            lateness: l.lateness.as_ref().map(|x| x.hist.summary()),
        }
    }
}

impl ArmBackend for UrArm {
    fn wait_ready(&mut self, timeout_s: f64) -> Result<ArmState, SetupError> {
        super::dashboard::prepare(&self.cfg, Duration::from_secs_f64(timeout_s))?;
        let r = UrRtde::connect(&self.cfg, Duration::from_secs_f64(timeout_s))?;
        check_measured(r.state(), &self.limits).map_err(|fault| UrSetupError::Stream {
            during: "first data package",
            fault,
        })?;
        let st = r.state();
        let s = self
            .sensor
            .state(&st.actual_q, &st.actual_qd, 0, 0, 0, ArmStatus::READY);
        self.rtde = Some(r);
        Ok(s)
    }

    fn connect(&mut self) -> Result<(), SetupError> {
        let r = self
            .rtde
            .take()
            .expect("wait_ready succeeded before connect");
        let session = r.start_program(&self.cfg, self.timeout)?;
        // The first command holds where the arm is: never where it cannot be.
        check_measured(&session.state, &self.limits).map_err(|fault| UrSetupError::Stream {
            during: "reading the queued packages",
            fault,
        })?;
        let setup = |why| {
            SetupError::Ur(UrSetupError::Io {
                during: "setup",
                why,
            })
        };
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
            sensor: self.sensor,
            cycle_s: session.cycle_s,
            period_s: self.period_s,
            servo: Servo::new(
                q,
                ts,
                session.cycle_s,
                self.period_s,
                self.joints,
                self.cfg.wrist_q,
            ),
            next_emit_ts: ts + self.period_s,
            awaiting_answer: false,
            idle: false,
            state_seq: 0,
            last_write_ns: monotonic_ns(),
            last_text: heapless::String::new(),
            robot_stop: None,
            program_seen: false,
            restarted: false,
            lost: None,
            reverse_closed: false,
            reverse_closed_ns: 0,
            reverse_closed_ts: 0.0,
            limits: self.limits.clone(),
            clock: ClockWatch::new(ts),
            stream_fault: None,
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
        live.write(&self.cfg).map_err(|_| {
            setup(std::io::Error::other(
                "the first reverse command could not be written",
            ))
        })?;
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
        l.idle = false;
        let written = l.write(&self.cfg);
        if ok {
            written
        } else {
            Err(ArmIoError::Send)
        }
    }

    fn idle(&mut self) {
        if let Some(l) = self.live.as_mut() {
            l.idle = true;
        }
    }

    fn lost(&self) -> Option<&'static str> {
        self.live.as_ref().and_then(|l| l.lost)
    }

    fn recover(&mut self) -> Result<bool, SetupError> {
        Ok(self.recover_protective_stop()?)
    }

    fn report(&self) -> Option<crate::arm::ArmReport> {
        Some(crate::arm::ArmReport::Ur(UrArm::report(self)))
    }
}

/// Why the arm is lost when its program's reverse connection closed and the robot reported no
/// stop.
/// After the reverse connection closed, the robot has this long (s of its clock) to report its
/// program ended (or a stop) before the arm counts as lost: the program's `stopj` runs first
/// (about 1 s from full speed).
const REVERSE_CLOSED_GRACE_S: f64 = 3.0;
/// … and, with no package queued, at least this long (ns of wall time; else the program's
/// receive timeout): the report may be a cycle behind the close.
const REVERSE_CLOSED_WAIT_NS: u64 = 50_000_000;

const REVERSE_CLOSED: &str =
    "the robot's program closed the reverse connection (it stopped: see the robot's log)";

/// A measured state the controller may act on: all six joints' `actual_q` and `actual_qd`
/// finite, the three active joints within `limits` (± [`MEASURED_LIMIT_MARGIN_RAD`]).
pub fn check_measured(r: &RobotState, limits: &ArmLimits) -> Result<(), StreamFault> {
    check_joints(&r.actual_q, &r.actual_qd, limits)
}

/// [`check_measured`] of six measured joint angles (rad) and speeds (rad/s).
pub fn check_joints(
    actual_q: &Joints6,
    actual_qd: &Joints6,
    limits: &ArmLimits,
) -> Result<(), StreamFault> {
    for j in 0..6 {
        let (q, qd) = (actual_q[j], actual_qd[j]);
        if !q.is_finite() || !qd.is_finite() {
            return Err(StreamFault::NonFinite { joint: j, q, qd });
        }
    }
    // The clamp's limits cover the task's active joints.
    for j in 0..limits.lower.len().min(6) {
        let (q, lower, upper) = (actual_q[j], limits.lower[j], limits.upper[j]);
        let m = MEASURED_LIMIT_MARGIN_RAD;
        if q < lower - m || q > upper + m {
            return Err(StreamFault::OutsideLimits {
                joint: j,
                q,
                lower,
                upper,
                margin: m,
            });
        }
    }
    Ok(())
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
            self.write_on(cfg)?;
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
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock && self.reverse_closed => {
                        // Everything queued is read; the robot's report of the ended program
                        // may still be a cycle behind: lost after the program's own receive
                        // timeout without one.
                        let waited = now.saturating_sub(self.reverse_closed_ns);
                        if waited >= (2 * Self::keepalive_ns(cfg)).max(REVERSE_CLOSED_WAIT_NS) {
                            self.lost = Some(REVERSE_CLOSED);
                            return Err(ArmIoError::Receive);
                        }
                        return Ok(None);
                    }
                    Ok(n) => {
                        self.dec.commit(n);
                        continue;
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        if now.saturating_sub(self.last_write_ns) >= Self::keepalive_ns(cfg) {
                            self.counts.keepalives += 1;
                            self.write_on(cfg)?;
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
                        ur_protocol::TextMessage::V1(b) => {
                            core::str::from_utf8(b).unwrap_or("(v1 text, not UTF-8)")
                        }
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
            if let Err(f) = self.check_stream() {
                // Nothing more is written: the program's receive timeout stops the arm.
                self.stream_fault = Some(f);
                self.lost = Some(f.reason());
                return Err(ArmIoError::Receive);
            }
            if let Some(l) = self.lateness.as_mut() {
                l.record(self.counts.packages, t_frame, self.robot.timestamp);
            }
            let emitted = self.on_package();
            if self.reverse_closed
                && self.robot_stop.is_none()
                && self.robot.timestamp - self.reverse_closed_ts > REVERSE_CLOSED_GRACE_S
            {
                // The robot streams on and reports no stop: its program is gone all the same.
                self.lost = Some(REVERSE_CLOSED);
                return Err(ArmIoError::Receive);
            }
            if emitted.is_none() || !self.awaiting_answer {
                self.write_on(cfg)?;
                self.cycle_ns.record(monotonic_ns() - t_frame);
            }
            if let Some(s) = emitted {
                self.counts.states += 1;
                return Ok(Some(s));
            }
        }
    }

    /// The newest package against the limits and the previous package's clock.
    fn check_stream(&mut self) -> Result<(), StreamFault> {
        check_measured(&self.robot, &self.limits)?;
        self.clock.check(self.robot.timestamp)?;
        Ok(())
    }

    /// [`Self::write`] inside the pump: a closed reverse connection does not end the read of
    /// what RTDE still delivers (the robot's stop report comes there, after the close).
    fn write_on(&mut self, cfg: &UrConfig) -> Result<(), ArmIoError> {
        match self.write(cfg) {
            Err(_) if self.reverse_closed => Ok(()),
            r => r,
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
        let before_restart = self.restarted && !self.program_seen;
        let stopped =
            !before_restart && (check_modes(r).is_err() || (self.program_seen && !playing));
        if stopped && self.robot_stop.is_none() {
            self.robot_stop = Some((r.robot_mode, r.safety_mode, r.runtime_state));
            // The controller hears of it at once, not at the next control period.
            self.awaiting_answer = true;
            return Some(self.emit(ArmStatus::READY));
        }
        let mut status = ArmStatus::READY;
        if self.servo.resetting() {
            if self
                .servo
                .reset_done(&r.actual_q, &r.actual_qd, ts)
                .is_some()
            {
                self.next_emit_ts = ts + period_s;
                self.awaiting_answer = true;
                return Some(self.emit(ArmStatus::READY));
            }
            status = ArmStatus::RESETTING;
        }
        // A state per control period of arm time (CB3: 12 or 13 cycles of 8 ms, 0.1 s on
        // average).
        if state_due(&mut self.next_emit_ts, ts, self.cycle_s, period_s) {
            // A reset's progress reports are not answered: its own commands go on.
            self.awaiting_answer = status != ArmStatus::RESETTING;
            return Some(self.emit(status));
        }
        None
    }

    fn emit(&mut self, status: ArmStatus) -> ArmState {
        self.state_seq += 1;
        let mut s = self.sensor.state(
            &self.robot.actual_q,
            &self.robot.actual_qd,
            self.state_seq,
            self.servo.last_command_seq,
            self.servo.episode,
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
        self.servo.take_command(
            cmd,
            limits,
            cfg.reset_speed_rad_s,
            cfg.servo_target,
            self.robot.actual_q,
            self.robot.timestamp,
        )
    }

    /// Writes the servo target for the next cycle on the reverse socket.
    fn write(&mut self, cfg: &UrConfig) -> Result<(), ArmIoError> {
        if self.reverse_closed {
            return Err(ArmIoError::Send);
        }
        let q = self.servo.target(cfg.servo_target, self.robot.timestamp);
        let cmd = ReverseCommand {
            timeout_ms: cfg.receive_timeout_ms as i32,
            q,
            mode: if self.idle {
                ControlMode::Idle
            } else {
                ControlMode::Servoj
            },
        };
        let bytes = cmd.encode().map_err(|_| ArmIoError::Send)?;
        self.last_write_ns = monotonic_ns();
        match self.reverse.write_all(&bytes) {
            Ok(()) => {
                self.counts.writes += 1;
                Ok(())
            }
            Err(_) => {
                // Lost once the robot's stream goes on without a stop report (pump).
                self.reverse_closed = true;
                self.reverse_closed_ns = monotonic_ns();
                self.reverse_closed_ts = self.robot.timestamp;
                Err(ArmIoError::Send)
            }
        }
    }
}
