//! The ROS 2 settings of the controller: how the `ros2` arm reaches UR's driver
//! (`[arm.ros2]`) and the live view (`[live_view]`), with their checks (docs/design.md §3.13).

use serde::{Deserialize, Serialize};
use ur5_shared::config::ConfigError;

use super::{ArmConfig, ArmKind};

/// How the `ros2` arm reaches UR's ROS 2 driver (`[arm.ros2]`); the arm itself (model, wrist
/// angles, end-effector offset, reset speed, servo target) is described by `[arm.ur]`. The
/// defaults are the driver's: its topics, ROS domain 0, and its QoS (reliable, keep last 10).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros2Config {
    /// ROS_DOMAIN_ID (0–232).
    pub domain_id: u16,
    /// `loopback` (the driver on this machine; nothing leaves it, no multicast) or `all` (DDS's
    /// default discovery by multicast on every interface).
    pub network: ur5_ros2::Network,
    /// The driver's joint states (`sensor_msgs/msg/JointState`, from `joint_state_broadcaster`).
    pub joint_states_topic: String,
    pub joint_states_qos: ur5_ros2::TopicQos,
    /// The forward position controller's input (`std_msgs/msg/Float64MultiArray`).
    pub command_topic: String,
    pub command_qos: ur5_ros2::TopicQos,
    /// The forward position controller's joints, in the order its commands carry them (its
    /// `joints` parameter; the driver's `ur_controllers.yaml` with an empty `tf_prefix`), in
    /// any order: each of UR's six joints is found by its name (or a name ending in it, as a
    /// `tf_prefix` makes), so the active joints are shoulder pan, shoulder lift and elbow
    /// wherever they are listed. Joint states are matched to them by name.
    pub joints: [String; 6],
    /// No joint state for this long (s of wall time) and the driver is taken as gone: the run
    /// ends as with a lost arm (exit 3), whatever `safety.give_up_after_s`. DDS has no
    /// connection to close, so a killed driver is known only by its silence. 2 s: a thousand
    /// e-Series cycles, far above the stale timeout (0.5 s) and the stalls of a loaded machine.
    pub lost_after_s: f64,
    /// Read the driver's robot and safety modes and stop the run (exit 5) when the robot is
    /// not RUNNING or the safety mode is not NORMAL (or REDUCED), like the `ur` arm.
    pub watch_status: bool,
    /// `io_and_status_controller`'s `ur_dashboard_msgs/msg/RobotMode`.
    pub robot_mode_topic: String,
    /// `io_and_status_controller`'s `ur_dashboard_msgs/msg/SafetyMode`.
    pub safety_mode_topic: String,
    pub status_qos: ur5_ros2::TopicQos,
    /// The rate the driver publishes joint states at (Hz): 500 for an e-Series, 125 for a CB3.
    /// A state is due every control period of their header stamps, within half a cycle.
    pub joint_state_rate_hz: f64,
}

/// The joint names of a UR arm in the driver's controller order.
pub use ur5_ros2::UR_JOINTS;

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            domain_id: 0,
            network: ur5_ros2::Network::Loopback,
            joint_states_topic: "/joint_states".into(),
            joint_states_qos: ur5_ros2::TopicQos::reliable(10),
            command_topic: "/forward_position_controller/commands".into(),
            command_qos: ur5_ros2::TopicQos::reliable(10),
            joints: UR_JOINTS.map(String::from),
            lost_after_s: 2.0,
            watch_status: true,
            robot_mode_topic: "/io_and_status_controller/robot_mode".into(),
            safety_mode_topic: "/io_and_status_controller/safety_mode".into(),
            status_qos: ur5_ros2::TopicQos::reliable(10),
            joint_state_rate_hz: 500.0,
        }
    }
}

/// The live view (`[live_view]`; docs/design.md §3.13): what the controller does, published on
/// ROS 2 topics for rviz2 or Foxglove, whatever the arm backend. Off by default. The loop hands
/// at most `rate_hz` entries a second to a DDS thread of its own (no allocation, no system call
/// in the loop; dropped, never waited for, when that thread falls behind).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LiveViewConfig {
    /// Publish the live view.
    pub enabled: bool,
    /// ROS_DOMAIN_ID (0–232).
    pub domain_id: u16,
    /// `loopback` (viewers on this machine; nothing leaves it) or `all` (DDS's multicast
    /// discovery on every interface).
    pub network: ur5_ros2::Network,
    /// The topics' namespace: `{namespace}/goal` and `{namespace}/end_effector`
    /// (`geometry_msgs/msg/PointStamped`), `{namespace}/episode` and
    /// `{namespace}/table_version` (`std_msgs/msg/UInt64`).
    pub namespace: String,
    /// The frame of the points: ur_description's `base`, the UR controller's base frame, which
    /// is this project's arm base frame (`base_link` is it turned by π about z).
    pub frame_id: String,
    /// Entries per second at most (wall clock): one per control tick below that rate, else the
    /// ticks that come `1 / rate_hz` s after the previous entry.
    pub rate_hz: f64,
    /// QoS of every live-view topic (reliable matches reliable and best-effort viewers).
    pub qos: ur5_ros2::TopicQos,
    /// Also publish the arm's six joints on `joint_states_topic` (`sensor_msgs/msg/JointState`,
    /// the wrist at `arm.ur.wrist_q`), for `robot_state_publisher` and ur_description's model
    /// when no driver publishes them (not with the `ros2` arm on the same domain and topic).
    pub joint_states: bool,
    pub joint_states_topic: String,
    /// The joint names of `joint_states_topic`, shoulder pan to wrist 3 (ur_description's, with
    /// an empty `tf_prefix`).
    pub joint_names: [String; 6],
}

