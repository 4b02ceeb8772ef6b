//! The discriminator of LQR+GAIfO (Torabi et al. 2019; docs/design.md §1.3 step 3): a WGAN-GP critic `D(s, s')` on state transitions, trained so that it is low on
//! expert transitions and can be used as a cost by the LQR step.
//!
//! - Input `x = [s; s'] ∈ R^{2 dX}` (24 for the UR5 task), one transition per row of a
//!   row-major batch.
//! - `D(x) = net((x − μ) ⊘ σ)` with `μ, σ` per input from data ([`Normalizer`]; LQR+GAIfO and
//!   GAIfO (PPO) fit them on expert ∪ first controller transitions, docs/design.md §5 D2) and
//!   `net` a tanh MLP with a scalar linear output ([`mlp`]). tanh, not ReLU: the LQR step
//!   needs the exact curvature `∇²ₓD`, and a ReLU net has none.
//! - Derivatives in the raw input: `∇ₓD = diag(1/σ) ∇_u net`,
//!   `∇²ₓD = diag(1/σ) ∇²_u net diag(1/σ)`.
//! - Training ([`Discriminator::train`]): Gulrajani et al. (2017) Algorithm 1, critic part,
//!   by Adam ([`adam`]), minimising
//!   `E_expert[D] − E_controller[D] + λ E_x̂[(‖∇ₓD(x̂)‖ − 1)²]`,
//!   `x̂ = ε x_expert + (1 − ε) x_controller`, `ε ~ U[0, 1]`. This sign makes D low on expert
//!   transitions, so D is a cost, and makes the Wasserstein estimate
//!   `E_controller[D] − E_expert[D]` non-negative. (The paper prints the opposite sign;
//!   why this one is right, with the measurement: docs/design.md §5 D1.)
//!
//! Model/data split as in crocoddyl: [`Discriminator`] holds parameters, normalisation, Adam
//! and RNG state; [`Workspace`] holds all scratch memory, built once per net size with
//! [`Discriminator::workspace`] and passed to every call.

pub mod adam;
mod mean_hessian;
pub mod mlp;
mod persist;
#[cfg(test)]
mod tests;

use std::path::PathBuf;

use faer::{Mat, MatMut, MatRef};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::ops::Range;

use ur5_shared::layout::{StateLayout, MAX_DX};

/// The tool-point inputs (each point's position minus its target, `StateLayout::points`) of a
/// state within a transition of `d` inputs, [s; s'] (d = 2 dX of a task,
/// `StateLayout::of_task_state`) or [s; s'; φ] with the phase (d = 2 dX + 1), and dX; `None`
/// for another `d`. The phase (input 2 dX) is never a tool point's.
fn point_inputs(d: usize) -> Option<(Range<usize>, usize)> {
    let layout = StateLayout::of_task_state(d / 2)?;
    Some((layout.points(), layout.dx()))
}

/// Inputs added by [`DiscriminatorConfig::near_goal_keep_raw`] to a transition of `d` inputs:
/// the tool-point inputs of s and of s' (six for a point goal).
fn raw_copies(d: usize) -> usize {
    point_inputs(d).map_or(0, |(p, _)| 2 * p.len())
}

/// The transition input that extra net input `k` copies: the tool-point inputs of s, then
/// those of s' (a point goal: x[6..9] then x[dX+6..dX+9]).
fn raw_copy(k: usize, d: usize) -> usize {
    let (p, dx) = point_inputs(d).expect("a task's transition");
    (k / p.len()) * dx + p.start + k % p.len()
}

/// Whether input `i` is among `points` ([`DiscriminatorConfig::warped_inputs`]): a tool
/// point's position minus its target, in s or s'.
fn warped(points: &Option<(Range<usize>, usize)>, i: usize) -> bool {
    points
        .as_ref()
        .is_some_and(|(p, dx)| i < 2 * dx && p.contains(&(i % dx)))
}

pub use adam::{Adam, AdamConfig};
pub use mean_hessian::MeanHessian;
pub use mlp::{Mlp, MlpWorkspace};

/// What went wrong in the discriminator, and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum DiscriminatorError {
    /// A configuration that cannot work.
    #[error("invalid discriminator config: {0}")]
    Config(String),
    /// Arrays whose sizes do not fit the net.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// NaN or ±inf in data, gradients or parameters.
    #[error("non-finite {0}; check the transitions fed to the discriminator")]
    NonFinite(String),
    /// The critic file could not be read or written.
    #[error("critic file {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The critic file is not JSON of the expected schema.
    #[error("critic file {path} is not a valid critic file (truncated or hand-edited?): {source}")]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    /// The critic file parsed but its contents are inconsistent.
    #[error("critic file {path}: {msg}")]
    BadFile { path: PathBuf, msg: String },
}

