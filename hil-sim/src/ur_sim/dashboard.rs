//! The dashboard server of `ur-sim` (a real controller's TCP 29999): one text line per
//! command, one text line per reply, a welcome line on connect. The replies are those of
//! Universal Robots' dashboard server as URCL's `DashboardClient` matches them
//! (`src/ur/dashboard_client_implementation_g5.cpp`: the command table with each command's
//! reply pattern and the first CB3 and e-Series versions that have it); where a command is newer
//! than the simulated controller's version (`safetystatus` and `is in remote control` on a CB3
//! 3.15) the server answers as an older controller does, with "could not understand".
//!
//! The replies read and change the simulated arm ([`super::plant::Arm`]): `power off` makes the
//! robot mode POWER_OFF (in RTDE too) and ends a running program, `power on` makes it IDLE,
//! `brake release` RUNNING (powering a powered-off arm on first, as a real controller does);
//! `unlock protective stop` clears a protective stop once 5 s of arm time have passed since it
//! (earlier it is refused with the controller's words); `stop` ends the running program at once
//! (runtime state and `programState` STOPPED, the reverse connection closed) while the arm
//! decelerates as with `stopj`; `play` runs the loaded program again. ur-sim has one
//! program: the last external_control program sent to its secondary interface; `load` of a
//! `.urp` name selects it under that name (docs/ur.md, "The dashboard server").

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use ur_protocol::{RobotMode, SafetyMode};

use super::plant::Phase;
use super::{Ctx, Series};

/// The first line a client reads.
pub const WELCOME: &str = "Connected: Universal Robots Dashboard Server";

/// A real controller refuses to unlock a protective stop earlier than this after it (s).
pub const UNLOCK_AFTER_S: f64 = 5.0;

/// The controller's reply to an `unlock protective stop` within [`UNLOCK_AFTER_S`].
pub const UNLOCK_TOO_EARLY: &str = "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of protective stop before unlocking";

/// Longest command line accepted (bytes); a longer one closes the connection.
const MAX_LINE: usize = 4096;

/// Serves one dashboard connection until `quit`, the client closes, or ur-sim stops.
pub(crate) fn serve_dashboard(ctx: Arc<Ctx>, mut stream: TcpStream) {
    let _ = stream.set_nodelay(true);
    let _ = stream.set_read_timeout(Some(Duration::from_millis(100)));
    if writeln!(stream, "{WELCOME}").is_err() {
        return;
    }
    let mut line: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 512];
    loop {
        if ctx.stop.load(Ordering::Relaxed) {
            return;
        }
        let n = match stream.read(&mut chunk) {
            Ok(0) => return,
            Ok(n) => n,
            Err(e) if ur_protocol::stream::timed_out(&e) => continue,
            Err(_) => return,
        };
        for &b in &chunk[..n] {
            if b != b'\n' {
                line.push(b);
                if line.len() > MAX_LINE {
                    let _ = writeln!(stream, "could not understand: a line over {MAX_LINE} bytes");
                    return;
                }
                continue;
            }
            let text = String::from_utf8_lossy(&line).trim().to_string();
            line.clear();
            if text.is_empty() {
                continue;
            }
            let (reply, quit) = answer(&ctx, &text);
            if writeln!(stream, "{reply}").is_err() || quit {
                return;
            }
        }
    }
}

/// The model's name as `get robot model` gives it: "UR5" for a UR5 and a UR5e alike (the
/// e-Series controller answers without the "e"; the PolyScope version tells the generations
/// apart).
pub fn model_reply(model: ur5_shared::UrModel) -> String {
    model.name().trim_end_matches('e').to_ascii_uppercase()
}

/// `PolyscopeVersion`'s reply for `series` driving `model`, e.g. "URSoftware 5.12.0.0
/// (hil-sim ur-sim)".
pub fn polyscope_reply(series: Series, model: ur5_shared::UrModel) -> String {
    let v = series.version(model);
    format!(
        "URSoftware {}.{}.{}.{} (hil-sim ur-sim)",
        v.major, v.minor, v.bugfix, v.build
    )
}

/// A serial number of the form real ones have ("20" and the year first, URCL checks "20…"):
/// the year of the simulated controller's release, the model's digits, a fixed sequence.
pub fn serial_reply(model: ur5_shared::UrModel, series: Series) -> String {
    let year = match series {
        Series::E => 2022,
        Series::Cb3 => 2018,
    };
    let digits: String = model.name().chars().filter(char::is_ascii_digit).collect();
    format!("{year}{digits:0>2}00001")
}

