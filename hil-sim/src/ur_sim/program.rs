//! The secondary interface and the project's program as `ur-sim` runs it.
//!
//! A script arrives as text on the secondary port. It is complete when the sender closes the
//! connection or pauses for [`SCRIPT_IDLE`]. If it is this project's external_control program
//! (`ur_protocol::script::parse`), a program thread does what the URScript does
//! (`rt-controller/urscript/external_control.script`):
//!
//! 1. connect to `reverse=IP:PORT` of the program's parameter line (loopback only);
//! 2. read one 32-byte command with a timeout: 1 s for the first, then the command's own;
//! 3. SERVOJ: the servo goal becomes the active joints' targets (a target outside the joint
//!    limits raises a protective stop); STOPPED ends the program; any other mode holds;
//! 4. a read that times out (or a closed socket) logs, stops the arm (`stopj`: decelerate to
//!    rest, hold) and ends the program.
//!
//! A new program replaces a running one, as on a real controller.

use std::io::Read;
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use ur_protocol::reverse::COMMAND_LEN;
use ur_protocol::rtde::level;
use ur_protocol::script::{self, ScriptError, ScriptParams};
use ur_protocol::{ControlMode, ReverseCommand, RobotMode, SafetyMode};

use super::plant::{Phase, ServojFilter, ServojModel, Violation};
use super::{Ctx, Stats};

/// A pause this long after some script text ends the script.
pub const SCRIPT_IDLE: Duration = Duration::from_millis(200);

/// The program's first read waits this long (s of arm time), as the URScript does.
pub const FIRST_TIMEOUT_S: f64 = 1.0;

/// Scripts longer than this are refused (bytes).
const MAX_SCRIPT: usize = 1 << 20;

/// Longest `stopj` simulated in lockstep (arm cycles) before the program ends anyway.
const MAX_STOP_CYCLES: u64 = 5_000;

/// Reads scripts from one secondary-interface connection.
pub(crate) fn serve_secondary(ctx: Arc<Ctx>, mut stream: TcpStream) {
    let _ = stream.set_read_timeout(Some(SCRIPT_IDLE));
    let mut text: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        if ctx.stop.load(Ordering::Relaxed) {
            return;
        }
        match stream.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) if text.len() + n <= MAX_SCRIPT => text.extend_from_slice(&chunk[..n]),
            Ok(_) => {
                ctx.broadcast(
                    "a script over 1 MiB was sent to the secondary interface; not run",
                    level::ERROR,
                );
                Stats::add(&ctx.stats.refused_scripts);
                return;
            }
            // EINTR (a SIGSTOP/SIGCONT of ur-sim): read on.
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) if ur_protocol::stream::timed_out(&e) => {
                if !text.is_empty() {
                    run_script(&ctx, &String::from_utf8_lossy(&text));
                    text.clear();
                }
            }
            Err(_) => break,
        }
    }
    if !text.is_empty() {
        run_script(&ctx, &String::from_utf8_lossy(&text));
    }
}

/// Starts the project's program (true), or says why a script is not run (false).
pub(crate) fn run_script(ctx: &Arc<Ctx>, text: &str) -> bool {
    let refuse = |why: String| {
        Stats::add(&ctx.stats.refused_scripts);
        ctx.broadcast(&why, level::ERROR);
        false
    };
    let params = match script::parse(text) {
        Ok(p) => p,
        Err(ScriptError::NotOurs) => {
            return refuse(format!(
                "hil-sim ur-sim runs only this project's external_control program (line `{}`); the script sent to the secondary interface was not run",
                script::MARKER
            ))
        }
        Err(e) => return refuse(format!("script not run: {e}")),
    };
    // The dashboard's `play` runs it again.
    ctx.program_store().script = Some(text.to_string());
    if !params.reverse_ip.is_loopback() {
        return refuse(format!(
            "script not run: reverse address {} is not a loopback address (ur-sim connects to loopback only)",
            params.reverse_ip
        ));
    }
    let cycle = ctx.cfg.series.cycle_s();
    if (params.steptime_s - cycle).abs() > 1e-9 {
        ctx.broadcast(
            &format!(
                "program steptime {} s differs from this controller's cycle {cycle} s; ur-sim servos once per cycle",
                params.steptime_s
            ),
            level::WARNING,
        );
    }
    let generation = {
        let mut arm = ctx.plant.lock();
        if arm.safety != SafetyMode::Normal {
            let safety = arm.safety;
            drop(arm);
            return refuse(format!(
                "program not started: safety mode is {safety} (unlock it on the dashboard: `unlock protective stop`, 5 s after the stop)"
            ));
        }
        if arm.robot_mode != RobotMode::Running {
            let mode = arm.robot_mode;
            drop(arm);
            return refuse(format!(
                "program not started: robot mode is {mode}, not RUNNING (on the dashboard: `power on`, then `brake release`)"
            ));
        }
        arm.program += 1;
        arm.phase = Phase::Running;
        arm.hold_here();
        arm.servoj = (ctx.cfg.servoj == ServojModel::Tracking)
            .then(|| ServojFilter::new(params.lookahead_time_s, params.gain, arm.dt, arm.q()));
        arm.program
    };
    Stats::add(&ctx.stats.programs);
    eprintln!(
        "hil-sim ur-sim: running the external_control program (reverse {}:{})",
        params.reverse_ip, params.reverse_port
    );
    let ctx = Arc::clone(ctx);
    std::thread::spawn(move || program(&ctx, generation, params));
    true
}

