//! The `ur` arm's dashboard-server client (TCP 29999): the model check and the bring-up at
//! setup, the unlock of a protective stop in a recovery. Setup-like code: it allocates,
//! blocks (every wait bounded) and fails with [`UrSetupError`]s. One text line per command, one
//! per reply, as Universal Robots' dashboard server speaks (URCL's `DashboardClient` matches the
//! same replies); docs/ur.md, "The dashboard server".

use std::io::{BufRead, BufReader, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use ur5_shared::UrModel;

use crate::config::UrConfig;

use crate::error::UrSetupError;

/// Pause between two polls of a mode (wall time).
const POLL: Duration = Duration::from_millis(20);

/// A connection to the robot's dashboard server.
pub struct Dashboard {
    addr: SocketAddr,
    reader: BufReader<TcpStream>,
    writer: TcpStream,
}

impl Dashboard {
    /// Connects to `arm.ur.host:arm.ur.dashboard_port` and reads the welcome line; every read
    /// is bounded by `timeout`.
    pub fn connect(cfg: &UrConfig, timeout: Duration) -> Result<Self, UrSetupError> {
        let host: Ipv4Addr = cfg
            .host
            .parse()
            .expect("validated by ControllerConfig::validate");
        let addr = SocketAddr::from((host, cfg.dashboard_port));
        let err = |why| UrSetupError::Dashboard { addr, why };
        let s = TcpStream::connect_timeout(&addr, timeout).map_err(err)?;
        s.set_read_timeout(Some(timeout)).map_err(err)?;
        s.set_nodelay(true).map_err(err)?;
        let writer = s.try_clone().map_err(err)?;
        let mut d = Self {
            addr,
            reader: BufReader::new(s),
            writer,
        };
        let welcome = d.line()?;
        if !welcome.starts_with("Connected: Universal Robots Dashboard Server") {
            return Err(UrSetupError::DashboardReply {
                command: "(connect)",
                reply: welcome,
                expected: "\"Connected: Universal Robots Dashboard Server\"",
            });
        }
        Ok(d)
    }

    fn line(&mut self) -> Result<String, UrSetupError> {
        let mut l = String::new();
        match self.reader.read_line(&mut l) {
            Ok(0) => Err(UrSetupError::Dashboard {
                addr: self.addr,
                why: std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    "the dashboard server closed the connection",
                ),
            }),
            Ok(_) => Ok(l.trim_end().to_string()),
            Err(why) => Err(UrSetupError::Dashboard {
                addr: self.addr,
                why,
            }),
        }
    }

    /// Sends one command and returns the reply line.
    pub fn ask(&mut self, command: &str) -> Result<String, UrSetupError> {
        writeln!(self.writer, "{command}").map_err(|why| UrSetupError::Dashboard {
            addr: self.addr,
            why,
        })?;
        self.line()
    }

    /// Sends `command` and checks that the reply starts with `expected`.
    fn expect(
        &mut self,
        command: &'static str,
        expected: &'static str,
    ) -> Result<(), UrSetupError> {
        let reply = self.ask(command)?;
        if reply.starts_with(expected) {
            Ok(())
        } else {
            Err(UrSetupError::DashboardReply {
                command,
                reply,
                expected,
            })
        }
    }

    /// The robot mode's name ("RUNNING", "POWER_OFF", …) from `robotmode`.
    pub fn robot_mode(&mut self) -> Result<String, UrSetupError> {
        let reply = self.ask("robotmode")?;
        match reply.strip_prefix("Robotmode: ") {
            Some(m) => Ok(m.trim().to_string()),
            None => Err(UrSetupError::DashboardReply {
                command: "robotmode",
                reply,
                expected: "\"Robotmode: <mode>\"",
            }),
        }
    }

    /// The safety mode's name ("NORMAL", "PROTECTIVE_STOP", …) from `safetymode`, which CB3
    /// and e-Series controllers both answer (`safetystatus` is e-Series only).
    pub fn safety_mode(&mut self) -> Result<String, UrSetupError> {
        let reply = self.ask("safetymode")?;
        match reply.strip_prefix("Safetymode: ") {
            Some(m) => Ok(m.trim().to_string()),
            None => Err(UrSetupError::DashboardReply {
                command: "safetymode",
                reply,
                expected: "\"Safetymode: <mode>\"",
            }),
        }
    }

    /// Refuses a robot of another model than `configured`: `get robot model` names the arm
    /// without its generation ("UR5" for a UR5 and a UR5e), `PolyscopeVersion` gives the
    /// generation (3.x: CB3, 5.x: e-Series).
    pub fn check_model(&mut self, configured: UrModel) -> Result<(), UrSetupError> {
        let robot = self.ask("get robot model")?;
        if !robot.starts_with("UR") {
            return Err(UrSetupError::DashboardReply {
                command: "get robot model",
                reply: robot,
                expected: "a model name (\"UR5\", …)",
            });
        }
        let polyscope = self.ask("PolyscopeVersion")?;
        let major = polyscope
            .strip_prefix("URSoftware ")
            .and_then(|v| v.split('.').next())
            .and_then(|m| m.trim().parse::<u32>().ok())
            .ok_or_else(|| UrSetupError::DashboardReply {
                command: "PolyscopeVersion",
                reply: polyscope.clone(),
                expected: "\"URSoftware <version> …\"",
            })?;
        let robot_model = robot_model(&robot, major >= 5);
        if robot_model == Some(configured) {
            Ok(())
        } else {
            Err(UrSetupError::ModelMismatch {
                configured,
                robot,
                polyscope,
                robot_model,
            })
        }
    }

    /// Polls `robotmode` until `ok(mode)`, at most `timeout`; the last mode seen otherwise.
    fn wait_mode(
        &mut self,
        ok: impl Fn(&str) -> bool,
        timeout: Duration,
    ) -> Result<Result<(), String>, UrSetupError> {
        let t0 = Instant::now();
        loop {
            let mode = self.robot_mode()?;
            if ok(&mode) {
                return Ok(Ok(()));
            }
            if t0.elapsed() >= timeout {
                return Ok(Err(mode));
            }
            std::thread::sleep(POLL);
        }
    }

    /// The bring-up: `power on` unless the arm is powered (then wait for IDLE or RUNNING),
    /// `brake release` unless it runs (then wait for RUNNING); each wait at most `timeout`.
    pub fn bring_up(&mut self, timeout: Duration) -> Result<(), UrSetupError> {
        let timeout_s = timeout.as_secs_f64();
        let mode = self.robot_mode()?;
        if mode == "RUNNING" {
            return Ok(());
        }
        if !matches!(mode.as_str(), "IDLE" | "POWER_ON") {
            self.expect("power on", "Powering on")?;
            if let Err(mode) = self.wait_mode(|m| m == "IDLE" || m == "RUNNING", timeout)? {
                return Err(UrSetupError::BringUp {
                    step: "power on",
                    mode,
                    expected: "IDLE",
                    timeout_s,
                });
            }
        }
        if self.robot_mode()? != "RUNNING" {
            self.expect("brake release", "Brake releasing")?;
            if let Err(mode) = self.wait_mode(|m| m == "RUNNING", timeout)? {
                return Err(UrSetupError::BringUp {
                    step: "brake release",
                    mode,
                    expected: "RUNNING",
                    timeout_s,
                });
            }
        }
        Ok(())
    }

    /// `unlock protective stop` (the caller has waited the 5 s a controller insists on; a
    /// refusal is retried while `wait_more` says the robot's time goes on), then waits for
    /// safety mode NORMAL, at most `timeout`.
    pub fn unlock_protective_stop(
        &mut self,
        timeout: Duration,
        mut wait_more: impl FnMut() -> Result<(), UrSetupError>,
    ) -> Result<(), UrSetupError> {
        let t0 = Instant::now();
        loop {
            let reply = self.ask("unlock protective stop")?;
            if reply.starts_with("Protective stop releasing") {
                break;
            }
            if t0.elapsed() >= timeout {
                return Err(UrSetupError::DashboardReply {
                    command: "unlock protective stop",
                    reply,
                    expected: "\"Protective stop releasing\"",
                });
            }
            wait_more()?;
        }
        loop {
            let mode = self.safety_mode()?;
            if mode == "NORMAL" {
                return Ok(());
            }
            if t0.elapsed() >= timeout {
                return Err(UrSetupError::Recovery(format!(
                    "the safety mode stayed {mode} after `unlock protective stop` for {} s",
                    timeout.as_secs_f64()
                )));
            }
            std::thread::sleep(POLL);
        }
    }
}