/// Configuration of the critic and its training; defaults follow Gulrajani et al. (2017),
/// Algorithm 1, except where noted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscriminatorConfig {
    /// Hidden layer widths (at least one layer).
    pub hidden: Vec<usize>,
    /// Gradient-penalty weight λ.
    pub lambda_gp: f64,
    /// Critic (Adam) steps per [`Discriminator::train`] call, `n_critic`.
    pub n_critic: usize,
    /// Minibatch size `m`: expert and controller samples per step, each.
    pub batch_size: usize,
    pub adam: AdamConfig,
    /// Seeds the weight initialisation and then the minibatch sampling.
    pub seed: u64,
    /// The input space in which the gradient penalty measures ‖∇D‖ (docs/design.md §5 D25).
    /// Critic files written before the field existed were trained with `raw`.
    #[serde(default)]
    pub penalty_space: PenaltySpace,
    /// Finer resolution near the goal, c (m; 0 = off, the default): the end-effector-minus-goal
    /// inputs of s and s' (x[6..9] and x[dX+6..dX+9], docs/design.md §2) enter the critic as
    /// `c·asinh(x/c)` before the normalisation: unchanged within c of the goal, logarithmic
    /// beyond, so their spread in the data, and with it the narrowest bowl a net that is
    /// 1-Lipschitz in normalised inputs can form, shrinks from the reach's decimetres towards
    /// c (docs/design.md §5 D36). Needs 2 dX inputs and `penalty_space = normalised`. Critic
    /// files written before the field existed have 0.
    #[serde(default)]
    pub near_goal_scale: f64,
    /// The slope the warp keeps far from the goal, a ∈ [0, 1) (0, the default: pure
    /// `c·asinh(x/c)`, whose slope falls as c/|x|): the warp is then
    /// `a·x + (1 − a)·c·asinh(x/c)`, so a critic of bounded slope in the warped inputs still
    /// pulls a controller that is decimetres away (docs/design.md §5 D36).
    #[serde(default)]
    pub near_goal_far_slope: f64,
    /// With [`Self::near_goal_scale`]: the six end-effector inputs also enter unwarped, as six
    /// more inputs of the net (2 dX + 6), so that the critic has both the fine resolution near
    /// the goal and the raw offset far from it (docs/design.md §5 D36). Default false.
    #[serde(default)]
    pub near_goal_keep_raw: bool,
    /// β of the running average of the weights, θ̄ ← β θ̄ + (1 − β) θ after every
    /// [`Discriminator::train`] call (θ̄ = θ after the first), β ∈ [0, 1); the averaged critic
    /// ([`Discriminator::averaged`]) is the one the learners take their cost from, so that the
    /// cost moves less between iterations than the trained critic does (docs/design.md §5
    /// D37). 0 (the default, and in critic files written before the field existed): off.
    #[serde(default)]
    pub param_average: f64,
}

/// Where the gradient penalty `λ (‖∇D(x̂)‖ − 1)²` takes the norm, and so in which metric D is
/// 1-Lipschitz and the Wasserstein distance is measured (docs/design.md §5 D25).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PenaltySpace {
    /// `‖∇ₓD‖` in the raw state units (rad, rad/s, m, m/s mixed): a metre of end-effector
    /// offset weighs as much as a rad/s of joint velocity. Gulrajani et al.'s form on
    /// unnormalised inputs.
    #[default]
    Raw,
    /// `‖∇_u D‖` in the normalised inputs `u = (x − μ) ⊘ σ`: every input in units of its own
    /// spread in the data, as when the inputs are normalised before the critic.
    Normalised,
}

impl Default for DiscriminatorConfig {
    /// - `hidden = [64, 64]`: not from a paper. Two tanh layers are the fewest that give a
    ///   curvature which is not a sum of ridge functions of the input; 64 units keep the exact
    ///   24×24 Hessian cheap (`O(h² n_0 + h n_0²)` per point, needed at every one of T = 100
    ///   steps per LQR iteration) and ~5.8k parameters do not drown 500 transitions per
    ///   iteration.
    /// - `lambda_gp = 10`, `n_critic = 5`, `batch_size = 64`, Adam(1e−4, 0, 0.9): Gulrajani et
    ///   al. (2017), Algorithm 1 ("default values").
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            lambda_gp: 10.0,
            n_critic: 5,
            batch_size: 64,
            adam: AdamConfig::default(),
            seed: 0,
            penalty_space: PenaltySpace::Raw,
            near_goal_scale: 0.0,
            near_goal_far_slope: 0.0,
            near_goal_keep_raw: false,
            param_average: 0.0,
        }
    }
}

impl DiscriminatorConfig {
    /// Largest accepted `n_critic` and `batch_size`: far above any use, low enough that a
    /// typo cannot ask for hours of steps or gigabytes of batch.
    pub const MAX_COUNT: usize = 100_000;
    /// Largest accepted hidden-layer width.
    pub const MAX_WIDTH: usize = 4096;
    /// Largest accepted number of hidden layers.
    pub const MAX_LAYERS: usize = 16;

    /// The hidden widths `h` of a net (the critic's, PPO's): 1 to [`Self::MAX_LAYERS`] layers,
    /// each 1 to [`Self::MAX_WIDTH`] units; else a message naming `name`.
    pub fn check_widths(name: &str, h: &[usize]) -> Result<(), String> {
        if h.is_empty()
            || h.len() > Self::MAX_LAYERS
            || h.iter().any(|&w| w == 0 || w > Self::MAX_WIDTH)
        {
            return Err(format!(
                "{name} = {h:?}: must list 1..={} widths, each in 1..={}",
                Self::MAX_LAYERS,
                Self::MAX_WIDTH
            ));
        }
        Ok(())
    }

