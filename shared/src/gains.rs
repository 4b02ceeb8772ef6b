//! Gain tables: the time-varying linear-Gaussian controller the learner publishes on
//! `controller/gains` and the controller executes (docs/design.md §1.2, §3.3).
//!
//! Per time step t < T the table holds the paper's controller
//!
//! ```text
//! p(a_t | s_t) = N( K_t (s_t − ŝ_t) + k_t + â_t ,  Σ_t ),   Σ_t = L_t L_tᵀ
//! ```
//!
//! as a step ([`GainStep`], a view of the table's values): K_t (dU × dX), k_t (dU), ŝ_t (dX),
//! â_t (dU) and L_t (dU × dU, lower Cholesky factor of Σ_t). The dimensions dX, dU are the
//! table's own (`dx`, `du`, those of a task's [`crate::layout::StateLayout`]), at most
//! [`MAX_DX`], [`MAX_DU`]. Matrices are row-major (numpy C order): K\[i\]\[j\] is row i (action
//! entry), column j (state entry, [`crate::layout::StateLayout::state_name`]). Units follow the
//! layout: states in rad, rad/s, m, m/s; actions in rad (goal joint angles) or N·m (torque mode).
//!
//! # Storage
//!
//! The steps are packed one after the other at the table's dimensions in `values`: step t is
//! the [`step_len`]`(dx, du)` values from `t · step_len`, in the order K row-major, k, ŝ, â, L
//! row-major (504 values for the reaching task's dX = 12, dU = 3). The table is a fixed-size
//! `#[repr(C)]` value of [`GAIN_TABLE_BYTES`] bytes (≈ 1 MB: [`MAX_HORIZON`] steps of the
//! largest layout) so that iceoryx2 can move it through shared memory without a heap and the
//! controller can keep two of them (double buffer) allocated once. Build one with
//! [`GainTable::new_boxed`] (heap, no stack temporary) or in place with
//! [`GainTable::init_zeroed`] (e.g. in a loaned iceoryx2 sample), set its dimensions
//! ([`GainTable::set_layout`]), fill the steps, then [`GainTable::seal`]. A receiver calls
//! [`GainTable::validate`] and checks the dimensions against its task
//! ([`GainTable::check_layout`]) before using it.
//!
//! # Checksum
//!
//! [`GainTable::compute_checksum`] is XXH3-64 (xxHash 0.8's `XXH3_64bits`, seed 0) of one byte
//! string: `version` (u64), `horizon` (u32), `dx` (u32), `du` (u32), then the T packed steps'
//! values in order (T · [`step_len`] f64), each value as its IEEE-754 bit pattern; all integers
//! and bit patterns little-endian (20 + 8 · T · step_len bytes; 20 + 504·T·8 for the reaching
//! task, the same bytes, and so the same checksums, as tables of wire type `GainTable.v3`, whose
//! steps had the reaching task's fixed sizes). On a little-endian machine this is exactly the
//! raw bytes of those header fields followed by the raw bytes of `values[..T · step_len]`, so any
//! other language with an xxHash library can recompute it from the struct. A table whose episode
//! plan is not the default ([`crate::plan`]: a goal, a noise stream or noise-free episodes)
//! appends the plan's 32 bytes, so every table without one keeps the checksum it had before
//! plans existed. Values past the T steps, the `epoch` field and the checksum field itself are
//! not covered. Note that 0.0 and −0.0 hash differently. The checksum guards against corruption
//! and half-written tables, not against an adversary. Tables of wire type `GainTable.v1` (and
//! table files of schema 1) carried a byte-wise FNV-1a 64 instead; XXH3 reads 8 bytes at a time
//! with SIMD and replaced it for speed (docs/design.md §5 D27).

use core::fmt;
use core::mem::MaybeUninit;

use crate::layout::{DimensionMismatch, StateLayout, MAX_DU, MAX_DX, MAX_HORIZON};
use crate::plan::{EpisodePlan, PlanError};
use crate::table::{self, HeaderBytes, Table};
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Values of one step at dimensions `dx`, `du`: K (du·dx), k (du), ŝ (dx), â (du), L (du·du).
pub const fn step_len(dx: usize, du: usize) -> usize {
    du * dx + du + dx + du + du * du
}

