//! Detects lost peers without touching the loop: a background thread with its own iceoryx2
//! node looks, every `monitor_period_s`, at which nodes own the ports of our four services and
//! whether their processes are alive. A peer is lost when its process is dead (killed without
//! cleaning up, e.g. SIGKILL or a crash: it stays registered in the services, so port counts
//! alone do not show it) or when its ports are gone (it exited, or someone removed its stale
//! resources).
//!
//! The loop only reads the atomic counters (no allocation, no lock). The monitor does not
//! remove a dead peer's resources: that changes the loop's connections, and connection changes
//! allocate inside iceoryx2; a restarted peer can call `Node::try_cleanup_dead_nodes` itself.

use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use serde::Serialize;
use ur5_shared::services::{self, ServiceNames};
use ur5_shared::{ArmCommand, ArmState, GainTable, StepSample};

/// Peer processes that went away. A node is classified by the ports it owns: any publisher of
/// `arm/state` or subscriber of `arm/command` is an arm, any subscriber of `learner/samples` or
/// publisher of `controller/gains` a learner (monitoring tools included).
#[derive(Debug, Default)]
pub struct PeerHealth {
    /// Arm processes that died (or left) during the run.
    pub lost_arm: AtomicU64,
    /// Learner processes that died (or left) during the run.
    pub lost_learner: AtomicU64,
    /// Scans completed (or `u64::MAX` when the monitor could not start): see
    /// [`PeerMonitor::wait_first_scan`].
    pub scans: AtomicU64,
}

/// Peer processes that died or left: a snapshot of [`PeerHealth`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct LostPeers {
    /// Arm processes.
    pub arm: u64,
    /// Learner processes.
    pub learner: u64,
}

impl PeerHealth {
    /// The counters now.
    pub fn lost(&self) -> LostPeers {
        LostPeers {
            arm: self.lost_arm.load(Ordering::Relaxed),
            learner: self.lost_learner.load(Ordering::Relaxed),
        }
    }
}

/// A running monitor; stops and joins on drop.
pub struct PeerMonitor {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    /// What it found.
    pub health: Arc<PeerHealth>,
}

impl Drop for PeerMonitor {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn open<T: core::fmt::Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    name: &str,
    qos: &services::Qos,
) -> Option<PubSubFactory<ipc::Service, T, ()>> {
    let sname = ServiceNames::service_name(name).ok()?;
    qos.open_or_create::<T>(node, &sname).ok()
}

impl PeerMonitor {
    /// Blocks until the monitor has finished one scan (or could not start), at most `timeout`;
    /// returns whether it did. Called in the controller's setup, after the arm and learner are
    /// connected, so that every peer present at the start is known before the loop runs: a
    /// peer killed in the first milliseconds is then reported as lost, not missed (its ports
    /// may be cleaned up before a first scan that comes later would see them).
    pub fn wait_first_scan(&self, timeout: Duration) -> bool {
        let t0 = std::time::Instant::now();
        while self.health.scans.load(Ordering::Acquire) == 0 {
            if t0.elapsed() >= timeout {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        true
    }

    /// Starts the monitor for the services under `prefix`, looking every `period`.
    pub fn spawn(prefix: &str, period: Duration) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let health = Arc::new(PeerHealth::default());
        let names = ServiceNames::new(prefix);
        let handle = {
            let (stop, health) = (stop.clone(), health.clone());
            std::thread::Builder::new()
                .name("peer-monitor".into())
                .spawn(move || watch(&names, period, &stop, &health))
                .ok()
        };
        Self {
            stop,
            handle,
            health,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    Arm,
    Learner,
}

fn watch(names: &ServiceNames, period: Duration, stop: &AtomicBool, health: &PeerHealth) {
    scan_loop(names, period, stop, health);
    // Could not start, or stopped: nobody waits for a scan that will not come.
    let _ = health
        .scans
        .compare_exchange(0, u64::MAX, Ordering::AcqRel, Ordering::Acquire);
}

fn scan_loop(names: &ServiceNames, period: Duration, stop: &AtomicBool, health: &PeerHealth) {
    let Ok(node) = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
    else {
        eprintln!("rt-controller: peer monitor could not create its node; dead peers will not be reported");
        return;
    };
    let (Some(state), Some(cmd), Some(samples), Some(gains)) = (
        open::<ArmState>(&node, &names.arm_state, &services::ARM_STATE_QOS),
        open::<ArmCommand>(&node, &names.arm_command, &services::ARM_COMMAND_QOS),
        open::<StepSample>(
            &node,
            &names.learner_samples,
            &services::LEARNER_SAMPLES_QOS,
        ),
        open::<GainTable>(
            &node,
            &names.controller_gains,
            &services::CONTROLLER_GAINS_QOS,
        ),
    ) else {
        eprintln!("rt-controller: peer monitor could not open the services; dead peers will not be reported");
        return;
    };
    let mut current: Vec<(UniqueNodeId, Role)> = Vec::new();
    let mut known: Vec<(UniqueNodeId, Role, bool)> = Vec::new();
    let mut dead: Vec<UniqueNodeId> = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        current.clear();
        dead.clear();
        state.dynamic_config().list_publishers(|p| {
            current.push((p.node_id, Role::Arm));
            CallbackProgression::Continue
        });
        cmd.dynamic_config().list_subscribers(|s| {
            current.push((s.node_id, Role::Arm));
            CallbackProgression::Continue
        });
        samples.dynamic_config().list_subscribers(|s| {
            current.push((s.node_id, Role::Learner));
            CallbackProgression::Continue
        });
        gains.dynamic_config().list_publishers(|p| {
            current.push((p.node_id, Role::Learner));
            CallbackProgression::Continue
        });
        let _ = Node::<ipc::Service>::list(node.config(), |n| {
            if let NodeState::Dead(view) = n {
                dead.push(*view.id());
            }
            CallbackProgression::Continue
        });
        for &(id, role) in &current {
            if !known.iter().any(|(k, r, _)| *k == id && *r == role) {
                known.push((id, role, false));
            }
        }
        for (id, role, lost) in known.iter_mut() {
            let present = current.iter().any(|(c, r)| c == id && r == role);
            if !*lost && (dead.contains(id) || !present) {
                *lost = true;
                let (counter, name) = match role {
                    Role::Arm => (&health.lost_arm, "arm"),
                    Role::Learner => (&health.lost_learner, "learner"),
                };
                counter.fetch_add(1, Ordering::Relaxed);
                eprintln!(
                    "rt-controller: peer died: {name} (pid {}) on prefix `{}` {}",
                    id.pid().value(),
                    names.prefix,
                    if present {
                        "(its ports stay registered until its resources are cleaned up)"
                    } else {
                        "(ports gone)"
                    }
                );
            }
        }
        health.scans.fetch_add(1, Ordering::AcqRel);
        std::thread::sleep(period);
    }
}
