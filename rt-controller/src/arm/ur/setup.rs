//! The `ur` arm's setup (docs/design.md §3.10): RTDE handshake, controller version,
//! output recipe, START and the mode checks, then the project's URScript program sent headless
//! to the secondary interface and its reverse connection accepted. Allocates, blocks and fails
//! with [`UrSetupError`]s that say what is wrong and what to do. The loop side is
//! [`super::live`].

use std::io::{Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use ur_protocol::modes::{robot_mode_name, safety_mode_name};
use ur_protocol::rtde::{ControllerVersion, PackageType, Protocol};
use ur_protocol::script::{self, ScriptParams};
use ur_protocol::{
    ClientMessage, FrameDecoder, OutputRecipe, RobotMessage, RobotMode, RobotState, SafetyMode,
};

use crate::config::{UrConfig, UrSeries};

/// The project's robot-side program (placeholders filled in by [`script::render`]).
pub const PROGRAM: &str = include_str!("../../../urscript/external_control.script");

/// The outputs the driver asks for (at least these).
pub const OUTPUTS: &str =
    "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state,speed_scaling";

pub use crate::error::{StreamFault, UrSetupError};

/// Text messages the setup keeps (the newest; all are counted): a robot that only talks
/// cannot grow them without bound.
pub const KEPT_TEXTS: usize = 16;

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
    /// The newest [`KEPT_TEXTS`] text messages.
    texts: Vec<String>,
    /// Text messages received in all.
    texts_total: u64,
    /// Every read of this setup step ends by then (`setup_timeout_s` from its start).
    deadline: Instant,
    timeout: Duration,
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
    /// A client on the connected socket `s`, protocol v1 until negotiated, its deadline
    /// `timeout` from now.
    fn new(s: TcpStream, timeout: Duration) -> Self {
        Self {
            s,
            dec: Box::default(),
            protocol: Protocol::V1,
            texts: Vec::new(),
            texts_total: 0,
            deadline: Instant::now() + timeout,
            timeout,
        }
    }

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
                        Ok(RobotMessage::TextMessage(ur_protocol::TextMessage::V1(b))) => {
                            // v1 (before negotiation): a level byte, then the text.
                            String::from_utf8_lossy(b)
                                .trim_start_matches(|c: char| c.is_control())
                                .to_owned()
                        }
                        Ok(RobotMessage::TextMessage(t)) => format!("{t:?}"),
                        _ => "(undecodable text message)".into(),
                    };
                    if self.texts.len() >= KEPT_TEXTS {
                        self.texts.remove(0);
                    }
                    self.texts.push(text);
                    self.texts_total += 1;
                    continue;
                }
                return Ok(Owned(kind, payload));
            }
            // The timeout bounds the whole step, not each read: a robot that keeps sending
            // text messages (and never the answer) does not hold the setup for ever.
            let left = self.deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(self.deadline_passed(during));
            }
            self.s.set_read_timeout(Some(left)).map_err(io(during))?;
            match self.s.read(self.dec.spare()) {
                Ok(0) => return Err(UrSetupError::Closed(during)),
                Ok(n) => self.dec.commit(n),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Err(self.deadline_passed(during))
                }
                Err(why) => return Err(UrSetupError::Io { during, why }),
            }
        }
    }

    fn deadline_passed(&self, during: &'static str) -> UrSetupError {
        UrSetupError::Deadline {
            during,
            timeout_s: self.timeout.as_secs_f64(),
            texts_total: self.texts_total,
            texts: self.texts.clone(),
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
    /// Setup of the `ur` arm, in the order of docs/design.md §3.10: the dashboard's model
    /// check and bring-up ([`super::dashboard::prepare`]), [`UrRtde::connect`], then
    /// [`UrRtde::start_program`]. Each wait is bounded by `timeout`.
    pub fn connect(cfg: &UrConfig, timeout: Duration) -> Result<Self, UrSetupError> {
        super::dashboard::prepare(cfg, timeout)?;
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
        let mut c = Rtde::new(s, timeout);
        let mut negotiated = None;
        for (v, p) in [(2u16, Protocol::V2), (1, Protocol::V1)] {
            let accepted = c
                .ask(
                    ClientMessage::RequestProtocolVersion(v),
                    "protocol negotiation",
                    |m| match m {
                        RobotMessage::ProtocolVersion { accepted } => Some(accepted),
                        _ => None,
                    },
                )
                .map_err(|e| not_rtde(cfg, rtde_addr, timeout, e))?;
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
        self.c.deadline = Instant::now() + self.c.timeout;
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
        c.deadline = Instant::now() + timeout;
        c.timeout = timeout;
        let reverse = send_program(cfg, &c.s, 1.0 / self.rate_hz, timeout, &mut c.texts)?;
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

/// A listener on `reverse_port` at the RTDE socket's local address, the program rendered with
/// it (and `arm.ur`'s servoj settings) and sent to the secondary port, its connection back
/// (blocking, no delay). `texts`: the robot's text messages so far, named if the program does
/// not connect back (they are taken then). Setup and recovery alike.
pub(crate) fn send_program(
    cfg: &UrConfig,
    rtde: &TcpStream,
    steptime_s: f64,
    timeout: Duration,
    texts: &mut Vec<String>,
) -> Result<TcpStream, UrSetupError> {
    let host: Ipv4Addr = cfg
        .host
        .parse()
        .expect("validated by ControllerConfig::validate");
    // The program connects back to the address this PC has toward the robot.
    let local = rtde.local_addr().map_err(io("setup"))?;
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
            steptime_s,
            lookahead_time_s: cfg.servoj_lookahead_time_s,
            gain: cfg.servoj_gain,
        },
    );
    let sec_addr = SocketAddr::from((host, cfg.secondary_port));
    let mut sec =
        TcpStream::connect_timeout(&sec_addr, timeout).map_err(|why| UrSetupError::Connect {
            what: "secondary interface",
            addr: sec_addr,
            why,
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
                    texts: std::mem::take(texts),
                })
            }
        }
    };
    reverse.set_nonblocking(false).map_err(io("setup"))?;
    reverse.set_nodelay(true).map_err(io("setup"))?;
    Ok(reverse)
}