/// Capacity of a table's values: [`MAX_HORIZON`] steps of the largest layout.
pub const GAIN_VALUES: usize = MAX_HORIZON * step_len(MAX_DX, MAX_DU);

/// Size of a [`GainTable`] in bytes (64-byte header + [`GAIN_VALUES`] f64).
pub const GAIN_TABLE_BYTES: usize = core::mem::size_of::<GainTable>();

const _: () = assert!(GAIN_TABLE_BYTES == 64 + GAIN_VALUES * 8);
// step_len grows with dx and du, so MAX_HORIZON steps of any layout fit.

/// One time step of the linear-Gaussian controller, a view of a table's values (units in the
/// module docs). Index with [`GainStep::k`] and [`GainStep::l`], or read the row-major slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GainStep<'a> {
    /// K_t, feedback gain, dU × dX row-major (action unit per state unit).
    pub k_mat: &'a [f64],
    /// k_t, feed-forward term, dU (action unit).
    pub k_vec: &'a [f64],
    /// ŝ_t, nominal state the feedback acts around, dX (layout units).
    pub s_hat: &'a [f64],
    /// â_t, nominal action, dU (action unit).
    pub a_hat: &'a [f64],
    /// L_t, lower Cholesky factor of the policy covariance Σ_t = L_t L_tᵀ, dU × dU row-major
    /// (action unit). Entries above the diagonal must be 0 and the diagonal positive.
    pub chol: &'a [f64],
}

impl GainStep<'_> {
    /// K_t\[i\]\[j\].
    #[inline]
    pub fn k(&self, i: usize, j: usize) -> f64 {
        self.k_mat[i * self.s_hat.len() + j]
    }

    /// L_t\[i\]\[j\].
    #[inline]
    pub fn l(&self, i: usize, j: usize) -> f64 {
        self.chol[i * self.k_vec.len() + j]
    }
}

/// One time step for filling in place (the arrays of [`GainStep`], writable).
#[derive(Debug, PartialEq)]
pub struct GainStepMut<'a> {
    /// K_t, dU × dX row-major.
    pub k_mat: &'a mut [f64],
    /// k_t, dU.
    pub k_vec: &'a mut [f64],
    /// ŝ_t, dX.
    pub s_hat: &'a mut [f64],
    /// â_t, dU.
    pub a_hat: &'a mut [f64],
    /// L_t, dU × dU row-major, lower triangular.
    pub chol: &'a mut [f64],
}

impl GainStepMut<'_> {
    /// Sets K_t\[i\]\[j\].
    pub fn set_k(&mut self, i: usize, j: usize, v: f64) {
        let dx = self.s_hat.len();
        self.k_mat[i * dx + j] = v;
    }

    /// Sets L_t\[i\]\[j\].
    pub fn set_l(&mut self, i: usize, j: usize, v: f64) {
        let du = self.k_vec.len();
        self.chol[i * du + j] = v;
    }

    /// Copies every array from `src` (of the same dimensions).
    pub fn copy_from(&mut self, src: &GainStep<'_>) {
        self.k_mat.copy_from_slice(src.k_mat);
        self.k_vec.copy_from_slice(src.k_vec);
        self.s_hat.copy_from_slice(src.s_hat);
        self.a_hat.copy_from_slice(src.a_hat);
        self.chol.copy_from_slice(src.chol);
    }
}

/// Splits one packed step (K, k, ŝ, â, L) at dimensions `dx`, `du`.
fn split_step(v: &[f64], dx: usize, du: usize) -> GainStep<'_> {
    let (k_mat, rest) = v.split_at(du * dx);
    let (k_vec, rest) = rest.split_at(du);
    let (s_hat, rest) = rest.split_at(dx);
    let (a_hat, chol) = rest.split_at(du);
    GainStep {
        k_mat,
        k_vec,
        s_hat,
        a_hat,
        chol,
    }
}

