//! Policy tables: the second controller kind the learner publishes (on `controller/policy`) and
//! the controller executes beside gain tables (docs/design.md §3.11, §6.8): the weights of the
//! MDGPS global policy (a Gaussian MLP on the state, docs/design.md §6.1) in a fixed-size,
//! versioned, checksummed `#[repr(C)]` value, and the one function that evaluates it,
//! [`policy_action`].
//!
//! # The law
//!
//! ```text
//! a = b(s) + μ(u) + σ ⊙ ε,   u = (s − m) ⊘ r,   ε ~ N(0, I_dU)
//! ```
//!
//! with b(s) = q = s[0..dU] (rad, the joint angles that open every layout,
//! [`crate::layout::StateLayout::q`]) in goal-angle mode and 0 in torque mode, m, r (dX each) the
//! input normalisation, σ = exp(log σ) (action unit, dU) and μ_j one tanh MLP per joint ("head"):
//! `dX → h_1 → … → h_k → 1`, tanh on the hidden layers, a linear output. The policy is
//! time-invariant: it acts at any t and for any horizon, and the goal enters only through the
//! state (the tool points minus their targets), so one table reaches any goal the controller
//! is given. dX and dU are the table's own (`dx`, `du`), those of a task's layout.
//!
//! # Parameter layout (θ, `params[..n_params]`, f64)
//!
//! `θ = [m (dX) | r (dX) | θ_μ0 | … | θ_μ(dU−1) | log σ (dU)]`; each head `θ_μj` holds its layers
//! in order, each layer `W_l` (row-major, `n_{l+1} × n_l`) then `b_l` (`n_{l+1}`). Its length is
//! [`flat_len`]`(dx, du, hidden)`: 15,198 values for the reaching task (dX = 12, dU = 3) and the
//! default `hidden = [64, 64]`. This is exactly
//! the learner's `imitation::mlp_policy::global::GlobalPolicy::flat` and the `params` array of a
//! policy file (docs/design.md §4.10).
//!
//! # Checksum
//!
//! XXH3-64 (seed 0) of `version` (u64), `dx`, `du`, `action_mode`, `n_hidden`, `hidden[0..4]`,
//! `n_params`, `model` (u32 each), then `params[..n_params]` as IEEE-754 bit patterns, all
//! little-endian (56 + 8·P bytes): on a little-endian machine the raw bytes of those fields; then, when the
//! episode plan is not the default, its 32 bytes ([`crate::plan`], as for gain tables). The
//! `epoch` field, the checksum itself and `params[n_params..]` are not covered.
//!
//! # Size
//!
//! [`POLICY_TABLE_BYTES`] = 96 + 8 · [`MAX_POLICY_PARAMS`] ≈ 384 KB: room for seven heads of
//! two hidden layers of 64 on the largest state (44 430 values), at most [`MAX_HIDDEN_LAYERS`] hidden layers of at
//! most [`MAX_WIDTH`] units. Like [`crate::GainTable`], build one on the heap
//! ([`PolicyTable::new_boxed`]) or in place ([`PolicyTable::init_zeroed`]), fill, [`PolicyTable::seal`];
//! a receiver calls [`PolicyTable::validate`] before use.

use core::fmt;
use core::mem::MaybeUninit;

use crate::config::ActionMode;
use crate::kernels::{affine, dot, tanh_in_place};
use crate::law::LawError;
use crate::layout::{DimensionMismatch, StateLayout, MAX_DX};
use crate::model::UrModel;
use crate::plan::{EpisodePlan, PlanError};
use crate::table::{self, HeaderBytes, Table};
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Most hidden layers per head.
pub const MAX_HIDDEN_LAYERS: usize = 4;
/// Widest hidden layer (units).
pub const MAX_WIDTH: usize = 256;
/// Most parameters a table carries: room for the largest task's default policy, 7 heads
/// 32-64-64-1 (44 430 parameters; 6 heads 30-64-64-1 for the six-joint pose task: 37 320).
/// `PolicyTable.v4`; v3 held 32 768, enough for three joints only.
pub const MAX_POLICY_PARAMS: usize = 49_152;
/// Size of a [`PolicyTable`] in bytes.
pub const POLICY_TABLE_BYTES: usize = core::mem::size_of::<PolicyTable>();

const _: () = assert!(POLICY_TABLE_BYTES == 96 + 8 * MAX_POLICY_PARAMS);

