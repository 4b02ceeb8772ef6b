//! Gain tables: the time-varying linear-Gaussian controller the learner publishes on
//! `controller/gains` and the controller executes (docs/design.md §1.2, §3.3).
//!
//! Per time step t < T the table holds the paper's controller
//!
//! ```text
//! p(a_t | s_t) = N( K_t (s_t − ŝ_t) + k_t + â_t ,  Σ_t ),   Σ_t = L_t L_tᵀ
//! ```
//!
//! as a [`GainStep`]: K_t (dU × dX), k_t (dU), ŝ_t (dX), â_t (dU) and L_t (dU × dU, lower
//! Cholesky factor of Σ_t). Matrices are stored row-major (numpy C order): `k_mat[i][j]` is
//! row i (action entry, [`crate::layout::ACTION_NAMES`]), column j (state entry,
//! [`crate::layout::STATE_NAMES`]). Units follow the layout: states in rad, rad/s, m, m/s;
//! actions in rad (goal joint angles) or N·m (torque mode).
//!
//! The table is a fixed-size `#[repr(C)]` value of [`GAIN_TABLE_BYTES`] bytes (≈ 64 KB) so that
//! iceoryx2 can move it through shared memory without a heap and the controller can keep two of
//! them (double buffer) allocated once. Build one with [`GainTable::new_boxed`] (heap, no stack
//! temporary) or in place with [`GainTable::init_zeroed`] (e.g. in a loaned iceoryx2 sample),
//! fill the steps, then [`GainTable::seal`]. A receiver calls [`GainTable::validate`] before
//! using it.
//!
//! # Checksum
//!
//! [`GainTable::compute_checksum`] is XXH3-64 (xxHash 0.8's `XXH3_64bits`, seed 0) of one byte
//! string: `version` (u64), `horizon` (u32), `dx` (u32), `du` (u32), then for t = 0..T every f64
//! of `steps[t]` in memory order (K row-major, k, ŝ, â, L row-major), each value as its IEEE-754
//! bit pattern; all integers and bit patterns little-endian (20 + 504·T bytes). On a
//! little-endian machine this is exactly the raw bytes of those header fields followed by the raw
//! bytes of `steps[..T]`, so any other language with an xxHash library can recompute it from the
//! struct. A table whose episode plan is not the default ([`crate::plan`]: a goal, a noise
//! stream or noise-free episodes) appends the plan's 32 bytes, so every table without one
//! keeps the checksum it had before plans existed. Steps at t ≥ T, the `epoch` field and the
//! checksum field itself are not covered. Note
//! that 0.0 and −0.0 hash differently. The checksum guards against corruption and half-written
//! tables, not against an adversary. Tables of wire type `GainTable.v1` (and table files of
//! schema 1) carried a byte-wise FNV-1a 64 instead; XXH3 reads 8 bytes at a time with SIMD and
//! replaced it for speed (docs/design.md §5 D27).

use core::fmt;
use core::mem::MaybeUninit;

use crate::layout::{DU, DX, MAX_HORIZON};
use crate::plan::{EpisodePlan, PlanError};
use crate::table::{self, HeaderBytes, Table};
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// One time step of the linear-Gaussian controller (units in the module docs).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Default, ZeroCopySend)]
#[type_name("ur5_shared::GainStep.v1")]
pub struct GainStep {
    /// K_t, feedback gain, dU × dX row-major (action unit per state unit).
    pub k_mat: [[f64; DX]; DU],
    /// k_t, feed-forward term, dU (action unit).
    pub k_vec: [f64; DU],
    /// ŝ_t, nominal state the feedback acts around, dX (layout units).
    pub s_hat: [f64; DX],
    /// â_t, nominal action, dU (action unit).
    pub a_hat: [f64; DU],
    /// L_t, lower Cholesky factor of the policy covariance Σ_t = L_t L_tᵀ, dU × dU row-major
    /// (action unit). Entries above the diagonal must be 0 and the diagonal positive.
    pub chol: [[f64; DU]; DU],
}

/// Number of f64 in one [`GainStep`].
pub const STEP_LEN: usize = DU * DX + DU + DX + DU + DU * DU;

/// Size of a [`GainTable`] in bytes (header + [`MAX_HORIZON`] steps).
pub const GAIN_TABLE_BYTES: usize = core::mem::size_of::<GainTable>();

const _: () = assert!(core::mem::size_of::<GainStep>() == STEP_LEN * 8);
const _: () = assert!(GAIN_TABLE_BYTES == 64 + MAX_HORIZON * STEP_LEN * 8);

impl GainStep {
    /// The step's values in memory order (K row-major, k, ŝ, â, L row-major), as hashed by the
    /// checksum.
    pub fn as_flat(&self) -> &[f64; STEP_LEN] {
        // SAFETY: GainStep is repr(C) and consists only of f64 arrays, so it has no padding
        // (checked by the size assertion above) and the same layout as [f64; STEP_LEN].
        unsafe { &*(self as *const GainStep).cast::<[f64; STEP_LEN]>() }
    }
}