    /// Checks that the config can build and train a net (and does not ask for an allocation
    /// that would abort the process).
    pub fn validate(&self) -> Result<(), DiscriminatorError> {
        let bad = |m: String| Err(DiscriminatorError::Config(m));
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return bad(format!(
                "hidden must list at least one non-zero width (a linear critic has no \
                 curvature for the LQR step); got {:?}",
                self.hidden
            ));
        }
        Self::check_widths("hidden", &self.hidden).map_err(DiscriminatorError::Config)?;
        if !(self.lambda_gp.is_finite() && self.lambda_gp >= 0.0) {
            return bad(format!(
                "lambda_gp must be finite and >= 0; got {}",
                self.lambda_gp
            ));
        }
        let count = |n: usize| (1..=Self::MAX_COUNT).contains(&n);
        if !count(self.n_critic) || !count(self.batch_size) {
            return bad(format!(
                "n_critic/batch_size = ({}, {}): must be in 1..={}",
                self.n_critic,
                self.batch_size,
                Self::MAX_COUNT
            ));
        }
        if !(self.near_goal_scale.is_finite() && self.near_goal_scale >= 0.0) {
            return bad(format!(
                "near_goal_scale must be finite and >= 0 (m; 0 = off); got {}",
                self.near_goal_scale
            ));
        }
        if !(0.0..1.0).contains(&self.near_goal_far_slope) {
            return bad(format!(
                "near_goal_far_slope must be in [0, 1); got {}",
                self.near_goal_far_slope
            ));
        }
        if !(0.0..1.0).contains(&self.param_average) {
            return bad(format!(
                "param_average must be in [0, 1) (0 = off); got {}",
                self.param_average
            ));
        }
        if self.near_goal_keep_raw && self.near_goal_scale == 0.0 {
            return bad("near_goal_keep_raw needs near_goal_scale > 0".into());
        }
        if self.near_goal_scale > 0.0 && self.penalty_space != PenaltySpace::Normalised {
            return bad(
                "near_goal_scale > 0 needs penalty_space = \"normalised\" (the penalty then \
                 holds in the warped inputs); with the raw penalty set near_goal_scale = 0"
                    .into(),
            );
        }
        self.adam.validate().map_err(DiscriminatorError::Config)
    }

    /// Whether input `i` of a transition of `d` = 2 dX inputs is one that
    /// [`Self::near_goal_scale`] warps: a tool point's position minus its target, in s or s'.
    fn warps(&self, i: usize, d: usize) -> bool {
        warped(&self.warped_inputs(d), i)
    }

    /// The tool-point inputs and dX of a transition of `d` inputs when
    /// [`Self::near_goal_scale`] warps them ([`warped`] tells input by input); `None` when
    /// nothing is warped.
    fn warped_inputs(&self, d: usize) -> Option<(Range<usize>, usize)> {
        (self.near_goal_scale > 0.0)
            .then(|| point_inputs(d))
            .flatten()
    }

    /// Input `i` of a transition of `d` inputs as the critic sees it before the normalisation:
    /// `x`, or `g(x) = a·x + (1 − a)·c·asinh(x/c)` (c = [`Self::near_goal_scale`],
    /// a = [`Self::near_goal_far_slope`]) for the inputs it warps.
    pub fn warp(&self, i: usize, d: usize, x: f64) -> f64 {
        self.warp_in(&self.warped_inputs(d), i, x)
    }

    /// [`Self::warp`] with the warped inputs found once ([`Self::warped_inputs`]).
    fn warp_in(&self, points: &Option<(Range<usize>, usize)>, i: usize, x: f64) -> f64 {
        if warped(points, i) {
            let (c, a) = (self.near_goal_scale, self.near_goal_far_slope);
            a * x + (1.0 - a) * c * (x / c).asinh()
        } else {
            x
        }
    }

    /// `(g'(x), g''(x))` of [`Self::warp`] `g` at input `i`: `(1, 0)` where it is the identity;
    /// else, with r = x/c, `g' = a + (1 − a)/√(1 + r²)` and
    /// `g'' = −(1 − a) r/(c (1 + r²)^{3/2})`.
    fn warp_derivatives(&self, i: usize, d: usize, x: f64) -> (f64, f64) {
        if self.warps(i, d) {
            let (c, a) = (self.near_goal_scale, self.near_goal_far_slope);
            let r = x / c;
            let q = 1.0 + r * r;
            (
                a + (1.0 - a) / q.sqrt(),
                -(1.0 - a) * r / (c * q * q.sqrt()),
            )
        } else {
            (1.0, 0.0)
        }
    }

    /// The rows of `x` (`n × d`) through [`Self::warp`], followed by the raw copies of
    /// [`Self::near_goal_keep_raw`] (`n × net_inputs(d)`): what the input normalisation is
    /// fitted on.
    pub fn warp_rows(&self, x: MatRef<'_, f64>) -> Mat<f64> {
        let d = x.ncols();
        Mat::from_fn(x.nrows(), self.net_inputs(d), |r, c| {
            if c < d {
                self.warp(c, d, x[(r, c)])
            } else {
                x[(r, raw_copy(c - d, d))]
            }
        })
    }

    /// The net's inputs for `d` transition inputs: `d`, plus the tool-point inputs of s and s'
    /// again with [`Self::near_goal_keep_raw`] (six for a point goal).
    pub fn net_inputs(&self, d: usize) -> usize {
        if self.near_goal_keep_raw {
            d + raw_copies(d)
        } else {
            d
        }
    }

    /// Layer sizes `[d_in, hidden..., 1]`.
    pub fn sizes(&self, d_in: usize) -> Vec<usize> {
        let mut s = Vec::with_capacity(self.hidden.len() + 2);
        s.push(d_in);
        s.extend_from_slice(&self.hidden);
        s.push(1);
        s
    }
}