/// Parameters of one head with hidden widths `hidden` on a state of `dx` entries:
/// Σ_l (n_l · n_{l+1} + n_{l+1}) over the layer sizes `[dX, hidden…, 1]`.
pub fn head_len(dx: usize, hidden: &[usize]) -> usize {
    let mut prev = dx;
    let mut n = 0;
    for &h in hidden.iter().chain(&[1]) {
        n += prev * h + h;
        prev = h;
    }
    n
}

/// Length of θ at dimensions `dx`, `du` for heads of hidden widths `hidden` (module docs):
/// `2 dX + dU · head + dU`.
pub fn flat_len(dx: usize, du: usize, hidden: &[usize]) -> usize {
    2 * dx + du * head_len(dx, hidden) + du
}

/// The weights of a Gaussian MLP policy (module docs), as sent on `controller/policy`.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ur5_shared::PolicyTable.v4")]
pub struct PolicyTable {
    /// Version, in the same increasing sequence as gain tables' (the controller takes the
    /// newest of either kind).
    pub version: u64,
    /// State dimension dX of the task's layout.
    pub dx: u32,
    /// Action dimension dU of the task's layout.
    pub du: u32,
    /// 0: goal angles (a = q + μ + σ ε, rad); 1: torques (a = μ + σ ε, N·m).
    pub action_mode: u32,
    /// Hidden layers per head, 1..=[`MAX_HIDDEN_LAYERS`].
    pub n_hidden: u32,
    /// Hidden widths; entries at and after `n_hidden` must be 0.
    pub hidden: [u32; MAX_HIDDEN_LAYERS],
    /// Length of θ; must equal [`flat_len`] of the hidden widths.
    pub n_params: u32,
    /// Publication of this version, as [`crate::GainTable::epoch`]: 0 when the learner first
    /// publishes it; a resumed learner publishes the same version again with a higher epoch,
    /// and a controller running the version takes it again and restarts the version's episode
    /// count k. Echoed in [`crate::StepSample::table_epoch`]. Not hashed; tables written before
    /// it had 0 here (the old `reserved`).
    pub epoch: u32,
    /// The arm model the policy was trained on ([`model_code`]; 0: not stated). A controller
    /// driving another model refuses the table: the same joint angles put another arm's end
    /// effector elsewhere.
    pub model: u32,
    /// Zero (alignment).
    pub reserved: u32,
    /// XXH3-64 checksum (module docs), set by [`PolicyTable::seal`].
    pub checksum: u64,
    /// The goal, noise stream and schedule of the table's episodes ([`crate::plan`]), as a
    /// gain table's; the default (all zero) runs the controller's own. Hashed unless it is the
    /// default.
    pub plan: EpisodePlan,
    /// θ in `params[..n_params]` (module docs); the rest is unused.
    pub params: [f64; MAX_POLICY_PARAMS],
}

impl fmt::Debug for PolicyTable {
    /// The header only.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("PolicyTable")
            .field("version", &self.version)
            .field("dx", &self.dx)
            .field("du", &self.du)
            .field("action_mode", &self.action_mode)
            .field(
                "hidden",
                &&self.hidden[..(self.n_hidden as usize).min(MAX_HIDDEN_LAYERS)],
            )
            .field("n_params", &self.n_params)
            .field("epoch", &self.epoch)
            .field("plan", &self.plan)
            .field("checksum", &format_args!("{:#018x}", self.checksum))
            .finish_non_exhaustive()
    }
}

/// Which part of θ a value belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolicyPart {
    /// Input mean m\[i\].
    InputMean,
    /// Input scale r\[i\].
    InputScale,
    /// A weight or bias of head j.
    Head(usize),
    /// log σ\[j\].
    LogStd,
}

/// Where a value sits: its part, the index within the part, and its index in θ. Displays as
/// e.g. `r[3] (θ[15])` or `head 1 parameter 17 (θ[4969])`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PolicyEntry {
    /// Part of θ.
    pub part: PolicyPart,
    /// Index within the part.
    pub index: usize,
    /// Index in θ.
    pub flat: usize,
}

impl fmt::Display for PolicyEntry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.part {
            PolicyPart::InputMean => write!(f, "m[{}] (θ[{}])", self.index, self.flat),
            PolicyPart::InputScale => write!(f, "r[{}] (θ[{}])", self.index, self.flat),
            PolicyPart::Head(j) => {
                write!(f, "head {j} parameter {} (θ[{}])", self.index, self.flat)
            }
            PolicyPart::LogStd => write!(f, "log_std[{}] (θ[{}])", self.index, self.flat),
        }
    }
}

