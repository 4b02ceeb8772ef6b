//! The Universal Robots arm models this project simulates and drives (docs/ur.md, "Arm
//! models"): each model's standard DH table, joint limits and default task.
//!
//! Sources of the numbers:
//! - DH `d`, `a`, `α`: Universal Robots' published "DH parameters for calculations of kinematics
//!   and dynamics" (universal-robots.com), as written in the ROS 2 description package
//!   `UniversalRobots/Universal_Robots_ROS2_Description` (BSD-3-Clause),
//!   `config/<model>/default_kinematics.yaml` (commit 2221ec0f, 2024-10-14), whose joint
//!   origins are these tables laid out as URDF origins. The models that package's snapshot
//!   lacks come from the same files in UR's ROS 1 description `ros-industrial/universal_robot`
//!   (`ur_description`, BSD), `ur_description/config/<model>/default_kinematics.yaml`: UR12e
//!   commit 2f339257, UR15 commit 499e728e, UR18 commit 34b13710. The UR7e's is the UR5e's and
//!   the UR12e's the UR10e's: in that package `config/ur7e` is a link to `config/ur5e` and
//!   `config/ur12e` one to `config/ur10e` (commit 3be81362).
//! - Joint limits: the ROS 2 package's `config/<model>/joint_limits.yaml` (from the models' user
//!   manuals and UR's "max. joint torques" article); UR12e and UR18 from its newer commits
//!   49d2ca22 and 272bdddb, UR15 from the ROS 1 package (commit 499e728e), the UR7e's the
//!   UR5e's (the link above). The elbow's ±π is the package's limit (the arm's own is ±2π, but
//!   the shoulder lift joint is in the way beyond ±π). The UR3's and UR3e's wrist 3 turns
//!   without limit; ±2π is written here (the wrist is locked in this project anyway).
//! - Not here: the UR8 Long. Its kinematics are published (ROS 1 `ur_description`
//!   `config/ur8long/default_kinematics.yaml`, commit 31e22940: d1 0.2186, a2 −0.8989,
//!   a3 −0.7149, d4 0.1824, d5 0.1361, d6 0.1434 m), but no joint limits for it were found in
//!   either package's stored files, and none are made up here.
//!
//! Convention (UR's, standard DH): T_i = Rz(θ_i) · Tz(d_i) · Tx(a_i) · Rx(α_i), base frame z up,
//! θ_i = the joint angle reported by the robot (no offsets), α = (π/2, 0, 0, π/2, −π/2, 0) and
//! a2, a3 < 0 on every model; the flange is the origin of frame 6. Units: m, rad, rad/s, N·m.

use std::f64::consts::{FRAC_PI_2, PI};

use serde::{Deserialize, Serialize};

use crate::layout::N_JOINTS;

/// One Universal Robots arm model (serde and command lines: the lower-case name, e.g. `"ur5e"`).
/// Default: the CB-series UR5 of the paper, so every existing configuration keeps its meaning.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UrModel {
    /// UR3 (CB series), 3 kg payload, 500 mm reach.
    Ur3,
    /// UR5 (CB series), 5 kg, 850 mm: the paper's arm.
    #[default]
    Ur5,
    /// UR10 (CB series), 10 kg, 1300 mm.
    Ur10,
    /// UR3e, 3 kg, 500 mm.
    Ur3e,
    /// UR5e, 5 kg, 850 mm.
    Ur5e,
    /// UR7e, 7.5 kg, 850 mm (`ur_description` gives it the UR5e's kinematics and limits).
    Ur7e,
    /// UR10e, 12.5 kg, 1300 mm.
    Ur10e,
    /// UR12e, 12.5 kg, 1300 mm (`ur_description` gives it the UR10e's kinematics and limits).
    Ur12e,
    /// UR16e, 16 kg, 900 mm.
    Ur16e,
    /// UR15, 15 kg, 1300 mm.
    Ur15,
    /// UR18, 18 kg, 1000 mm.
    Ur18,
    /// UR20, 20 kg, 1750 mm.
    Ur20,
    /// UR30, 30 kg, 1300 mm.
    Ur30,
}