/// Per-input affine normalisation `u = (x − μ) ⊘ σ`, fitted to the expert transitions.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalizer {
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
}

impl Normalizer {
    /// An input whose expert standard deviation is below this (state units) is constant for
    /// the expert; it is only centred (σ = 1), otherwise any controller deviation along it
    /// would be blown up by 1/σ and saturate the tanh units.
    pub const MIN_STD: f64 = 1e-6;

    /// `μ = 0`, `σ = 1`.
    pub fn identity(d: usize) -> Self {
        Self {
            mean: vec![0.0; d],
            std: vec![1.0; d],
        }
    }

    /// Column means and population standard deviations of `x` (`n × d`, one sample per row),
    /// σ replaced by 1 where it is below [`Self::MIN_STD`].
    pub fn from_data(x: MatRef<'_, f64>) -> Result<Self, DiscriminatorError> {
        let (n, d) = (x.nrows(), x.ncols());
        if n == 0 {
            return Err(DiscriminatorError::Shape(
                "cannot fit the input normalisation to zero samples".into(),
            ));
        }
        check_finite(x, "expert data")?;
        let mut mean = vec![0.0; d];
        let mut var = vec![0.0; d];
        for i in 0..n {
            for (j, m) in mean.iter_mut().enumerate() {
                *m += x[(i, j)];
            }
        }
        for m in &mut mean {
            *m /= n as f64;
        }
        for i in 0..n {
            for (j, v) in var.iter_mut().enumerate() {
                let e = x[(i, j)] - mean[j];
                *v += e * e;
            }
        }
        let std = var
            .iter()
            .map(|v| {
                let s = (v / n as f64).sqrt();
                if s >= Self::MIN_STD {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        Ok(Self { mean, std })
    }

    fn validate(&self, d: usize) -> Result<(), String> {
        if self.mean.len() != d || self.std.len() != d {
            return Err(format!(
                "normalisation has {} means and {} stds for {d} inputs",
                self.mean.len(),
                self.std.len()
            ));
        }
        if let Some(i) = self.mean.iter().position(|m| !m.is_finite()) {
            return Err(format!(
                "normalisation mean (norm_mean[{i}]) = {} is not finite",
                self.mean[i]
            ));
        }
        if let Some(i) = self.std.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(format!(
                "normalisation std (norm_std[{i}]) = {} must be finite and > 0",
                self.std[i]
            ));
        }
        Ok(())
    }
}

/// Scratch memory for one net size ([`Discriminator::workspace`]).
#[derive(Clone, Debug)]
pub struct Workspace {
    mlp: MlpWorkspace,
    /// Gradient accumulator over `θ`.
    grad: Vec<f64>,
    /// Raw input rows: expert, controller, interpolate.
    x_e: Vec<f64>,
    x_c: Vec<f64>,
    x_hat: Vec<f64>,
    /// `∇²_u net`, row-major `d × d`.
    hess_u: Vec<f64>,
}

/// What one [`Discriminator::train`] call did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainStats {
    /// Mean over the `n_critic` steps of the minibatch loss
    /// `mean D(x_e) − mean D(x_c) + λ mean (‖∇D(x̂)‖ − 1)²`, each at the weights before its step.
    pub critic_loss: f64,
    /// The penalty term of `critic_loss` (same averaging).
    pub gradient_penalty: f64,
    /// `E_controller[D] − E_expert[D]` over all the given transitions after the last step:
    /// the critic's estimate of the Wasserstein-1 distance (≥ 0 when it separates them).
    pub wasserstein: f64,
}

/// The WGAN-GP critic `D(x)`, its normalisation, Adam state and minibatch RNG.
#[derive(Clone, Debug)]
pub struct Discriminator {
    config: DiscriminatorConfig,
    net: Mlp,
    norm: Normalizer,
    adam: Adam,
    rng: ChaCha8Rng,
    /// θ̄, the running average of the weights ([`DiscriminatorConfig::param_average`]); empty
    /// when that is off or before the first [`Discriminator::train`] call.
    avg: Vec<f64>,
    /// Transition inputs d (2 dX); the net has [`DiscriminatorConfig::net_inputs`]`(d)`.
    d_in: usize,
}

impl Discriminator {
    /// A fresh critic for `d_in` inputs: Glorot-uniform weights from `ChaCha8(config.seed)`,
    /// which then goes on to draw the minibatches.
    pub fn new(
        d_in: usize,
        config: DiscriminatorConfig,
        norm: Normalizer,
    ) -> Result<Self, DiscriminatorError> {
        config.validate()?;
        if d_in == 0 {
            return Err(DiscriminatorError::Config("input dimension is 0".into()));
        }
        if config.near_goal_scale > 0.0 && point_inputs(d_in).is_none() {
            return Err(DiscriminatorError::Config(format!(
                "near_goal_scale warps the tool points of transitions [s; s'] of a task (24, 36 \
                 or 60 inputs); this critic has {d_in}"
            )));
        }
        norm.validate(config.net_inputs(d_in))
            .map_err(DiscriminatorError::Shape)?;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let net = Mlp::glorot(&config.sizes(config.net_inputs(d_in)), &mut rng);
        let adam = Adam::new(config.adam, net.params().len());
        Ok(Self {
            config,
            net,
            norm,
            adam,
            rng,
            avg: Vec::new(),
            d_in,
        })
    }