/// A whole gain table: header plus [`MAX_HORIZON`] steps, of which the first `horizon` are used.
///
/// All fields are public because this is a wire format: whatever arrives from shared memory may
/// hold any bits, and [`GainTable::validate`] is the gate. Prefer the methods for filling it.
/// The type is `Copy`, but it is 64 KB: copy with [`GainTable::copy_from`] into an existing
/// buffer rather than by value onto a stack.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ur5_shared::GainTable.v3")]
pub struct GainTable {
    /// Table version, chosen by the learner (increasing). Samples carry the version of the
    /// table that produced them.
    pub version: u64,
    /// Horizon T: steps 0..T are used; 1 ≤ T ≤ [`MAX_HORIZON`].
    pub horizon: u32,
    /// State dimension; must equal [`DX`].
    pub dx: u32,
    /// Action dimension; must equal [`DU`].
    pub du: u32,
    /// Publication of this version (docs/design.md §3.6, "Exact resume"): 0 when the learner
    /// first publishes it; a resumed learner publishes the same version again with a higher
    /// epoch, and a controller running the version takes it again and restarts the version's
    /// episode count k (the noise key of `Noise::new(seed, version, k)`), so that the episodes
    /// after a resume are those the first publication gave. Echoed in
    /// [`crate::StepSample::table_epoch`]. Not hashed (the contents of a version do not change
    /// with its publication); tables written before it had 0 here (the old `reserved`).
    pub epoch: u32,
    /// XXH3-64 checksum (module docs), set by [`GainTable::seal`].
    pub checksum: u64,
    /// The goal, noise stream and schedule of the table's episodes ([`crate::plan`]); the
    /// default (all zero) runs the controller's own. Hashed unless it is the default.
    pub plan: EpisodePlan,
    /// Steps t = 0..MAX_HORIZON; only t < `horizon` are meaningful.
    pub steps: [GainStep; MAX_HORIZON],
}

impl fmt::Debug for GainTable {
    /// Prints the header only; the steps are 8000 numbers.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GainTable")
            .field("version", &self.version)
            .field("horizon", &self.horizon)
            .field("dx", &self.dx)
            .field("du", &self.du)
            .field("epoch", &self.epoch)
            .field("plan", &self.plan)
            .field("checksum", &format_args!("{:#018x}", self.checksum))
            .finish_non_exhaustive()
    }
}

/// Which array of a [`GainStep`] a problem was found in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GainField {
    /// K_t, dU × dX.
    KMat,
    /// k_t, dU.
    KVec,
    /// ŝ_t, dX.
    SHat,
    /// â_t, dU.
    AHat,
    /// L_t, dU × dU.
    Chol,
}

impl GainField {
    /// Name as in the paper's formula.
    pub fn name(self) -> &'static str {
        match self {
            GainField::KMat => "K",
            GainField::KVec => "k",
            GainField::SHat => "s_hat",
            GainField::AHat => "a_hat",
            GainField::Chol => "L",
        }
    }

    /// The [`GainBounds`] field that bounds this array.
    pub fn bound_name(self) -> &'static str {
        match self {
            GainField::KMat => "max_abs_k_mat",
            GainField::KVec => "max_abs_k_vec",
            GainField::SHat => "max_abs_s_hat",
            GainField::AHat => "max_abs_a_hat",
            GainField::Chol => "max_abs_chol",
        }
    }

    /// Number of columns (1 for vectors).
    fn cols(self) -> usize {
        match self {
            GainField::KMat => DX,
            GainField::Chol => DU,
            _ => 1,
        }
    }
}

/// Where in a table a value sits: field, time step and flat index within the field
/// (row-major for matrices). Displays as e.g. `K[t=3][1][4]` or `s_hat[t=0][7]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GainEntry {
    /// Array of the step.
    pub field: GainField,
    /// Time step.
    pub t: usize,
    /// Flat index within the array (row × cols + col for matrices).
    pub index: usize,
}

impl GainEntry {
    /// (row, column) for matrices; (index, 0) for vectors.
    pub fn row_col(&self) -> (usize, usize) {
        let c = self.field.cols();
        (self.index / c, self.index % c)
    }
}

impl fmt::Display for GainEntry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.field {
            GainField::KMat | GainField::Chol => {
                let (r, c) = self.row_col();
                write!(f, "{}[t={}][{}][{}]", self.field.name(), self.t, r, c)
            }
            _ => write!(f, "{}[t={}][{}]", self.field.name(), self.t, self.index),
        }
    }
}

