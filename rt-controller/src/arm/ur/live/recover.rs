//! Recovery from a protective stop (`arm.ur.recover_protective_stop`), a setup-like step the
//! controller runs outside the tick, between episodes ([`crate::ArmBackend::recover`]): it
//! allocates and blocks, every wait bounded (docs/ur.md, "Protective stops").
//!
//! 1. Wait until the robot's clock (the RTDE timestamps) is 5 s past the stop: a controller
//!    refuses to unlock earlier.
//! 2. `unlock protective stop` on the dashboard (retried while the robot still refuses), then
//!    wait for safety mode NORMAL.
//! 3. Send the program again ([`super::super::setup::send_program`]) and accept its reverse
//!    connection; the arm holds where it stopped until the controller's next reset.

use std::time::{Duration, Instant};

use ur_protocol::client::ClientError;
use ur_protocol::{RobotMessage, SafetyMode};

use super::{Live, UrArm, REVERSE_CLOSED};
use crate::arm::ur::dashboard::Dashboard;
use crate::arm::ur::setup::{send_program, UrSetupError};

/// A controller refuses `unlock protective stop` this soon after the stop (s of its time).
pub const UNLOCK_AFTER_S: f64 = 5.0;

/// Wall time one refused unlock waits before the next try.
const RETRY: Duration = Duration::from_millis(100);

impl UrArm {
    /// Steps 1–3 of the module docs; `Ok(false)` when recovery is off, or the stop is not a
    /// protective stop, or RTDE is gone.
    pub(super) fn recover_protective_stop(&mut self) -> Result<bool, UrSetupError> {
        if !self.cfg.recover_protective_stop {
            return Ok(false);
        }
        let timeout = self.timeout;
        let period_s = self.period_s;
        let cfg = self.cfg.clone();
        let Some(l) = self.live.as_mut() else {
            return Ok(false);
        };
        let Some((_, safety, _)) = l.robot_stop else {
            return Ok(false);
        };
        if safety != SafetyMode::ProtectiveStop.code()
            || l.lost.is_some_and(|m| m != REVERSE_CLOSED)
        {
            return Ok(false);
        }
        let t_stop = l.robot.timestamp;
        eprintln!(
            "rt-controller: protective stop at robot time {t_stop:.3} s; unlocking it {UNLOCK_AFTER_S} s later, then sending the program again"
        );
        // The robot's clock runs at most as slowly as wall time (time compression ≥ 1).
        let wall = timeout + Duration::from_secs_f64(UNLOCK_AFTER_S);
        read_until(l, Instant::now() + wall, |ts| ts >= t_stop + UNLOCK_AFTER_S)?;
        let mut d = Dashboard::connect(&cfg, timeout)?;
        d.unlock_protective_stop(timeout, || {
            let until = Instant::now() + RETRY;
            read_until(l, until, |_| false).map(|_| ())
        })?;
        read_until(l, Instant::now(), |_| false)?;
        let mut texts = Vec::new();
        let reverse = send_program(&cfg, &l.rtde, l.cycle_s, timeout, &mut texts)?;
        let ts = l.robot.timestamp;
        let q = l.robot.actual_q;
        l.reverse = reverse;
        l.robot_stop = None;
        l.lost = None;
        l.reverse_closed = false;
        l.program_seen = false;
        l.restarted = true;
        l.servo.hold_here(&q, ts);
        l.next_emit_ts = ts + period_s;
        l.awaiting_answer = false;
        l.counts.recoveries += 1;
        // The program's first command: hold where the arm is.
        l.write(&cfg).map_err(|_| {
            UrSetupError::Recovery("the program's first command could not be written".into())
        })?;
        eprintln!("rt-controller: protective stop unlocked, program running again");
        Ok(true)
    }
}

/// Reads RTDE (non-blocking socket) into `l.robot` until `done(timestamp)` or `until` (wall);
/// true if `done`. A closed connection is an error; the deadline is one only for a `done` that
/// can hold.
fn read_until(
    l: &mut Live,
    until: Instant,
    done: impl Fn(f64) -> bool,
) -> Result<bool, UrSetupError> {
    use std::io::Read;
    loop {
        while let Some(frame) = l.dec.next_frame().map_err(|why| {
            UrSetupError::Rtde(ClientError::Frame {
                during: "protective-stop recovery",
                why,
            })
        })? {
            if let Ok(m @ RobotMessage::DataPackage { .. }) =
                RobotMessage::decode(&frame, l.protocol)
            {
                if l.robot.update(&l.recipe, &m).is_ok() {
                    l.counts.packages += 1;
                }
            }
        }
        if done(l.robot.timestamp) {
            return Ok(true);
        }
        match l.rtde.read(l.dec.spare()) {
            Ok(0) => return Err(UrSetupError::Closed("protective-stop recovery")),
            Ok(n) => {
                l.dec.commit(n);
                continue;
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(why) => {
                return Err(UrSetupError::Io {
                    during: "protective-stop recovery",
                    why,
                })
            }
        }
        if Instant::now() >= until {
            return if done(f64::INFINITY) {
                Err(UrSetupError::Recovery(format!(
                    "the robot's clock stood at {} s, short of {UNLOCK_AFTER_S} s after the stop; is it still streaming?",
                    l.robot.timestamp
                )))
            } else {
                Ok(false)
            };
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}