    /// Scratch memory for this net's size; reuse it for every call.
    pub fn workspace(&self) -> Workspace {
        let (d, dn) = (self.input_dim(), self.net.input_dim());
        Workspace {
            mlp: MlpWorkspace::new(self.net.sizes()),
            grad: vec![0.0; self.net.params().len()],
            x_e: vec![0.0; d],
            x_c: vec![0.0; d],
            x_hat: vec![0.0; d],
            hess_u: vec![0.0; dn * dn],
        }
    }

    /// Input dimension `2 dX` (the transition; the net may see six more,
    /// [`DiscriminatorConfig::near_goal_keep_raw`]).
    pub fn input_dim(&self) -> usize {
        self.d_in
    }

    /// The net's inputs beyond the transition's.
    fn extra_inputs(&self) -> usize {
        self.net.input_dim() - self.d_in
    }

    pub fn config(&self) -> &DiscriminatorConfig {
        &self.config
    }

    pub fn normalizer(&self) -> &Normalizer {
        &self.norm
    }

    pub fn net(&self) -> &Mlp {
        &self.net
    }

    pub fn adam(&self) -> &Adam {
        &self.adam
    }

    /// Sets the Adam learning rate of the next steps (a schedule over iterations; the
    /// configured `config().adam.lr` stays the base rate). Must be finite and > 0.
    pub fn set_learning_rate(&mut self, lr: f64) -> Result<(), DiscriminatorError> {
        if !(lr.is_finite() && lr > 0.0) {
            return Err(DiscriminatorError::Config(format!(
                "the critic's learning rate must be finite and > 0; got {lr}"
            )));
        }
        self.adam.config.lr = lr;
        Ok(())
    }

    /// The flat parameter vector `θ` (layout: [`mlp`]).
    pub fn params(&self) -> &[f64] {
        self.net.params()
    }

    /// θ̄, the running average of the weights (empty when
    /// [`DiscriminatorConfig::param_average`] is 0 or before the first training call).
    pub fn param_average(&self) -> &[f64] {
        &self.avg
    }

    /// The critic with the averaged weights θ̄ in place of θ (the cost's critic,
    /// docs/design.md §5 D37); `None` when averaging is off or nothing is trained yet.
    pub fn averaged(&self) -> Option<Discriminator> {
        if self.avg.is_empty() {
            return None;
        }
        let mut d = self.clone();
        d.net.params_mut().copy_from_slice(&self.avg);
        d.avg.clear();
        Some(d)
    }

    /// θ̄ ← β θ̄ + (1 − β) θ, or θ̄ = θ the first time (β = `param_average` > 0).
    fn update_average(&mut self) {
        let beta = self.config.param_average;
        if beta == 0.0 {
            return;
        }
        let theta = self.net.params();
        if self.avg.is_empty() {
            self.avg.extend_from_slice(theta);
        } else {
            for (a, &t) in self.avg.iter_mut().zip(theta) {
                *a = beta * *a + (1.0 - beta) * t;
            }
        }
    }

    /// Mutable `θ` (for tests and external optimisers).
    pub fn params_mut(&mut self) -> &mut [f64] {
        self.net.params_mut()
    }

    fn check_ws(&self, ws: &Workspace) {
        assert!(
            ws.mlp.sizes() == self.net.sizes(),
            "workspace built for {:?}, net is {:?}",
            ws.mlp.sizes(),
            self.net.sizes()
        );
    }

    /// Normalises `x` into the net's input buffer and runs the forward pass.
    fn forward_raw(&self, x: &[f64], mlp_ws: &mut MlpWorkspace) -> f64 {
        assert_eq!(x.len(), self.input_dim(), "input length");
        let d = x.len();
        let points = self.config.warped_inputs(d);
        for (i, (((u, &xi), &m), &s)) in mlp_ws
            .u
            .iter_mut()
            .zip(x)
            .zip(&self.norm.mean)
            .zip(&self.norm.std)
            .enumerate()
        {
            *u = (self.config.warp_in(&points, i, xi) - m) / s;
        }
        for k in 0..self.extra_inputs() {
            mlp_ws.u[d + k] = (x[raw_copy(k, d)] - self.norm.mean[d + k]) / self.norm.std[d + k];
        }
        self.net.forward(mlp_ws)
    }

