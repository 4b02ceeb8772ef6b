//! A blocking client of the robot's dashboard server (TCP 29999): one text line per command,
//! one per reply, as Universal Robots' dashboard server speaks (URCL's `DashboardClient`
//! matches the same replies); docs/ur.md, "The dashboard server". `rt-controller`'s `ur` arm
//! (model check, bring-up, unlock of a protective stop) and `learner record` (model check)
//! share it. Every read is bounded by the connection's timeout.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

use ur5_shared::UrModel;

/// The longest reply line read (bytes): a dashboard reply is one short line; a server that
/// sends more without a newline is not one.
pub const MAX_REPLY: u64 = 4096;

/// What can go wrong talking to the dashboard server.
#[derive(Debug, thiserror::Error)]
pub enum DashboardError {
    /// No connection, or a read or write failed (a read timeout included).
    #[error("cannot talk to the robot's dashboard server at {addr}: {why}")]
    Io {
        /// Where.
        addr: SocketAddr,
        /// The OS error.
        why: std::io::Error,
    },
    /// A reply that is not the expected one.
    #[error("the dashboard server answered `{command}` with \"{reply}\", expected {expected}")]
    Reply {
        /// The command sent.
        command: &'static str,
        /// What came back.
        reply: String,
        /// What was expected.
        expected: &'static str,
    },
}

/// A connection to the robot's dashboard server.
pub struct Dashboard {
    addr: SocketAddr,
    reader: BufReader<TcpStream>,
    writer: TcpStream,
}

/// What the robot says it is: `get robot model` and `PolyscopeVersion`'s replies.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RobotIdentity {
    /// `get robot model`'s reply ("UR5" for a UR5 and a UR5e alike).
    pub robot: String,
    /// `PolyscopeVersion`'s reply ("URSoftware 5.12.0 …").
    pub polyscope: String,
    /// PolyScope 5 or later: an e-Series controller (3.x: CB3).
    pub e_series: bool,
}

impl RobotIdentity {
    /// The model both replies name (`None` for one this project does not know).
    pub fn model(&self) -> Option<UrModel> {
        robot_model(&self.robot, self.e_series)
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

impl Dashboard {
    /// Connects to `addr` and reads the welcome line; every read is bounded by `timeout`.
    pub fn connect(addr: SocketAddr, timeout: Duration) -> Result<Self, DashboardError> {
        let err = |why| DashboardError::Io { addr, why };
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
            return Err(DashboardError::Reply {
                command: "(connect)",
                reply: welcome,
                expected: "\"Connected: Universal Robots Dashboard Server\"",
            });
        }
        Ok(d)
    }

    /// The server's address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    fn line(&mut self) -> Result<String, DashboardError> {
        let mut l = Vec::new();
        let n = (&mut self.reader)
            .take(MAX_REPLY)
            .read_until(b'\n', &mut l)
            .map_err(|why| DashboardError::Io {
                addr: self.addr,
                why,
            })?;
        if n == 0 {
            return Err(DashboardError::Io {
                addr: self.addr,
                why: std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    "the dashboard server closed the connection",
                ),
            });
        }
        Ok(String::from_utf8_lossy(&l).trim_end().to_string())
    }

    /// Sends one command and returns the reply line.
    pub fn ask(&mut self, command: &str) -> Result<String, DashboardError> {
        writeln!(self.writer, "{command}").map_err(|why| DashboardError::Io {
            addr: self.addr,
            why,
        })?;
        self.line()
    }

    /// Sends `command` and checks that the reply starts with `expected`.
    pub fn expect(
        &mut self,
        command: &'static str,
        expected: &'static str,
    ) -> Result<(), DashboardError> {
        let reply = self.ask(command)?;
        if reply.starts_with(expected) {
            Ok(())
        } else {
            Err(DashboardError::Reply {
                command,
                reply,
                expected,
            })
        }
    }

    /// The reply to `command` after `prefix` (e.g. "Robotmode: "), trimmed.
    fn field(
        &mut self,
        command: &'static str,
        prefix: &str,
        expected: &'static str,
    ) -> Result<String, DashboardError> {
        let reply = self.ask(command)?;
        match reply.strip_prefix(prefix) {
            Some(m) => Ok(m.trim().to_string()),
            None => Err(DashboardError::Reply {
                command,
                reply,
                expected,
            }),
        }
    }

    /// The robot mode's name ("RUNNING", "POWER_OFF", …) from `robotmode`.
    pub fn robot_mode(&mut self) -> Result<String, DashboardError> {
        self.field("robotmode", "Robotmode: ", "\"Robotmode: <mode>\"")
    }

    /// The safety mode's name ("NORMAL", "PROTECTIVE_STOP", …) from `safetymode`, which CB3
    /// and e-Series controllers both answer (`safetystatus` is e-Series only).
    pub fn safety_mode(&mut self) -> Result<String, DashboardError> {
        self.field("safetymode", "Safetymode: ", "\"Safetymode: <mode>\"")
    }

    /// What the robot says it is: `get robot model` names the arm without its generation
    /// ("UR5" for a UR5 and a UR5e), `PolyscopeVersion` gives the generation (3.x: CB3, 5.x:
    /// e-Series).
    pub fn identity(&mut self) -> Result<RobotIdentity, DashboardError> {
        let robot = self.ask("get robot model")?;
        if !robot.starts_with("UR") {
            return Err(DashboardError::Reply {
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
            .ok_or_else(|| DashboardError::Reply {
                command: "PolyscopeVersion",
                reply: polyscope.clone(),
                expected: "\"URSoftware <version> …\"",
            })?;
        Ok(RobotIdentity {
            robot,
            polyscope,
            e_series: major >= 5,
        })
    }
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
        assert_eq!(robot_model("UR5e", true), Some(UrModel::Ur5e));
        // A UR16 on a CB3, a UR20 on a CB3, unknown models: no such arm.
        assert_eq!(robot_model("UR16", false), None);
        assert_eq!(robot_model("UR20", false), None);
        assert_eq!(robot_model("UR8LONG", true), None);
        assert_eq!(robot_model("UR99", true), None);
    }
}