/// Why a policy table was rejected; each message names the field or θ entry and the limit.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum PolicyTableError {
    /// `dx`/`du` of no task ([`StateLayout::from_dims`]).
    #[error("policy table has dx = {dx}, du = {du}, the dimensions of no task (dX = 2n + 6p and dU = n for n joints and p tool points; shared/src/layout.rs)")]
    WrongDimensions {
        /// Received dx.
        dx: u32,
        /// Received du.
        du: u32,
    },
    /// `n_hidden`, a hidden width or `n_params` impossible.
    #[error("policy table version {version}: {what} (limits: 1..={MAX_HIDDEN_LAYERS} hidden layers of 1..={MAX_WIDTH} units, at most {MAX_POLICY_PARAMS} parameters)")]
    BadShape {
        /// Table version.
        version: u64,
        /// What is wrong.
        what: &'static str,
    },
    /// `n_params` is not the length the hidden widths need.
    #[error("policy table version {version}: n_params = {n_params}, but the hidden widths need {expected}")]
    WrongParamCount {
        /// Table version.
        version: u64,
        /// Received.
        n_params: u32,
        /// [`flat_len`] of the widths.
        expected: usize,
    },
    /// `action_mode` not 0 or 1.
    #[error("policy table version {version}: action_mode = {mode} (0 goal angles, 1 torques)")]
    BadActionMode {
        /// Table version.
        version: u64,
        /// Received.
        mode: u32,
    },
    /// Contents do not match the checksum.
    #[error("policy table version {version}: checksum mismatch (stored {stored:#018x}, computed {computed:#018x}); was the table sealed after its last change?")]
    ChecksumMismatch {
        /// Table version.
        version: u64,
        /// Checksum field.
        stored: u64,
        /// Checksum of the contents.
        computed: u64,
    },
    /// An episode plan that is not valid ([`EpisodePlan::validate`]).
    #[error("policy table version {version}: {source}")]
    Plan {
        /// Table version.
        version: u64,
        /// What is wrong with the plan.
        source: PlanError,
    },
    /// A NaN or infinity.
    #[error("policy table: {entry} = {value} is not finite")]
    NonFinite {
        /// Where.
        entry: PolicyEntry,
        /// The value.
        value: f64,
    },
    /// A value outside [`PolicyBounds`] (the message names the bound).
    #[error("policy table: {entry} = {value} is outside PolicyBounds::{bound_name} ({bound})")]
    OutOfBounds {
        /// Where.
        entry: PolicyEntry,
        /// The value.
        value: f64,
        /// Name of the bound.
        bound_name: &'static str,
        /// The bound.
        bound: f64,
    },
}

/// Limits a policy table must satisfy ([`PolicyTable::validate`]). Like [`crate::GainBounds`]
/// they catch garbage and divergence, not aggressive policies: actions are clamped anyway
/// (docs/design.md §2.4). A NaN bound rejects every table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PolicyBounds {
    /// Largest |weight or bias| of a head. Default 1e4 (trained heads hold values of order 1;
    /// tanh saturates long before).
    pub max_abs_weight: f64,
    /// Largest |m\[i\]| (state units). Default 1e2, as `max_abs_s_hat` of gain tables.
    pub max_abs_input_mean: f64,
    /// Input scales r\[i\] (state units) must lie in [`min_input_scale`, `max_input_scale`].
    /// Defaults 1e-6 and 1e2: a smaller scale multiplies a state error by more than 1e6.
    pub min_input_scale: f64,
    /// See `min_input_scale`.
    pub max_input_scale: f64,
    /// Largest σ\[j\] = exp(log σ\[j\]) (action unit). Default 1e2, as `max_abs_chol`.
    pub max_std: f64,
}

impl Default for PolicyBounds {
    fn default() -> Self {
        Self {
            max_abs_weight: 1e4,
            max_abs_input_mean: 1e2,
            min_input_scale: 1e-6,
            max_input_scale: 1e2,
            max_std: 1e2,
        }
    }
}

impl PolicyBounds {
    /// Every bound finite and > 0, and min_input_scale < max_input_scale; returns the first bad
    /// key and its value.
    pub fn validate(&self) -> Result<(), (&'static str, f64)> {
        for (name, v) in [
            ("max_abs_weight", self.max_abs_weight),
            ("max_abs_input_mean", self.max_abs_input_mean),
            ("min_input_scale", self.min_input_scale),
            ("max_input_scale", self.max_input_scale),
            ("max_std", self.max_std),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err((name, v));
            }
        }
        if self.min_input_scale >= self.max_input_scale {
            return Err(("min_input_scale", self.min_input_scale));
        }
        Ok(())
    }
}