    /// `D(x)` for one transition `x = [s; s']`.
    pub fn value(&self, x: &[f64], ws: &mut Workspace) -> f64 {
        self.check_ws(ws);
        self.forward_raw(x, &mut ws.mlp)
    }

    /// `D(x)`, and `∇ₓD(x) = diag(g'/σ) ∇_u net` into `grad` (length `d`; g' = 1 but for the
    /// inputs [`DiscriminatorConfig::near_goal_scale`] warps).
    pub fn value_gradient(&self, x: &[f64], ws: &mut Workspace, grad: &mut [f64]) -> f64 {
        self.check_ws(ws);
        assert_eq!(grad.len(), self.input_dim(), "gradient length");
        let y = self.forward_raw(x, &mut ws.mlp);
        self.net.backward(&mut ws.mlp, true);
        for ((g, &gu), &s) in grad.iter_mut().zip(&ws.mlp.grad_u).zip(&self.norm.std) {
            *g = gu / s;
        }
        let d = x.len();
        if self.config.near_goal_scale > 0.0 {
            for (i, g) in grad.iter_mut().enumerate() {
                *g *= self.config.warp_derivatives(i, d, x[i]).0;
            }
        }
        for k in 0..self.extra_inputs() {
            grad[raw_copy(k, d)] += ws.mlp.grad_u[d + k] / self.norm.std[d + k];
        }
        y
    }

    /// `D(x)`, `∇ₓD(x)` into `grad` (`d`) and the exact
    /// `∇²ₓD(x) = diag(1/σ) ∇²_u net diag(1/σ)` (with the chain rule through
    /// [`DiscriminatorConfig::warp`] where it warps) into `hess` (`d × d`, symmetric): what the
    /// second-order expansion of the composite cost needs (docs/design.md §1.3 step 5).
    pub fn value_gradient_hessian(
        &self,
        x: &[f64],
        ws: &mut Workspace,
        grad: &mut [f64],
        mut hess: MatMut<'_, f64>,
    ) -> f64 {
        let d = self.input_dim();
        assert!(
            hess.nrows() == d && hess.ncols() == d,
            "Hessian must be d x d"
        );
        let y = self.value_gradient(x, ws, grad);
        self.net.input_hessian(&mut ws.mlp, &mut ws.hess_u);
        if self.extra_inputs() > 0 {
            self.hessian_with_raw_copies(x, ws, hess);
            return y;
        }
        let s = &self.norm.std;
        // Column by column (faer's storage order); the same quotient per entry.
        for q in 0..d {
            for p in 0..d {
                hess[(p, q)] = ws.hess_u[p * d + q] / (s[p] * s[q]);
            }
        }
        if self.config.near_goal_scale > 0.0 {
            // x ↦ g(x) elementwise: ∇²ₓD = diag(g') H diag(g') + diag(∂D/∂g ⊙ g'').
            // d = 2 dX of a task here (checked at construction).
            let mut g1 = [1.0; 2 * MAX_DX];
            let mut g2 = [0.0; 2 * MAX_DX];
            for p in 0..d {
                (g1[p], g2[p]) = self.config.warp_derivatives(p, d, x[p]);
            }
            for p in 0..d {
                for q in 0..d {
                    hess[(p, q)] *= g1[p] * g1[q];
                }
                hess[(p, p)] += ws.mlp.grad_u[p] / s[p] * g2[p];
            }
        }
        y
    }

    /// `∇²ₓD` when the net also sees raw copies of the end-effector inputs: with J the
    /// Jacobian of the net's inputs u(x) (u_p = (g(x_p) − μ_p)/σ_p, u_{d+k} = (x_{c(k)} −
    /// μ_{d+k})/σ_{d+k}), `Jᵀ ∇²_u net J + diag(∂D/∂u_p g''_p/σ_p)`; each entry summed once and
    /// mirrored, so the result is symmetric bit for bit. `ws.hess_u` holds ∇²_u net.
    fn hessian_with_raw_copies(&self, x: &[f64], ws: &Workspace, mut hess: MatMut<'_, f64>) {
        let (d, dn) = (x.len(), self.net.input_dim());
        let s = &self.norm.std;
        // Column p of J: (p, g'_p/σ_p) and, where input p has a raw copy d + k, (d + k, 1/σ_{d+k}).
        let mut cols = [[(0usize, 0.0f64); 2]; 2 * MAX_DX];
        let mut len = [1usize; 2 * MAX_DX];
        let mut g2 = [0.0; 2 * MAX_DX];
        for p in 0..d {
            let (g1p, g2p) = self.config.warp_derivatives(p, d, x[p]);
            cols[p][0] = (p, g1p / s[p]);
            g2[p] = g2p;
        }
        for k in 0..self.extra_inputs() {
            let p = raw_copy(k, d);
            cols[p][1] = (d + k, 1.0 / s[d + k]);
            len[p] = 2;
        }
        for p in 0..d {
            for q in p..d {
                let mut h = 0.0;
                for &(a, ja) in &cols[p][..len[p]] {
                    for &(b, jb) in &cols[q][..len[q]] {
                        h += ja * ws.hess_u[a * dn + b] * jb;
                    }
                }
                hess[(p, q)] = h;
                hess[(q, p)] = h;
            }
            hess[(p, p)] += ws.mlp.grad_u[p] / s[p] * g2[p];
        }
    }

