//! The contract shared by `hil-sim`, `rt-controller` and `learner` (docs/design.md §2–§3).
//!
//! One home for each fact; every other crate imports these from here:
//!
//! - [`layout`]: a task's state layout ([`StateLayout`]: dimensions, parts, names, index ranges),
//!   the capacities [`MAX_DX`], [`MAX_DU`], [`MAX_HORIZON`] of every table and message, and
//!   [`state_vector`], the single place a state vector is assembled.
//! - [`gains`]: the gain table ([`GainTable`], ≈ 1 MB, `#[repr(C)]`, zero-copy), its checksum
//!   and [`GainTable::validate`] against [`GainBounds`].
//! - [`law`]: the controller law a = K_t (s − ŝ_t) + k_t + â_t + L_t ε ([`controller_action`]),
//!   used by both the real-time loop and the learner's rollouts.
//! - [`policy`]: the policy table ([`PolicyTable`], ≈ 384 KB), the second controller kind: the
//!   weights of a Gaussian MLP policy, checksum, validation and [`policy_action`].
//! - [`msg`]: the other IPC payloads ([`ArmState`], [`ArmCommand`], [`StepSample`]).
//! - [`services`]: iceoryx2 service names, per-run prefixes and the quality of service of each
//!   service ([`services::Qos`]).
//! - [`status`]: why a peer stopped ([`status::PeerStatus`], on `controller/status` and
//!   `learner/status`), so that neither side waits silently for the other.
//! - [`atomic_file`]: the one atomic write (temporary file, fsync, rename) of every file a
//!   restart reads back.
//! - [`clock`]: the monotonic clock of every timestamp.
//! - [`model`]: the UR arm models ([`UrModel`]): DH tables, joint limits, default tasks.
//! - [`kinematics`]: a UR arm's end-effector point and velocity from joint angles (f64, no
//!   simulator), for arms that report joint states only; [`ik`]: its inverse in closed form
//!   (a tool pose, or a tool point with the wrist locked, to joint angles).
//! - [`joints`]: per-joint values of run-time length ([`joints::Joints`], 3 or 6 joints).
//! - [`pose`]: UR's tool pose p[x, y, z, rx, ry, rz], tool points and the orientation error.
//! - [`cost`]: the task cost C(τ) and normalised performance.
//! - [`noise`]: seeded exploration noise ε, per (run seed, table version, episode).
//! - [`safety`]: the action clamp ([`safety::clamp_action`]) used by every path to an arm.
//! - [`config`]: task and simulator configuration (TOML), arm limits.
//! - [`kernels`]: dot product, affine map and tanh of every MLP (learner and controller alike).
//! - [`table`]: the storage gain and policy tables share: zeroed construction on the heap or in
//!   place, the XXH3-64 checksum and seal.
//!
//! Conventions: SI units (rad, rad/s, m, m/s, N·m, s; timestamps in monotonic ns); Cartesian
//! quantities in the arm base frame; matrices row-major (numpy C order). Nothing the
//! controller calls per tick ([`controller_action`], [`GainTable::validate`],
//! [`GainTable::copy_from`], [`state_vector`], the payload types) allocates.

pub mod atomic_file;
pub mod clock;
pub mod config;
pub mod cost;
pub mod gains;
pub mod ik;
pub mod joints;
pub mod kernels;
pub mod kinematics;
pub mod law;
pub mod layout;
pub mod model;
pub mod msg;
pub mod noise;
pub mod plan;
pub mod policy;
pub mod pose;
pub mod report;
pub mod safety;
pub mod services;
pub mod status;
pub mod table;

pub use cost::{normalised_performance, task_cost, task_cost_from_distances, CostError};
pub use gains::{
    GainBounds, GainEntry, GainField, GainStep, GainStepMut, GainTable, GainTableError,
};
pub use law::{controller_action, LawError, NO_NOISE};
pub use layout::{state_vector, StateLayout, DU, DX, MAX_DU, MAX_DX, MAX_HORIZON};
pub use model::UrModel;
pub use msg::{ArmCommand, ArmFaults, ArmState, ArmStatus, CommandKind, StepSample};
pub use plan::{EpisodePlan, PlanError};
pub use policy::{policy_action, PolicyBounds, PolicyScratch, PolicyTable, PolicyTableError};
pub use services::ServiceNames;
