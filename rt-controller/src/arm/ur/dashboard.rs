//! The `ur` arm's use of the dashboard server (TCP 29999; the shared client,
//! [`ur_protocol::dashboard`]): the model check and the bring-up at setup, the unlock of a
//! protective stop in a recovery. Setup-like code: it allocates, blocks (every wait bounded)
//! and fails with [`UrSetupError`]s; docs/ur.md, "The dashboard server".

use std::net::{Ipv4Addr, SocketAddr};
use std::time::{Duration, Instant};

use ur5_shared::UrModel;
use ur_protocol::dashboard::DashboardError;

use crate::config::UrConfig;

use crate::error::UrSetupError;

/// Pause between two polls of a mode (wall time).
const POLL: Duration = Duration::from_millis(20);

/// A connection to the robot's dashboard server (the shared client,
/// [`ur_protocol::dashboard`]).
pub struct Dashboard(ur_protocol::dashboard::Dashboard);

impl From<DashboardError> for UrSetupError {
    fn from(e: DashboardError) -> Self {
        match e {
            DashboardError::Io { addr, why } => UrSetupError::Dashboard { addr, why },
            DashboardError::Reply {
                command,
                reply,
                expected,
            } => UrSetupError::DashboardReply {
                command,
                reply,
                expected,
            },
        }
    }
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
        Ok(Self(ur_protocol::dashboard::Dashboard::connect(
            addr, timeout,
        )?))
    }

    /// Sends one command and returns the reply line.
    pub fn ask(&mut self, command: &str) -> Result<String, UrSetupError> {
        Ok(self.0.ask(command)?)
    }

    /// Sends `command` and checks that the reply starts with `expected`.
    fn expect(
        &mut self,
        command: &'static str,
        expected: &'static str,
    ) -> Result<(), UrSetupError> {
        Ok(self.0.expect(command, expected)?)
    }

    /// The robot mode's name ("RUNNING", "POWER_OFF", …) from `robotmode`.
    pub fn robot_mode(&mut self) -> Result<String, UrSetupError> {
        Ok(self.0.robot_mode()?)
    }

    /// The safety mode's name ("NORMAL", "PROTECTIVE_STOP", …) from `safetymode`.
    pub fn safety_mode(&mut self) -> Result<String, UrSetupError> {
        Ok(self.0.safety_mode()?)
    }

    /// Refuses a robot of another model than `configured` ([`ur_protocol::dashboard::
    /// Dashboard::identity`]).
    pub fn check_model(&mut self, configured: UrModel) -> Result<(), UrSetupError> {
        let id = self.0.identity()?;
        let robot_model = id.model();
        if robot_model == Some(configured) {
            Ok(())
        } else {
            Err(UrSetupError::ModelMismatch {
                configured,
                robot: id.robot,
                polyscope: id.polyscope,
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
