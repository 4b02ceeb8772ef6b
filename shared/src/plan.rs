//! The episode plan a controller table carries (docs/design.md §3.3, "Episode plan"): the goal
//! its episodes run to, the noise stream they draw from and whether they run without noise.
//! A learner with several goals (MDGPS: one linear-Gaussian controller per goal and one global
//! policy evaluated at each) sends every goal's episodes with the table that runs them, so that
//! the controller needs no goal of its own per episode; a table with the default plan (all
//! zero: no goal, stream 0, the controller's schedule) runs as tables always did.
//!
//! # Wire layout (32 bytes, `#[repr(C)]`)
//!
//! `flags` (u32: [`PLAN_GOAL`] = 1, [`PLAN_NOISE_FREE`] = 2, other bits invalid),
//! `noise_stream` (u32), `goal` (3 × f64, m, arm base frame).
//!
//! - **Goal**: with [`PLAN_GOAL`] the controller builds its states with `goal` (s[6..9] =
//!   ee − goal) for the table's episodes; without it `goal` must be all zero (+0.0) and the
//!   controller uses its configured goal (`task.goal`, `rt-controller run --goal`).
//! - **Noise stream**: the table's noisy episodes draw `Noise::new(stream_seed(seed, s), v, k)`
//!   ([`crate::noise::stream_seed`]); stream 0 is the controller's seed itself.
//! - **Noise-free**: with [`PLAN_NOISE_FREE`] every episode of the table runs without noise
//!   (an evaluation), instead of the controller's schedule of N noisy and E noise-free.
//!
//! # Checksum
//!
//! A table's checksum covers its plan only when the plan is not the default: then the plan's
//! 32 bytes (flags, noise_stream, the goal's bit patterns, little-endian) follow the hashed
//! values. So every table of an earlier build, which had no plan, keeps its checksum and stays
//! valid, and a plan changed in transit (or set on a sealed table) fails the checksum.

use iceoryx2::prelude::ZeroCopySend;

/// [`EpisodePlan::flags`] bit: `goal` is the goal of the table's episodes.
pub const PLAN_GOAL: u32 = 1;
/// [`EpisodePlan::flags`] bit: every episode of the table runs without noise.
pub const PLAN_NOISE_FREE: u32 = 2;
/// Every flag bit this build knows.
const KNOWN_FLAGS: u32 = PLAN_GOAL | PLAN_NOISE_FREE;
/// Largest |goal coordinate| (m): every UR arm reaches less than 2 m; larger values are garbage.
pub const MAX_ABS_GOAL: f64 = 10.0;
/// Bytes of a plan in a table's checksum.
pub const PLAN_HASHED_BYTES: usize = 32;

/// The episode plan of a table (module docs). All zero is the default: the controller's own
/// goal, seed and schedule.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("ur5_shared::EpisodePlan.v1")]
pub struct EpisodePlan {
    /// [`PLAN_GOAL`] | [`PLAN_NOISE_FREE`].
    pub flags: u32,
    /// Noise stream of the table's noisy episodes; 0: the controller's seed.
    pub noise_stream: u32,
    /// The goal (m, arm base frame) when [`PLAN_GOAL`] is set, else all +0.0.
    pub goal: [f64; 3],
}

const _: () = assert!(core::mem::size_of::<EpisodePlan>() == PLAN_HASHED_BYTES);

/// Why a table's plan is not valid.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// Flag bits this build does not know.
    #[error("episode plan: unknown flag bits {flags:#x} (known: goal 0x1, noise-free 0x2)")]
    UnknownFlags {
        /// The flags received.
        flags: u32,
    },
    /// A goal coordinate that is not finite or beyond [`MAX_ABS_GOAL`].
    #[error("episode plan: goal[{index}] = {value} m is not finite or beyond ±{MAX_ABS_GOAL} m")]
    BadGoal {
        /// Coordinate.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A goal coordinate other than +0.0 without [`PLAN_GOAL`].
    #[error("episode plan: goal[{index}] = {value} without the goal flag (must be 0 when the controller's own goal applies)")]
    GoalWithoutFlag {
        /// Coordinate.
        index: usize,
        /// Its value.
        value: f64,
    },
}

impl EpisodePlan {
    /// The plan of a table whose episodes run to `goal`.
    pub fn to_goal(goal: [f64; 3]) -> Self {
        Self {
            flags: PLAN_GOAL,
            goal,
            ..Self::default()
        }
    }

    /// This plan with noise stream `stream`.
    pub fn with_noise_stream(self, stream: u32) -> Self {
        Self {
            noise_stream: stream,
            ..self
        }
    }

    /// This plan with every episode noise-free.
    pub fn noise_free(self) -> Self {
        Self {
            flags: self.flags | PLAN_NOISE_FREE,
            ..self
        }
    }

