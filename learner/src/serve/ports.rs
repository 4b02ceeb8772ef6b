//! The learner's iceoryx2 ports: samples in, gain or policy tables out (docs/design.md §3).

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::status::PeerStatus;
use ur5_shared::{GainTable, PolicyTable, StepSample};

use core::mem::MaybeUninit;

use super::ServeError;

/// The status ports of a learner (docs/design.md §3.12): `learner/status` out (why this learner
/// stops), `controller/status` in (why the controller stopped). Create them before the sample
/// subscriber, so that they exist when the controller's setup sees the learner.
pub(crate) struct StatusPorts {
    out: Publisher<ipc::Service, PeerStatus, ()>,
    out_svc: PubSubFactory<ipc::Service, PeerStatus, ()>,
    from_controller: Subscriber<ipc::Service, PeerStatus, ()>,
}

impl StatusPorts {
    pub(crate) fn create(
        node: &Node<ipc::Service>,
        names: &ServiceNames,
    ) -> Result<Self, ServeError> {
        let out_svc = services::STATUS_QOS
            .open_or_create_retrying::<PeerStatus>(node, &names.learner_status)?;
        let in_svc = services::STATUS_QOS
            .open_or_create_retrying::<PeerStatus>(node, &names.controller_status)?;
        let out = out_svc.publisher_builder().create().map_err(|e| {
            ServeError::Ipc(format!(
                "cannot publish on `{}`: {e:?}",
                names.learner_status
            ))
        })?;
        let from_controller = in_svc.subscriber_builder().create().map_err(|e| {
            ServeError::Ipc(format!(
                "cannot subscribe to `{}`: {e:?}",
                names.controller_status
            ))
        })?;
        Ok(Self {
            out,
            out_svc,
            from_controller,
        })
    }

    /// `Err` with the controller's message if it said it stopped.
    pub(crate) fn check_controller(&self) -> Result<(), ServeError> {
        while let Some(s) = self
            .from_controller
            .receive()
            .map_err(|e| ServeError::Ipc(format!("receiving the controller's status: {e:?}")))?
        {
            if s.is_fatal() {
                return Err(ServeError::ControllerStopped(s.text().to_string()));
            }
        }
        Ok(())
    }

    /// Tells the controller why this learner stops, then waits (at most 2 s) until it has
    /// read it and gone (it stops on reading it).
    pub(crate) fn stopping(&self, why: &ServeError) {
        let st = PeerStatus::fatal(
            ur5_shared::clock::monotonic_ns(),
            format_args!("the learner stopped: {}", crate::error::line(why)),
        );
        let _ = self.out.update_connections();
        if self.out.send_copy(st).is_err() {
            return;
        }
        let t0 = std::time::Instant::now();
        while self.out_svc.dynamic_config().number_of_subscribers() > 0
            && t0.elapsed() < std::time::Duration::from_secs(2)
        {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }
}

/// A table the learner publishes to the controller: gain tables on `controller/gains`
/// (`learner serve`), policy tables on `controller/policy` (`learner policy serve`).
pub(super) trait Outgoing: Sized + core::fmt::Debug + ZeroCopySend + 'static {
    /// Its service's QoS.
    const QOS: services::Qos;
    /// What a loaned sample holds, for errors ("a gain-table sample").
    const SAMPLE: &'static str;
    /// What is published, for errors ("a gain table").
    const PUBLISHED: &'static str;
    /// Its service's name under the prefix.
    fn service(names: &ServiceNames) -> &str;
    /// Writes `self` into a loaned, uninitialised sample, initialising all of it.
    fn write_to(&self, slot: &mut MaybeUninit<Self>);
}

impl Outgoing for GainTable {
    const QOS: services::Qos = services::CONTROLLER_GAINS_QOS;
    const SAMPLE: &'static str = "a gain-table sample";
    const PUBLISHED: &'static str = "a gain table";
    fn service(names: &ServiceNames) -> &str {
        &names.controller_gains
    }
    fn write_to(&self, slot: &mut MaybeUninit<Self>) {
        self.copy_to_uninit(slot);
    }
}

impl Outgoing for PolicyTable {
    const QOS: services::Qos = services::CONTROLLER_POLICY_QOS;
    const SAMPLE: &'static str = "a policy-table sample";
    const PUBLISHED: &'static str = "the policy table";
    fn service(names: &ServiceNames) -> &str {
        &names.controller_policy
    }
    fn write_to(&self, slot: &mut MaybeUninit<Self>) {
        PolicyTable::init_zeroed(slot).copy_from(self);
    }
}

/// The learner's iceoryx2 node and its ports: samples in, tables `T` out. Fields drop in
/// order: ports before the node.
pub(super) struct Ports<T: Outgoing> {
    pub(super) status: StatusPorts,
    pub(super) samples: Subscriber<ipc::Service, StepSample, ()>,
    tables: Publisher<ipc::Service, T, ()>,
    pub(super) node: Node<ipc::Service>,
    /// This learner is the prefix's only one while it runs.
    _role: services::RoleLock,
}

impl<T: Outgoing> Ports<T> {
    /// Setup: removes what dead processes left behind (e.g. this learner's killed
    /// predecessor), then opens both services with the project's QoS and creates the ports
    /// (the status ports first, §3.12).
    pub(super) fn create(prefix: &str) -> Result<Self, ServeError> {
        let role = services::RoleLock::acquire(prefix, "learner")?;
        let _ = Node::<ipc::Service>::try_cleanup_dead_nodes(Config::global_config());
        let names = ServiceNames::new(prefix);
        let node = NodeBuilder::new().create::<ipc::Service>().map_err(|e| {
            ServeError::Ipc(format!(
                "cannot create the iceoryx2 node: {e:?}; is /dev/shm writable?"
            ))
        })?;
        let status = StatusPorts::create(&node, &names)?;
        let samples_svc = services::LEARNER_SAMPLES_QOS
            .open_or_create_retrying::<StepSample>(&node, &names.learner_samples)?;
        let tables_svc = T::QOS.open_or_create_retrying::<T>(&node, T::service(&names))?;
        let samples = samples_svc
            .subscriber_builder()
            .buffer_size(services::LEARNER_SAMPLES_QOS.subscriber_buffer)
            .create()
            .map_err(|e| {
                ServeError::Ipc(format!(
                    "cannot subscribe to `{}`: {e:?}",
                    names.learner_samples
                ))
            })?;
        let tables = tables_svc.publisher_builder().create().map_err(|e| {
            ServeError::Ipc(format!("cannot publish on `{}`: {e:?}", T::service(&names)))
        })?;
        Ok(Self {
            status,
            samples,
            tables,
            node,
            _role: role,
        })
    }

    /// Publishes `table` (one loaned sample).
    pub(super) fn publish(&self, table: &T) -> Result<(), ServeError> {
        let mut slot = self
            .tables
            .loan_uninit()
            .map_err(|e| ServeError::Ipc(format!("loaning {}: {e:?}", T::SAMPLE)))?;
        table.write_to(slot.payload_mut());
        // SAFETY: write_to initialised the whole payload.
        unsafe { slot.assume_init() }
            .send()
            .map_err(|e| ServeError::Ipc(format!("publishing {}: {e:?}", T::PUBLISHED)))?;
        Ok(())
    }

    /// Delivers the published history to subscribers that connected since (a controller
    /// that started late).
    pub(super) fn update_connections(&self) {
        let _ = self.tables.update_connections();
    }
}