/// A standard DH table, base to wrist 3: `d` (m), `a` (m), `alpha` (rad) per joint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DhTable {
    /// Offsets along the previous z axis (m).
    pub d: [f64; 6],
    /// Lengths along the new x axis (m).
    pub a: [f64; 6],
    /// Twists about the new x axis (rad).
    pub alpha: [f64; 6],
}

/// Limits of all six joints, base to wrist 3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits6 {
    /// Lower position limits (rad).
    pub lower: [f64; 6],
    /// Upper position limits (rad).
    pub upper: [f64; 6],
    /// Velocity limits (rad/s).
    pub velocity: [f64; 6],
    /// Effort limits (N·m).
    pub effort: [f64; 6],
}

/// UR's twists, the same on every model.
const ALPHA: [f64; 6] = [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0];

/// A DH table from UR's six non-zero numbers (d1, a2, a3, d4, d5, d6).
const fn dh(d1: f64, a2: f64, a3: f64, d4: f64, d5: f64, d6: f64) -> DhTable {
    DhTable {
        d: [d1, 0.0, 0.0, d4, d5, d6],
        a: [0.0, a2, a3, 0.0, 0.0, 0.0],
        alpha: ALPHA,
    }
}

/// 120°/s, 150°/s, 210°/s, 240°/s and 300°/s (rad/s), as `f64::to_radians` gives them.
const DEG120: f64 = 2.0943951023931953;
const DEG150: f64 = 2.6179938779914944;
const DEG210: f64 = 3.6651914291880923;
const DEG240: f64 = 4.1887902047863905;
const DEG300: f64 = 5.235987755982989;
const TWO_PI: f64 = 2.0 * PI;

/// ±2π on every joint but the elbow (±π), with the given speeds and torques.
const fn limits(velocity: [f64; 6], effort: [f64; 6]) -> JointLimits6 {
    JointLimits6 {
        lower: [-TWO_PI, -TWO_PI, -PI, -TWO_PI, -TWO_PI, -TWO_PI],
        upper: [TWO_PI, TWO_PI, PI, TWO_PI, TWO_PI, TWO_PI],
        velocity,
        effort,
    }
}

impl UrModel {
    /// Every model, CB series first.
    pub const ALL: [UrModel; 13] = [
        UrModel::Ur3,
        UrModel::Ur5,
        UrModel::Ur10,
        UrModel::Ur3e,
        UrModel::Ur5e,
        UrModel::Ur7e,
        UrModel::Ur10e,
        UrModel::Ur12e,
        UrModel::Ur16e,
        UrModel::Ur15,
        UrModel::Ur18,
        UrModel::Ur20,
        UrModel::Ur30,
    ];

    /// Whether this is the UR5 (the default; for `skip_serializing_if`).
    pub fn is_ur5(&self) -> bool {
        *self == UrModel::Ur5
    }

    /// Whether the model is of the e-Series generation (PolyScope 5, 500 Hz): every model but
    /// the CB-era UR3, UR5 and UR10 (the UR15, UR18, UR20 and UR30 run the e-Series
    /// controller).
    pub fn is_e_series(self) -> bool {
        !matches!(self, UrModel::Ur3 | UrModel::Ur5 | UrModel::Ur10)
    }