/// The reply to one command line, and whether the connection ends.
pub(crate) fn answer(ctx: &Arc<Ctx>, cmd: &str) -> (String, bool) {
    let series = ctx.cfg.series;
    let e_series = series == Series::E;
    let not_understood = || format!("could not understand: '{cmd}'");
    let reply = match cmd {
        "quit" => return ("Disconnected".into(), true),
        "get robot model" => model_reply(ctx.model),
        "get serial number" => serial_reply(ctx.model, series),
        "PolyscopeVersion" => polyscope_reply(series, ctx.model),
        "version" if e_series => {
            let v = series.version(ctx.model);
            format!("{}.{}.{}.{}", v.major, v.minor, v.bugfix, v.build)
        }
        "robotmode" => format!("Robotmode: {}", ctx.plant.lock().robot_mode.name()),
        "safetymode" => format!("Safetymode: {}", ctx.plant.lock().safety.name()),
        // Since 5.4 (e-Series only).
        "safetystatus" if e_series => {
            format!("Safetystatus: {}", ctx.plant.lock().safety.name())
        }
        // Since 5.6 (e-Series only); ur-sim is always in remote control.
        "is in remote control" if e_series => "true".into(),
        "programState" => {
            let running = playing(ctx);
            format!(
                "{} {}",
                if running { "PLAYING" } else { "STOPPED" },
                program_name(ctx)
            )
        }
        "running" => format!("Program running: {}", playing(ctx)),
        "get loaded program" => match loaded(ctx) {
            Some(name) => format!("Loaded program: {name}"),
            None => "No program loaded".into(),
        },
        "power on" => {
            ctx.advance(false, |arm| {
                if arm.robot_mode == RobotMode::PowerOff {
                    arm.robot_mode = RobotMode::Idle;
                    arm.refresh();
                }
                Ok(())
            });
            "Powering on".into()
        }
        "power off" => {
            ctx.advance(false, |arm| {
                arm.robot_mode = RobotMode::PowerOff;
                // The program cannot run unpowered: it ends, the brakes hold the arm.
                if arm.phase != Phase::Idle {
                    arm.program += 1;
                    arm.phase = Phase::Idle;
                }
                arm.hold_here();
                arm.refresh();
                Ok(())
            });
            "Powering off".into()
        }
        "brake release" => {
            // A powered-off robot is powered on on the fly, then its brakes released (as UR's
            // controller does, and the ROS driver's `brake_release` service says).
            ctx.advance(false, |arm| {
                if matches!(arm.robot_mode, RobotMode::PowerOff | RobotMode::Idle) {
                    arm.robot_mode = RobotMode::Running;
                    arm.refresh();
                }
                Ok(())
            });
            "Brake releasing".into()
        }
        "unlock protective stop" => {
            let mut refused = false;
            ctx.advance(false, |arm| {
                match arm.since_stop_s() {
                    Some(s) if s < UNLOCK_AFTER_S => refused = true,
                    Some(_) => {
                        arm.safety = SafetyMode::Normal;
                        arm.refresh();
                    }
                    None => {}
                }
                Ok(())
            });
            if refused {
                UNLOCK_TOO_EARLY.into()
            } else {
                "Protective stop releasing".into()
            }
        }
        "close safety popup" => "closing safety popup".into(),
        "close popup" => "closing popup".into(),
        "stop" => {
            let mut stopped = false;
            ctx.advance(false, |arm| {
                stopped = arm.stop_program();
                Ok(())
            });
            if stopped {
                "Stopped".into()
            } else {
                "Failed to execute: stop".into()
            }
        }
        "play" => play(ctx),
        _ => match cmd.strip_prefix("load ") {
            Some(file) => load(ctx, file.trim()),
            None => not_understood(),
        },
    };
    (reply, false)
}

fn playing(ctx: &Ctx) -> bool {
    matches!(ctx.plant.lock().phase, Phase::Running | Phase::Stopping)
}

fn loaded(ctx: &Ctx) -> Option<String> {
    ctx.program_store().loaded.clone()
}

/// The name `programState` gives: the loaded program's file name, "<unnamed>" for a program
/// sent to the secondary interface with none loaded.
fn program_name(ctx: &Ctx) -> String {
    loaded(ctx)
        .map(|p| {
            std::path::Path::new(&p)
                .file_name()
                .map_or(p.clone(), |f| f.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "<unnamed>".into())
}

fn load(ctx: &Ctx, file: &str) -> String {
    let mut store = ctx.program_store();
    if !file.ends_with(".urp") || store.script.is_none() {
        return format!("File not found: {file}");
    }
    store.loaded = Some(file.to_string());
    format!("Loading program: {file}")
}

fn play(ctx: &Arc<Ctx>) -> String {
    let script = {
        let store = ctx.program_store();
        match (&store.loaded, &store.script) {
            (Some(_), Some(s)) => s.clone(),
            _ => return "Failed to execute: play".into(),
        }
    };
    {
        let arm = ctx.plant.lock();
        if arm.robot_mode != RobotMode::Running
            || arm.safety != SafetyMode::Normal
            || arm.phase != Phase::Idle
        {
            return "Failed to execute: play".into();
        }
    }
    if super::program::run_script(ctx, &script) {
        "Starting program".into()
    } else {
        "Failed to execute: play".into()
    }
}
