//! The learner's iceoryx2 ports: samples in, gain tables out (docs/design.md §3).

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::status::PeerStatus;
use ur5_shared::{GainTable, StepSample};

/// The status ports of a learner (docs/design.md §3.12): `learner/status` out (why this learner
/// stops), `controller/status` in (why the controller stopped). Create them before the sample
/// subscriber, so that they exist when the controller's setup sees the learner.
pub(crate) struct StatusPorts {
    out: Publisher<ipc::Service, PeerStatus, ()>,
    out_svc: PubSubFactory<ipc::Service, PeerStatus, ()>,
    from_controller: Subscriber<ipc::Service, PeerStatus, ()>,
}

impl StatusPorts {
    pub(crate) fn create(node: &Node<ipc::Service>, names: &ServiceNames) -> anyhow::Result<Self> {
        let out_svc = services::STATUS_QOS
            .open_or_create_retrying::<PeerStatus>(node, &names.learner_status)?;
        let in_svc = services::STATUS_QOS
            .open_or_create_retrying::<PeerStatus>(node, &names.controller_status)?;
        let out = out_svc
            .publisher_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("cannot publish on `{}`: {e:?}", names.learner_status))?;
        let from_controller = in_svc.subscriber_builder().create().map_err(|e| {
            anyhow::anyhow!("cannot subscribe to `{}`: {e:?}", names.controller_status)
        })?;
        Ok(Self {
            out,
            out_svc,
            from_controller,
        })
    }

    /// `Err` with the controller's message if it said it stopped.
    pub(crate) fn check_controller(&self) -> anyhow::Result<()> {
        while let Some(s) = self
            .from_controller
            .receive()
            .map_err(|e| anyhow::anyhow!("receiving the controller's status: {e:?}"))?
        {
            if s.is_fatal() {
                anyhow::bail!("the controller stopped: {}", s.text());
            }
        }
        Ok(())
    }

    /// Tells the controller why this learner stops, then waits (at most 2 s) until it has
    /// read it and gone (it stops on reading it).
    pub(crate) fn stopping(&self, why: &anyhow::Error) {
        let st = PeerStatus::fatal(
            ur5_shared::clock::monotonic_ns(),
            format_args!("the learner stopped: {why:#}"),
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

/// The learner's iceoryx2 node and its ports. Fields drop in order: ports before the node.
pub(super) struct Ports {
    pub(super) status: StatusPorts,
    pub(super) samples: Subscriber<ipc::Service, StepSample, ()>,
    pub(super) gains: Publisher<ipc::Service, GainTable, ()>,
    pub(super) node: Node<ipc::Service>,
    /// This learner is the prefix's only one while it runs.
    _role: services::RoleLock,
}

impl Ports {
    /// Setup: removes what dead processes left behind (e.g. this learner's killed
    /// predecessor), then opens both services with the project's QoS and creates the ports.
    pub(super) fn create(prefix: &str) -> anyhow::Result<Self> {
        let role = services::RoleLock::acquire(prefix, "learner")?;
        let _ = Node::<ipc::Service>::try_cleanup_dead_nodes(Config::global_config());
        let names = ServiceNames::new(prefix);
        let node = NodeBuilder::new().create::<ipc::Service>().map_err(|e| {
            anyhow::anyhow!("cannot create the iceoryx2 node: {e:?}; is /dev/shm writable?")
        })?;
        let status = StatusPorts::create(&node, &names)?;
        let samples_svc = services::LEARNER_SAMPLES_QOS
            .open_or_create_retrying::<StepSample>(&node, &names.learner_samples)?;
        let gains_svc = services::CONTROLLER_GAINS_QOS
            .open_or_create_retrying::<GainTable>(&node, &names.controller_gains)?;
        let samples = samples_svc
            .subscriber_builder()
            .buffer_size(services::LEARNER_SAMPLES_QOS.subscriber_buffer)
            .create()
            .map_err(|e| {
                anyhow::anyhow!("cannot subscribe to `{}`: {e:?}", names.learner_samples)
            })?;
        let gains = gains_svc.publisher_builder().create().map_err(|e| {
            anyhow::anyhow!("cannot publish on `{}`: {e:?}", names.controller_gains)
        })?;
        Ok(Self {
            status,
            samples,
            gains,
            node,
            _role: role,
        })
    }

    pub(super) fn publish(&self, table: &GainTable) -> anyhow::Result<()> {
        let mut slot = self
            .gains
            .loan_uninit()
            .map_err(|e| anyhow::anyhow!("loaning a gain-table sample: {e:?}"))?;
        table.copy_to_uninit(slot.payload_mut());
        // SAFETY: copy_to_uninit initialised the whole payload.
        unsafe { slot.assume_init() }
            .send()
            .map_err(|e| anyhow::anyhow!("publishing a gain table: {e:?}"))?;
        Ok(())
    }
}
