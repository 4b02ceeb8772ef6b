//! The reverse interface (docs/design.md §3.10): the PC listens (TCP 50001 by default), the
//! robot-side program connects and reads one command per arm cycle.
//!
//! Layout: 8 big-endian `i32` = 32 bytes:
//!
//! | word | meaning |
//! |---|---|
//! | 0 | receive timeout for the program's *next* read (ms); on a timeout the program stops the arm |
//! | 1..=6 | joint targets × [`MULT_JOINTSTATE`] (rad → µrad) |
//! | 7 | control mode ([`ControlMode`]) |

use crate::modes::ControlMode;
use crate::{DecodeError, EncodeError};

/// Bytes of one command.
pub const COMMAND_LEN: usize = 32;

/// Joint targets travel as integers: rad × 1 000 000 (1 µrad resolution).
pub const MULT_JOINTSTATE: f64 = 1_000_000.0;

/// One reverse-interface command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReverseCommand {
    /// Receive timeout for the next read (ms); the arm's own watchdog.
    pub timeout_ms: i32,
    /// Six joint targets (rad), base to wrist 3.
    pub q: [f64; 6],
    /// What to do with them.
    pub mode: ControlMode,
}

impl ReverseCommand {
    /// The 32 bytes on the wire. Targets are rounded to 1 µrad.
    pub fn encode(&self) -> Result<[u8; COMMAND_LEN], EncodeError> {
        let mut out = [0u8; COMMAND_LEN];
        out[0..4].copy_from_slice(&self.timeout_ms.to_be_bytes());
        for (j, q) in self.q.iter().enumerate() {
            let v = (q * MULT_JOINTSTATE).round();
            if !(v.is_finite() && v >= f64::from(i32::MIN) && v <= f64::from(i32::MAX)) {
                return Err(EncodeError::BadTarget {
                    joint: j,
                    value: *q,
                });
            }
            // In range by the check above.
            out[4 + 4 * j..8 + 4 * j].copy_from_slice(&(v as i32).to_be_bytes());
        }
        out[28..32].copy_from_slice(&self.mode.code().to_be_bytes());
        Ok(out)
    }

    /// Decodes 32 bytes (the robot side's read).
    pub fn decode(bytes: &[u8; COMMAND_LEN]) -> Result<Self, DecodeError> {
        let word = |i: usize| {
            i32::from_be_bytes([
                bytes[4 * i],
                bytes[4 * i + 1],
                bytes[4 * i + 2],
                bytes[4 * i + 3],
            ])
        };
        let mode =
            ControlMode::from_code(word(7)).ok_or(DecodeError::UnknownControlMode(word(7)))?;
        Ok(Self {
            timeout_ms: word(0),
            q: core::array::from_fn(|j| f64::from(word(1 + j)) / MULT_JOINTSTATE),
            mode,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_and_round_trip() {
        let c = ReverseCommand {
            timeout_ms: 20,
            q: [0.5, -1.25, 2.0, -1.5, 1.5, 0.0],
            mode: ControlMode::Servoj,
        };
        let b = c.encode().unwrap();
        assert_eq!(&b[0..4], &[0, 0, 0, 20]);
        assert_eq!(&b[4..8], &500_000i32.to_be_bytes());
        assert_eq!(&b[28..32], &[0, 0, 0, 1]);
        assert_eq!(ReverseCommand::decode(&b).unwrap(), c);
        let mut bad = b;
        bad[31] = 7;
        assert_eq!(
            ReverseCommand::decode(&bad),
            Err(DecodeError::UnknownControlMode(7))
        );
        let nan = ReverseCommand {
            q: [f64::NAN; 6],
            ..c
        };
        assert!(nan.encode().is_err());
    }
}