/// The model `get robot model`'s reply names on a controller of the given generation
/// (`None` for a name this project does not know).
pub fn robot_model(reply: &str, e_series: bool) -> Option<UrModel> {
    let base = reply.trim().to_ascii_lowercase();
    // An e-Series controller leaves the "e" out ("UR5" for a UR5e; URSim runs the UR7e and
    // UR12e as "UR7" and "UR12" on PolyScope 5, "UR7e" and "UR12e" on PolyScope X: URCL's
    // start_ursim.sh). The UR15, UR18, UR20 and UR30 exist only on the e-Series controller and
    // carry no "e".
    let bare = !base.ends_with('e') && !matches!(base.as_str(), "ur15" | "ur18" | "ur20" | "ur30");
    let name = if e_series && bare {
        format!("{base}e")
    } else {
        base
    };
    let m: UrModel = name.parse().ok()?;
    (m.is_e_series() == e_series).then_some(m)
}

/// The setup's dashboard part, before RTDE: the model check (`check_model`) and the bring-up
/// (`bring_up`); nothing (no connection) when neither is asked.
pub fn prepare(cfg: &UrConfig, timeout: Duration) -> Result<(), UrSetupError> {
    if !cfg.check_model && !cfg.bring_up {
        return Ok(());
    }
    let mut d = Dashboard::connect(cfg, timeout)?;
    if cfg.check_model {
        d.check_model(cfg.model)?;
    }
    if cfg.bring_up {
        d.bring_up(timeout)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_robots_reply_and_generation_name_the_model() {
        assert_eq!(robot_model("UR5", false), Some(UrModel::Ur5));
        assert_eq!(robot_model("UR5", true), Some(UrModel::Ur5e));
        assert_eq!(robot_model("UR16", true), Some(UrModel::Ur16e));
        assert_eq!(robot_model("UR20", true), Some(UrModel::Ur20));
        assert_eq!(robot_model("UR30", true), Some(UrModel::Ur30));
        assert_eq!(robot_model("UR10", false), Some(UrModel::Ur10));
        // The newer models (URSim's names for them on PolyScope 5: URCL's start_ursim.sh).
        assert_eq!(robot_model("UR7", true), Some(UrModel::Ur7e));
        assert_eq!(robot_model("UR12", true), Some(UrModel::Ur12e));
        assert_eq!(robot_model("UR7e", true), Some(UrModel::Ur7e));
        assert_eq!(robot_model("UR15", true), Some(UrModel::Ur15));
        assert_eq!(robot_model("UR18", true), Some(UrModel::Ur18));
        // A UR16 on a CB3, a UR20 on a CB3, a UR15 on a CB3, unknown models: no such arm.
        assert_eq!(robot_model("UR16", false), None);
        assert_eq!(robot_model("UR20", false), None);
        assert_eq!(robot_model("UR15", false), None);
        assert_eq!(robot_model("UR8LONG", true), None);
        assert_eq!(robot_model("UR99", true), None);
    }
}
