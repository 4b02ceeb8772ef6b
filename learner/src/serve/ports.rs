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

/// A table of either kind, as a learner with several goals publishes them (`learner serve
/// --algo mdgps`: gain tables for the controllers' episodes, policy tables for the
/// evaluations).
#[derive(Debug)]
pub enum AnyTable {
    /// On `controller/gains`.
    Gain(Box<GainTable>),
    /// On `controller/policy`.
    Policy(Box<PolicyTable>),
}

impl Clone for AnyTable {
    /// A copy on the heap (a gain table is too large for the stack).
    fn clone(&self) -> Self {
        match self {
            AnyTable::Gain(t) => AnyTable::Gain(t.boxed_clone()),
            AnyTable::Policy(p) => AnyTable::Policy(p.clone()),
        }
    }
}

impl AnyTable {
    /// Its publication (version, epoch).
    pub fn publication(&self) -> (u64, u32) {
        match self {
            Self::Gain(t) => (t.version, t.epoch),
            Self::Policy(t) => (t.version, t.epoch),
        }
    }
}

/// Creates a publisher of tables `U` on `node`.
fn table_publisher<U: Outgoing>(
    node: &Node<ipc::Service>,
    names: &ServiceNames,
) -> Result<Publisher<ipc::Service, U, ()>, ServeError> {
    let svc = U::QOS.open_or_create_retrying::<U>(node, U::service(names))?;
    svc.publisher_builder()
        .create()
        .map_err(|e| ServeError::Ipc(format!("cannot publish on `{}`: {e:?}", U::service(names))))
}

/// Publishes `table` on `publisher` (one loaned sample).
fn publish_on<U: Outgoing>(
    publisher: &Publisher<ipc::Service, U, ()>,
    table: &U,
) -> Result<(), ServeError> {
    let mut slot = publisher
        .loan_uninit()
        .map_err(|e| ServeError::Ipc(format!("loaning {}: {e:?}", U::SAMPLE)))?;
    table.write_to(slot.payload_mut());
    // SAFETY: write_to initialised the whole payload.
    unsafe { slot.assume_init() }
        .send()
        .map_err(|e| ServeError::Ipc(format!("publishing {}: {e:?}", U::PUBLISHED)))?;
    Ok(())
}

/// The learner's iceoryx2 node and its ports: samples in, tables `T` out (and, for a learner
/// that also publishes policy tables, those). Fields drop in order: ports before the node.
pub(super) struct Ports<T: Outgoing> {
    pub(super) status: StatusPorts,
    pub(super) samples: Subscriber<ipc::Service, StepSample, ()>,
    tables: Publisher<ipc::Service, T, ()>,
    /// Policy tables beside the gain tables ([`Ports::with_policy_tables`]).
    policies: Option<Publisher<ipc::Service, PolicyTable, ()>>,
    pub(super) node: Node<ipc::Service>,
    names: ServiceNames,
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
        let tables = table_publisher::<T>(&node, &names)?;
        Ok(Self {
            status,
            samples,
            tables,
            policies: None,
            node,
            names,
            _role: role,
        })
    }

    /// Publishes `table` (one loaned sample).
    pub(super) fn publish(&self, table: &T) -> Result<(), ServeError> {
        publish_on(&self.tables, table)
    }

    /// Delivers the published history to subscribers that connected since (a controller
    /// that started late).
    pub(super) fn update_connections(&self) {
        let _ = self.tables.update_connections();
        if let Some(p) = &self.policies {
            let _ = p.update_connections();
        }
    }
}

impl Ports<GainTable> {
    /// These ports with a publisher of policy tables too (a learner with several goals
    /// evaluates its policy through them).
    pub(super) fn with_policy_tables(mut self) -> Result<Self, ServeError> {
        self.policies = Some(table_publisher::<PolicyTable>(&self.node, &self.names)?);
        Ok(self)
    }

    /// Publishes `table` on its service.
    pub(super) fn publish_any(&self, table: &AnyTable) -> Result<(), ServeError> {
        match table {
            AnyTable::Gain(t) => self.publish(t),
            AnyTable::Policy(t) => match &self.policies {
                Some(p) => publish_on(p, &**t),
                None => Err(ServeError::Ipc(
                    "a policy table on ports without a policy-table publisher (a bug)".into(),
                )),
            },
        }
    }
}
