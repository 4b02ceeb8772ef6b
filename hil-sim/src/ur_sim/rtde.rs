//! The RTDE server side of `ur-sim`: one reader thread per connection answers requests, one
//! writer thread sends a data package per arm cycle once started. Both write through the
//! connection's [`Outlet`], whose lock keeps frames whole.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ur_protocol::recipe::{answer_types, Answered, InputRecipe, OutputRecipe, MAX_FIELDS};
use ur_protocol::rtde::{level, Protocol, TextMessage};
use ur_protocol::state::InputRegisters;
use ur_protocol::stream::FrameDecoder;
use ur_protocol::{ClientMessage, Input, Output, RobotMessage};

use super::{Ctx, Stats};

/// Largest frame accepted from a client (long recipes of registers fit).
const RX_CAPACITY: usize = 16 * 1024;

/// Largest answer or text frame sent (bytes).
const TX_CAPACITY: usize = 2048;

/// A client whose socket takes no bytes for this long is dropped.
const WRITE_TIMEOUT: Duration = Duration::from_millis(200);

/// The writing end of one connection.
pub(crate) struct Outlet {
    stream: Mutex<TcpStream>,
    protocol: AtomicU8,
}

impl Outlet {
    fn protocol(&self) -> Protocol {
        Protocol::from_u16(self.protocol.load(Ordering::Relaxed).into()).unwrap_or(Protocol::V1)
    }

    /// Writes bytes as one `write_all` under the lock. A client that does not read for
    /// [`WRITE_TIMEOUT`] is dropped, as a real controller drops a client that falls behind.
    fn send(&self, bytes: &[u8]) -> std::io::Result<()> {
        let mut s = self.stream.lock().unwrap_or_else(|e| e.into_inner());
        let r = s.write_all(bytes);
        if let Err(e) = &r {
            if ur_protocol::stream::timed_out(e) {
                eprintln!(
                    "hil-sim ur-sim: dropping an RTDE client that does not read its packages"
                );
            }
            let _ = s.shutdown(Shutdown::Both);
        }
        r
    }

    /// Sends a robot package.
    fn send_msg(&self, m: &RobotMessage<'_>) -> std::io::Result<()> {
        let mut buf = [0u8; TX_CAPACITY];
        let n = m
            .encode(&mut buf)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        self.send(&buf[..n])
    }

    /// Sends a text message in the negotiated layout (v2; v1: level byte then the text).
    pub(crate) fn text(&self, message: &str, lvl: u8) {
        let message = truncate(message, 255);
        let mut v1 = [0u8; 256];
        let t = match self.protocol() {
            Protocol::V2 => TextMessage::V2 {
                message,
                source: "hil-sim",
                level: lvl,
            },
            Protocol::V1 => {
                v1[0] = lvl;
                v1[1..=message.len()].copy_from_slice(message.as_bytes());
                TextMessage::V1(&v1[..=message.len()])
            }
        };
        let _ = self.send_msg(&RobotMessage::TextMessage(t));
    }
}

fn truncate(s: &str, max: usize) -> &str {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

/// What the writer needs from the reader.
#[derive(Default)]
struct Session {
    started: AtomicBool,
    /// Send the current state at once (START).
    send_now: AtomicBool,
    closed: AtomicBool,
    /// The output recipe and its decimation (arm cycles per package).
    recipe: Mutex<Option<(OutputRecipe, u64)>>,
}

/// Serves one RTDE client until it disconnects or the server stops.
pub(crate) fn serve_connection(ctx: Arc<Ctx>, stream: TcpStream) {
    let _ = stream.set_nodelay(true);
    let Ok(wstream) = stream.try_clone() else {
        return;
    };
    let _ = wstream.set_write_timeout(Some(WRITE_TIMEOUT));
    let outlet = Arc::new(Outlet {
        stream: Mutex::new(wstream),
        protocol: AtomicU8::new(1),
    });
    let id = ctx.register(&outlet);
    let session = Arc::new(Session::default());
    let writer = {
        let (ctx, outlet, session) = (Arc::clone(&ctx), Arc::clone(&outlet), Arc::clone(&session));
        std::thread::spawn(move || write_packages(&ctx, &outlet, &session))
    };
    let mut reader = Reader {
        ctx: &ctx,
        outlet: &outlet,
        session: &session,
        id,
        inputs: Vec::new(),
        registers: InputRegisters::default(),
    };
    if let Err(e) = reader.run(stream.try_clone()) {
        eprintln!("hil-sim ur-sim: RTDE client {id}: {e}");
    }
    session.closed.store(true, Ordering::Relaxed);
    let _ = stream.shutdown(Shutdown::Both);
    ctx.plant.notify();
    let _ = writer.join();
    ctx.inputs_in_use
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .retain(|(_, c)| *c != id);
}

struct Reader<'a> {
    ctx: &'a Ctx,
    outlet: &'a Outlet,
    session: &'a Session,
    id: u64,
    inputs: Vec<InputRecipe>,
    registers: InputRegisters,
}

