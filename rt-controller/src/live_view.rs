//! The live view (`[live_view]`; docs/design.md §3.13): what the controller does, on ROS 2
//! topics for rviz2 or Foxglove, with every arm backend.
//!
//! | topic | type | what |
//! |---|---|---|
//! | `{namespace}/goal` | `geometry_msgs/msg/PointStamped` | `task.goal` (m, `frame_id`) |
//! | `{namespace}/end_effector` | `geometry_msgs/msg/PointStamped` | the end-effector point of a state the controller acted on (a state of the learner's samples) |
//! | `{namespace}/episode` | `std_msgs/msg/UInt64` | the episode number (of the next one between episodes) |
//! | `{namespace}/table_version` | `std_msgs/msg/UInt64` | the active table's version (0 before the first) |
//! | `joint_states_topic` (optional) | `sensor_msgs/msg/JointState` | the arm's six joints, a wrist the task does not move at `arm.ur.wrist_q` |
//!
//! The loop offers an entry at every control tick and at every fresh state between episodes
//! (reset, hold, waiting for a table); it keeps one per `1 / rate_hz` s of wall time (the
//! clock it reads anyway) and pushes it into a preallocated lock-free queue
//! ([`crate::dds_thread::Handoff`], the `ros2` arm's; the oldest entry is dropped when it is
//! full, counted). No allocation, no lock and no system call in the loop: the DDS thread is
//! not woken by the loop but wakes by itself every `1 / rate_hz` s, so an entry waits at most
//! that long. It publishes each entry: goal, episode and table version always; the
//! end-effector point when the entry is a tick's; the joint states if enabled. Headers carry
//! the wall-clock time (ROS time) of the loop's offer.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::Serialize;
use ur5_ros2::{Header, JointState, Node, Point, PointStamped, Time, UInt64, Writer};
use ur5_shared::clock::monotonic_ns;
use ur5_shared::ArmState;

use crate::config::LiveViewConfig;
use crate::dds_thread::{DdsThread, DdsWork, Handoff, Wake};
pub use crate::error::LiveViewError;

/// Entries the loop may queue ahead of the DDS thread: 2 s at the highest rate.
const QUEUE: usize = 2048;

/// One entry, built in the loop (fixed size, `Copy`).
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    /// The loop's offer (monotonic ns).
    at_ns: u64,
    /// A control tick's state: the controller acted on it (the end-effector point goes out).
    tick: bool,
    episode: u64,
    table_version: u64,
    ee: [f64; 3],
    /// The arm's active joints (`joints` of them) in `q[..joints]`, `qd[..joints]`.
    joints: usize,
    q: [f64; 6],
    qd: [f64; 6],
}

/// What the loop and the DDS thread share.
struct Shared {
    entries: Handoff<Entry>,
    published: AtomicU64,
    publish_errors: AtomicU64,
}

/// What the live view did (the summary's `live_view`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LiveViewReport {
    /// Entries the loop queued, and of them dropped because the DDS thread fell behind.
    pub entries: u64,
    pub dropped: u64,
    /// Entries published, and publications that failed.
    pub published: u64,
    pub publish_errors: u64,
}

/// The live view: the loop side ([`Self::offer`]) and its DDS thread.
pub struct LiveView {
    shared: Arc<Shared>,
    /// Stopped and joined on drop.
    _thread: DdsThread,
    interval_ns: u64,
    next_ns: u64,
    entries: u64,
}

impl LiveView {
    /// Setup: joins the ROS domain, creates the writers and starts the DDS thread. `goal` (m,
    /// arm base frame) and `wrist_q` (rad) are constant for the run.
    pub fn start(
        cfg: &LiveViewConfig,
        goal: [f64; 3],
        wrist_q: [f64; 3],
    ) -> Result<Self, LiveViewError> {
        let domain = cfg.domain_id;
        let dds = |source| LiveViewError::Dds { domain, source };
        let node = Node::new(domain, cfg.network).map_err(dds)?;
        let ns = cfg.namespace.trim_end_matches('/');
        let topic = |name: &str| format!("{ns}/{name}");
        let writers = Writers {
            goal: node.writer(&topic("goal"), cfg.qos).map_err(dds)?,
            ee: node.writer(&topic("end_effector"), cfg.qos).map_err(dds)?,
            episode: node.writer(&topic("episode"), cfg.qos).map_err(dds)?,
            table_version: node.writer(&topic("table_version"), cfg.qos).map_err(dds)?,
            joint_states: if cfg.joint_states {
                Some(node.writer(&cfg.joint_states_topic, cfg.qos).map_err(dds)?)
            } else {
                None
            },
        };
        let shared = Arc::new(Shared {
            entries: Handoff::new(QUEUE),
            published: AtomicU64::new(0),
            publish_errors: AtomicU64::new(0),
        });
        let interval_ns = (1e9 / cfg.rate_hz).round() as u64;
        let work = Publish {
            _node: node,
            writers,
            shared: Arc::clone(&shared),
            frame_id: cfg.frame_id.clone(),
            goal: Point {
                x: goal[0],
                y: goal[1],
                z: goal[2],
            },
            joint_names: cfg.joint_names.to_vec(),
            wrist_q,
            wall_minus_monotonic_ns: wall_minus_monotonic_ns(),
        };
        let thread = DdsThread::spawn(
            "live-view-dds",
            Arc::new(Wake::new().map_err(LiveViewError::Thread)?),
            Duration::from_nanos(interval_ns),
            work,
        )
        .map_err(LiveViewError::Thread)?;
        Ok(Self {
            shared,
            _thread: thread,
            interval_ns,
            next_ns: 0,
            entries: 0,
        })
    }