    /// The goal of the table's episodes, if the table sets one.
    #[inline]
    pub fn goal(&self) -> Option<&[f64; 3]> {
        (self.flags & PLAN_GOAL != 0).then_some(&self.goal)
    }

    /// Every episode of the table runs without noise.
    #[inline]
    pub fn is_noise_free(&self) -> bool {
        self.flags & PLAN_NOISE_FREE != 0
    }

    /// The seed the table's noisy episodes draw from under the controller's `seed`.
    #[inline]
    pub fn noise_seed(&self, seed: u64) -> u64 {
        crate::noise::stream_seed(seed, self.noise_stream)
    }

    /// All zero (the goal's bit patterns included): a table of an earlier build.
    pub fn is_default(&self) -> bool {
        self.flags == 0 && self.noise_stream == 0 && self.goal.iter().all(|g| g.to_bits() == 0)
    }

    /// The bytes the table's checksum covers when the plan is not the default (module docs).
    pub fn hashed_bytes(&self) -> [u8; PLAN_HASHED_BYTES] {
        let mut b = [0; PLAN_HASHED_BYTES];
        b[..4].copy_from_slice(&self.flags.to_le_bytes());
        b[4..8].copy_from_slice(&self.noise_stream.to_le_bytes());
        for (i, g) in self.goal.iter().enumerate() {
            b[8 + 8 * i..16 + 8 * i].copy_from_slice(&g.to_bits().to_le_bytes());
        }
        b
    }

    /// Known flags; with the goal flag a finite goal within ±[`MAX_ABS_GOAL`], without it a
    /// zero goal. Allocation-free.
    pub fn validate(&self) -> Result<(), PlanError> {
        if self.flags & !KNOWN_FLAGS != 0 {
            return Err(PlanError::UnknownFlags { flags: self.flags });
        }
        for (index, &value) in self.goal.iter().enumerate() {
            if self.flags & PLAN_GOAL != 0 {
                // Written so that a NaN is refused.
                if !(value.abs() <= MAX_ABS_GOAL) {
                    return Err(PlanError::BadGoal { index, value });
                }
            } else if value.to_bits() != 0 {
                return Err(PlanError::GoalWithoutFlag { index, value });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_plan_is_all_zero_and_valid() {
        let p = EpisodePlan::default();
        assert!(p.is_default() && p.validate().is_ok());
        assert_eq!(
            (p.goal(), p.is_noise_free(), p.noise_seed(7)),
            (None, false, 7)
        );
        let g = EpisodePlan::to_goal([0.1, -0.2, 0.3])
            .with_noise_stream(2)
            .noise_free();
        assert!(!g.is_default() && g.validate().is_ok());
        assert_eq!(g.goal(), Some(&[0.1, -0.2, 0.3]));
        assert!(g.is_noise_free());
        assert_eq!(g.noise_seed(7), crate::noise::stream_seed(7, 2));
        assert_ne!(g.noise_seed(7), 7);
        // −0.0 is not the default, and not valid without the flag.
        let neg = EpisodePlan {
            goal: [0.0, -0.0, 0.0],
            ..EpisodePlan::default()
        };
        assert!(!neg.is_default());
        assert!(matches!(
            neg.validate(),
            Err(PlanError::GoalWithoutFlag { index: 1, .. })
        ));
    }

    #[test]
    fn a_bad_plan_is_named() {
        let bad = |p: EpisodePlan| p.validate().unwrap_err().to_string();
        let unknown = EpisodePlan {
            flags: 4,
            ..EpisodePlan::default()
        };
        assert!(bad(unknown).contains("unknown flag bits 0x4"));
        let e = bad(EpisodePlan::to_goal([0.1, f64::NAN, 0.0]));
        assert!(e.contains("goal[1] = NaN"), "{e}");
        let e = bad(EpisodePlan::to_goal([0.1, 0.0, 11.0]));
        assert!(e.contains("goal[2] = 11"), "{e}");
        let e = bad(EpisodePlan {
            goal: [0.0, 0.0, 0.5],
            ..EpisodePlan::default()
        });
        assert!(e.contains("without the goal flag"), "{e}");
    }

    #[test]
    fn hashed_bytes_are_the_fields_little_endian() {
        let p = EpisodePlan::to_goal([1.5, -2.0, 0.25]).with_noise_stream(3);
        let b = p.hashed_bytes();
        assert_eq!(&b[..4], &1u32.to_le_bytes());
        assert_eq!(&b[4..8], &3u32.to_le_bytes());
        assert_eq!(&b[8..16], &1.5f64.to_bits().to_le_bytes());
        assert_eq!(&b[24..32], &0.25f64.to_bits().to_le_bytes());
    }
}