/// The action mode's code in [`PolicyTable::action_mode`].
pub fn mode_code(mode: ActionMode) -> u32 {
    match mode {
        ActionMode::GoalAngles => 0,
        ActionMode::Torque => 1,
    }
}

/// The arm model's code in [`PolicyTable::model`]: 1 + its place in [`UrModel::ALL`].
pub fn model_code(model: UrModel) -> u32 {
    UrModel::ALL
        .iter()
        .position(|m| *m == model)
        .map_or(0, |i| i as u32 + 1)
}

const HASHED_HEADER_BYTES: usize = 8 + 4 * 4 + 4 * MAX_HIDDEN_LAYERS + 4 + 4;

// SAFETY: repr(C), integers and f64 only (the size assertion above: no padding).
unsafe impl Table for PolicyTable {
    type Header = [u8; HASHED_HEADER_BYTES];

    fn hashed_header(&self) -> Self::Header {
        let h = HeaderBytes::new()
            .u64(self.version)
            .u32(self.dx)
            .u32(self.du)
            .u32(self.action_mode)
            .u32(self.n_hidden);
        self.hidden
            .iter()
            .fold(h, |h, &w| h.u32(w))
            .u32(self.n_params)
            .u32(self.model)
            .finish()
    }

    /// θ (`params[..n_params]`).
    fn hashed_values(&self) -> &[f64] {
        self.theta()
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

/// Scratch memory of [`policy_action`]: two layer buffers of [`MAX_WIDTH`] (4 KB, no heap).
#[derive(Clone, Debug)]
pub struct PolicyScratch {
    x: [f64; MAX_WIDTH],
    y: [f64; MAX_WIDTH],
}

impl Default for PolicyScratch {
    fn default() -> Self {
        Self {
            x: [0.0; MAX_WIDTH],
            y: [0.0; MAX_WIDTH],
        }
    }
}

impl PolicyTable {
    /// A zeroed table on the heap with the reaching task's `dx`, `du` (it does not validate
    /// until filled).
    pub fn new_boxed() -> Box<PolicyTable> {
        table::new_boxed()
    }

    /// Zeroes `slot` in place (e.g. a loaned iceoryx2 sample) and sets `dx`, `du`.
    pub fn init_zeroed(slot: &mut MaybeUninit<PolicyTable>) -> &mut PolicyTable {
        table::init_zeroed(slot)
    }

    /// Fills a table from hidden widths and θ (version, layout and mode as given; epoch 0 and
    /// the default episode plan) and seals it. `Err` if the widths or θ's length exceed the
    /// table's limits.
    pub fn fill(
        &mut self,
        version: u64,
        layout: &StateLayout,
        mode: ActionMode,
        hidden: &[usize],
        theta: &[f64],
    ) -> Result<(), PolicyTableError> {
        let shape = |what| PolicyTableError::BadShape { version, what };
        if hidden.is_empty() || hidden.len() > MAX_HIDDEN_LAYERS {
            return Err(shape("the number of hidden layers is outside the limits"));
        }
        if hidden.iter().any(|&h| h == 0 || h > MAX_WIDTH) {
            return Err(shape("a hidden width is outside the limits"));
        }
        let (dx, du) = (layout.dx(), layout.du());
        let expected = flat_len(dx, du, hidden);
        if expected > MAX_POLICY_PARAMS {
            return Err(shape(
                "the hidden widths need more parameters than a table holds",
            ));
        }
        if theta.len() != expected {
            return Err(PolicyTableError::WrongParamCount {
                version,
                n_params: theta.len().min(u32::MAX as usize) as u32,
                expected,
            });
        }
        self.version = version;
        self.dx = dx as u32;
        self.du = du as u32;
        self.action_mode = mode_code(mode);
        self.n_hidden = hidden.len() as u32;
        self.hidden = [0; MAX_HIDDEN_LAYERS];
        for (w, &h) in self.hidden.iter_mut().zip(hidden) {
            *w = h as u32;
        }
        self.n_params = expected as u32;
        self.epoch = 0;
        self.model = 0;
        self.reserved = 0;
        self.plan = EpisodePlan::default();
        self.params[..expected].copy_from_slice(theta);
        self.params[expected..].fill(0.0);
        self.seal();
        Ok(())
    }

    /// Copies `src` into `self` (one memcpy of the used part and the header; no allocation).
    pub fn copy_from(&mut self, src: &PolicyTable) {
        let n = (src.n_params as usize).min(MAX_POLICY_PARAMS);
        let header = core::mem::offset_of!(PolicyTable, params);
        table::copy_prefix(self, src, header + 8 * n);
    }

    /// The arm model the table states (`None`: not stated, or a code of no model).
    pub fn arm_model(&self) -> Option<UrModel> {
        (self.model as usize)
            .checked_sub(1)
            .and_then(|i| UrModel::ALL.get(i).copied())
    }

    /// States the arm model the policy was trained on and seals the table again.
    pub fn set_arm_model(&mut self, model: UrModel) {
        self.model = model_code(model);
        self.seal();
    }

    /// The action mode, if the code is valid.
    pub fn mode(&self) -> Option<ActionMode> {
        match self.action_mode {
            0 => Some(ActionMode::GoalAngles),
            1 => Some(ActionMode::Torque),
            _ => None,
        }
    }

    /// The hidden widths (call after [`Self::validate`]; clamped to the limits otherwise).
    pub fn hidden_widths(&self) -> impl Iterator<Item = usize> + '_ {
        self.hidden[..(self.n_hidden as usize).min(MAX_HIDDEN_LAYERS)]
            .iter()
            .map(|&h| h as usize)
    }

    /// The dimensions (dX, dU) as usize.
    pub fn dims(&self) -> (usize, usize) {
        (self.dx as usize, self.du as usize)
    }

    /// `Ok` if the table's dimensions are `layout`'s; otherwise the mismatch, naming both.
    pub fn check_layout(&self, layout: &StateLayout) -> Result<(), DimensionMismatch> {
        layout.check_dims("policy table", self.dx as usize, self.du as usize)
    }

    fn head_len(&self) -> usize {
        let mut prev = self.dx as usize;
        let mut n = 0;
        for h in self.hidden_widths().chain([1]) {
            n += prev * h + h;
            prev = h;
        }
        n
    }

    /// θ as stored (`params[..n_params]`, clamped to the table).
    pub fn theta(&self) -> &[f64] {
        &self.params[..(self.n_params as usize).min(MAX_POLICY_PARAMS)]
    }

    /// Checksum of the current contents (module docs).
    pub fn compute_checksum(&self) -> u64 {
        table::compute_checksum(self)
    }

    /// Stores the checksum of the current contents.
    pub fn seal(&mut self) {
        table::seal(self)
    }

    /// The part of θ that index `flat` belongs to.
    fn entry(&self, flat: usize) -> PolicyEntry {
        let head = self.head_len();
        let (dx, du) = self.dims();
        let (part, index) = if flat < dx {
            (PolicyPart::InputMean, flat)
        } else if flat < 2 * dx {
            (PolicyPart::InputScale, flat - dx)
        } else if flat < 2 * dx + du * head {
            let k = flat - 2 * dx;
            (PolicyPart::Head(k / head), k % head)
        } else {
            (PolicyPart::LogStd, flat - 2 * dx - du * head)
        };
        PolicyEntry { part, index, flat }
    }

    /// Checks the table before use: dimensions, shape (layers, widths, parameter count), action
    /// mode, checksum, every value finite, then [`PolicyBounds`]. Returns the first problem.
    /// Allocation-free.
    pub fn validate(&self, bounds: &PolicyBounds) -> Result<(), PolicyTableError> {
        let version = self.version;
        let (dx, du) = self.dims();
        if StateLayout::from_dims(dx, du).is_none() {
            return Err(PolicyTableError::WrongDimensions {
                dx: self.dx,
                du: self.du,
            });
        }
        let shape = |what| Err(PolicyTableError::BadShape { version, what });
        let n_hidden = self.n_hidden as usize;
        if n_hidden == 0 || n_hidden > MAX_HIDDEN_LAYERS {
            return shape("n_hidden is outside the limits");
        }
        if self.hidden[..n_hidden]
            .iter()
            .any(|&h| h == 0 || h as usize > MAX_WIDTH)
        {
            return shape("a hidden width is outside the limits");
        }
        if self.hidden[n_hidden..].iter().any(|&h| h != 0) {
            return shape("a hidden width after n_hidden is not 0");
        }
        let expected = 2 * dx + du * self.head_len() + du;
        if expected > MAX_POLICY_PARAMS {
            return shape("the hidden widths need more parameters than a table holds");
        }
        if self.n_params as usize != expected {
            return Err(PolicyTableError::WrongParamCount {
                version,
                n_params: self.n_params,
                expected,
            });
        }
        if self.model != 0 && self.arm_model().is_none() {
            return shape("model is the code of no arm model");
        }
        if self.mode().is_none() {
            return Err(PolicyTableError::BadActionMode {
                version,
                mode: self.action_mode,
            });
        }
        let computed = self.compute_checksum();
        if computed != self.checksum {
            return Err(PolicyTableError::ChecksumMismatch {
                version,
                stored: self.checksum,
                computed,
            });
        }
        self.plan
            .validate()
            .map_err(|source| PolicyTableError::Plan { version, source })?;
        let theta = self.theta();
        if let Some(i) = theta.iter().position(|v| !v.is_finite()) {
            return Err(PolicyTableError::NonFinite {
                entry: self.entry(i),
                value: theta[i],
            });
        }
        let log_std_start = expected - du;
        for (i, &value) in theta.iter().enumerate() {
            // Written so that a NaN bound rejects.
            let (ok, bound_name, bound) = if i < dx {
                let b = bounds.max_abs_input_mean;
                (value.abs() <= b, "max_abs_input_mean", b)
            } else if i < 2 * dx {
                let ok = value >= bounds.min_input_scale && value <= bounds.max_input_scale;
                if value < bounds.min_input_scale {
                    (ok, "min_input_scale", bounds.min_input_scale)
                } else {
                    (ok, "max_input_scale", bounds.max_input_scale)
                }
            } else if i < log_std_start {
                let b = bounds.max_abs_weight;
                (value.abs() <= b, "max_abs_weight", b)
            } else {
                let b = bounds.max_std;
                (value.exp() <= b, "max_std (as exp(log_std))", b)
            };
            if !ok {
                return Err(PolicyTableError::OutOfBounds {
                    entry: self.entry(i),
                    value,
                    bound_name,
                    bound,
                });
            }
        }
        Ok(())
    }
}

/// Writes a = b(s) + μ(u(s)) + σ ⊙ ε into `a` (module docs), for a table that passed
/// [`PolicyTable::validate`]. `s`: the state, dX entries (the table's task's layout,
/// [`crate::layout::StateLayout`]); `eps`: standard-normal noise, at least dU entries,
/// [`crate::NO_NOISE`] for the mean; `a`: dU entries; `scratch`: layer buffers. Pure apart from
/// `scratch`, allocation-free, no panics for a validated table; arrays of other sizes are an
/// error and leave `a` alone. The caller clamps `a` as for gain tables (docs/design.md §2.4).
///
/// Operation order is that of the learner's `GlobalPolicy::mean_action` plus `σ ε` (the same
/// [`crate::kernels`]), so both give the same bits (tested in `imitation`).
pub fn policy_action(
    table: &PolicyTable,
    s: &[f64],
    eps: &[f64],
    scratch: &mut PolicyScratch,
    a: &mut [f64],
) -> Result<(), LawError> {
    let (dx, du) = table.dims();
    crate::law::check_arrays(dx, du, s, eps, a)?;
    let theta = table.theta();
    let (m, rest) = theta.split_at(dx);
    let (r, heads) = rest.split_at(dx);
    let head = table.head_len();
    let mut u = [0.0; MAX_DX];
    let u = &mut u[..dx];
    for i in 0..dx {
        u[i] = (s[i] - m[i]) / r[i];
    }
    let goal_angles = table.action_mode == 0;
    for j in 0..du {
        let mut w = &heads[j * head..(j + 1) * head];
        // The two buffers trade roles by swapping the references, not their 2 KB contents.
        let (mut x, mut y) = (&mut scratch.x, &mut scratch.y);
        x[..dx].copy_from_slice(u);
        let mut n_in = dx;
        for h in table.hidden_widths() {
            let (wl, rest) = w.split_at(h * n_in);
            let (bl, rest) = rest.split_at(h);
            affine(wl, bl, &x[..n_in], &mut y[..h]);
            tanh_in_place(&mut y[..h]);
            core::mem::swap(&mut x, &mut y);
            n_in = h;
            w = rest;
        }
        let mu = dot(&w[..n_in], &x[..n_in]) + w[n_in];
        // The joint angles open every layout: s[q] = s[0..dU].
        let base = if goal_angles { s[j] } else { 0.0 };
        let log_std = heads[du * head + j];
        a[j] = (base + mu) + log_std.exp() * eps[j];
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::layout::{DU, DX};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random valid table (weights in ±0.5, identity-like normalisation, σ = 0.1).
    pub(crate) fn random_policy(seed: u64, hidden: &[usize]) -> Box<PolicyTable> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = flat_len(DX, DU, hidden);
        let mut theta: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..0.5)).collect();
        for v in &mut theta[DX..2 * DX] {
            *v = rng.random_range(0.5..2.0);
        }
        for v in &mut theta[n - DU..] {
            *v = 0.1f64.ln();
        }
        let mut p = PolicyTable::new_boxed();
        p.fill(
            seed + 1,
            &StateLayout::REACH3,
            ActionMode::GoalAngles,
            hidden,
            &theta,
        )
        .unwrap();
        p
    }

    fn err_after(f: impl FnOnce(&mut PolicyTable)) -> PolicyTableError {
        let mut p = random_policy(3, &[64, 64]);
        f(&mut p);
        p.seal();
        let e = p.validate(&PolicyBounds::default()).unwrap_err();
        assert!(!e.to_string().is_empty());
        e
    }

    #[test]
    fn lengths_and_a_good_table() {
        assert_eq!(flat_len(DX, DU, &[64, 64]), 15_198);
        assert_eq!(flat_len(DX, DU, &[96, 96]), 31_998);
        assert!(flat_len(DX, DU, &[96, 96]) <= MAX_POLICY_PARAMS);
        let p = random_policy(1, &[64, 64]);
        p.validate(&PolicyBounds::default()).unwrap();
        random_policy(2, &[8])
            .validate(&PolicyBounds::default())
            .unwrap();
        random_policy(2, &[16, 8, 4, 2])
            .validate(&PolicyBounds::default())
            .unwrap();
        let mut copy = PolicyTable::new_boxed();
        copy.copy_from(&p);
        assert_eq!(copy.theta(), p.theta());
        copy.validate(&PolicyBounds::default()).unwrap();
        // `epoch` is copied and not hashed: a republication of a version keeps its checksum.
        assert_eq!(copy.epoch, 0);
        copy.epoch = 7;
        assert_eq!(copy.compute_checksum(), p.checksum);
        copy.validate(&PolicyBounds::default()).unwrap();
        let mut again = PolicyTable::new_boxed();
        again.copy_from(&copy);
        assert_eq!(again.epoch, 7);
        again.validate(&PolicyBounds::default()).unwrap();
    }

    #[test]
    fn rejects_each_class_with_a_message_naming_it() {
        assert!(matches!(
            err_after(|p| p.dx = 13),
            PolicyTableError::WrongDimensions { dx: 13, .. }
        ));
        let e = err_after(|p| p.n_hidden = 5);
        assert!(e.to_string().contains("n_hidden"), "{e}");
        let e = err_after(|p| p.hidden[1] = 1000);
        assert!(e.to_string().contains("hidden width"), "{e}");
        let e = err_after(|p| p.hidden[3] = 7);
        assert!(e.to_string().contains("after n_hidden"), "{e}");
        let e = err_after(|p| p.n_params += 1);
        assert!(e.to_string().contains("n_params = 15199"), "{e}");
        let e = err_after(|p| p.n_params = u32::MAX);
        assert!(matches!(e, PolicyTableError::WrongParamCount { .. }), "{e}");
        assert!(matches!(
            err_after(|p| p.action_mode = 2),
            PolicyTableError::BadActionMode { mode: 2, .. }
        ));
        let e = err_after(|p| p.params[30] = f64::NAN);
        assert!(e.to_string().contains("head 0 parameter 6 (θ[30])"), "{e}");
        let e = err_after(|p| p.params[DX + 3] = 0.0);
        assert!(
            e.to_string().contains("r[3]") && e.to_string().contains("min_input_scale"),
            "{e}"
        );
        let e = err_after(|p| p.params[5] = 1e3);
        assert!(e.to_string().contains("m[5]"), "{e}");
        let e = err_after(|p| p.params[100] = 2e4);
        assert!(e.to_string().contains("max_abs_weight"), "{e}");
        let e = err_after(|p| p.params[15_197] = 10.0);
        assert!(
            e.to_string().contains("log_std[2]") && e.to_string().contains("max_std"),
            "{e}"
        );
        // A change after sealing.
        let mut p = random_policy(3, &[64, 64]);
        p.params[7] += 1e-9;
        assert!(matches!(
            p.validate(&PolicyBounds::default()),
            Err(PolicyTableError::ChecksumMismatch { .. })
        ));
        // A NaN bound rejects.
        let p = random_policy(3, &[64, 64]);
        let nan = PolicyBounds {
            max_abs_weight: f64::NAN,
            ..Default::default()
        };
        assert!(p.validate(&nan).is_err());
        assert!(nan.validate().is_err());
        assert!(PolicyBounds::default().validate().is_ok());
    }

    #[test]
    fn the_action_is_the_documented_law() {
        // One hidden layer of 2 written out by hand.
        let hidden = [2usize];
        let mut theta = vec![0.0; flat_len(DX, DU, &hidden)];
        for i in 0..DX {
            theta[i] = 0.1 * i as f64; // m
            theta[DX + i] = 2.0; // r
        }
        let head = head_len(DX, &hidden);
        assert_eq!(head, 2 * DX + 2 + 2 + 1);
        for j in 0..DU {
            let h = &mut theta[2 * DX + j * head..2 * DX + (j + 1) * head];
            h[0] = 1.0 + j as f64; // W0[0][0]
            h[DX + 1] = -0.5; // W0[1][1]
            h[2 * DX] = 0.25; // b0[0]
            h[2 * DX + 2] = 2.0; // W1[0]
            h[2 * DX + 3] = -1.0; // W1[1]
            h[2 * DX + 4] = 0.125; // b1
        }
        let n = theta.len();
        theta[n - DU..].copy_from_slice(&[0.0, 0.5f64.ln(), 2.0f64.ln()]);
        let mut p = PolicyTable::new_boxed();
        p.fill(
            9,
            &StateLayout::REACH3,
            ActionMode::GoalAngles,
            &hidden,
            &theta,
        )
        .unwrap();
        p.validate(&PolicyBounds::default()).unwrap();
        let s: [f64; DX] = core::array::from_fn(|i| 0.3 - 0.07 * i as f64);
        let eps = [1.0, -2.0, 0.5];
        let mut a = [0.0; DU];
        policy_action(&p, &s, &eps, &mut PolicyScratch::default(), &mut a).unwrap();
        let u: Vec<f64> = (0..DX).map(|i| (s[i] - 0.1 * i as f64) / 2.0).collect();
        let std = [1.0, 0.5, 2.0];
        for j in 0..DU {
            let z0 = ((1.0 + j as f64) * u[0] + 0.25).tanh();
            let z1 = (-0.5 * u[1]).tanh();
            let mu = 2.0 * z0 - z1 + 0.125;
            let want = s[j] + mu + std[j] * eps[j];
            assert!((a[j] - want).abs() < 1e-14, "j={j}: {} vs {want}", a[j]);
        }
        // Torque mode drops the q base.
        p.action_mode = 1;
        p.seal();
        let mut b = [0.0; DU];
        policy_action(&p, &s, &eps, &mut PolicyScratch::default(), &mut b).unwrap();
        for j in 0..DU {
            assert!((a[j] - s[j] - b[j]).abs() < 1e-14);
        }
    }

    /// The whole arm and a pose (dX = 30, dU = 6): heads with zero output layers give
    /// a = q + σ ε on all six joints; arrays of the reaching task's sizes are refused.
    #[test]
    fn any_layout_acts_on_its_own_dimensions() {
        let layout = StateLayout::POSE6;
        let (dx, du) = (layout.dx(), layout.du());
        let hidden = [4usize];
        let n = flat_len(dx, du, &hidden);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut theta: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..0.5)).collect();
        theta[dx..2 * dx].fill(1.0);
        let head = head_len(dx, &hidden);
        for j in 0..du {
            // The output layer (4 weights and the bias) at the end of each head: zero.
            let end = 2 * dx + (j + 1) * head;
            theta[end - 5..end].fill(0.0);
        }
        theta[n - du..].fill(0.5f64.ln());
        let mut p = PolicyTable::new_boxed();
        p.fill(1, &layout, ActionMode::GoalAngles, &hidden, &theta)
            .unwrap();
        p.validate(&PolicyBounds::default()).unwrap();
        assert_eq!(p.dims(), (30, 6));
        p.check_layout(&layout).unwrap();
        assert!(p.check_layout(&StateLayout::REACH3).is_err());
        let s: Vec<f64> = (0..dx).map(|i| 0.01 * i as f64).collect();
        let eps = [1.0, -1.0, 2.0, 0.0, 0.5, -0.5];
        let mut a = [0.0; 6];
        policy_action(&p, &s, &eps, &mut PolicyScratch::default(), &mut a).unwrap();
        for j in 0..du {
            assert_eq!(a[j], s[j] + 0.5 * eps[j], "joint {j}");
        }
        let mut a3 = [0.0; 3];
        assert!(policy_action(&p, &s[..12], &eps, &mut PolicyScratch::default(), &mut a3).is_err());
    }
}
