//! The arm as the controller loop sees it: a source of [`ArmState`]s and a sink of
//! [`ArmCommand`]s (docs/design.md §3.4, §3.10). The loop ([`crate::controller`]) is generic over
//! [`ArmBackend`] (static dispatch: no virtual call, no allocation per cycle); samples and gain
//! tables stay on iceoryx2 whatever the arm.
//!
//! - [`iceoryx2`]: `arm/state` in, `arm/command` out: `hil-sim serve` or another process on the
//!   same service prefix.
//! - [`ur`]: a Universal Robots controller (or `hil-sim ur-sim`) over RTDE and the reverse
//!   interface ([`ur::UrArm`]).
//! - [`ros2`]: Universal Robots' ROS 2 driver (or `hil-sim ros2-sim`) over DDS
//!   ([`ros2::Ros2Arm`]).
//!
//! [`servo`] is what the `ur` and `ros2` arms share: the goal held between commands, resets as
//! quintic moves, the state built from six measured joints.

pub mod iceoryx2;
pub mod ros2;
pub(crate) mod servo;
pub mod ur;

pub use self::iceoryx2::Iceoryx2Arm;
pub use self::ros2::Ros2Arm;
pub use self::ur::UrArm;

use ur5_shared::{ArmCommand, ArmState};

use crate::error::SetupError;

/// A failed receive or send in the loop; counted (`ipc_errors`), never allocated or formatted
/// there.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ArmIoError {
    /// The state could not be read.
    #[error("cannot receive the arm state")]
    Receive,
    /// The command could not be sent.
    #[error("cannot send the arm command")]
    Send,
}

/// What the controller loop needs from an arm.
///
/// [`Self::wait_ready`] belongs to the setup phase (may allocate, block and fail); every other
/// method is called in the loop and must not allocate, lock or block.
pub trait ArmBackend {
    /// Setup: waits until the arm delivers a state and accepts commands, at most `timeout_s`;
    /// returns the first state. The error names what did not show up and what to do.
    fn wait_ready(&mut self, timeout_s: f64) -> Result<ArmState, SetupError>;

    /// Setup, last step: establishes every connection now, so that the loop's first receive and
    /// send do not.
    fn connect(&mut self) -> Result<(), SetupError>;

    /// Loop: takes the next queued state, oldest first (`Ok(None)`: nothing new).
    fn receive(&mut self) -> Result<Option<ArmState>, ArmIoError>;

    /// Loop: sends one command.
    fn send(&mut self, cmd: &ArmCommand) -> Result<(), ArmIoError>;

    /// Loop, lockstep: the controller has nothing to command until further notice (it waits
    /// for a table); the next [`Self::send`] ends that. An arm that needs traffic to stay
    /// alive keeps it up without moving the arm (the `ur` arm: IDLE keepalives).
    fn idle(&mut self) {}

    /// Loop: why the arm is gone for good (its connection closed), if it is; the loop then
    /// ends with [`crate::ExitReason::ArmLost`] at its next step (a stale wait, or a fresh one
    /// after a send that failed) instead of waiting for `safety.give_up_after_s`.
    fn lost(&self) -> Option<&'static str> {
        None
    }

    /// Outside the tick, a setup-like step (may allocate, block and fail): after the arm
    /// reported a stop (`ArmFaults::DRIVER`), clear it and make the arm ready for the next
    /// episode if the backend can and its configuration allows; `Ok(false)`: it cannot (the
    /// run ends with [`crate::ExitReason::ArmStopped`]).
    fn recover(&mut self) -> Result<bool, SetupError> {
        Ok(false)
    }

    /// After the loop (may allocate): what the backend has to add to the summary.
    fn report(&self) -> Option<ArmReport> {
        None
    }
}

/// A backend's own part of the run summary (`arm` in `--json`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "backend", rename_all = "snake_case")]
pub enum ArmReport {
    /// The `ur` arm's counters.
    Ur(ur::UrReport),
    /// The `ros2` arm's counters.
    Ros2(ros2::Ros2Report),
}
