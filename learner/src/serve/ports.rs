//! The learner's iceoryx2 ports: samples in, gain tables out (docs/design.md §3).

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{GainTable, StepSample};

/// The learner's iceoryx2 node and its two ports. Fields drop in order: ports before the node.
pub(super) struct Ports {
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