/// Why a gain table was rejected. Each message names the field, time step and index.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum GainTableError {
    /// `dx`/`du` differ from this build's [`DX`]/[`DU`].
    #[error("gain table has dx = {dx}, du = {du}; this build expects dx = {DX}, du = {DU} (shared/src/layout.rs): learner and controller were built from different layouts")]
    WrongDimensions {
        /// Received dx.
        dx: u32,
        /// Received du.
        du: u32,
    },
    /// Horizon 0 or larger than [`MAX_HORIZON`].
    #[error("gain table horizon T = {horizon} is outside 1..={MAX_HORIZON}")]
    BadHorizon {
        /// Received horizon.
        horizon: u64,
    },
    /// The stored checksum does not match the contents (corrupt, half-written or not sealed).
    #[error("gain table version {version}: checksum mismatch (stored {stored:#018x}, computed {computed:#018x}); was the table sealed after its last change?")]
    ChecksumMismatch {
        /// Table version as received.
        version: u64,
        /// Checksum field.
        stored: u64,
        /// Checksum of the contents.
        computed: u64,
    },
    /// An episode plan that is not valid ([`EpisodePlan::validate`]).
    #[error("gain table version {version}: {source}")]
    Plan {
        /// Table version.
        version: u64,
        /// What is wrong with the plan.
        source: PlanError,
    },
    /// A NaN or infinity.
    #[error("gain table: {entry} = {value} is not finite")]
    NonFinite {
        /// Where.
        entry: GainEntry,
        /// The value.
        value: f64,
    },
    /// L_t has a non-zero entry above its diagonal.
    #[error("gain table: {entry} = {value} lies above the diagonal; L must be the lower Cholesky factor (upper entries exactly 0)")]
    NotLowerTriangular {
        /// Where (field is always L).
        entry: GainEntry,
        /// The value.
        value: f64,
    },
    /// L_t has a diagonal entry ≤ 0 (Σ_t not positive definite, or not the Cholesky factor).
    #[error("gain table: diagonal {entry} = {value} must be > 0 (L is the Cholesky factor of a positive definite covariance)")]
    NonPositiveDiagonal {
        /// Where (field is always L, index on the diagonal).
        entry: GainEntry,
        /// The value.
        value: f64,
    },
    /// |value| exceeds the configured bound.
    #[error("gain table: |{entry}| = {abs} exceeds GainBounds::{bound_name} = {bound}", abs = value.abs(), bound_name = entry.field.bound_name())]
    OutOfBounds {
        /// Where.
        entry: GainEntry,
        /// The value.
        value: f64,
        /// The bound it exceeds.
        bound: f64,
    },
}

/// Limits on gain-table entries, checked by [`GainTable::validate`] as |value| ≤ bound.
///
/// The defaults are deliberately generous: they catch a learner that has diverged or a table
/// that is garbage, not a controller that is merely aggressive (the controller clamps actions to
/// joint, velocity and effort limits anyway, docs/design.md §2.4). A NaN bound rejects every table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GainBounds {
    /// Largest |K_t\[i\]\[j\]| (action unit per state unit). Default 1e4: in goal-angle mode a
    /// gain of 1e3 rad/m already turns 1 mm of end-effector error into a 1 rad goal, far past
    /// the per-step clamp (≈ 0.3 rad); in torque mode 1e4 N·m/rad saturates the UR5's 150 N·m
    /// effort limit at 15 mrad of error, stiffer than any useful servo.
    pub max_abs_k_mat: f64,
    /// Largest |k_t\[i\]| (action unit). Default 1e3: ≈ 160× the UR5 joint range of ±2π rad
    /// and ≈ 7× its largest effort limit (150 N·m).
    pub max_abs_k_vec: f64,
    /// Largest |ŝ_t\[j\]| (layout units). Default 1e2: the UR5 has joint ranges of ±2π rad,
    /// joint speeds ≤ 3.2 rad/s, 0.85 m reach and end-effector speeds of a few m/s, so no
    /// physical nominal state comes near 100 in any unit.
    pub max_abs_s_hat: f64,
    /// Largest |â_t\[i\]| (action unit). Default 1e3, as for k_t.
    pub max_abs_a_hat: f64,
    /// Largest |L_t\[i\]\[j\]| (action unit), applied to every entry, diagonal included. Each
    /// entry of a Cholesky factor is bounded by the standard deviation of its action
    /// (|L_ij| ≤ √Σ_ii), so this bounds the exploration noise. Default 1e2: 100 rad is ~8× the
    /// whole joint range and 100 N·m is two-thirds of the largest UR5 effort limit; GPS starts
    /// from variances of order 1.
    pub max_abs_chol: f64,
}

impl Default for GainBounds {
    fn default() -> Self {
        Self {
            max_abs_k_mat: 1e4,
            max_abs_k_vec: 1e3,
            max_abs_s_hat: 1e2,
            max_abs_a_hat: 1e3,
            max_abs_chol: 1e2,
        }
    }
}