/// Splits one packed step for writing.
fn split_step_mut(v: &mut [f64], dx: usize, du: usize) -> GainStepMut<'_> {
    let (k_mat, rest) = v.split_at_mut(du * dx);
    let (k_vec, rest) = rest.split_at_mut(du);
    let (s_hat, rest) = rest.split_at_mut(dx);
    let (a_hat, chol) = rest.split_at_mut(du);
    GainStepMut {
        k_mat,
        k_vec,
        s_hat,
        a_hat,
        chol,
    }
}

/// A whole gain table: header plus up to [`MAX_HORIZON`] packed steps, of which the first
/// `horizon` are used.
///
/// All fields are public because this is a wire format: whatever arrives from shared memory may
/// hold any bits, and [`GainTable::validate`] is the gate. Prefer the methods for filling it.
/// It is about 1 MB, more than a test thread's stack holds twice, so it is neither `Clone` nor
/// `Copy`: copy with [`GainTable::copy_from`] into an existing buffer or with
/// [`GainTable::boxed_clone`] onto the heap.
#[repr(C)]
#[derive(ZeroCopySend)]
#[type_name("ur5_shared::GainTable.v4")]
pub struct GainTable {
    /// Table version, chosen by the learner (increasing). Samples carry the version of the
    /// table that produced them.
    pub version: u64,
    /// Horizon T: steps 0..T are used; 1 ≤ T ≤ [`MAX_HORIZON`].
    pub horizon: u32,
    /// State dimension dX of the task's layout, 1..=[`MAX_DX`].
    pub dx: u32,
    /// Action dimension dU of the task's layout, 1..=[`MAX_DU`].
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
    /// The steps packed at the table's dimensions (module docs); only the first
    /// T · [`step_len`]`(dx, du)` values are meaningful.
    pub values: [f64; GAIN_VALUES],
}

impl PartialEq for GainTable {
    /// Equal headers and equal used values (what is hashed, plus `epoch` and `checksum`);
    /// values past the horizon are not compared.
    fn eq(&self, other: &Self) -> bool {
        self.version == other.version
            && self.horizon == other.horizon
            && self.dx == other.dx
            && self.du == other.du
            && self.epoch == other.epoch
            && self.checksum == other.checksum
            && self.plan == other.plan
            && self.used_values() == other.used_values()
    }
}

impl fmt::Debug for GainTable {
    /// Prints the header only; the steps are thousands of numbers.
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

/// Which array of a step ([`GainStep`]) a problem was found in.
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
}

/// Where in a table a value sits: field, time step, row and column (column 0 for vectors).
/// Displays as e.g. `K[t=3][1][4]` or `s_hat[t=0][7]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GainEntry {
    /// Array of the step.
    pub field: GainField,
    /// Time step.
    pub t: usize,
    /// Row (matrices) or index (vectors).
    pub row: usize,
    /// Column (matrices); 0 for vectors.
    pub col: usize,
}

impl GainEntry {
    /// The entry at flat index `index` of `field`, a matrix of `cols` columns or a vector.
    fn at(field: GainField, t: usize, index: usize, cols: usize) -> Self {
        match field {
            GainField::KMat | GainField::Chol => Self {
                field,
                t,
                row: index / cols,
                col: index % cols,
            },
            _ => Self {
                field,
                t,
                row: index,
                col: 0,
            },
        }
    }
}

impl fmt::Display for GainEntry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.field {
            GainField::KMat | GainField::Chol => {
                write!(
                    f,
                    "{}[t={}][{}][{}]",
                    self.field.name(),
                    self.t,
                    self.row,
                    self.col
                )
            }
            _ => write!(f, "{}[t={}][{}]", self.field.name(), self.t, self.row),
        }
    }
}