impl Reader<'_> {
    fn run(&mut self, stream: std::io::Result<TcpStream>) -> Result<(), String> {
        let mut stream = stream.map_err(|e| e.to_string())?;
        stream
            .set_read_timeout(Some(Duration::from_millis(50)))
            .map_err(|e| e.to_string())?;
        let mut dec: Box<FrameDecoder<RX_CAPACITY>> = Box::default();
        loop {
            if self.ctx.stop.load(Ordering::Relaxed) || self.session.closed.load(Ordering::Relaxed)
            {
                return Ok(());
            }
            match stream.read(dec.spare()) {
                Ok(0) => return Ok(()),
                Ok(n) => dec.commit(n),
                // A read timeout, or EINTR (a SIGSTOP/SIGCONT of ur-sim interrupts a read
                // with a timeout even without a signal handler): read again.
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    continue
                }
                Err(e) => return Err(e.to_string()),
            }
            loop {
                let frame = match dec.next_frame() {
                    Ok(Some(f)) => f,
                    Ok(None) => break,
                    Err(e) => {
                        self.outlet
                            .text(&format!("closing the connection: {e}"), level::ERROR);
                        return Err(e.to_string());
                    }
                };
                let msg = match ClientMessage::decode(&frame, self.outlet.protocol()) {
                    Ok(m) => m,
                    Err(e) => {
                        self.outlet
                            .text(&format!("ignored a malformed package: {e}"), level::WARNING);
                        continue;
                    }
                };
                self.handle(msg).map_err(|e| e.to_string())?;
            }
        }
    }

    /// Sends an answer, preceded by a text message if that fault is on.
    fn reply(&self, m: RobotMessage<'_>) -> std::io::Result<()> {
        if self.ctx.cfg.faults.text_before_reply {
            self.outlet.text(
                "hil-sim fault injection: a text message ahead of the answer",
                level::WARNING,
            );
        }
        self.outlet.send_msg(&m)
    }

    fn handle(&mut self, msg: ClientMessage<'_>) -> std::io::Result<()> {
        let faults = &self.ctx.cfg.faults;
        if faults.text_only && !matches!(msg, ClientMessage::TextMessage(_)) {
            self.outlet.text(
                "hil-sim fault injection: a text message instead of the answer",
                level::INFO,
            );
            return Ok(());
        }
        match msg {
            ClientMessage::RequestProtocolVersion(v) => {
                let refused = faults.refuse_versions || (faults.refuse_v2 && v == 2);
                let accepted = !refused && Protocol::from_u16(v).is_some();
                // The answer uses the layout of the version in force before it.
                self.reply(RobotMessage::ProtocolVersion { accepted })?;
                if accepted {
                    self.outlet.protocol.store(v as u8, Ordering::Relaxed);
                }
                Ok(())
            }
            ClientMessage::GetUrcontrolVersion => self.reply(RobotMessage::UrcontrolVersion(
                self.ctx.cfg.series.version(self.ctx.model),
            )),
            ClientMessage::SetupOutputs { frequency, names } => {
                self.setup_outputs(frequency, names)
            }
            ClientMessage::SetupInputs { names } => self.setup_inputs(names),
            ClientMessage::Start => {
                let ready = self
                    .session
                    .recipe
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .is_some();
                let accepted = ready && !faults.refuse_start;
                if !ready {
                    self.outlet.text(
                        "START refused: set up a usable output recipe first",
                        level::ERROR,
                    );
                }
                self.reply(RobotMessage::Start { accepted })?;
                if accepted {
                    self.session.started.store(true, Ordering::Relaxed);
                    self.session.send_now.store(true, Ordering::Relaxed);
                    self.ctx.plant.notify();
                }
                Ok(())
            }
            ClientMessage::Pause => {
                self.session.started.store(false, Ordering::Relaxed);
                self.reply(RobotMessage::Pause { accepted: true })
            }
            ClientMessage::DataPackage { recipe_id, values } => {
                let r = self.inputs.iter().find(|r| r.id == recipe_id);
                let res = match r {
                    Some(r) => self
                        .registers
                        .decode_from(r, recipe_id, values)
                        .map_err(|e| e.to_string()),
                    None => Err(format!("input package for unknown recipe {recipe_id}")),
                };
                if let Err(e) = res {
                    self.outlet
                        .text(&format!("input package ignored: {e}"), level::WARNING);
                }
                Ok(())
            }
            ClientMessage::TextMessage(t) => {
                eprintln!("hil-sim ur-sim: RTDE client {}: {t:?}", self.id);
                Ok(())
            }
        }
    }

    fn setup_outputs(&mut self, frequency: Option<f64>, names: &str) -> std::io::Result<()> {
        let rate = self.ctx.cfg.series.rate_hz();
        let mut types = String::new();
        let usable = answer_types(
            names,
            |n| Output::from_name(n).map_or(Answered::NotFound, |o| Answered::Type(o.var_type())),
            &mut types,
        )
        .unwrap_or(false);
        let refusal = recipe_refusal("SETUP_OUTPUTS", names);
        let usable = usable && refusal.is_none();
        fit_answer(&mut types);
        let started = self.session.started.load(Ordering::Relaxed);
        let mut recipe = self
            .session
            .recipe
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        let id = if usable && !started {
            let f = frequency.unwrap_or(rate);
            let f = if f.is_finite() && f > 0.0 && f <= rate {
                f
            } else {
                self.outlet.text(
                    &format!("output frequency {f} Hz is outside (0, {rate}]; using {rate} Hz"),
                    level::WARNING,
                );
                rate
            };
            let mut fields = heapless::Vec::new();
            for o in ur_protocol::recipe::names(names).filter_map(Output::from_name) {
                // At most MAX_FIELDS names (refused above): every push fits.
                if fields.push(o).is_err() {
                    break;
                }
            }
            *recipe = Some((
                OutputRecipe { id: 1, fields },
                ((rate / f).round() as u64).max(1),
            ));
            1
        } else {
            if let Some(why) = &refusal {
                eprintln!("hil-sim ur-sim: RTDE client {}: {why}", self.id);
                self.outlet.text(why, level::ERROR);
            } else if started {
                self.outlet.text(
                    "SETUP_OUTPUTS refused while started: PAUSE first",
                    level::ERROR,
                );
            }
            0
        };
        drop(recipe);
        self.reply(RobotMessage::SetupOutputs {
            recipe_id: id,
            types: &types,
        })
    }

    fn setup_inputs(&mut self, names: &str) -> std::io::Result<()> {
        let mut in_use = self
            .ctx
            .inputs_in_use
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        let mut types = String::new();
        let usable = answer_types(
            names,
            |n| match Input::from_name(n) {
                None => Answered::NotFound,
                Some(i) if in_use.iter().any(|(x, c)| *x == i && *c != self.id) => Answered::InUse,
                Some(i) => Answered::Type(i.var_type()),
            },
            &mut types,
        )
        .unwrap_or(false);
        let refusal = recipe_refusal("SETUP_INPUTS", names);
        fit_answer(&mut types);
        let id = if usable && refusal.is_none() && self.inputs.len() < 200 {
            let mut fields: heapless::Vec<Input, MAX_FIELDS> = heapless::Vec::new();
            for i in ur_protocol::recipe::names(names).filter_map(Input::from_name) {
                // At most MAX_FIELDS names (refused above): every push fits.
                if fields.push(i).is_err() {
                    break;
                }
            }
            for f in &fields {
                in_use.push((*f, self.id));
            }
            let id = 2 + self.inputs.len() as u8;
            self.inputs.push(InputRecipe { id, fields });
            id
        } else {
            if let Some(why) = &refusal {
                eprintln!("hil-sim ur-sim: RTDE client {}: {why}", self.id);
                self.outlet.text(why, level::ERROR);
            } else if usable {
                self.outlet.text(
                    "SETUP_INPUTS refused: 200 input recipes on this connection",
                    level::ERROR,
                );
            }
            0
        };
        drop(in_use);
        self.reply(RobotMessage::SetupInputs {
            recipe_id: id,
            types: &types,
        })
    }
}

