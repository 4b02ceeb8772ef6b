//! hil-sim: the simulated UR arm of the paper's set-up (docs/design.md §2; the UR5 by default,
//! any UR model with `sim.model`, docs/ur.md) as a library and a binary.
//!
//! - [`urdf`]: the bundled URDF of every UR model and the generator that writes them;
//! - [`model`]: the URDF (the model's bundled one or a user file) parsed by `urdf-rs`, checked,
//!   wrist joints locked (three active joints, the default) or active (six);
//! - [`sim`]: the rapier3d multibody built by `rapier3d-urdf` (three or six active joints), its
//!   physics loop, the 12-dim state of the task, the flange's pose (UR's p[x, y, z, rx, ry,
//!   rz]), the perturbation knobs of the stand-in "physical arm";
//! - [`servo`]: the arm's own joint servo for goal-angle actions;
//! - [`serve`]: the arm behind `arm/state` / `arm/command` over iceoryx2 (`hil-sim serve`);
//! - [`ur_sim`]: the arm behind a UR controller's RTDE and secondary interfaces
//!   (`hil-sim ur-sim`).

pub mod model;
pub mod ros2_sim;
pub mod serve;
pub mod servo;
pub mod sim;
pub mod ur_sim;
pub mod urdf;

use std::path::PathBuf;

pub use model::ArmModel;
pub use sim::{Observation, Ur5Sim};

/// Everything that can go wrong building or driving the simulated arm.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The URDF file could not be read.
    #[error("cannot read URDF {path}: {source}")]
    UrdfRead {
        /// File asked for.
        path: PathBuf,
        /// I/O error.
        source: std::io::Error,
    },
    /// The URDF is not valid XML or not a valid URDF.
    #[error("malformed URDF {path}: {message}")]
    UrdfParse {
        /// File (or bundled path).
        path: PathBuf,
        /// Parser message.
        message: String,
    },
    /// A joint the simulator needs is missing.
    #[error("URDF has no joint named `{name}` (joints: {available:?})")]
    UnknownJoint {
        /// Missing name.
        name: String,
        /// Joints the URDF has.
        available: Vec<String>,
    },
    /// A link the simulator needs is missing.
    #[error("URDF has no link named `{name}` (links: {available:?})")]
    UnknownLink {
        /// Missing name.
        name: String,
        /// Links the URDF has.
        available: Vec<String>,
    },
    /// A joint exists but cannot be used as it is.
    #[error("joint `{name}`: {why}")]
    BadJoint {
        /// Joint name.
        name: String,
        /// What is wrong.
        why: String,
    },
    /// A link exists but cannot be used as it is.
    #[error("link `{name}`: {why}")]
    BadLink {
        /// Link name.
        name: String,
        /// What is wrong.
        why: String,
    },
    /// A goal point the arm cannot reach.
    #[error("goal {goal:?} m is outside the arm's reach: {distance:.3} m from the shoulder, reach {reach:.3} m")]
    GoalOutOfReach {
        /// Goal (m, base frame).
        goal: [f64; 3],
        /// Distance from the shoulder-lift joint (m).
        distance: f64,
        /// Reach (m).
        reach: f64,
    },
    /// A joint angle outside the URDF limits.
    #[error("joint `{joint}` angle {value} rad is outside its limits [{lower}, {upper}]")]
    OutOfLimits {
        /// Joint name.
        joint: String,
        /// Requested angle (rad).
        value: f64,
        /// Lower limit (rad).
        lower: f64,
        /// Upper limit (rad).
        upper: f64,
    },
    /// Invalid configuration.
    #[error(transparent)]
    Config(#[from] ur5_shared::config::ConfigError),
}
