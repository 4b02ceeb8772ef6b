//! The controller's iceoryx2 node and learner ports, created in the setup phase (docs/design.md
//! §3.2, §3.4): `learner/samples` out, `controller/gains` in, each with the quality of service of
//! [`ur5_shared::services`]. The arm's ports are the arm backend's ([`crate::arm`]); the
//! iceoryx2 arm ([`crate::arm::Iceoryx2Arm`]) is created on this node.

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{GainTable, StepSample};

use crate::error::port_err;
pub use crate::error::SetupError;

/// The node and the two learner ports. Fields drop in order: ports before services before the
/// node (an arm created on [`Self::node`] must be dropped before this).
pub struct ControllerPorts {
    pub(crate) sample_pub: Publisher<ipc::Service, StepSample, ()>,
    pub(crate) gains_sub: Subscriber<ipc::Service, GainTable, ()>,
    pub(crate) samples_svc: PubSubFactory<ipc::Service, StepSample, ()>,
    pub(crate) gains_svc: PubSubFactory<ipc::Service, GainTable, ()>,
    /// Names in use.
    pub names: ServiceNames,
    _node: Node<ipc::Service>,
    /// This controller is the prefix's only one while it runs.
    _role: services::RoleLock,
}

impl ControllerPorts {
    /// Creates the node (signal handling left to the caller) and the learner ports.
    pub fn create(prefix: &str) -> Result<Self, SetupError> {
        let role = services::RoleLock::acquire(prefix, "controller")?;
        let names = ServiceNames::new(prefix);
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| SetupError::Node(format!("{e:?}")))?;
        let samples_svc = services::LEARNER_SAMPLES_QOS
            .open_or_create_retrying::<StepSample>(&node, &names.learner_samples)?;
        let gains_svc = services::CONTROLLER_GAINS_QOS
            .open_or_create_retrying::<GainTable>(&node, &names.controller_gains)?;
        let sample_pub = samples_svc
            .publisher_builder()
            .create()
            .map_err(|e| port_err("publisher", &names.learner_samples, &e))?;
        let gains_sub = gains_svc
            .subscriber_builder()
            .create()
            .map_err(|e| port_err("subscriber", &names.controller_gains, &e))?;
        Ok(Self {
            sample_pub,
            gains_sub,
            samples_svc,
            gains_svc,
            names,
            _node: node,
            _role: role,
        })
    }

    /// The node, for the iceoryx2 arm's ports.
    pub fn node(&self) -> &Node<ipc::Service> {
        &self._node
    }

    /// Number of sample subscribers and gain publishers connected (the learner's ports).
    pub fn learner_peers(&self) -> (usize, usize) {
        (
            self.samples_svc.dynamic_config().number_of_subscribers(),
            self.gains_svc.dynamic_config().number_of_publishers(),
        )
    }

    /// Establishes the connections to the learner now, so that the loop's first send does not
    /// (connection changes allocate inside iceoryx2).
    pub fn connect(&self) {
        let _ = self.sample_pub.update_connections();
        let _ = self.gains_sub.update_connections();
    }
}
