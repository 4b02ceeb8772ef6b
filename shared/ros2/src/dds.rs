//! ROS 2's mapping onto DDS, over RustDDS (pure Rust, no ROS installation): a topic `/name` is the
//! DDS topic `rt/name` of type `pkg::msg::dds_::Name_`, carried as plain CDR ([`crate::cdr`]);
//! the QoS a ROS 2 node asks for becomes DDS reliability, history depth and durability.
//!
//! Discovery. By default ([`Network::Loopback`]) a participant announces and accepts only
//! 127.0.0.1 and finds the others on the same host by unicast SPDP to the well-known ports
//! 7400 + 250·domain + 10 + 2·i, i = 0, 1, … (RustDDS's same-host peers; CycloneDDS gets the
//! same with `<Peers><Peer address="127.0.0.1"/></Peers>` and multicast off), so no datagram
//! leaves the machine and no multicast route is needed: on Linux `lo` is not multicast-capable
//! by default. [`Network::All`] is the DDS default, SPDP multicast on every interface, for a
//! driver on another machine.

use core::marker::PhantomData;
use std::net::{IpAddr, Ipv4Addr};

use rustdds::bytes::Bytes;
use rustdds::no_key::{DataReader, DataWriter, Decode, DefaultDecoder};
use rustdds::policy::{Durability, History, Reliability};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, Publisher, QosPolicies, QosPolicyBuilder,
    RepresentationIdentifier, Subscriber, TopicKind,
};

use crate::cdr::{CdrError, CdrReader};
use crate::msg::Message;

/// Which interfaces DDS discovery and data use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Network {
    /// 127.0.0.1 only, peers found by unicast on the well-known ports (the same host).
    #[default]
    Loopback,
    /// Every interface, SPDP multicast (the DDS default; peers on other hosts).
    All,
}

/// Reliability of a topic's readers and writers (ROS 2's `reliability` QoS).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReliabilityKind {
    /// ROS 2's default (`rclcpp::QoS(depth)`, `SystemDefaultsQoS` with the common DDS).
    #[default]
    Reliable,
    /// ROS 2's sensor-data profile.
    BestEffort,
}

impl ReliabilityKind {
    /// Whether a writer offering `self` matches a reader requesting `requested` (DDS's
    /// request–offered rule: reliable offers serve both, best effort only best effort).
    pub fn serves(self, requested: ReliabilityKind) -> bool {
        self == ReliabilityKind::Reliable || requested == ReliabilityKind::BestEffort
    }

    /// The QoS setting's spelling (`reliable`, `best_effort`).
    pub fn name(self) -> &'static str {
        match self {
            ReliabilityKind::Reliable => "reliable",
            ReliabilityKind::BestEffort => "best_effort",
        }
    }

    fn of(r: Option<Reliability>, default: ReliabilityKind) -> ReliabilityKind {
        match r {
            Some(Reliability::Reliable { .. }) => ReliabilityKind::Reliable,
            Some(Reliability::BestEffort) => ReliabilityKind::BestEffort,
            None => default,
        }
    }
}

/// A reader or writer another participant announced on a topic.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Endpoint {
    /// Its DDS GUID (participant prefix and entity id).
    pub guid: [u8; 16],
    /// Its DDS type name.
    pub type_name: String,
    /// The reliability it offers (a writer) or requests (a reader); DDS's default when it
    /// announced none (writers reliable, readers best effort).
    pub reliability: ReliabilityKind,
}

/// The QoS of one topic: reliability and `KEEP_LAST` history depth; durability volatile, as
/// ROS 2's defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct TopicQos {
    pub reliability: ReliabilityKind,
    /// History depth (≥ 1).
    pub depth: u32,
}

impl TopicQos {
    /// `rclcpp::QoS(depth)`: reliable, keep last `depth`, volatile.
    pub const fn reliable(depth: u32) -> Self {
        Self {
            reliability: ReliabilityKind::Reliable,
            depth,
        }
    }

    /// The DDS policies (a reliable writer blocks at most 100 ms on a full history, RTPS's
    /// usual default; with keep-last it never does).
    pub fn policies(self) -> QosPolicies {
        let b = QosPolicyBuilder::new()
            .durability(Durability::Volatile)
            .history(History::KeepLast {
                depth: self.depth.clamp(1, i32::MAX as u32) as i32,
            });
        match self.reliability {
            ReliabilityKind::Reliable => b.reliability(Reliability::Reliable {
                max_blocking_time: rustdds::Duration::from_millis(100),
            }),
            ReliabilityKind::BestEffort => b.reliability(Reliability::BestEffort),
        }
        .build()
    }
}

