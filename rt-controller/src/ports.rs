//! The controller's iceoryx2 node and learner ports, created in the setup phase (docs/design.md
//! §3.2, §3.4, §3.11): `learner/samples` out, `controller/gains` and `controller/policy` in, each with the quality of service of
//! [`ur5_shared::services`]. The arm's ports are the arm backend's ([`crate::arm`]); the
//! iceoryx2 arm ([`crate::arm::Iceoryx2Arm`]) is created on this node.

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::status::PeerStatus;
use ur5_shared::{GainTable, PolicyTable, StepSample};

use crate::error::port_err;
pub use crate::error::SetupError;

/// The node and the two learner ports. Fields drop in order: ports before services before the
/// node (an arm created on [`Self::node`] must be dropped before this).
pub struct ControllerPorts {
    pub(crate) sample_pub: Publisher<ipc::Service, StepSample, ()>,
    pub(crate) gains_sub: Subscriber<ipc::Service, GainTable, ()>,
    pub(crate) policy_sub: Subscriber<ipc::Service, PolicyTable, ()>,
    /// `controller/status`: why this controller stopped (docs/design.md §3.12).
    pub(crate) status_pub: Publisher<ipc::Service, PeerStatus, ()>,
    /// `learner/status`: why the learner stopped.
    pub(crate) learner_status_sub: Subscriber<ipc::Service, PeerStatus, ()>,
    pub(crate) status_svc: PubSubFactory<ipc::Service, PeerStatus, ()>,
    pub(crate) samples_svc: PubSubFactory<ipc::Service, StepSample, ()>,
    pub(crate) gains_svc: PubSubFactory<ipc::Service, GainTable, ()>,
    pub(crate) policy_svc: PubSubFactory<ipc::Service, PolicyTable, ()>,
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
        let policy_svc = services::CONTROLLER_POLICY_QOS
            .open_or_create_retrying::<PolicyTable>(&node, &names.controller_policy)?;
        let status_svc = services::STATUS_QOS
            .open_or_create_retrying::<PeerStatus>(&node, &names.controller_status)?;
        let learner_status_svc = services::STATUS_QOS
            .open_or_create_retrying::<PeerStatus>(&node, &names.learner_status)?;
        let status_pub = status_svc
            .publisher_builder()
            .create()
            .map_err(|e| port_err("publisher", &names.controller_status, &e))?;
        let learner_status_sub = learner_status_svc
            .subscriber_builder()
            .create()
            .map_err(|e| port_err("subscriber", &names.learner_status, &e))?;
        let sample_pub = samples_svc
            .publisher_builder()
            .create()
            .map_err(|e| port_err("publisher", &names.learner_samples, &e))?;
        let gains_sub = gains_svc
            .subscriber_builder()
            .create()
            .map_err(|e| port_err("subscriber", &names.controller_gains, &e))?;
        let policy_sub = policy_svc
            .subscriber_builder()
            .create()
            .map_err(|e| port_err("subscriber", &names.controller_policy, &e))?;
        Ok(Self {
            sample_pub,
            gains_sub,
            policy_sub,
            status_pub,
            learner_status_sub,
            status_svc,
            samples_svc,
            gains_svc,
            policy_svc,
            names,
            _node: node,
            _role: role,
        })
    }

    /// The node, for the iceoryx2 arm's ports.
    pub fn node(&self) -> &Node<ipc::Service> {
        &self._node
    }

    /// Number of sample subscribers and of table publishers (gain and policy) connected (the
    /// learner's ports).
    pub fn learner_peers(&self) -> (usize, usize) {
        (
            self.samples_svc.dynamic_config().number_of_subscribers(),
            self.gains_svc.dynamic_config().number_of_publishers()
                + self.policy_svc.dynamic_config().number_of_publishers(),
        )
    }

    /// Establishes the connections to the learner now, so that the loop's first send does not
    /// (connection changes allocate inside iceoryx2).
    pub fn connect(&self) {
        let _ = self.sample_pub.update_connections();
        let _ = self.gains_sub.update_connections();
        let _ = self.policy_sub.update_connections();
        let _ = self.status_pub.update_connections();
        let _ = self.learner_status_sub.update_connections();
    }

    /// Publishes why this controller stops (no allocation: a loaned sample of a Copy payload).
    pub(crate) fn send_status(&self, status: &PeerStatus) -> bool {
        match self.status_pub.loan_uninit() {
            Ok(slot) => slot.write_payload(*status).send().is_ok(),
            Err(_) => false,
        }
    }

    /// A fatal status from the learner, if one arrived (no allocation).
    pub(crate) fn learner_status(&self) -> Option<PeerStatus> {
        while let Ok(Some(s)) = self.learner_status_sub.receive() {
            if s.is_fatal() {
                return Some(*s);
            }
        }
        None
    }

    /// Waits (setup/teardown only) until no learner listens on `controller/status` any more, at
    /// most `max`: the learner reads the status and exits, after which the controller may too.
    pub fn linger_for_status(&self, max: core::time::Duration) {
        let t0 = std::time::Instant::now();
        while self.status_svc.dynamic_config().number_of_subscribers() > 0 && t0.elapsed() < max {
            std::thread::sleep(core::time::Duration::from_millis(5));
        }
    }
}