impl GainBounds {
    /// Every bound finite and > 0: a NaN bound would reject every table (`|x| <= NaN` is
    /// false) and leave the controller holding forever. Returns the name of
    /// the first bad key and its value.
    pub fn validate(&self) -> Result<(), (&'static str, f64)> {
        for (name, v) in [
            ("max_abs_k_mat", self.max_abs_k_mat),
            ("max_abs_k_vec", self.max_abs_k_vec),
            ("max_abs_s_hat", self.max_abs_s_hat),
            ("max_abs_a_hat", self.max_abs_a_hat),
            ("max_abs_chol", self.max_abs_chol),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((name, v));
            }
        }
        Ok(())
    }

    fn for_field(&self, field: GainField) -> f64 {
        match field {
            GainField::KMat => self.max_abs_k_mat,
            GainField::KVec => self.max_abs_k_vec,
            GainField::SHat => self.max_abs_s_hat,
            GainField::AHat => self.max_abs_a_hat,
            GainField::Chol => self.max_abs_chol,
        }
    }
}

/// Length of the hashed header: version (8), horizon, dx, du (4 each).
const HASHED_HEADER_BYTES: usize = 20;

// SAFETY: repr(C), integers and f64 arrays only (the size assertions above: no padding).
unsafe impl Table for GainTable {
    type Header = [u8; HASHED_HEADER_BYTES];

    fn hashed_header(&self) -> Self::Header {
        HeaderBytes::new()
            .u64(self.version)
            .u32(self.horizon)
            .u32(self.dx)
            .u32(self.du)
            .finish()
    }

    /// `steps[..T]`, every f64 in memory order.
    fn hashed_values(&self) -> &[f64] {
        let steps = self.used_steps();
        // SAFETY: GainStep is repr(C) plain f64 data without padding (size assertion above),
        // so `steps` is `STEP_LEN · steps.len()` contiguous, aligned f64.
        unsafe { core::slice::from_raw_parts(steps.as_ptr().cast::<f64>(), STEP_LEN * steps.len()) }
    }

    fn plan(&self) -> &EpisodePlan {
        &self.plan
    }

    fn checksum_mut(&mut self) -> &mut u64 {
        &mut self.checksum
    }

    fn dims_mut(&mut self) -> (&mut u32, &mut u32) {
        (&mut self.dx, &mut self.du)
    }
}

/// Iterates the arrays of a step with their field tags.
fn step_fields(step: &GainStep) -> [(GainField, &[f64]); 5] {
    [
        (GainField::KMat, step.k_mat.as_flattened()),
        (GainField::KVec, &step.k_vec[..]),
        (GainField::SHat, &step.s_hat[..]),
        (GainField::AHat, &step.a_hat[..]),
        (GainField::Chol, step.chol.as_flattened()),
    ]
}

impl GainTable {
    /// A zeroed table on the heap with `dx`, `du` set to [`DX`], [`DU`]; version 0, horizon 0
    /// (so it does not validate until filled). Allocates once and never builds the 64 KB value
    /// on the stack.
    pub fn new_boxed() -> Box<GainTable> {
        table::new_boxed()
    }

    /// Zeroes `slot` in place (e.g. the payload of an iceoryx2 `loan_uninit()` sample) and sets
    /// `dx`, `du`; returns the initialised table. No allocation, no stack temporary.
    pub fn init_zeroed(slot: &mut MaybeUninit<GainTable>) -> &mut GainTable {
        table::init_zeroed(slot)
    }

    /// Copies `src` into `self` (one 64 KB memcpy, no allocation), e.g. into the inactive half
    /// of the controller's double buffer.
    pub fn copy_from(&mut self, src: &GainTable) {
        *self = *src;
    }