    /// `grad_params += c ∂D(x)/∂θ`; returns `D(x)`.
    pub fn accumulate_param_gradient(
        &self,
        x: &[f64],
        c: f64,
        ws: &mut Workspace,
        grad_params: &mut [f64],
    ) -> f64 {
        self.check_ws(ws);
        assert_eq!(
            grad_params.len(),
            self.params().len(),
            "parameter gradient length"
        );
        let y = self.forward_raw(x, &mut ws.mlp);
        self.net.backward(&mut ws.mlp, false);
        self.net.accumulate_param_grad(&ws.mlp, c, grad_params);
        y
    }

    /// The gradient penalty at one interpolate, `P = λ (‖∇ₓD(x̂)‖ − 1)²`, and
    /// `grad_params += c ∂P/∂θ`. With `v = ∇ₓD`, `∂P/∂θ = (∂v/∂θ)ᵀ r`,
    /// `r = 2λ (‖v‖ − 1) v / ‖v‖`, i.e. the θ-gradient of `ρᵀ ∇_u net` with
    /// `ρ = r ⊘ σ` held fixed ([`mlp`] docs). At `v = 0` the subgradient 0 is used.
    pub fn accumulate_penalty_gradient(
        &self,
        x_hat: &[f64],
        c: f64,
        ws: &mut Workspace,
        grad_params: &mut [f64],
    ) -> f64 {
        self.check_ws(ws);
        assert_eq!(
            grad_params.len(),
            self.params().len(),
            "parameter gradient length"
        );
        self.penalty_into(x_hat, c, &mut ws.mlp, grad_params)
    }

    fn penalty_into(
        &self,
        x_hat: &[f64],
        c: f64,
        mlp_ws: &mut MlpWorkspace,
        grad_params: &mut [f64],
    ) -> f64 {
        let lambda = self.config.lambda_gp;
        self.forward_raw(x_hat, mlp_ws);
        self.net.backward(mlp_ws, true);
        // v = ∇ₓD = ∇_u net ⊘ σ (raw) or v = ∇_u net (normalised): scale w = 1/σ or 1.
        let raw = self.config.penalty_space == PenaltySpace::Raw;
        let s = &self.norm.std;
        let w = |si: f64| if raw { 1.0 / si } else { 1.0 };
        let norm2: f64 = mlp_ws
            .grad_u
            .iter()
            .zip(s)
            .map(|(&g, &si)| (g * w(si)) * (g * w(si)))
            .sum();
        let nv = norm2.sqrt();
        let p = lambda * (nv - 1.0) * (nv - 1.0);
        if nv > 0.0 && c != 0.0 && lambda != 0.0 {
            let coef = c * 2.0 * lambda * (nv - 1.0) / nv;
            for ((rho, &g), &si) in mlp_ws.rho.iter_mut().zip(&mlp_ws.grad_u).zip(s) {
                *rho = coef * g * w(si) * w(si);
            }
            self.net
                .accumulate_directional_grad_param_grad(mlp_ws, grad_params);
        }
        p
    }

    /// One sample of the critic loss, `ℓ = D(x_e) − D(x_c) + λ (‖∇ₓD(x̂)‖ − 1)²` with
    /// `x̂ = ε x_e + (1 − ε) x_c`, and `grad_params += c ∂ℓ/∂θ`. Returns `(ℓ, penalty)`.
    /// [`Self::train`]'s minibatch gradient is the sum of these with `c = 1/m`.
    pub fn accumulate_critic_loss_gradient(
        &self,
        x_e: &[f64],
        x_c: &[f64],
        eps: f64,
        c: f64,
        ws: &mut Workspace,
        grad_params: &mut [f64],
    ) -> (f64, f64) {
        self.check_ws(ws);
        assert_eq!(
            grad_params.len(),
            self.params().len(),
            "parameter gradient length"
        );
        assert_eq!(x_c.len(), self.input_dim(), "input length");
        self.critic_sample(x_e, x_c, eps, c, &mut ws.mlp, &mut ws.x_hat, grad_params)
    }