/// The DDS topic of a ROS 2 topic: `/joint_states` → `rt/joint_states` (a name without the
/// leading slash is taken as absolute too).
pub fn dds_topic(ros_topic: &str) -> String {
    format!("rt/{}", ros_topic.trim_start_matches('/'))
}

/// A DDS failure at setup, naming what was being created.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    #[error("cannot create the DDS participant on domain {domain}: {source}")]
    Participant {
        domain: u16,
        #[source]
        source: rustdds::dds::CreateError,
    },
    #[error("cannot create the DDS {what} for {topic}: {source}")]
    Endpoint {
        what: &'static str,
        topic: String,
        #[source]
        source: rustdds::dds::CreateError,
    },
    #[error("ROS domain id {0} out of range (0–232: ports 7400 + 250·domain must fit in 16 bits)")]
    Domain(u16),
}

/// One DDS participant with a publisher and a subscriber: what a ROS 2 node is on the wire.
pub struct Node {
    participant: DomainParticipant,
    publisher: Publisher,
    subscriber: Subscriber,
}

impl Node {
    /// Joins `domain` (ROS_DOMAIN_ID) on `network`.
    pub fn new(domain: u16, network: Network) -> Result<Self, DdsError> {
        if domain > 232 {
            return Err(DdsError::Domain(domain));
        }
        let builder = DomainParticipantBuilder::new(domain).same_host_loopback(true);
        let builder = match network {
            Network::Loopback => builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]),
            Network::All => builder,
        };
        let participant = builder
            .build()
            .map_err(|source| DdsError::Participant { domain, source })?;
        let qos = QosPolicies::qos_none();
        let publisher = participant
            .create_publisher(&qos)
            .map_err(|source| DdsError::Participant { domain, source })?;
        let subscriber = participant
            .create_subscriber(&qos)
            .map_err(|source| DdsError::Participant { domain, source })?;
        Ok(Self {
            participant,
            publisher,
            subscriber,
        })
    }

    fn topic<M: Message>(
        &self,
        ros_topic: &str,
        qos: &QosPolicies,
    ) -> Result<rustdds::Topic, DdsError> {
        self.participant
            .create_topic(
                dds_topic(ros_topic),
                M::DDS_TYPE.to_owned(),
                qos,
                TopicKind::NoKey,
            )
            .map_err(|source| DdsError::Endpoint {
                what: "topic",
                topic: ros_topic.to_owned(),
                source,
            })
    }

    /// A writer of `M` on the ROS topic `ros_topic`.
    pub fn writer<M: Message>(
        &self,
        ros_topic: &str,
        qos: TopicQos,
    ) -> Result<Writer<M>, DdsError> {
        let qos = qos.policies();
        let topic = self.topic::<M>(ros_topic, &qos)?;
        let inner = self
            .publisher
            .create_datawriter_no_key::<M, CdrAdapter<M>>(&topic, Some(qos))
            .map_err(|source| DdsError::Endpoint {
                what: "writer",
                topic: ros_topic.to_owned(),
                source,
            })?;
        Ok(Writer { inner })
    }

    /// A reader of `M` on the ROS topic `ros_topic`.
    pub fn reader<M: Message + 'static>(
        &self,
        ros_topic: &str,
        qos: TopicQos,
    ) -> Result<Reader<M>, DdsError> {
        let qos = qos.policies();
        let topic = self.topic::<M>(ros_topic, &qos)?;
        let inner = self
            .subscriber
            .create_datareader_no_key::<M, CdrAdapter<M>>(&topic, Some(qos))
            .map_err(|source| DdsError::Endpoint {
                what: "reader",
                topic: ros_topic.to_owned(),
                source,
            })?;
        Ok(Reader { inner })
    }

    /// Writers discovered on the ROS topic (other participants'), with their DDS type names.
    pub fn publishers_of(&self, ros_topic: &str) -> Vec<String> {
        let name = dds_topic(ros_topic);
        self.participant
            .discovered_writers()
            .into_iter()
            .filter(|w| w.publication_topic_data.topic_name == name)
            .map(|w| w.publication_topic_data.type_name)
            .collect()
    }

    /// Writers discovered on the ROS topic (other participants'), with their GUIDs and QoS.
    pub fn writers_on(&self, ros_topic: &str) -> Vec<Endpoint> {
        let name = dds_topic(ros_topic);
        self.participant
            .discovered_writers()
            .into_iter()
            .filter(|w| w.publication_topic_data.topic_name == name)
            .map(|w| {
                let d = w.publication_topic_data;
                Endpoint {
                    guid: d.key.to_bytes(),
                    type_name: d.type_name,
                    reliability: ReliabilityKind::of(d.reliability, ReliabilityKind::Reliable),
                }
            })
            .collect()
    }

    /// Readers discovered on the ROS topic (other participants'), with their GUIDs and QoS.
    pub fn readers_on(&self, ros_topic: &str) -> Vec<Endpoint> {
        let name = dds_topic(ros_topic);
        self.participant
            .discovered_readers()
            .into_iter()
            .filter(|r| r.subscription_topic_data.topic_name() == &name)
            .map(|r| {
                let d = r.subscription_topic_data;
                Endpoint {
                    guid: d.key().to_bytes(),
                    type_name: d.type_name().clone(),
                    reliability: ReliabilityKind::of(
                        d.qos().reliability(),
                        ReliabilityKind::BestEffort,
                    ),
                }
            })
            .collect()
    }

    /// Readers discovered on the ROS topic (other participants'), with their DDS type names.
    pub fn subscribers_of(&self, ros_topic: &str) -> Vec<String> {
        let name = dds_topic(ros_topic);
        self.participant
            .discovered_readers()
            .into_iter()
            .filter(|r| r.subscription_topic_data.topic_name() == &name)
            .map(|r| r.subscription_topic_data.type_name().clone())
            .collect()
    }
}