    /// The lower-case name (`"ur5e"`), as in configuration files and on command lines.
    pub fn name(self) -> &'static str {
        match self {
            UrModel::Ur3 => "ur3",
            UrModel::Ur5 => "ur5",
            UrModel::Ur10 => "ur10",
            UrModel::Ur3e => "ur3e",
            UrModel::Ur5e => "ur5e",
            UrModel::Ur7e => "ur7e",
            UrModel::Ur10e => "ur10e",
            UrModel::Ur12e => "ur12e",
            UrModel::Ur16e => "ur16e",
            UrModel::Ur15 => "ur15",
            UrModel::Ur18 => "ur18",
            UrModel::Ur20 => "ur20",
            UrModel::Ur30 => "ur30",
        }
    }

    /// The model's standard DH table (UR's published values; module docs).
    pub fn dh(self) -> DhTable {
        match self {
            UrModel::Ur3 => dh(0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819),
            UrModel::Ur5 => dh(0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
            UrModel::Ur10 => dh(0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922),
            UrModel::Ur3e => dh(0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921),
            UrModel::Ur5e | UrModel::Ur7e => dh(0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996),
            UrModel::Ur10e | UrModel::Ur12e => {
                dh(0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655)
            }
            UrModel::Ur16e => dh(0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655),
            UrModel::Ur15 => dh(0.2186, -0.6475, -0.5164, 0.1824, 0.1361, 0.1434),
            UrModel::Ur18 => dh(0.2186, -0.475, -0.3389, 0.1824, 0.1361, 0.1434),
            UrModel::Ur20 => dh(0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543),
            UrModel::Ur30 => dh(0.2363, -0.637, -0.5037, 0.201, 0.1593, 0.1543),
        }
    }

    /// Limits of the six joints (ROS 2 `ur_description` `joint_limits.yaml`; module docs).
    pub fn joint_limits(self) -> JointLimits6 {
        match self {
            UrModel::Ur3 => limits(
                [PI, PI, PI, TWO_PI, TWO_PI, TWO_PI],
                [56.0, 56.0, 28.0, 12.0, 12.0, 12.0],
            ),
            UrModel::Ur3e => limits(
                [PI, PI, PI, TWO_PI, TWO_PI, TWO_PI],
                [54.0, 54.0, 28.0, 9.0, 9.0, 9.0],
            ),
            UrModel::Ur5 | UrModel::Ur5e | UrModel::Ur7e => {
                limits([PI; 6], [150.0, 150.0, 150.0, 28.0, 28.0, 28.0])
            }
            UrModel::Ur10 => limits(
                [DEG120, DEG120, PI, PI, PI, PI],
                [330.0, 330.0, 150.0, 56.0, 56.0, 56.0],
            ),
            UrModel::Ur10e | UrModel::Ur12e | UrModel::Ur16e => limits(
                [DEG120, DEG120, PI, PI, PI, PI],
                [330.0, 330.0, 150.0, 54.0, 54.0, 54.0],
            ),
            UrModel::Ur15 | UrModel::Ur18 => limits(
                [PI, PI, DEG240, DEG300, DEG300, DEG300],
                [433.0, 433.0, 204.0, 70.0, 70.0, 70.0],
            ),
            UrModel::Ur20 | UrModel::Ur30 => limits(
                [DEG120, DEG120, DEG150, DEG210, DEG210, DEG210],
                [738.0, 738.0, 433.0, 107.0, 107.0, 107.0],
            ),
        }
    }

    /// The length of the stretched-out arm from the shoulder to the flange (m):
    /// √((|a2| + |a3|)² + (d4 + d6)²) + d5, an upper bound on how far from the shoulder the
    /// flange can be.
    pub fn reach(self) -> f64 {
        let t = self.dh();
        let x = t.a[1].abs() + t.a[2].abs();
        let y = t.d[3] + t.d[5];
        (x * x + y * y).sqrt() + t.d[4]
    }

    /// Default start pose (rad, shoulder pan, shoulder lift, elbow): the UR5's retracted pose
    /// (upper arm raised, elbow folded) on every model; the same angles are the same posture on
    /// each, since the models share the DH layout.
    pub fn default_start_q(self) -> [f64; N_JOINTS] {
        [0.0, -2.0, 2.4]
    }

    /// Default goal of the end effector (m, base frame): where the UR5's goal posture (the
    /// angles that put the UR5's flange at (−0.45, −0.25, 0.25) m, about (0.293, −1.379, 2.092)
    /// rad) puts each model's flange, rounded to 1 cm. Within reach of every model by
    /// construction, in front of the arm at a height that scales with the arm.
    pub fn default_goal(self) -> [f64; 3] {
        match self {
            UrModel::Ur3 => [-0.28, -0.2, 0.26],
            UrModel::Ur5 => [-0.45, -0.25, 0.25],
            UrModel::Ur10 => [-0.62, -0.36, 0.35],
            UrModel::Ur3e => [-0.28, -0.22, 0.27],
            UrModel::Ur5e | UrModel::Ur7e => [-0.46, -0.28, 0.33],
            UrModel::Ur10e | UrModel::Ur12e => [-0.63, -0.37, 0.42],
            UrModel::Ur16e => [-0.46, -0.32, 0.42],
            UrModel::Ur15 => [-0.63, -0.38, 0.54],
            UrModel::Ur18 => [-0.47, -0.33, 0.48],
            UrModel::Ur20 => [-0.84, -0.46, 0.62],
            UrModel::Ur30 => [-0.63, -0.4, 0.54],
        }
    }

    /// Default angles of the locked wrist joints (rad, wrist 1–3): UR's usual home posture of
    /// the wrist, (−π/2, π/2, 0), the same on every model (the tool points down).
    pub fn default_wrist_q(self) -> [f64; 3] {
        [-FRAC_PI_2, FRAC_PI_2, 0.0]
    }

    /// Default end-effector offset from the flange (m, `wrist_3_link` frame): none on every
    /// model (the end-effector point is the tool flange's centre; a tool adds its TCP here).
    pub fn default_ee_offset(self) -> [f64; 3] {
        [0.0; 3]
    }
}

