//! ur-protocol: the one home of the Universal Robots wire formats this project speaks
//! (docs/design.md §3.10). `rt-controller` uses it as a client of a UR controller and
//! `hil-sim ur-sim` as the controller's side of the same wire.
//!
//! - [`rtde`]: RTDE (TCP 30004) frames and every request and answer, in both directions;
//! - [`stream`]: an incremental frame decoder over a fixed buffer, for arbitrary TCP reads;
//! - [`recipe`]: variable types, the output/input name tables, negotiated recipes;
//! - [`state`]: the robot state the project reads, decoded from and encoded into data packages;
//! - [`reverse`]: the 8 × i32 command of the reverse interface (TCP 50001 on the PC);
//! - [`modes`]: robot, safety and control modes with their names;
//! - [`script`]: the header of the project's robot-side URScript program (its marker and the
//!   reverse address the driver substitutes);
//! - [`clock`]: the robot's clock (RTDE `timestamp`) checked package by package;
//! - [`client`]: a blocking RTDE client over a `TcpStream` (setup, recording, tests; it
//!   allocates, unlike everything above);
//! - [`dashboard`]: a blocking client of the dashboard server (TCP 29999): modes, the robot's
//!   model (it allocates too).
//!
//! Everything on the wire is big-endian. Decoding and encoding in the steady state (data
//! packages, reverse commands, the stream decoder) work on caller-owned buffers and never
//! allocate; setup (recipes) may fail with typed errors but does not allocate either (except
//! in [`client`]).
//! No decode path panics on any input.

pub mod client;
pub mod clock;
pub mod dashboard;
pub mod modes;
pub mod recipe;
pub mod reverse;
pub mod rtde;
pub mod script;
pub mod state;
pub mod stream;
mod wire;

pub use modes::{ControlMode, RobotMode, SafetyMode};
pub use recipe::{Input, InputRecipe, Output, OutputRecipe, VarType};
pub use reverse::ReverseCommand;
pub use rtde::{
    ClientMessage, ControllerVersion, PackageType, Protocol, RobotMessage, TextMessage,
};
pub use state::RobotState;
pub use stream::{Frame, FrameDecoder};

/// Errors decoding one package's payload (the frame itself was well formed).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The payload ended before a field.
    #[error("{what}: payload too short: need {need} bytes at offset {at}, have {have}")]
    Truncated {
        /// Package or field being read.
        what: &'static str,
        /// Bytes needed from `at`.
        need: usize,
        /// Offset in the payload.
        at: usize,
        /// Payload length.
        have: usize,
    },
    /// The payload has bytes after the last field.
    #[error("{what}: {extra} unexpected bytes after the last field")]
    TrailingBytes {
        /// Package being read.
        what: &'static str,
        /// Bytes left over.
        extra: usize,
    },
    /// A text field is not UTF-8.
    #[error("{what}: text is not UTF-8")]
    NotUtf8 {
        /// Package or field being read.
        what: &'static str,
    },
    /// A data package for a recipe this side did not set up.
    #[error("data package for recipe {got}, but the negotiated recipe is {expected}; set up the recipe before START")]
    WrongRecipe {
        /// Recipe id in the package.
        got: u8,
        /// Recipe id negotiated.
        expected: u8,
    },
    /// A reverse-interface control mode outside the known set.
    #[error("reverse command: unknown control mode {0} (known: -2..=6, 8)")]
    UnknownControlMode(i32),
    /// A package type this side does not expect in this direction.
    #[error("package type {0:?} is not sent in this direction")]
    WrongDirection(PackageType),
}

/// Errors encoding into a caller-owned buffer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EncodeError {
    /// The buffer is too small for the package.
    #[error("buffer of {capacity} bytes is too small for the package (needs at least {needed}); use a larger buffer")]
    BufferTooSmall {
        /// Bytes needed so far.
        needed: usize,
        /// Buffer length.
        capacity: usize,
    },
    /// The package would exceed the 16-bit RTDE size field.
    #[error("package of {0} bytes exceeds the RTDE maximum of 65535; ask for fewer variables")]
    TooLarge(usize),
    /// A length-prefixed text field is longer than 255 bytes.
    #[error("{what} is {len} bytes; RTDE text fields hold at most 255")]
    TextTooLong {
        /// Field.
        what: &'static str,
        /// Its length.
        len: usize,
    },
    /// A joint target that cannot be sent (non-finite or beyond ±2147 rad).
    #[error("reverse command: joint {joint} target {value} rad is not finite or beyond ±2147 rad")]
    BadTarget {
        /// Joint index 0..6.
        joint: usize,
        /// Value (rad).
        value: f64,
    },
}