/// How the program ended.
enum End {
    Timeout,
    Closed,
    Stopped,
    Replaced,
    ProtectiveStop,
}

/// The program's main loop (see the module docs).
fn program(ctx: &Ctx, generation: u64, p: ScriptParams) {
    let end = match TcpStream::connect_timeout(
        &SocketAddr::from((p.reverse_ip, p.reverse_port)),
        Duration::from_secs(1),
    ) {
        Ok(s) => command_loop(ctx, generation, s),
        Err(e) => {
            ctx.broadcast(
                &format!(
                    "program: cannot reach the PC at {}:{}: {e}; program ends",
                    p.reverse_ip, p.reverse_port
                ),
                level::ERROR,
            );
            End::Stopped
        }
    };
    if matches!(end, End::Replaced) {
        return;
    }
    match end {
        End::Timeout => {
            Stats::add(&ctx.stats.receive_timeouts);
            ctx.broadcast(
                "program: no command from the PC within the receive timeout; stopping the arm",
                level::WARNING,
            );
        }
        End::Closed => ctx.broadcast(
            "program: the PC closed the reverse connection; stopping the arm",
            level::WARNING,
        ),
        _ => {}
    }
    // stopj: the clock (real time) or this thread (lockstep) decelerates the arm to rest.
    let lockstep = ctx.cfg.lockstep;
    ctx.advance(false, |arm| {
        if arm.program == generation {
            arm.begin_stop();
        }
        Ok(())
    });
    if lockstep {
        for _ in 0..MAX_STOP_CYCLES {
            let mut done = false;
            ctx.advance(true, |arm| {
                done = arm.program != generation || arm.phase != Phase::Stopping;
                Ok(())
            });
            if done || ctx.stop.load(Ordering::Relaxed) {
                break;
            }
        }
        let mut arm = ctx.plant.lock();
        if arm.program == generation && arm.phase == Phase::Stopping {
            arm.hold_here();
            arm.phase = Phase::Idle;
        }
    }
}

fn command_loop(ctx: &Ctx, generation: u64, mut s: TcpStream) -> End {
    let _ = s.set_nodelay(true);
    let compression = if ctx.cfg.lockstep {
        1.0
    } else {
        ctx.cfg.time_compression
    };
    let mut timeout_s = FIRST_TIMEOUT_S;
    let mut warned_wrist = false;
    loop {
        if ctx.stop.load(Ordering::Relaxed) {
            return End::Stopped;
        }
        let wall = Duration::from_secs_f64((timeout_s / compression).max(1e-3));
        let _ = s.set_read_timeout(Some(wall));
        let mut bytes = [0u8; COMMAND_LEN];
        if let Err(e) = s.read_exact(&mut bytes) {
            // A timeout, a closed socket or a partial command: the URScript's read returns
            // fewer than 8 integers in every case, and the program stops the arm.
            return if ur_protocol::stream::timed_out(&e) {
                End::Timeout
            } else {
                End::Closed
            };
        }
        Stats::add(&ctx.stats.commands);
        let cmd = ReverseCommand::decode(&bytes).ok();
        if let Some(c) = &cmd {
            timeout_s = f64::from(c.timeout_ms.max(1)) / 1000.0;
        }
        if matches!(
            cmd,
            Some(ReverseCommand {
                mode: ControlMode::Stopped,
                ..
            })
        ) {
            return End::Stopped;
        }
        // Lockstep: an IDLE command (the driver's keepalive while it has nothing to command)
        // is not a cycle: no time passes, so nothing moves and no package follows.
        if ctx.cfg.lockstep
            && matches!(
                cmd,
                Some(ReverseCommand {
                    mode: ControlMode::Idle,
                    ..
                })
            )
        {
            continue;
        }
        let mut end = None;
        let mut wrist_off = None;
        ctx.advance(ctx.cfg.lockstep, |arm| {
            if arm.program != generation {
                end = Some(End::Replaced);
                return Ok(());
            }
            if arm.phase != Phase::Running {
                end = Some(End::ProtectiveStop);
                return Ok(());
            }
            match cmd {
                Some(ReverseCommand {
                    mode: ControlMode::Servoj,
                    q,
                    ..
                }) => {
                    let target = [q[0], q[1], q[2], q[3], q[4], q[5]];
                    if let Err(v) = arm.check_target(&target) {
                        end = Some(End::ProtectiveStop);
                        return Err(Violation(v.0));
                    }
                    let w = arm.wrist_q();
                    if arm.joints() == 3 && (0..3).any(|k| (q[3 + k] - w[k]).abs() > 1e-3) {
                        wrist_off = Some(([q[3], q[4], q[5]], w));
                    }
                    arm.set_goal(target);
                }
                _ => arm.hold_here(),
            }
            Ok(())
        });
        if let (Some((got, locked)), false) = (wrist_off, warned_wrist) {
            warned_wrist = true;
            ctx.broadcast(
                &format!("wrist targets {got:?} rad differ from the locked wrist angles {locked:?} rad; the simulated wrist stays locked"),
                level::WARNING,
            );
        }
        if let Some(e) = end {
            return e;
        }
    }
}