impl std::fmt::Display for UrModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not one of [`UrModel::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown UR model `{0}`: expected one of ur3, ur5, ur10, ur3e, ur5e, ur7e, ur10e, ur12e, \
     ur16e, ur15, ur18, ur20, ur30"
)]
pub struct UnknownModel(pub String);

impl std::str::FromStr for UrModel {
    type Err = UnknownModel;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        UrModel::ALL
            .into_iter()
            .find(|m| m.name() == lower)
            .ok_or_else(|| UnknownModel(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_serde_uses_them() {
        for m in UrModel::ALL {
            assert_eq!(m.name().parse::<UrModel>().unwrap(), m);
            assert_eq!(toml::Value::try_from(m).unwrap().as_str(), Some(m.name()));
        }
        assert_eq!(UrModel::default(), UrModel::Ur5);
        let e = "ur8".parse::<UrModel>().unwrap_err();
        assert!(
            e.to_string().contains("`ur8`") && e.to_string().contains("ur16e"),
            "{e}"
        );
        // The message lists every model.
        for m in UrModel::ALL {
            assert!(e.to_string().contains(m.name()), "{m}: {e}");
        }
    }

    #[test]
    fn the_speed_limits_are_the_degrees_of_the_sources() {
        assert_eq!(120f64.to_radians(), DEG120);
        assert_eq!(150f64.to_radians(), DEG150);
        assert_eq!(210f64.to_radians(), DEG210);
        assert_eq!(240f64.to_radians(), DEG240);
        assert_eq!(300f64.to_radians(), DEG300);
    }

    #[test]
    fn every_default_task_is_within_the_models_reach_and_limits() {
        for m in UrModel::ALL {
            let t = m.dh();
            let g = m.default_goal();
            let shoulder = [0.0, 0.0, t.d[0]];
            let dist = (0..3)
                .map(|i| (g[i] - shoulder[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(
                dist < 0.8 * m.reach(),
                "{m}: goal {dist} m from the shoulder, reach {}",
                m.reach()
            );
            let l = m.joint_limits();
            let q = m.default_start_q();
            assert!(
                (0..3).all(|j| q[j] > l.lower[j] && q[j] < l.upper[j]),
                "{m}"
            );
            assert!(
                (0..6).all(|j| l.lower[j] < l.upper[j] && l.velocity[j] > 0.0 && l.effort[j] > 0.0)
            );
        }
    }
}