/// A typed DDS writer.
pub struct Writer<M: Message> {
    inner: DataWriter<M, CdrAdapter<M>>,
}

impl<M: Message> Writer<M> {
    /// Publishes one message (allocates: the DDS thread's, never the control loop's).
    pub fn write(&self, msg: M) -> Result<(), WriteError> {
        self.inner.write(msg, None).map_err(|_| WriteError)
    }
}

/// A DDS write failed (the participant's thread is gone or a reliable history is full).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("DDS write failed")]
pub struct WriteError;

/// A typed DDS reader; registers with a `rustdds::mio1::Poll` (mio 1, edge-triggered: drain
/// with [`Reader::take`] after each readiness event). Not with mio 0.6: RustDDS 0.15's mio 0.6
/// notification channel is never drained, so after its capacity it stops signalling (the
/// readers then looked rate-limited to their history depth per poll timeout).
pub struct Reader<M: Message + 'static> {
    inner: DataReader<M, CdrAdapter<M>>,
}

impl<M: Message + 'static> Reader<M> {
    /// The next message received, oldest first; `None` when none is queued. Samples that do not
    /// decode are skipped.
    pub fn take(&mut self) -> Option<M> {
        loop {
            match self.inner.take_next_sample() {
                Ok(Some(s)) => return Some(s.into_value()),
                Ok(None) => return None,
                Err(_) => continue,
            }
        }
    }

    /// [`Reader::take`] with the GUID of the writer that sent the message.
    pub fn take_with_writer(&mut self) -> Option<(M, [u8; 16])> {
        loop {
            match self.inner.take_next_sample() {
                Ok(Some(s)) => {
                    let guid = s.sample_info().writer_guid().to_bytes();
                    return Some((s.into_value(), guid));
                }
                Ok(None) => return None,
                Err(_) => continue,
            }
        }
    }

    /// For `Registry::register`.
    pub fn source(&mut self) -> &mut impl rustdds::mio1::event::Source {
        &mut self.inner
    }
}

/// The RustDDS (de)serializer of a [`Message`]: plain CDR, either byte order in, little-endian
/// out.
pub struct CdrAdapter<M>(PhantomData<M>);

impl<M: Message> rustdds::no_key::SerializerAdapter<M> for CdrAdapter<M> {
    type Error = CdrError;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &M) -> Result<Bytes, CdrError> {
        // RustDDS writes the encapsulation header itself: the body only.
        let mut buf = Vec::new();
        value.encode_into(&mut buf);
        Ok(Bytes::from(buf).slice(4..))
    }
}

impl<M: Message> rustdds::no_key::DeserializerAdapter<M> for CdrAdapter<M> {
    type Error = CdrError;
    type Decoded = M;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
        ]
    }
    fn transform_decoded(decoded: M) -> M {
        decoded
    }
}

/// Decodes a body with the encapsulation RustDDS has already read.
pub struct CdrDecoder<M>(PhantomData<M>);