    /// Loop: offers the state `s` at `now_ns` (monotonic); kept if `1 / rate_hz` s passed since
    /// the last entry kept. `tick`: the controller acted on `s` at this step. No allocation, no
    /// lock, no system call.
    #[inline]
    pub fn offer(
        &mut self,
        now_ns: u64,
        s: &ArmState,
        tick: bool,
        episode: u64,
        table_version: u64,
    ) {
        if now_ns < self.next_ns {
            return;
        }
        self.next_ns = now_ns + self.interval_ns;
        self.entries += 1;
        self.shared.entries.push(Entry {
            at_ns: now_ns,
            tick,
            episode,
            table_version,
            ee: s.points[0],
            joints: s.joints as usize,
            q: core::array::from_fn(|j| s.q[j]),
            qd: core::array::from_fn(|j| s.qd[j]),
        });
    }

    /// What it did so far (after the loop).
    pub fn report(&self) -> LiveViewReport {
        LiveViewReport {
            entries: self.entries,
            dropped: self.shared.entries.dropped(),
            published: self.shared.published.load(Ordering::Relaxed),
            publish_errors: self.shared.publish_errors.load(Ordering::Relaxed),
        }
    }
}

/// Wall clock minus monotonic clock (ns), measured once: turns the loop's monotonic offers
/// into ROS time without a clock read in the loop beyond the one it makes anyway.
fn wall_minus_monotonic_ns() -> i128 {
    let wall = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i128);
    wall - monotonic_ns() as i128
}

struct Writers {
    goal: Writer<PointStamped>,
    ee: Writer<PointStamped>,
    episode: Writer<UInt64>,
    table_version: Writer<UInt64>,
    joint_states: Option<Writer<JointState>>,
}

/// The DDS thread's work: publishes every queued entry.
struct Publish {
    /// Owns the participant the writers belong to.
    _node: Node,
    writers: Writers,
    shared: Arc<Shared>,
    frame_id: String,
    goal: Point,
    joint_names: Vec<String>,
    wrist_q: [f64; 3],
    wall_minus_monotonic_ns: i128,
}

impl Publish {
    fn publish(&self, e: &Entry) -> bool {
        let w = &self.writers;
        let ns = (e.at_ns as i128 + self.wall_minus_monotonic_ns).max(0) as u64;
        let header = Header {
            stamp: Time::from_ns(ns),
            frame_id: self.frame_id.clone(),
        };
        let mut ok = w
            .goal
            .write(PointStamped {
                header: header.clone(),
                point: self.goal,
            })
            .is_ok();
        if e.tick {
            ok &=
                w.ee.write(PointStamped {
                    header: header.clone(),
                    point: Point {
                        x: e.ee[0],
                        y: e.ee[1],
                        z: e.ee[2],
                    },
                })
                .is_ok();
        }
        ok &= w.episode.write(UInt64 { data: e.episode }).is_ok();
        ok &= w
            .table_version
            .write(UInt64 {
                data: e.table_version,
            })
            .is_ok();
        if let Some(js) = &w.joint_states {
            let (q, qd) = (e.q, e.qd);
            ok &= js
                .write(JointState {
                    header: Header {
                        stamp: header.stamp,
                        frame_id: String::new(),
                    },
                    name: self.joint_names.clone(),
                    // A wrist the task does not move: at `wrist_q`, at rest.
                    position: (0..6)
                        .map(|j| {
                            if j < e.joints.max(3) {
                                q[j]
                            } else {
                                self.wrist_q[j - 3]
                            }
                        })
                        .collect(),
                    velocity: (0..6)
                        .map(|j| if j < e.joints.max(3) { qd[j] } else { 0.0 })
                        .collect(),
                    effort: Vec::new(),
                })
                .is_ok();
        }
        ok
    }
}

impl DdsWork for Publish {
    fn step(&mut self) {
        while let Some(e) = self.shared.entries.pop() {
            let c = if self.publish(&e) {
                &self.shared.published
            } else {
                &self.shared.publish_errors
            };
            c.fetch_add(1, Ordering::Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A domain DDS cannot join is a setup error naming the live view and the domain.
    #[test]
    fn a_live_view_that_cannot_start_says_so() {
        let cfg = LiveViewConfig {
            enabled: true,
            domain_id: 233,
            ..LiveViewConfig::default()
        };
        let err = LiveView::start(&cfg, [0.0; 3], [0.0; 3])
            .err()
            .expect("domain 233 is refused");
        let text = err.to_string();
        assert!(
            text.contains("live view ([live_view]) on ROS domain 233"),
            "{text}"
        );
    }

    /// The loop keeps one entry per interval of its clock, whatever the number of offers.
    #[test]
    fn offers_are_rate_limited_by_the_loops_clock() {
        let cfg = LiveViewConfig {
            enabled: true,
            // This test's own domain (no other test uses 202).
            domain_id: 202,
            namespace: format!("/lv{}", std::process::id()),
            rate_hz: 100.0,
            ..LiveViewConfig::default()
        };
        let mut lv = LiveView::start(&cfg, [0.0; 3], [0.0; 3]).expect("live view");
        let s = ArmState::default();
        // 1 s of offers every 1 ms: one kept per 10 ms.
        for k in 0..1000u64 {
            lv.offer(1_000_000_000 + k * 1_000_000, &s, true, 0, 0);
        }
        assert_eq!(lv.report().entries, 100);
    }
}