impl Default for LiveViewConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            domain_id: 0,
            network: ur5_ros2::Network::Loopback,
            namespace: "/rt_controller".into(),
            frame_id: "base".into(),
            rate_hz: 30.0,
            qos: ur5_ros2::TopicQos::reliable(10),
            joint_states: false,
            joint_states_topic: "/joint_states".into(),
            joint_names: UR_JOINTS.map(String::from),
        }
    }
}

pub(super) fn is_live_view_default(c: &LiveViewConfig) -> bool {
    *c == LiveViewConfig::default()
}

/// Longest topic name ROS 2 takes (rmw's `RMW_TOPIC_MAX_NAME_LENGTH`, 255 less the 8 of the
/// DDS prefix `rt/`…).
const MAX_TOPIC_LEN: usize = 247;

/// A ROS 2 topic name as rmw validates a full one (`rmw_validate_full_topic_name`), its leading
/// slash optional (a name relative to the root namespace): tokens of letters, digits and `_`,
/// none empty (no `//`, no trailing `/`) and none starting with a digit. A name DDS carries but
/// no ROS node can subscribe to would only end in "no publisher".
pub(super) fn check_topic(key: &'static str, topic: &str) -> Result<(), ConfigError> {
    let bad = |why: &str| {
        Err(ConfigError::Invalid {
            key,
            why: format!("`{topic}` is not a ROS 2 topic name: {why}"),
        })
    };
    let name = topic.strip_prefix('/').unwrap_or(topic);
    if name.is_empty() {
        return bad("it is empty");
    }
    if topic.len() > MAX_TOPIC_LEN {
        return bad(&format!("longer than {MAX_TOPIC_LEN} characters"));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
    {
        return bad(&format!(
            "`{c}` is not allowed (letters, digits, `_` and `/` only)"
        ));
    }
    for token in name.split('/') {
        if token.is_empty() {
            return bad("an empty token (`//` or a trailing `/`)");
        }
        if token.starts_with(|c: char| c.is_ascii_digit()) {
            return bad(&format!("the token `{token}` starts with a digit"));
        }
    }
    Ok(())
}

/// ROS_DOMAIN_ID's range.
pub(super) fn check_domain(key: &'static str, domain: u16) -> Result<(), ConfigError> {
    if domain > 232 {
        return Err(ConfigError::Invalid {
            key,
            why: format!("{domain} must be in 0..=232 (ROS_DOMAIN_ID)"),
        });
    }
    Ok(())
}

/// Six different, non-empty joint names.
pub(super) fn check_joint_names(
    key: &'static str,
    joints: &[String; 6],
) -> Result<(), ConfigError> {
    if joints.iter().any(String::is_empty) || (1..6).any(|i| joints[..i].contains(&joints[i])) {
        return Err(ConfigError::Invalid {
            key,
            why: format!("{joints:?} must be six different joint names"),
        });
    }
    Ok(())
}

/// Where each of UR's joints (shoulder pan … wrist 3, [`UR_JOINTS`]) is in `joints`: the
/// name itself or the one name ending in `_` and it (a `tf_prefix`). `key` names the setting
/// in the error.
pub fn ur_joint_order(key: &'static str, joints: &[String; 6]) -> Result<[usize; 6], ConfigError> {
    let mut order = [0usize; 6];
    for (k, ur) in UR_JOINTS.iter().enumerate() {
        let suffix = format!("_{ur}");
        let found: Vec<usize> = (0..6)
            .filter(|&i| joints[i] == *ur || joints[i].ends_with(&suffix))
            .collect();
        match found[..] {
            [i] => order[k] = i,
            [] => {
                return Err(ConfigError::Invalid {
                    key,
                    why: format!("{joints:?} names no `{ur}` (or `PREFIX_{ur}`): UR's six joints are found by name"),
                })
            }
            _ => {
                return Err(ConfigError::Invalid {
                    key,
                    why: format!("{joints:?} names `{ur}` more than once"),
                })
            }
        }
    }
    Ok(order)
}

impl Ros2Config {
    /// The checks of the joints and of the silence that ends a run (the rest is checked with
    /// the other arm settings).
    pub(super) fn check_joints_and_silence(&self) -> Result<(), ConfigError> {
        check_joint_names("arm.ros2.joints", &self.joints)?;
        ur_joint_order("arm.ros2.joints", &self.joints)?;
        if !(self.lost_after_s > 0.0 && self.lost_after_s <= 3600.0) {
            return Err(ConfigError::Invalid {
                key: "arm.ros2.lost_after_s",
                why: format!(
                    "{} must be in (0, 3600] s: a silent driver must end the run",
                    self.lost_after_s
                ),
            });
        }
        Ok(())
    }
}

impl LiveViewConfig {
    /// Checks the section when it is enabled; `arm`: the ros2 arm's driver publishes its own
    /// joint states.
    pub(super) fn validate(&self, arm: &ArmConfig) -> Result<(), ConfigError> {
        if !self.enabled {
            return Ok(());
        }
        let bad = |key, why: String| Err(ConfigError::Invalid { key, why });
        check_domain("live_view.domain_id", self.domain_id)?;
        check_topic("live_view.namespace", &format!("{}/goal", self.namespace))?;
        check_topic("live_view.joint_states_topic", &self.joint_states_topic)?;
        check_joint_names("live_view.joint_names", &self.joint_names)?;
        if self.frame_id.is_empty() || self.frame_id.contains(char::is_whitespace) {
            return bad(
                "live_view.frame_id",
                format!("`{}` is not a frame name", self.frame_id),
            );
        }
        if !(self.rate_hz > 0.0 && self.rate_hz <= 1000.0) {
            return bad(
                "live_view.rate_hz",
                format!("{} must be in (0, 1000] Hz", self.rate_hz),
            );
        }
        if self.qos.depth == 0 {
            return bad("live_view.qos.depth", "must be >= 1".into());
        }
        if self.joint_states
            && arm.backend == ArmKind::Ros2
            && arm.ros2.domain_id == self.domain_id
            && arm.ros2.joint_states_topic.trim_start_matches('/')
                == self.joint_states_topic.trim_start_matches('/')
        {
            return bad(
                "live_view.joint_states",
                format!(
                    "the driver publishes {} on ROS domain {} (arm.backend = \"ros2\"): a second publisher would make the model jump between them; set joint_states = false",
                    self.joint_states_topic, self.domain_id
                ),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urs_joints_are_found_by_name_in_any_order() {
        let names = |v: [&str; 6]| v.map(String::from);
        assert_eq!(
            ur_joint_order("k", &names(UR_JOINTS)).unwrap(),
            [0, 1, 2, 3, 4, 5]
        );
        // The wrists first: the active joints are where their names are.
        let wrists_first = names([
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint",
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
        ]);
        assert_eq!(
            ur_joint_order("k", &wrists_first).unwrap(),
            [3, 4, 5, 0, 1, 2]
        );
        // A tf_prefix.
        let prefixed = UR_JOINTS.map(|n| format!("ur5_{n}"));
        assert_eq!(ur_joint_order("k", &prefixed).unwrap(), [0, 1, 2, 3, 4, 5]);
        let mut other = names(UR_JOINTS);
        other[2] = "knee_joint".into();
        let e = ur_joint_order("arm.ros2.joints", &other)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("arm.ros2.joints") && e.contains("`elbow_joint`"),
            "{e}"
        );
        let mut twice = names(UR_JOINTS);
        twice[2] = "a_shoulder_pan_joint".into();
        let e = ur_joint_order("k", &twice).unwrap_err().to_string();
        assert!(e.contains("more than once"), "{e}");
        let silent = Ros2Config {
            lost_after_s: 0.0,
            ..Ros2Config::default()
        };
        let e = silent.check_joints_and_silence().unwrap_err().to_string();
        assert!(e.contains("arm.ros2.lost_after_s"), "{e}");
    }

    #[test]
    fn topic_names_are_checked_as_ros_2_does() {
        for ok in [
            "/joint_states",
            "joint_states",
            "/forward_position_controller/commands",
            "/io_and_status_controller/robot_mode",
            "/a_1/b2",
        ] {
            check_topic("t", ok).unwrap();
        }
        for (bad, why) in [
            ("/a//b", "empty token"),
            ("/1abc", "starts with a digit"),
            ("/a/2b", "starts with a digit"),
            ("/a/", "trailing"),
            ("/", "empty"),
            ("", "empty"),
            ("/a b", "` ` is not allowed"),
            ("/a-b", "`-` is not allowed"),
            ("~/a", "`~` is not allowed"),
        ] {
            let e = check_topic("arm.ros2.command_topic", bad)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("arm.ros2.command_topic") && e.contains(why),
                "{bad}: {e}"
            );
        }
        assert!(check_topic("t", &format!("/{}", "a".repeat(MAX_TOPIC_LEN))).is_err());
    }
}
