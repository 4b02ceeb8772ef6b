//! The `ur` arm (docs/design.md §3.10): [`dashboard`] (the model check, the bring-up and
//! the unlock of a protective stop over the dashboard server), [`setup`] (RTDE handshake,
//! recipe, mode checks, the program sent and connected back; allocates, may fail) and [`live`] (the loop
//! side: [`UrArm`], the [`crate::arm::ArmBackend`] of a Universal Robots controller or
//! `hil-sim ur-sim`).

pub mod dashboard;
pub mod live;
pub mod setup;

pub use dashboard::Dashboard;
pub use live::{
    check_joints, UrArm, UrReport, LATENESS_BASELINE, RESET_SETTLE_MAX_S, RESET_TOL_Q, RESET_TOL_QD,
};
pub use setup::{check_modes, UrRtde, UrSession, UrSetupError, OUTPUTS, PROGRAM};
