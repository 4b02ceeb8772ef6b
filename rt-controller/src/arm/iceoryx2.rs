//! The iceoryx2 arm: `arm/state` in, `arm/command` out, with the quality of service of
//! [`ur5_shared::services`] (docs/design.md §3.2): `hil-sim serve`, or any process that
//! publishes and subscribes on the same prefix.

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ur5_shared::clock::monotonic_ns;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{ArmCommand, ArmState};

use super::{ArmBackend, ArmIoError};
use crate::error::{port_err, SetupError};

/// The arm's two ports and their services. Created on the controller's node
/// ([`crate::ports::ControllerPorts::node`]), which must outlive it.
pub struct Iceoryx2Arm {
    state_sub: Subscriber<ipc::Service, ArmState, ()>,
    cmd_pub: Publisher<ipc::Service, ArmCommand, ()>,
    state_svc: PubSubFactory<ipc::Service, ArmState, ()>,
    cmd_svc: PubSubFactory<ipc::Service, ArmCommand, ()>,
    prefix: String,
}

impl Iceoryx2Arm {
    /// Opens (or creates) `arm/state` and `arm/command` under `names` and creates the ports.
    pub fn create(node: &Node<ipc::Service>, names: &ServiceNames) -> Result<Self, SetupError> {
        let state_svc =
            services::ARM_STATE_QOS.open_or_create_retrying::<ArmState>(node, &names.arm_state)?;
        let cmd_svc = services::ARM_COMMAND_QOS
            .open_or_create_retrying::<ArmCommand>(node, &names.arm_command)?;
        let state_sub = state_svc
            .subscriber_builder()
            .create()
            .map_err(|e| port_err("subscriber", &names.arm_state, &e))?;
        let cmd_pub = cmd_svc
            .publisher_builder()
            .create()
            .map_err(|e| port_err("publisher", &names.arm_command, &e))?;
        Ok(Self {
            state_sub,
            cmd_pub,
            state_svc,
            cmd_svc,
            prefix: names.prefix.clone(),
        })
    }

    /// Number of arm-state publishers and arm-command subscribers connected.
    pub fn peers(&self) -> (usize, usize) {
        (
            self.state_svc.dynamic_config().number_of_publishers(),
            self.cmd_svc.dynamic_config().number_of_subscribers(),
        )
    }
}

impl ArmBackend for Iceoryx2Arm {
    fn wait_ready(&mut self, timeout_s: f64) -> Result<ArmState, SetupError> {
        let t0 = monotonic_ns();
        let timeout_ns = (timeout_s * 1e9) as u64;
        let mut latest = None;
        loop {
            if let Ok(Some(s)) = self.state_sub.receive() {
                latest = Some(*s);
            }
            let (_, cmd_subs) = self.peers();
            if let (Some(s), true) = (latest, cmd_subs > 0) {
                return Ok(s);
            }
            if monotonic_ns() - t0 > timeout_ns {
                return Err(SetupError::PeerTimeout {
                    what: if latest.is_none() {
                        "arm state on arm/state"
                    } else {
                        "arm subscriber on arm/command"
                    },
                    start: "hil-sim serve",
                    timeout_s,
                    prefix: self.prefix.clone(),
                });
            }
            std::thread::sleep(core::time::Duration::from_millis(1));
        }
    }

    fn connect(&mut self) -> Result<(), SetupError> {
        let _ = self.cmd_pub.update_connections();
        let _ = self.state_sub.update_connections();
        Ok(())
    }

    #[inline]
    fn receive(&mut self) -> Result<Option<ArmState>, ArmIoError> {
        match self.state_sub.receive() {
            Ok(Some(s)) => Ok(Some(*s)),
            Ok(None) => Ok(None),
            Err(_) => Err(ArmIoError::Receive),
        }
    }

    #[inline]
    fn send(&mut self, cmd: &ArmCommand) -> Result<(), ArmIoError> {
        self.cmd_pub
            .send_copy(*cmd)
            .map(|_| ())
            .map_err(|_| ArmIoError::Send)
    }
}