    /// Copies `self` into an uninitialised slot (e.g. a loaned iceoryx2 sample) and returns it.
    pub fn copy_to_uninit<'a>(&self, slot: &'a mut MaybeUninit<GainTable>) -> &'a mut GainTable {
        // SAFETY: `self` is a valid table and `slot` is a distinct, writable, aligned location.
        unsafe {
            core::ptr::copy_nonoverlapping(self as *const GainTable, slot.as_mut_ptr(), 1);
            slot.assume_init_mut()
        }
    }

    /// Horizon T as usize.
    pub fn horizon(&self) -> usize {
        self.horizon as usize
    }

    /// Sets the version.
    pub fn set_version(&mut self, version: u64) {
        self.version = version;
    }

    /// Sets the horizon T (1 ≤ T ≤ [`MAX_HORIZON`]).
    pub fn set_horizon(&mut self, horizon: usize) -> Result<(), GainTableError> {
        if horizon == 0 || horizon > MAX_HORIZON {
            return Err(GainTableError::BadHorizon {
                horizon: horizon as u64,
            });
        }
        self.horizon = horizon as u32;
        Ok(())
    }

    /// Step t. Panics if t ≥ [`MAX_HORIZON`]; steps at t ≥ T are unused.
    pub fn step(&self, t: usize) -> &GainStep {
        &self.steps[t]
    }

    /// Step t for filling in place. Panics if t ≥ [`MAX_HORIZON`].
    pub fn step_mut(&mut self, t: usize) -> &mut GainStep {
        &mut self.steps[t]
    }

    /// Overwrites step t. Panics if t ≥ [`MAX_HORIZON`].
    pub fn set_step(&mut self, t: usize, step: &GainStep) {
        self.steps[t] = *step;
    }

    /// The used steps `steps[..T]` (clamped to [`MAX_HORIZON`]).
    pub fn used_steps(&self) -> &[GainStep] {
        &self.steps[..self.horizon().min(MAX_HORIZON)]
    }

    /// Checksum of the current contents (module docs). Uses at most [`MAX_HORIZON`] steps even
    /// if `horizon` is larger.
    pub fn compute_checksum(&self) -> u64 {
        table::compute_checksum(self)
    }

    /// Stores the checksum of the current contents. Call after the last change, before
    /// publishing.
    pub fn seal(&mut self) {
        table::seal(self)
    }

    /// Checks the table before use, in this order: dimensions, horizon, checksum, episode plan,
    /// then for each step t < T: every value finite, L lower triangular, L diagonal > 0, every |value| within
    /// `bounds`. Returns the first problem found. Allocation-free. The controller validates when a
    /// table arrives, not on every tick (cost: docs/design.md §3.9).
    pub fn validate(&self, bounds: &GainBounds) -> Result<(), GainTableError> {
        if self.dx as usize != DX || self.du as usize != DU {
            return Err(GainTableError::WrongDimensions {
                dx: self.dx,
                du: self.du,
            });
        }
        let horizon = self.horizon();
        if horizon == 0 || horizon > MAX_HORIZON {
            return Err(GainTableError::BadHorizon {
                horizon: u64::from(self.horizon),
            });
        }
        let computed = self.compute_checksum();
        if computed != self.checksum {
            return Err(GainTableError::ChecksumMismatch {
                version: self.version,
                stored: self.checksum,
                computed,
            });
        }
        self.plan
            .validate()
            .map_err(|source| GainTableError::Plan {
                version: self.version,
                source,
            })?;
        for (t, step) in self.used_steps().iter().enumerate() {
            let fields = step_fields(step);
            for (field, values) in fields {
                for (index, &value) in values.iter().enumerate() {
                    if !value.is_finite() {
                        let entry = GainEntry { field, t, index };
                        return Err(GainTableError::NonFinite { entry, value });
                    }
                }
            }
            for i in 0..DU {
                for j in i + 1..DU {
                    let value = step.chol[i][j];
                    if value != 0.0 {
                        let entry = GainEntry {
                            field: GainField::Chol,
                            t,
                            index: i * DU + j,
                        };
                        return Err(GainTableError::NotLowerTriangular { entry, value });
                    }
                }
                let value = step.chol[i][i];
                if value <= 0.0 {
                    let entry = GainEntry {
                        field: GainField::Chol,
                        t,
                        index: i * DU + i,
                    };
                    return Err(GainTableError::NonPositiveDiagonal { entry, value });
                }
            }
            for (field, values) in fields {
                let bound = bounds.for_field(field);
                for (index, &value) in values.iter().enumerate() {
                    // Written so that a NaN bound rejects.
                    if !(value.abs() <= bound) {
                        let entry = GainEntry { field, t, index };
                        return Err(GainTableError::OutOfBounds {
                            entry,
                            value,
                            bound,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random valid table: entries well inside the default bounds, L lower triangular with
    /// diagonal in [0.1, 1].
    pub(crate) fn random_table(seed: u64, horizon: usize) -> Box<GainTable> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut table = GainTable::new_boxed();
        table.set_version(seed + 1);
        table.set_horizon(horizon).unwrap();
        for t in 0..horizon {
            let st = table.step_mut(t);
            for v in st.k_mat.as_flattened_mut() {
                *v = rng.random_range(-5.0..5.0);
            }
            for v in st
                .k_vec
                .iter_mut()
                .chain(st.a_hat.iter_mut())
                .chain(st.s_hat.iter_mut())
            {
                *v = rng.random_range(-2.0..2.0);
            }
            for i in 0..DU {
                for j in 0..i {
                    st.chol[i][j] = rng.random_range(-0.5..0.5);
                }
                st.chol[i][i] = rng.random_range(0.1..1.0);
            }
        }
        table.seal();
        table
    }

    fn good() -> Box<GainTable> {
        random_table(7, 100)
    }

    fn err_after(f: impl FnOnce(&mut GainTable)) -> GainTableError {
        let mut table = good();
        f(&mut table);
        table.seal();
        let err = table.validate(&GainBounds::default()).unwrap_err();
        // Every message must render (and say something).
        assert!(!err.to_string().is_empty());
        err
    }

    #[test]
    fn accepts_a_good_table() {
        let table = good();
        assert_eq!(table.validate(&GainBounds::default()), Ok(()));
        assert_eq!(table.horizon(), 100);
        assert_eq!(table.version, 8);
        // Full horizon and T = 1 are fine too.
        random_table(1, MAX_HORIZON)
            .validate(&GainBounds::default())
            .unwrap();
        random_table(2, 1).validate(&GainBounds::default()).unwrap();
    }

    #[test]
    fn rejects_wrong_dimensions() {
        let err = err_after(|t| t.dx = 13);
        assert_eq!(err, GainTableError::WrongDimensions { dx: 13, du: 3 });
        assert!(err.to_string().contains("dx = 13"));
        let err = err_after(|t| t.du = 6);
        assert_eq!(err, GainTableError::WrongDimensions { dx: 12, du: 6 });
    }

    #[test]
    fn rejects_bad_horizon() {
        assert_eq!(
            err_after(|t| t.horizon = 0),
            GainTableError::BadHorizon { horizon: 0 }
        );
        assert_eq!(
            err_after(|t| t.horizon = MAX_HORIZON as u32 + 1),
            GainTableError::BadHorizon { horizon: 129 }
        );
        assert!(good().set_horizon(0).is_err());
        assert!(good().set_horizon(MAX_HORIZON + 1).is_err());
    }

    #[test]
    fn rejects_non_finite() {
        let err = err_after(|t| t.steps[42].s_hat[7] = f64::NAN);
        match err {
            GainTableError::NonFinite { entry, value } => {
                assert!(value.is_nan());
                assert_eq!(
                    entry,
                    GainEntry {
                        field: GainField::SHat,
                        t: 42,
                        index: 7
                    }
                );
            }
            e => panic!("wrong error {e:?}"),
        }
        let err = err_after(|t| t.steps[3].k_mat[1][4] = f64::INFINITY);
        assert!(
            err.to_string().contains("K[t=3][1][4] = inf"),
            "message: {err}"
        );
        // Beyond the horizon nothing is looked at.
        let mut table = good();
        table.steps[100].k_vec[0] = f64::NAN;
        table.seal();
        table.validate(&GainBounds::default()).unwrap();
    }

    #[test]
    fn rejects_upper_triangular_entries() {
        let err = err_after(|t| t.steps[5].chol[0][2] = 1e-9);
        assert_eq!(
            err,
            GainTableError::NotLowerTriangular {
                entry: GainEntry {
                    field: GainField::Chol,
                    t: 5,
                    index: 2
                },
                value: 1e-9
            }
        );
        assert!(err.to_string().contains("L[t=5][0][2]"), "message: {err}");
    }

    #[test]
    fn rejects_non_positive_diagonal() {
        for bad in [0.0, -0.0, -0.3] {
            let err = err_after(|t| t.steps[99].chol[2][2] = bad);
            assert_eq!(
                err,
                GainTableError::NonPositiveDiagonal {
                    entry: GainEntry {
                        field: GainField::Chol,
                        t: 99,
                        index: 8
                    },
                    value: bad
                }
            );
            assert!(err.to_string().contains("L[t=99][2][2]"), "message: {err}");
        }
    }

    #[test]
    fn rejects_out_of_bounds_in_every_field() {
        let b = GainBounds::default();
        let cases: [(GainField, usize, f64, fn(&mut GainStep, f64)); 5] = [
            (GainField::KMat, 13, b.max_abs_k_mat, |s, v| {
                s.k_mat[1][1] = v
            }),
            (GainField::KVec, 2, b.max_abs_k_vec, |s, v| s.k_vec[2] = v),
            (GainField::SHat, 11, b.max_abs_s_hat, |s, v| s.s_hat[11] = v),
            (GainField::AHat, 0, b.max_abs_a_hat, |s, v| s.a_hat[0] = v),
            (GainField::Chol, 4, b.max_abs_chol, |s, v| s.chol[1][1] = v),
        ];
        for (field, index, bound, set) in cases {
            // Exactly at the bound passes, just past it fails (either sign where allowed).
            let mut table = good();
            set(&mut table.steps[10], bound);
            table.seal();
            table.validate(&b).unwrap();
            let over = bound * (1.0 + 1e-12);
            let signs: &[f64] = if field == GainField::Chol {
                &[1.0]
            } else {
                &[1.0, -1.0]
            };
            for &sign in signs {
                let err = err_after(|t| set(&mut t.steps[10], sign * over));
                assert_eq!(
                    err,
                    GainTableError::OutOfBounds {
                        entry: GainEntry {
                            field,
                            t: 10,
                            index
                        },
                        value: sign * over,
                        bound
                    }
                );
                assert!(err.to_string().contains(field.bound_name()));
            }
        }
        // A NaN bound fails safe.
        let nan = GainBounds {
            max_abs_s_hat: f64::NAN,
            ..GainBounds::default()
        };
        assert!(matches!(
            good().validate(&nan),
            Err(GainTableError::OutOfBounds { .. })
        ));
    }

    #[test]
    fn rejects_checksum_mismatch() {
        let mut table = good();
        table.steps[50].k_mat[2][11] += 1e-12;
        let err = table.validate(&GainBounds::default()).unwrap_err();
        assert!(matches!(
            err,
            GainTableError::ChecksumMismatch { version: 8, .. }
        ));
        assert!(err.to_string().contains("checksum mismatch"));
    }

    #[test]
    fn checksum_detects_a_single_changed_number() {
        let table = good();
        let base = table.compute_checksum();
        assert_eq!(base, table.checksum);
        let mut copy = GainTable::new_boxed();
        for t in [0, 1, 57, 99] {
            for i in 0..STEP_LEN {
                copy.copy_from(&table);
                let v = copy.steps[t].as_flat()[i];
                set_flat(&mut copy.steps[t], i, f64::from_bits(v.to_bits() ^ 1));
                assert_ne!(copy.compute_checksum(), base, "t={t} i={i}");
            }
        }
        // Header fields are covered.
        for f in [
            |t: &mut GainTable| t.version += 1,
            |t: &mut GainTable| t.horizon -= 1,
            |t: &mut GainTable| t.dx += 1,
            |t: &mut GainTable| t.du += 1,
        ] {
            copy.copy_from(&table);
            f(&mut copy);
            assert_ne!(copy.compute_checksum(), base);
        }
        // Steps past the horizon, `epoch` and `checksum` are not.
        copy.copy_from(&table);
        copy.steps[100].k_vec[0] = 3.0;
        copy.epoch = 9;
        copy.checksum = 1;
        assert_eq!(copy.compute_checksum(), base);
    }

    fn set_flat(step: &mut GainStep, i: usize, v: f64) {
        let mut k = i;
        for arr in [
            step.k_mat.as_flattened_mut(),
            &mut step.k_vec[..],
            &mut step.s_hat[..],
            &mut step.a_hat[..],
            step.chol.as_flattened_mut(),
        ] {
            if k < arr.len() {
                arr[k] = v;
                return;
            }
            k -= arr.len();
        }
        panic!("index {i} out of range");
    }

    #[test]
    fn checksum_is_xxh3_of_the_documented_bytes() {
        // XXH3_64bits test vector of the reference implementation (empty input, seed 0).
        assert_eq!(xxhash_rust::xxh3::xxh3_64(b""), 0x2d06_8005_38d3_94c2);
        // The documented byte string, built independently and hashed in one call, for short and
        // full horizons (the streaming hasher must agree with the one-shot hash at every length).
        for (seed, horizon) in [(3, 1), (4, 4), (5, 100), (6, MAX_HORIZON)] {
            let table = random_table(seed, horizon);
            let mut bytes = Vec::new();
            bytes.extend_from_slice(&table.version.to_le_bytes());
            bytes.extend_from_slice(&table.horizon.to_le_bytes());
            bytes.extend_from_slice(&table.dx.to_le_bytes());
            bytes.extend_from_slice(&table.du.to_le_bytes());
            for s in &table.steps[..horizon] {
                for row in &s.k_mat {
                    row.iter()
                        .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
                }
                for v in s.k_vec.iter().chain(&s.s_hat).chain(&s.a_hat) {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
                for row in &s.chol {
                    row.iter()
                        .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
                }
            }
            assert_eq!(bytes.len(), 20 + horizon * STEP_LEN * 8);
            assert_eq!(table.checksum, xxhash_rust::xxh3::xxh3_64(&bytes));
        }
    }

    /// A plan other than the default is hashed after the steps (its 32 bytes); the default
    /// plan adds nothing, so the checksum of a table without one is the one it always had. A
    /// plan changed after sealing fails the checksum; a sealed invalid plan is named.
    #[test]
    fn a_plan_is_hashed_after_the_steps_and_validated() {
        let mut table = random_table(5, 7);
        let plain = table.checksum;
        let steps = |t: &GainTable| {
            let mut bytes = t.hashed_header().to_vec();
            for v in t.hashed_values() {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            bytes
        };
        assert_eq!(plain, xxhash_rust::xxh3::xxh3_64(&steps(&table)));
        table.plan = EpisodePlan::to_goal([-0.4, 0.1, 0.3]).with_noise_stream(2);
        let e = table.validate(&GainBounds::default()).unwrap_err();
        assert!(matches!(e, GainTableError::ChecksumMismatch { .. }), "{e}");
        table.seal();
        let mut bytes = steps(&table);
        bytes.extend_from_slice(&table.plan.hashed_bytes());
        assert_eq!(table.checksum, xxhash_rust::xxh3::xxh3_64(&bytes));
        assert_ne!(table.checksum, plain);
        table.validate(&GainBounds::default()).unwrap();
        // Each part of the plan is covered.
        for f in [
            |p: &mut EpisodePlan| p.goal[2] = f64::from_bits(p.goal[2].to_bits() ^ 1),
            |p: &mut EpisodePlan| p.noise_stream = 3,
            |p: &mut EpisodePlan| p.flags |= crate::plan::PLAN_NOISE_FREE,
        ] {
            let mut copy = table.clone();
            f(&mut copy.plan);
            assert_ne!(copy.compute_checksum(), table.checksum);
        }
        // Back to the default plan: the old checksum.
        table.plan = EpisodePlan::default();
        assert_eq!(table.compute_checksum(), plain);
        // A sealed plan with a NaN goal.
        table.plan = EpisodePlan::to_goal([0.0, f64::NAN, 0.0]);
        table.seal();
        let e = table.validate(&GainBounds::default()).unwrap_err();
        assert!(
            matches!(
                e,
                GainTableError::Plan {
                    version: 6,
                    source: PlanError::BadGoal { index: 1, .. }
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("goal[1] = NaN"), "{e}");
    }

    #[test]
    fn checksum_matches_the_reference_xxhash() {
        // A table anyone can rebuild: version 1, T = 2, value i of step t = (63 t + i) / 4.
        // The expected value is from the xxHash reference implementation (C libxxhash 0.8.4 via
        // Python's `xxhash.xxh3_64_intdigest`) over the documented byte string.
        let mut table = GainTable::new_boxed();
        table.set_version(1);
        table.set_horizon(2).unwrap();
        for t in 0..2 {
            for i in 0..STEP_LEN {
                set_flat(&mut table.steps[t], i, (STEP_LEN * t + i) as f64 / 4.0);
            }
        }
        assert_eq!(table.compute_checksum(), 0x846a_c5be_5d90_5f00);
    }

    #[test]
    fn accessors_round_trip() {
        let src = good();
        let mut dst = GainTable::new_boxed();
        assert_eq!((dst.dx, dst.du, dst.horizon, dst.version), (12, 3, 0, 0));
        dst.set_version(src.version);
        dst.set_horizon(src.horizon()).unwrap();
        for t in 0..src.horizon() {
            let step = *src.step(t);
            dst.set_step(t, &step);
            assert_eq!(dst.step(t), src.step(t));
        }
        dst.seal();
        assert_eq!(dst.checksum, src.checksum);
        assert_eq!(*dst, *src);
        dst.validate(&GainBounds::default()).unwrap();

        // Filling in place through step_mut gives the same table.
        let mut inplace = GainTable::new_boxed();
        inplace.set_version(src.version);
        inplace.set_horizon(100).unwrap();
        for t in 0..100 {
            let s = inplace.step_mut(t);
            s.k_mat = src.steps[t].k_mat;
            s.k_vec = src.steps[t].k_vec;
            s.s_hat = src.steps[t].s_hat;
            s.a_hat = src.steps[t].a_hat;
            s.chol = src.steps[t].chol;
        }
        inplace.seal();
        assert_eq!(*inplace, *src);
        assert_eq!(inplace.used_steps().len(), 100);

        // Uninitialised slots (as loaned from iceoryx2).
        let mut slot = Box::<GainTable>::new_uninit();
        let copied = src.copy_to_uninit(&mut slot);
        assert_eq!(*copied, *src);
        let zeroed = GainTable::init_zeroed(&mut slot);
        assert_eq!((zeroed.dx, zeroed.du, zeroed.horizon), (12, 3, 0));
        assert!(zeroed.steps.iter().all(|s| *s == GainStep::default()));
    }

    #[test]
    fn layout_is_as_documented() {
        assert_eq!(core::mem::offset_of!(GainTable, version), 0);
        assert_eq!(core::mem::offset_of!(GainTable, horizon), 8);
        assert_eq!(core::mem::offset_of!(GainTable, dx), 12);
        assert_eq!(core::mem::offset_of!(GainTable, du), 16);
        assert_eq!(core::mem::offset_of!(GainTable, epoch), 20);
        assert_eq!(core::mem::offset_of!(GainTable, checksum), 24);
        assert_eq!(core::mem::offset_of!(GainTable, plan), 32);
        assert_eq!(core::mem::offset_of!(GainTable, steps), 64);
        assert_eq!(GAIN_TABLE_BYTES, 64_576);
        let s = GainStep::default();
        let base = &s as *const GainStep as usize;
        assert_eq!(&s.k_vec as *const _ as usize - base, 36 * 8);
        assert_eq!(&s.chol as *const _ as usize - base, 54 * 8);
    }

    #[test]
    fn bounds_serde_round_trip_and_partial_files() {
        let b = GainBounds::default();
        let text = toml::to_string(&b).unwrap();
        assert_eq!(toml::from_str::<GainBounds>(&text).unwrap(), b);
        let partial: GainBounds = toml::from_str("max_abs_k_mat = 50.0").unwrap();
        assert_eq!(partial.max_abs_k_mat, 50.0);
        assert_eq!(partial.max_abs_chol, b.max_abs_chol);
        assert!(toml::from_str::<GainBounds>("max_abs_k = 1.0").is_err());
    }
}