/// Why a SETUP request cannot be set up whatever its names are, as a controller refuses it
/// (recipe id 0 and a text message): no variable at all, or more than [`MAX_FIELDS`].
fn recipe_refusal(what: &str, names: &str) -> Option<String> {
    let n = ur_protocol::recipe::names(names).count();
    if n == 0 {
        Some(format!("{what} refused: the recipe names no variable"))
    } else if n > MAX_FIELDS {
        Some(format!(
            "{what} refused: the recipe names {n} variables, this controller sets up at most {MAX_FIELDS}"
        ))
    } else {
        None
    }
}

/// An answer's type list longer than a [`TX_CAPACITY`] frame (clients' receive buffers are a
/// few KB: URCL's and ur_rtde's 4096 bytes) is answered empty; only a recipe refused for its
/// size has one (64 names answer at most 64 × 14 bytes).
fn fit_answer(types: &mut String) {
    if types.len() + 4 > TX_CAPACITY {
        types.clear();
    }
}

/// Sends a data package per arm cycle (or per `decimation` cycles) while started, with the
/// configured faults.
fn write_packages(ctx: &Ctx, outlet: &Outlet, session: &Session) {
    let faults = &ctx.cfg.faults;
    let mut last_cycle = ctx.plant.lock().cycle;
    let mut sent: u64 = 0;
    let mut count: u64 = 0;
    let mut prev = [0u8; 4096];
    let mut prev_len = 0usize;
    let mut buf = [0u8; 4096];
    let mut frozen_ts: Option<f64> = None;
    let mut backwards_from: Option<f64> = None;
    let mut last_text = std::time::Instant::now();
    loop {
        if ctx.stop.load(Ordering::Relaxed) || session.closed.load(Ordering::Relaxed) {
            return;
        }
        let (mut state, cycle) = {
            let arm = ctx
                .plant
                .wait_cycle(last_cycle, Duration::from_millis(50), || {
                    session.send_now.load(Ordering::Relaxed)
                        || session.closed.load(Ordering::Relaxed)
                        || ctx.stop.load(Ordering::Relaxed)
                });
            (arm.snapshot, arm.cycle)
        };
        if faults.text_only {
            // Talks, never streams: a burst of texts per wake (at least 20 wakes a second).
            if last_text.elapsed() >= Duration::from_millis(10) {
                last_text = std::time::Instant::now();
                for _ in 0..8 {
                    outlet.text(
                        "hil-sim fault injection: a robot that only sends text messages",
                        level::INFO,
                    );
                }
            }
            continue;
        }
        let now = session.send_now.swap(false, Ordering::Relaxed);
        if !now && cycle == last_cycle {
            continue;
        }
        last_cycle = cycle;
        if !session.started.load(Ordering::Relaxed) {
            continue;
        }
        let Some((recipe, decimation)) = session
            .recipe
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
        else {
            continue;
        };
        if !now && cycle % decimation != 0 {
            continue;
        }
        let k = count + 1;
        let at = |after: u64| after > 0 && k >= after;
        if at(faults.frozen_clock_after) {
            state.timestamp = *frozen_ts.get_or_insert(state.timestamp);
        }
        if at(faults.backwards_clock_after) {
            let base = *backwards_from.get_or_insert(state.timestamp);
            let back = (k - faults.backwards_clock_after) as f64 * ctx.cfg.series.cycle_s();
            state.timestamp = base - back;
        }
        if at(faults.nan_q_after) {
            state.actual_q[0] = f64::NAN;
        }
        if at(faults.q_out_of_limits_after) {
            state.actual_q[0] = 100.0;
        }
        let Ok(n) = state.encode_package(&recipe, &mut buf) else {
            continue;
        };
        count += 1;
        if faults.drop_every > 0 && count % faults.drop_every == 0 {
            continue;
        }
        if faults.delay_every > 0 && count % faults.delay_every == 0 {
            std::thread::sleep(Duration::from_millis(faults.delay_ms));
        }
        let pkg = &buf[..n];
        let result = match count % 3 {
            // The previous package again, then this one, in one write.
            1 if faults.merge_split && prev_len > 0 && prev_len + n <= prev.len() => {
                prev[prev_len..prev_len + n].copy_from_slice(pkg);
                outlet.send(&prev[..prev_len + n])
            }
            // One package over two writes, 2 ms apart.
            2 if faults.merge_split => outlet.send(&pkg[..n / 2]).and_then(|_| {
                std::thread::sleep(Duration::from_millis(2));
                outlet.send(&pkg[n / 2..])
            }),
            _ => outlet.send(pkg),
        };
        if faults.merge_split && n <= prev.len() / 2 {
            prev[..n].copy_from_slice(pkg);
            prev_len = n;
        }
        if result.is_err() {
            return;
        }
        sent += 1;
        Stats::add(&ctx.stats.packages);
        if faults.disconnect_after > 0 && sent >= faults.disconnect_after {
            eprintln!("hil-sim ur-sim: fault injection: closing the RTDE connection after {sent} packages");
            session.closed.store(true, Ordering::Relaxed);
            let _ = outlet
                .stream
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .shutdown(Shutdown::Both);
            return;
        }
    }
}