/// Why a gain table was rejected. Each message names the field, time step and index.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum GainTableError {
    /// `dx`/`du` of no task: outside 1..=[`MAX_DX`], 1..=[`MAX_DU`], or not 2n + 6p, n (n
    /// joints, p tool points; [`StateLayout::from_dims`]).
    #[error("gain table has dx = {dx}, du = {du}, the dimensions of no task (dX = 2n + 6p and dU = n for n ≤ {MAX_DU} joints and p ≤ 3 tool points; shared/src/layout.rs)")]
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

// SAFETY: repr(C), integers and f64 arrays only (the size assertion above: no padding).
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

    /// The T packed steps.
    fn hashed_values(&self) -> &[f64] {
        self.used_values()
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
fn step_fields<'a>(step: &GainStep<'a>) -> [(GainField, &'a [f64]); 5] {
    [
        (GainField::KMat, step.k_mat),
        (GainField::KVec, step.k_vec),
        (GainField::SHat, step.s_hat),
        (GainField::AHat, step.a_hat),
        (GainField::Chol, step.chol),
    ]
}

impl GainTable {
    /// A zeroed table on the heap with the reaching task's dimensions
    /// ([`StateLayout::REACH3`]); version 0, horizon 0 (so it does not validate until filled).
    /// Allocates once and never builds the 1 MB value on the stack.
    pub fn new_boxed() -> Box<GainTable> {
        table::new_boxed()
    }

    /// A zeroed table on the heap for `layout`'s dimensions.
    pub fn new_boxed_for(layout: &StateLayout) -> Box<GainTable> {
        let mut t = Self::new_boxed();
        t.set_layout(layout);
        t
    }

    /// Zeroes `slot` in place (e.g. the payload of an iceoryx2 `loan_uninit()` sample) and sets
    /// the reaching task's `dx`, `du`; returns the initialised table. No allocation, no stack
    /// temporary.
    pub fn init_zeroed(slot: &mut MaybeUninit<GainTable>) -> &mut GainTable {
        table::init_zeroed(slot)
    }

    /// Sets the dimensions to `layout`'s. Call before filling the steps: the packing of the
    /// values depends on them.
    pub fn set_layout(&mut self, layout: &StateLayout) {
        self.dx = layout.dx() as u32;
        self.du = layout.du() as u32;
    }

    /// The dimensions (dX, dU) as usize.
    pub fn dims(&self) -> (usize, usize) {
        (self.dx as usize, self.du as usize)
    }

    /// Values per step at the table's dimensions.
    pub fn step_len(&self) -> usize {
        step_len(self.dx as usize, self.du as usize)
    }

    /// Bytes from the start of the table through the used values, clamped to the table (what
    /// [`GainTable::copy_from`] copies).
    fn used_bytes(&self) -> usize {
        (64 + 8 * self.used_len()).min(GAIN_TABLE_BYTES)
    }

    /// T · step_len, clamped to [`GAIN_VALUES`].
    fn used_len(&self) -> usize {
        self.horizon()
            .saturating_mul(self.step_len())
            .min(GAIN_VALUES)
    }

    /// Copies `src` into `self`: its header and used values, one memcpy, no allocation (e.g.
    /// into the inactive half of the controller's double buffer). Values past `src`'s horizon
    /// keep what `self` had; nothing reads them.
    pub fn copy_from(&mut self, src: &GainTable) {
        table::copy_prefix(self, src, src.used_bytes());
    }

    /// A copy on the heap (header and used values; the rest zero), never on the stack.
    pub fn boxed_clone(&self) -> Box<GainTable> {
        let mut b = Self::new_boxed();
        b.copy_from(self);
        b
    }

    /// Copies `self` into an uninitialised slot (e.g. a loaned iceoryx2 sample) and returns it:
    /// the header and used values; the rest of the slot is zeroed first.
    pub fn copy_to_uninit<'a>(&self, slot: &'a mut MaybeUninit<GainTable>) -> &'a mut GainTable {
        let dst = Self::init_zeroed(slot);
        dst.copy_from(self);
        dst
    }

    /// Horizon T as usize.
    pub fn horizon(&self) -> usize {
        self.horizon as usize
    }

    /// Sets the version.
    pub fn set_version(&mut self, version: u64) {
        self.version = version;
    }

    /// Sets the horizon T (1 ≤ T ≤ [`MAX_HORIZON`]; T steps of any layout fit the storage).
    pub fn set_horizon(&mut self, horizon: usize) -> Result<(), GainTableError> {
        if horizon == 0 || horizon > MAX_HORIZON {
            return Err(GainTableError::BadHorizon {
                horizon: horizon as u64,
            });
        }
        self.horizon = horizon as u32;
        Ok(())
    }

    /// Step t. Panics if the step lies outside the storage; steps at t ≥ T are unused.
    pub fn step(&self, t: usize) -> GainStep<'_> {
        let (dx, du) = self.dims();
        let n = step_len(dx, du);
        split_step(&self.values[t * n..(t + 1) * n], dx, du)
    }

    /// Step t for filling in place. Panics if the step lies outside the storage.
    pub fn step_mut(&mut self, t: usize) -> GainStepMut<'_> {
        let (dx, du) = self.dims();
        let n = step_len(dx, du);
        split_step_mut(&mut self.values[t * n..(t + 1) * n], dx, du)
    }

    /// The used values: the T packed steps (clamped to the storage).
    pub fn used_values(&self) -> &[f64] {
        &self.values[..self.used_len()]
    }

    /// Checksum of the current contents (module docs). Uses at most the storage's values even
    /// if `horizon` claims more.
    pub fn compute_checksum(&self) -> u64 {
        table::compute_checksum(self)
    }

    /// Stores the checksum of the current contents. Call after the last change, before
    /// publishing.
    pub fn seal(&mut self) {
        table::seal(self)
    }

    /// `Ok` if the table's dimensions are `layout`'s; otherwise the mismatch, naming both.
    pub fn check_layout(&self, layout: &StateLayout) -> Result<(), DimensionMismatch> {
        layout.check_dims("gain table", self.dx as usize, self.du as usize)
    }

    /// Checks the table before use, in this order: dimensions (those of some task, so that T
    /// steps fit the storage), horizon, checksum, episode plan, then for each step t < T:
    /// every value finite, L lower triangular, L diagonal > 0, every |value| within `bounds`.
    /// Returns the first problem found. Allocation-free. Whether the dimensions are the
    /// receiver's task's is [`GainTable::check_layout`]. The controller validates when a table
    /// arrives, not on every tick (cost: docs/design.md §3.9).
    pub fn validate(&self, bounds: &GainBounds) -> Result<(), GainTableError> {
        let (dx, du) = self.dims();
        if StateLayout::from_dims(dx, du).is_none() {
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
        let cols = |field| if field == GainField::Chol { du } else { dx };
        for t in 0..horizon {
            let step = self.step(t);
            let fields = step_fields(&step);
            for (field, values) in fields {
                for (index, &value) in values.iter().enumerate() {
                    if !value.is_finite() {
                        let entry = GainEntry::at(field, t, index, cols(field));
                        return Err(GainTableError::NonFinite { entry, value });
                    }
                }
            }
            for i in 0..du {
                for j in i + 1..du {
                    let value = step.l(i, j);
                    if value != 0.0 {
                        let entry = GainEntry::at(GainField::Chol, t, i * du + j, du);
                        return Err(GainTableError::NotLowerTriangular { entry, value });
                    }
                }
                let value = step.l(i, i);
                if value <= 0.0 {
                    let entry = GainEntry::at(GainField::Chol, t, i * du + i, du);
                    return Err(GainTableError::NonPositiveDiagonal { entry, value });
                }
            }
            for (field, values) in fields {
                let bound = bounds.for_field(field);
                for (index, &value) in values.iter().enumerate() {
                    // Written so that a NaN bound rejects.
                    if !(value.abs() <= bound) {
                        let entry = GainEntry::at(field, t, index, cols(field));
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

    /// A random valid table of `layout`'s dimensions: entries well inside the default bounds, L
    /// lower triangular with diagonal in [0.1, 1].
    pub(crate) fn random_table_for(
        layout: &StateLayout,
        seed: u64,
        horizon: usize,
    ) -> Box<GainTable> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut table = GainTable::new_boxed_for(layout);
        table.set_version(seed + 1);
        table.set_horizon(horizon).unwrap();
        let du = layout.du();
        for t in 0..horizon {
            let mut st = table.step_mut(t);
            for v in st.k_mat.iter_mut() {
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
            for i in 0..du {
                for j in 0..i {
                    st.set_l(i, j, rng.random_range(-0.5..0.5));
                }
                st.set_l(i, i, rng.random_range(0.1..1.0));
            }
        }
        table.seal();
        table
    }

    /// [`random_table_for`] the reaching task.
    pub(crate) fn random_table(seed: u64, horizon: usize) -> Box<GainTable> {
        random_table_for(&StateLayout::REACH3, seed, horizon)
    }

    fn good() -> Box<GainTable> {
        random_table(7, 100)
    }

    fn err_after(f: impl FnOnce(&mut GainTable)) -> GainTableError {
        let mut table = good();
        f(&mut table);
        table.seal();
        let err = table.validate(&GainBounds::default()).unwrap_err();
        // Every error must render (and say something).
        assert!(!err.to_string().is_empty());
        err
    }

    fn entry(field: GainField, t: usize, row: usize, col: usize) -> GainEntry {
        GainEntry { field, t, row, col }
    }

    #[test]
    fn accepts_a_good_table() {
        let table = good();
        assert_eq!(table.validate(&GainBounds::default()), Ok(()));
        assert_eq!(table.horizon(), 100);
        assert_eq!(table.version, 8);
        // Full horizon and T = 1 are fine too, at every layout.
        for layout in [StateLayout::REACH3, StateLayout::POSE6] {
            random_table_for(&layout, 1, MAX_HORIZON)
                .validate(&GainBounds::default())
                .unwrap();
            random_table_for(&layout, 2, 1)
                .validate(&GainBounds::default())
                .unwrap();
        }
        // The largest layout fills the storage exactly at the largest horizon.
        let largest = StateLayout::new(crate::layout::MAX_JOINTS, 3).unwrap();
        let t = random_table_for(&largest, 3, MAX_HORIZON);
        assert_eq!(t.used_values().len(), GAIN_VALUES);
        t.validate(&GainBounds::default()).unwrap();
    }

    #[test]
    fn rejects_wrong_dimensions() {
        let err = err_after(|t| t.dx = 13);
        assert_eq!(err, GainTableError::WrongDimensions { dx: 13, du: 3 });
        assert!(err.to_string().contains("dx = 13"));
        let err = err_after(|t| t.du = 6);
        assert_eq!(err, GainTableError::WrongDimensions { dx: 12, du: 6 });
        let err = err_after(|t| t.dx = 0);
        assert_eq!(err, GainTableError::WrongDimensions { dx: 0, du: 3 });
        // A table of another task validates but is refused by the task's check, naming both.
        let pose = random_table_for(&StateLayout::POSE6, 4, 10);
        pose.validate(&GainBounds::default()).unwrap();
        let e = pose.check_layout(&StateLayout::REACH3).unwrap_err();
        assert!(e.to_string().contains("dX = 30, dU = 6"), "{e}");
        assert!(e.to_string().contains("dX = 12, dU = 3"), "{e}");
        pose.check_layout(&StateLayout::POSE6).unwrap();
    }

    #[test]
    fn rejects_bad_horizon() {
        assert_eq!(
            err_after(|t| t.horizon = 0),
            GainTableError::BadHorizon { horizon: 0 }
        );
        assert_eq!(
            err_after(|t| t.horizon = MAX_HORIZON as u32 + 1),
            GainTableError::BadHorizon {
                horizon: MAX_HORIZON as u64 + 1
            }
        );
        assert!(good().set_horizon(0).is_err());
        assert!(good().set_horizon(MAX_HORIZON + 1).is_err());
    }

    #[test]
    fn rejects_non_finite() {
        let err = err_after(|t| t.step_mut(42).s_hat[7] = f64::NAN);
        match err {
            GainTableError::NonFinite { entry: e, value } => {
                assert!(value.is_nan());
                assert_eq!(e, entry(GainField::SHat, 42, 7, 0));
            }
            e => panic!("wrong error {e:?}"),
        }
        let err = err_after(|t| t.step_mut(3).set_k(1, 4, f64::INFINITY));
        assert!(
            err.to_string().contains("K[t=3][1][4] = inf"),
            "message: {err}"
        );
        // Beyond the horizon nothing is looked at.
        let mut table = good();
        table.step_mut(100).k_vec[0] = f64::NAN;
        table.seal();
        table.validate(&GainBounds::default()).unwrap();
    }

    #[test]
    fn rejects_upper_triangular_entries() {
        let err = err_after(|t| t.step_mut(5).set_l(0, 2, 1e-9));
        assert_eq!(
            err,
            GainTableError::NotLowerTriangular {
                entry: entry(GainField::Chol, 5, 0, 2),
                value: 1e-9
            }
        );
        assert!(err.to_string().contains("L[t=5][0][2]"), "message: {err}");
    }

    #[test]
    fn rejects_non_positive_diagonal() {
        for bad in [0.0, -0.0, -0.3] {
            let err = err_after(|t| t.step_mut(99).set_l(2, 2, bad));
            assert_eq!(
                err,
                GainTableError::NonPositiveDiagonal {
                    entry: entry(GainField::Chol, 99, 2, 2),
                    value: bad
                }
            );
            assert!(err.to_string().contains("L[t=99][2][2]"), "message: {err}");
        }
    }

    #[test]
    fn rejects_out_of_bounds_in_every_field() {
        let b = GainBounds::default();
        let cases: [(GainEntry, f64, fn(&mut GainStepMut, f64)); 5] = [
            (entry(GainField::KMat, 10, 1, 1), b.max_abs_k_mat, |s, v| {
                s.set_k(1, 1, v)
            }),
            (entry(GainField::KVec, 10, 2, 0), b.max_abs_k_vec, |s, v| {
                s.k_vec[2] = v
            }),
            (
                entry(GainField::SHat, 10, 11, 0),
                b.max_abs_s_hat,
                |s, v| s.s_hat[11] = v,
            ),
            (entry(GainField::AHat, 10, 0, 0), b.max_abs_a_hat, |s, v| {
                s.a_hat[0] = v
            }),
            (entry(GainField::Chol, 10, 1, 1), b.max_abs_chol, |s, v| {
                s.set_l(1, 1, v)
            }),
        ];
        for (at, bound, set) in cases {
            // Exactly at the bound passes, just past it fails (either sign where allowed).
            let mut table = good();
            set(&mut table.step_mut(10), bound);
            table.seal();
            table.validate(&b).unwrap();
            let over = bound * (1.0 + 1e-12);
            let signs: &[f64] = if at.field == GainField::Chol {
                &[1.0]
            } else {
                &[1.0, -1.0]
            };
            for &sign in signs {
                let err = err_after(|t| set(&mut t.step_mut(10), sign * over));
                assert_eq!(
                    err,
                    GainTableError::OutOfBounds {
                        entry: at,
                        value: sign * over,
                        bound
                    }
                );
                assert!(err.to_string().contains(at.field.bound_name()));
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
        let v = table.step(50).k(2, 11);
        table.step_mut(50).set_k(2, 11, v + 1e-12);
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
        let n = table.step_len();
        for t in [0, 1, 57, 99] {
            for i in 0..n {
                copy.copy_from(&table);
                let v = copy.values[t * n + i];
                copy.values[t * n + i] = f64::from_bits(v.to_bits() ^ 1);
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
        copy.step_mut(100).k_vec[0] = 3.0;
        copy.epoch = 9;
        copy.checksum = 1;
        assert_eq!(copy.compute_checksum(), base);
    }

    #[test]
    fn checksum_is_xxh3_of_the_documented_bytes() {
        // XXH3_64bits test vector of the reference implementation (empty input, seed 0).
        assert_eq!(xxhash_rust::xxh3::xxh3_64(b""), 0x2d06_8005_38d3_94c2);
        // The documented byte string, built independently from the step views and hashed in
        // one call, for short and full horizons and two layouts (the streaming hasher must
        // agree with the one-shot hash at every length).
        for layout in [StateLayout::REACH3, StateLayout::POSE6] {
            for (seed, horizon) in [(3, 1), (4, 4), (5, 100), (6, MAX_HORIZON)] {
                let table = random_table_for(&layout, seed, horizon);
                let mut bytes = Vec::new();
                bytes.extend_from_slice(&table.version.to_le_bytes());
                bytes.extend_from_slice(&table.horizon.to_le_bytes());
                bytes.extend_from_slice(&table.dx.to_le_bytes());
                bytes.extend_from_slice(&table.du.to_le_bytes());
                for t in 0..horizon {
                    let s = table.step(t);
                    for v in s.k_mat.iter().chain(s.k_vec).chain(s.s_hat).chain(s.a_hat) {
                        bytes.extend_from_slice(&v.to_le_bytes());
                    }
                    for v in s.chol {
                        bytes.extend_from_slice(&v.to_le_bytes());
                    }
                }
                let n = step_len(layout.dx(), layout.du());
                assert_eq!(bytes.len(), 20 + horizon * n * 8);
                assert_eq!(table.checksum, xxhash_rust::xxh3::xxh3_64(&bytes));
            }
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
            let mut copy = table.boxed_clone();
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
        // A table anyone can rebuild: version 1, T = 2, value i of step t = (63 t + i) / 4 (the
        // reaching task: 504 values a step). The expected value is from the xxHash reference
        // implementation (C libxxhash 0.8.4 via Python's `xxhash.xxh3_64_intdigest`) over the
        // documented byte string; tables of wire type v3, whose steps had fixed sizes, had the
        // same checksum.
        let mut table = GainTable::new_boxed();
        table.set_version(1);
        table.set_horizon(2).unwrap();
        let n = table.step_len();
        assert_eq!(n, 63);
        for i in 0..2 * n {
            table.values[i] = i as f64 / 4.0;
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
            dst.step_mut(t).copy_from(&src.step(t));
            assert_eq!(dst.step(t), src.step(t));
        }
        dst.seal();
        assert_eq!(dst.checksum, src.checksum);
        assert_eq!(*dst, *src);
        dst.validate(&GainBounds::default()).unwrap();
        assert_eq!(dst.step(4).k(2, 7), dst.step(4).k_mat[2 * 12 + 7]);
        assert_eq!(dst.step(4).l(2, 1), dst.step(4).chol[2 * 3 + 1]);

        // A copy of a short table over a long one: the used part and the header.
        let mut long = random_table(9, MAX_HORIZON);
        long.copy_from(&src);
        assert_eq!(*long, *src);

        // Uninitialised slots (as loaned from iceoryx2).
        let mut slot = Box::<GainTable>::new_uninit();
        let copied = src.copy_to_uninit(&mut slot);
        assert_eq!(*copied, *src);
        let zeroed = GainTable::init_zeroed(&mut slot);
        assert_eq!((zeroed.dx, zeroed.du, zeroed.horizon), (12, 3, 0));
        assert!(zeroed.values.iter().all(|v| v.to_bits() == 0));

        // Another layout: dims from the layout, the steps packed at its sizes.
        let pose = random_table_for(&StateLayout::POSE6, 2, 3);
        assert_eq!(pose.dims(), (30, 6));
        assert_eq!(pose.step(1).k_mat.len(), 180);
        assert_eq!(pose.step(1).chol.len(), 36);
        assert_eq!(pose.used_values().len(), 3 * step_len(30, 6));
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
        assert_eq!(core::mem::offset_of!(GainTable, values), 64);
        assert_eq!(step_len(12, 3), 63);
        assert_eq!(GAIN_TABLE_BYTES, 64 + 8 * 400 * 319);
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
