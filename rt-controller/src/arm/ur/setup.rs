//! The `ur` arm's setup (docs/design.md §3.10): RTDE handshake, controller version,
//! output recipe, START and the mode checks, then the project's URScript program sent headless
//! to the secondary interface and its reverse connection accepted. Allocates, blocks and fails
//! with [`UrSetupError`]s that say what is wrong and what to do. The loop side is
//! [`super::live`].

use std::io::Write;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use ur_protocol::client::{self, Client, ClientError};
use ur_protocol::rtde::{ControllerVersion, Protocol};
use ur_protocol::script::{self, ScriptParams};
use ur_protocol::{FrameDecoder, OutputRecipe, RobotState};

use crate::config::{UrConfig, UrSeries};

/// The project's robot-side program (placeholders filled in by [`script::render`]).
pub const PROGRAM: &str = include_str!("../../../urscript/external_control.script");

/// The outputs the driver asks for (at least these).
pub const OUTPUTS: &str =
    "timestamp,actual_q,actual_qd,robot_mode,safety_mode,runtime_state,speed_scaling";

pub use crate::error::{StreamFault, UrSetupError};

pub use ur_protocol::client::KEPT_TEXTS;

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

/// The `ur` arm after the RTDE half of the setup: streaming the recipe, RUNNING and NORMAL,
/// the program not sent yet ([`UrRtde::start_program`] does that).
pub struct UrRtde {
    c: Client,
    version: ControllerVersion,
    rate_hz: f64,
    recipe: OutputRecipe,
    state: RobotState,
    /// Bounds each [`UrRtde::next_state`].
    timeout: Duration,
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
        let mut c = Client::connect(rtde_addr, timeout)?;
        c.negotiate()
            .map_err(|e| not_rtde(cfg, rtde_addr, timeout, e.into()))?;
        let version = c.controller_version()?;
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
        let recipe = c.setup_outputs(OUTPUTS, rate_hz)?;
        c.start()?;
        let state = c.state(&recipe)?;
        check_modes(&state)?;
        Ok(Self {
            c,
            version,
            rate_hz,
            recipe,
            state,
            timeout,
        })
    }

    /// The newest state (setup).
    pub fn state(&self) -> &RobotState {
        &self.state
    }

    /// Blocks for the next data package (bounded by the setup timeout) and returns its state:
    /// an observer's read (tests watch the arm through a second RTDE connection with it).
    pub fn next_state(&mut self) -> Result<&RobotState, UrSetupError> {
        self.c.restart_deadline(self.timeout);
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
        self.c.catch_up(&self.recipe, &mut self.state)?;
        check_modes(&self.state)?;
        let mut texts = self.c.take_texts();
        let reverse = send_program(
            cfg,
            self.c.socket(),
            1.0 / self.rate_hz,
            timeout,
            &mut texts,
        )?;
        let Self {
            c,
            version,
            rate_hz,
            recipe,
            state,
            ..
        } = self;
        let (rtde, decoder, protocol, _) = c.into_parts();
        Ok(UrSession {
            rtde,
            decoder,
            protocol,
            version,
            cycle_s: 1.0 / rate_hz,
            recipe,
            state,
            reverse,
            texts,
        })
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
        UrSetupError::Rtde(ClientError::Frame { why, .. }) => format!(
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
    Client::new(s, timeout).request_protocol(2).is_ok()
}

fn io(during: &'static str) -> impl Fn(std::io::Error) -> UrSetupError {
    move |why| UrSetupError::Io { during, why }
}

/// Refuses to drive an arm that is not RUNNING with safety NORMAL.
pub fn check_modes(s: &RobotState) -> Result<(), UrSetupError> {
    Ok(client::check_modes(s)?)
}