impl<M> Clone for CdrDecoder<M> {
    fn clone(&self) -> Self {
        Self(PhantomData)
    }
}

impl<M: Message> DefaultDecoder<M> for CdrAdapter<M> {
    type Decoder = CdrDecoder<M>;
    const DECODER: Self::Decoder = CdrDecoder(PhantomData);
}

impl<'de, M: Message> Decode<'de, M> for CdrDecoder<M> {
    type Error = CdrError;
    fn decode_bytes(
        self,
        body: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<M, CdrError> {
        M::read(&mut CdrReader::from_body(encoding.to_bytes(), body)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Header, JointState, Time};

    /// Two participants on the loopback find each other and exchange a joint state; nothing is
    /// sent by multicast (the IPv4 multicast packet counter of the host does not move).
    #[test]
    fn two_nodes_talk_over_loopback_unicast_only() {
        let mcast_before = ipv4_out_multicast_packets();
        // Domain 201: unique to this test (parallel tests use others); the topic is this
        // process's, so that a second run at the same time does not cross-talk.
        let topic = format!("/t{}/joint_states", std::process::id());
        let a = Node::new(201, Network::Loopback).unwrap();
        let b = Node::new(201, Network::Loopback).unwrap();
        let w = a
            .writer::<JointState>(&topic, TopicQos::reliable(10))
            .unwrap();
        // Without the leading slash: the same ROS topic.
        let mut r = b
            .reader::<JointState>(topic.trim_start_matches('/'), TopicQos::reliable(10))
            .unwrap();
        let msg = JointState {
            header: Header {
                stamp: Time { sec: 1, nanosec: 2 },
                frame_id: String::new(),
            },
            name: vec!["elbow_joint".into()],
            position: vec![0.5],
            velocity: vec![],
            effort: vec![],
        };
        // Volatile: what is written before the reader is matched is lost; write until it
        // arrives (the bound only keeps a broken build from hanging).
        let mut got = None;
        for _ in 0..3000 {
            w.write(msg.clone()).unwrap();
            std::thread::sleep(std::time::Duration::from_millis(10));
            if let Some(m) = r.take_with_writer() {
                got = Some(m);
                break;
            }
        }
        let (got, writer) = got.expect("a joint state arrived");
        assert_eq!(got, msg);
        // The sample names its writer as discovery does, with the QoS it offers.
        let writers = b.writers_on(&topic);
        assert_eq!(writers.len(), 1);
        assert_eq!(writers[0].guid, writer);
        assert_eq!(writers[0].reliability, ReliabilityKind::Reliable);
        let readers = a.readers_on(&topic);
        assert_eq!(readers.len(), 1);
        assert_eq!(readers[0].reliability, ReliabilityKind::Reliable);
        assert_ne!(readers[0].guid, writer);
        assert_eq!(
            b.publishers_of(&topic),
            vec!["sensor_msgs::msg::dds_::JointState_".to_owned()]
        );
        assert_eq!(
            a.subscribers_of(&topic),
            vec!["sensor_msgs::msg::dds_::JointState_".to_owned()]
        );
        if let (Some(before), Some(after)) = (mcast_before, ipv4_out_multicast_packets()) {
            assert_eq!(after, before, "IPv4 multicast packets were sent");
        }
    }

    /// `IpExt: OutMcastPkts` of /proc/net/netstat (Linux), if readable.
    fn ipv4_out_multicast_packets() -> Option<u64> {
        let s = std::fs::read_to_string("/proc/net/netstat").ok()?;
        let mut lines = s.lines().filter(|l| l.starts_with("IpExt:"));
        let (names, values) = (lines.next()?, lines.next()?);
        let i = names.split_whitespace().position(|n| n == "OutMcastPkts")?;
        values.split_whitespace().nth(i)?.parse().ok()
    }

    #[test]
    fn reliability_offered_serves_as_dds_matches() {
        use ReliabilityKind::*;
        assert!(Reliable.serves(Reliable));
        assert!(Reliable.serves(BestEffort));
        assert!(BestEffort.serves(BestEffort));
        assert!(!BestEffort.serves(Reliable));
    }

    #[test]
    fn topic_names_and_domains() {
        assert_eq!(dds_topic("/joint_states"), "rt/joint_states");
        assert_eq!(
            dds_topic("/forward_position_controller/commands"),
            "rt/forward_position_controller/commands"
        );
        assert!(matches!(
            Node::new(233, Network::Loopback),
            Err(DdsError::Domain(233))
        ));
    }
}
