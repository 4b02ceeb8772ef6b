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

/// Setup failures; each message says what to check.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// Invalid configuration.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
    /// The configured arm backend is not the one this setup builds, or not available.
    #[error("arm.backend = \"{0}\" is not available yet: the UR driver (issue 13) has its configuration and setup (rt_controller::arm::ur) but not its loop; use arm.backend = \"iceoryx2\" with `hil-sim serve`")]
    BackendUnavailable(&'static str),
    /// The `ur` arm's setup failed.
    #[error(transparent)]
    Ur(#[from] crate::arm::ur::UrSetupError),
    /// Another controller runs on the prefix.
    #[error(transparent)]
    Role(#[from] ur5_shared::services::RoleLockError),
    /// A service name iceoryx2 refused.
    #[error(transparent)]
    Name(#[from] ur5_shared::services::InvalidServiceName),
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node: {0}; is /dev/shm writable?")]
    Node(String),
    /// A service could not be opened or created.
    #[error(transparent)]
    Service(#[from] ur5_shared::services::OpenServiceError),
    /// A port could not be created.
    #[error("cannot create a {kind} on `{name}`: {why}; too many processes may be connected (stale ports of killed processes count until cleaned up)")]
    Port {
        /// publisher / subscriber.
        kind: &'static str,
        /// Full service name.
        name: String,
        /// iceoryx2's error.
        why: String,
    },
    /// A peer did not show up in time.
    #[error("no {what} within {timeout_s} s on prefix `{prefix}`: start it with the same --prefix (e.g. `hil-sim serve --prefix {prefix}`), or raise setup_timeout_s")]
    PeerTimeout {
        /// What was waited for.
        what: &'static str,
        /// Timeout (s).
        timeout_s: f64,
        /// The service prefix.
        prefix: String,
    },
}

/// `SetupError::Port` for a port iceoryx2 refused.
pub(crate) fn port_err(kind: &'static str, name: &str, e: &dyn core::fmt::Debug) -> SetupError {
    SetupError::Port {
        kind,
        name: name.to_owned(),
        why: format!("{e:?}"),
    }
}

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
