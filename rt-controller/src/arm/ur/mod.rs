//! The `ur` arm (docs/design.md §3.10): [`setup`] (RTDE handshake, recipe, mode
//! checks, the program sent and connected back; allocates, may fail) and [`live`] (the loop
//! side: [`UrArm`], the [`crate::arm::ArmBackend`] of a Universal Robots controller or
//! `hil-sim ur-sim`).

pub mod live;
pub mod setup;

pub use live::{UrArm, UrReport, LATENESS_BASELINE, RESET_SETTLE_MAX_S, RESET_TOL_Q, RESET_TOL_QD};
pub use setup::{check_modes, UrRtde, UrSession, UrSetupError, OUTPUTS, PROGRAM};