    #[allow(clippy::too_many_arguments)]
    fn critic_sample(
        &self,
        x_e: &[f64],
        x_c: &[f64],
        eps: f64,
        c: f64,
        mlp_ws: &mut MlpWorkspace,
        x_hat: &mut [f64],
        grad: &mut [f64],
    ) -> (f64, f64) {
        for ((h, &e), &xc) in x_hat.iter_mut().zip(x_e).zip(x_c) {
            *h = eps * e + (1.0 - eps) * xc;
        }
        let de = self.forward_raw(x_e, mlp_ws);
        self.net.backward(mlp_ws, false);
        self.net.accumulate_param_grad(mlp_ws, c, grad);
        let dc = self.forward_raw(x_c, mlp_ws);
        self.net.backward(mlp_ws, false);
        self.net.accumulate_param_grad(mlp_ws, -c, grad);
        let p = self.penalty_into(x_hat, c, mlp_ws, grad);
        (de - dc + p, p)
    }

    /// Mean of `D` over the rows of `x` (`n × d`).
    pub fn mean_value(&self, x: MatRef<'_, f64>, ws: &mut Workspace) -> f64 {
        self.check_ws(ws);
        assert_eq!(
            x.ncols(),
            self.input_dim(),
            "columns must be the input dimension"
        );
        let mut sum = 0.0;
        for i in 0..x.nrows() {
            copy_row(x, i, &mut ws.x_e);
            sum += self.forward_raw(&ws.x_e, &mut ws.mlp);
        }
        sum / x.nrows() as f64
    }

    /// The critic's Wasserstein-1 estimate `E_controller[D] − E_expert[D]` (sample means).
    pub fn wasserstein_estimate(
        &self,
        expert: MatRef<'_, f64>,
        controller: MatRef<'_, f64>,
        ws: &mut Workspace,
    ) -> f64 {
        self.mean_value(controller, ws) - self.mean_value(expert, ws)
    }

    /// `n_critic` WGAN-GP critic steps (Gulrajani et al. 2017, Algorithm 1 lines 2–9, with
    /// the roles: "real" = controller, "generated" = expert; see the module docs). Each step
    /// draws `m` expert rows, `m` controller rows (uniformly, with replacement) and `m` values
    /// `ε ~ U[0,1)`, and takes one Adam step on the gradient of
    /// `(1/m) Σ [D(x_e) − D(x_c) + λ (‖∇ₓD(x̂)‖ − 1)²]`, `x̂ = ε x_e + (1 − ε) x_c`
    /// (sign: module docs; D ends up low on expert transitions).
    /// `expert` and `controller` are `n × d` transitions `[s; s']`, one per row.
    ///
    /// Errors on wrong shapes, empty or non-finite data, or a non-finite gradient (then the
    /// weights are left as they were before that step).
    pub fn train(
        &mut self,
        expert: MatRef<'_, f64>,
        controller: MatRef<'_, f64>,
        ws: &mut Workspace,
    ) -> Result<TrainStats, DiscriminatorError> {
        self.check_ws(ws);
        let d = self.input_dim();
        for (name, x) in [("expert", expert), ("controller", controller)] {
            if x.ncols() != d || x.nrows() == 0 {
                return Err(DiscriminatorError::Shape(format!(
                    "{name} transitions are {}x{}, need n >= 1 rows of {d} = [s; s']",
                    x.nrows(),
                    x.ncols()
                )));
            }
            check_finite(x, name)?;
        }
        let m = self.config.batch_size;
        let inv_m = 1.0 / m as f64;
        let (mut loss_sum, mut gp_sum) = (0.0, 0.0);
        for _ in 0..self.config.n_critic {
            ws.grad.fill(0.0);
            let (mut loss, mut gp) = (0.0, 0.0);
            for _ in 0..m {
                let i = self.rng.random_range(0..expert.nrows());
                let j = self.rng.random_range(0..controller.nrows());
                let eps: f64 = self.rng.random();
                copy_row(expert, i, &mut ws.x_e);
                copy_row(controller, j, &mut ws.x_c);
                let (l, p) = self.critic_sample(
                    &ws.x_e,
                    &ws.x_c,
                    eps,
                    inv_m,
                    &mut ws.mlp,
                    &mut ws.x_hat,
                    &mut ws.grad,
                );
                loss += l;
                gp += p;
            }
            if !ws.grad.iter().all(|g| g.is_finite()) {
                return Err(DiscriminatorError::NonFinite(
                    "critic gradient (weights left unchanged by this step)".into(),
                ));
            }
            self.adam.step(self.net.params_mut(), &ws.grad);
            loss_sum += loss * inv_m;
            gp_sum += gp * inv_m;
        }
        self.update_average();
        let n = self.config.n_critic as f64;
        Ok(TrainStats {
            critic_loss: loss_sum / n,
            gradient_penalty: gp_sum / n,
            wasserstein: self.wasserstein_estimate(expert, controller, ws),
        })
    }
}

fn copy_row(x: MatRef<'_, f64>, i: usize, out: &mut [f64]) {
    for (j, o) in out.iter_mut().enumerate() {
        *o = x[(i, j)];
    }
}

fn check_finite(x: MatRef<'_, f64>, what: &str) -> Result<(), DiscriminatorError> {
    for i in 0..x.nrows() {
        for j in 0..x.ncols() {
            if !x[(i, j)].is_finite() {
                return Err(DiscriminatorError::NonFinite(format!(
                    "{what} at row {i}, column {j} ({})",
                    x[(i, j)]
                )));
            }
        }
    }
    Ok(())
}