/// The first request found no RTDE interface at `addr`: says what answered instead, and
/// whether the configured secondary port answers RTDE (the ports swapped). Other errors pass.
fn not_rtde(cfg: &UrConfig, addr: SocketAddr, timeout: Duration, e: UrSetupError) -> UrSetupError {
    let what = match &e {
        UrSetupError::Deadline { texts_total: 0, .. } => format!(
            "no answer to the protocol request within {} s",
            timeout.as_secs_f64()
        ),
        UrSetupError::Frame { why, .. } => format!(
            "it sends bytes that are not RTDE frames ({why}; a UR's primary and secondary interfaces stream robot-state packages)"
        ),
        _ => return e,
    };
    let secondary = SocketAddr::from((addr.ip(), cfg.secondary_port));
    if secondary != addr && answers_rtde(secondary, timeout) {
        return UrSetupError::PortsSwapped {
            rtde_port: cfg.rtde_port,
            secondary_port: cfg.secondary_port,
            timeout_s: timeout.as_secs_f64(),
        };
    }
    UrSetupError::NotRtde {
        addr,
        secondary_port: cfg.secondary_port,
        what,
    }
}

/// Whether `addr` answers an RTDE protocol request within `timeout`.
fn answers_rtde(addr: SocketAddr, timeout: Duration) -> bool {
    let Ok(s) = TcpStream::connect_timeout(&addr, timeout) else {
        return false;
    };
    let mut c = Rtde::new(s, timeout);
    c.ask(
        ClientMessage::RequestProtocolVersion(2),
        "probe",
        |m| match m {
            RobotMessage::ProtocolVersion { .. } => Some(()),
            _ => None,
        },
    )
    .is_ok()
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
