//! The supervised fit of a [`GlobalPolicy`]: MDGPS's S-step (docs/design.md §6.4; GPS
//! `PolicyOpt.update(obs, tgt_mu, tgt_prc, tgt_wt)`) and BCO's cloning (§7, unit precisions),
//! so below both. It regresses the policy's mean onto target offsets at given states (MDGPS:
//! the controllers' action means at the sampled states), each residual weighted by a precision
//! (MDGPS: that controller's action precision Σ_t⁻¹):
//!
//! ```text
//! L(θ) = 1/n Σ_i ½ (μ_θ(u_i) − Δ*_i)ᵀ P_i (μ_θ(u_i) − Δ*_i),   Δ*_i = K_t s_i + k_t − base(s_i),
//! P_i = Σ_t⁻¹ (rad⁻²),
//! ```
//!
//! minimised by Adam on shuffled minibatches (the order seeded, so a seed gives the same policy
//! bit for bit on any machine and thread count). Then the policy's σ is set to the precision
//! the controllers ask for on average, σ_j² = 1 / mean_i (P_i)_jj (GPS `policy_opt_tf`'s
//! variance update, without its entropy term).

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use ur5_shared::joints::Joints;

use gps::snapshot::Snapshot;
use gps::GpsError;

use super::global::{GlobalPolicy, GlobalPolicyWorkspace};
use crate::discriminator::{Adam, AdamConfig};
use crate::ImitationError;

/// Settings of the global policy and its S-step (TOML table `[mdgps.policy]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PolicyOptConfig {
    /// Hidden widths of each mean head. Ours: 64, 64, the PPO baseline's (docs/design.md §1.5).
    pub hidden: Vec<usize>,
    /// Adam. Ours: GPS `policy_opt` defaults (lr 1e-3, β 0.9 / 0.999).
    pub adam: AdamConfig,
    /// Minibatch size. Ours: 64.
    pub batch_size: usize,
    /// Adam steps per S-step. Ours: 1000 (docs/design.md §6.4).
    pub steps: usize,
    /// Lower bound on σ (rad) after the variance update, so that a controller that has become
    /// nearly deterministic does not make the policy's linearisation singular in the C-step's
    /// KL term. Ours: 1e-3.
    pub min_std: f64,
}

impl Default for PolicyOptConfig {
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            adam: FIT_ADAM,
            batch_size: 64,
            steps: 1000,
            min_std: 1e-3,
        }
    }
}

impl PolicyOptConfig {
    /// Checks the ranges (widths and counts as the critic's, Adam's own, σ floor in (0, 1]).
    pub fn validate(&self) -> Result<(), ImitationError> {
        check_fit(
            "policy",
            &self.hidden,
            &self.adam,
            (self.batch_size, self.steps, 1),
        )?;
        crate::error::check_reals(&[(
            "policy.min_std",
            self.min_std,
            self.min_std > 0.0 && self.min_std <= 1.0,
            "in (0, 1] rad",
        )])
        .map_err(ImitationError::Config)
    }
}

/// Adam of a supervised fit of MLP heads (the S-step, BCO's cloning and inverse model): GPS
/// `policy_opt`'s defaults, lr 1e-3, β 0.9 / 0.999, ε 1e-8.
pub const FIT_ADAM: AdamConfig = AdamConfig {
    lr: 1e-3,
    beta1: 0.9,
    beta2: 0.999,
    eps: 1e-8,
};

/// Checks what every minibatch Adam fit of MLP heads is set by, naming each key under `table`
/// (`policy.hidden`, `model.steps`, …): the hidden widths as the critic's, `batch_size ≥ 1`,
/// `steps ≥ min_steps` (both at most [`crate::settings::MAX_COUNT`]) and Adam's own ranges.
pub fn check_fit(
    table: &str,
    hidden: &[usize],
    adam: &AdamConfig,
    (batch_size, steps, min_steps): (usize, usize, usize),
) -> Result<(), ImitationError> {
    crate::discriminator::DiscriminatorConfig::check_widths(&format!("{table}.hidden"), hidden)
        .map_err(ImitationError::Config)?;
    let (batch_key, steps_key) = (format!("{table}.batch_size"), format!("{table}.steps"));
    crate::error::check_counts(
        &[
            (batch_key.as_str(), batch_size, 1),
            (steps_key.as_str(), steps, min_steps),
        ],
        crate::settings::MAX_COUNT,
    )
    .map_err(ImitationError::Config)?;
    adam.validate()
        .map_err(|e| ImitationError::Config(format!("{table}.adam: {e}")))
}

/// The seeded minibatch order of a fit over n samples: a fresh permutation of 0..n, drawn from
/// the fit's RNG, at the start of every fit and whenever fewer than b samples of the current
/// one are left (the S-step's, BCO's cloning and inverse model's). Not state across fits: a
/// restored fit draws its first order anew.
#[derive(Clone, Debug, Default)]
pub struct Minibatches {
    order: Vec<usize>,
    cursor: usize,
}

impl Minibatches {
    /// Starts a fit: the next [`Minibatches::next`] draws a new permutation.
    pub fn start(&mut self) {
        self.order.clear();
        self.cursor = 0;
    }

    /// The next b of n sample indices (b ≤ n), after a new permutation from `rng` if needed.
    pub fn next(&mut self, n: usize, b: usize, rng: &mut ChaCha8Rng) -> &[usize] {
        if self.cursor + b > self.order.len() || self.order.len() != n {
            self.order = (0..n).collect();
            self.order.shuffle(rng);
            self.cursor = 0;
        }
        self.cursor += b;
        &self.order[self.cursor - b..self.cursor]
    }
}

/// The regression targets of one S-step: per sample the state s_i, the target offset Δ*_i
/// and the precision P_i (row-major dU × dU, symmetric positive definite), in flat arrays of
/// the task's dimensions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Targets {
    /// State dimension dX.
    pub dx: usize,
    /// Action dimension dU.
    pub du: usize,
    /// States, (n, dX) row-major.
    pub states: Vec<f64>,
    /// Target offsets Δ* (rad), (n, dU).
    pub offsets: Vec<f64>,
    /// Precisions P (rad⁻²), (n, dU, dU).
    pub precisions: Vec<f64>,
}

impl Targets {
    /// No samples yet, of dimensions `dx`, `du`.
    pub fn new(dx: usize, du: usize) -> Self {
        Self {
            dx,
            du,
            ..Self::default()
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.offsets.len() / self.du.max(1)
    }

    /// No samples.
    pub fn is_empty(&self) -> bool {
        self.offsets.is_empty()
    }

    /// Adds a sample: state `s` (dX), target offset `offset` (dU), precision `precision`
    /// (dU × dU row-major).
    pub fn push(&mut self, s: &[f64], offset: &[f64], precision: &[f64]) {
        assert!(
            s.len() == self.dx && offset.len() == self.du && precision.len() == self.du * self.du,
            "a sample of the targets' dX = {}, dU = {}",
            self.dx,
            self.du
        );
        self.states.extend_from_slice(s);
        self.offsets.extend_from_slice(offset);
        self.precisions.extend_from_slice(precision);
    }

    /// State of sample i (dX).
    pub fn state(&self, i: usize) -> &[f64] {
        &self.states[i * self.dx..(i + 1) * self.dx]
    }

    /// Target offset of sample i (dU).
    pub fn offset(&self, i: usize) -> &[f64] {
        &self.offsets[i * self.du..(i + 1) * self.du]
    }

    /// Precision of sample i (dU × dU row-major).
    pub fn precision(&self, i: usize) -> &[f64] {
        let n = self.du * self.du;
        &self.precisions[i * n..(i + 1) * n]
    }
}

/// What one S-step did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SStepReport {
    /// L(θ) over all targets before and after the Adam steps.
    pub loss_before: f64,
    pub loss_after: f64,
}

/// The S-step's optimiser state: Adam's moments carry over from one S-step to the next (GPS
/// keeps its solver), the minibatch order is drawn from `rng`.
pub struct PolicyOpt {
    cfg: PolicyOptConfig,
    adam: Adam,
    rng: ChaCha8Rng,
    theta: Vec<f64>,
    grad: Vec<f64>,
    batches: Minibatches,
}

/// Snapshot arrays of the S-step's optimiser.
const ADAM_T: &str = "s_step.adam.t";
const ADAM_M: &str = "s_step.adam.m";
const ADAM_V: &str = "s_step.adam.v";
const RNG: &str = "s_step.rng";

impl PolicyOpt {
    /// The optimiser for `pol`, its minibatch order seeded with `seed`.
    pub fn new(cfg: PolicyOptConfig, pol: &GlobalPolicy, seed: u64) -> Self {
        let n = pol.net().n_params();
        Self {
            adam: Adam::new(cfg.adam, n),
            rng: ChaCha8Rng::seed_from_u64(seed),
            theta: vec![0.0; n],
            grad: vec![0.0; n],
            batches: Minibatches::default(),
            cfg,
        }
    }

    /// Adds the optimiser's state to `s`: Adam's step count and moments, the minibatch RNG
    /// position (the minibatch order is drawn again at the start of every S-step, so it is not
    /// state).
    pub fn snapshot(&self, s: &mut Snapshot) {
        s.put_words(ADAM_T, &[self.adam.t]);
        s.put(ADAM_M, &[self.adam.m.len()], &self.adam.m);
        s.put(ADAM_V, &[self.adam.v.len()], &self.adam.v);
        s.put_rng(RNG, &self.rng);
    }

    /// Restores the state saved by [`PolicyOpt::snapshot`] (into an optimiser of a policy of
    /// the same size); nothing changes on an error.
    pub fn restore(&mut self, s: &Snapshot) -> Result<(), GpsError> {
        let n = self.adam.m.len();
        let t = s.words(ADAM_T, 1)?[0];
        let m = s.real(ADAM_M, &[n])?.to_vec();
        let v = s.real(ADAM_V, &[n])?.to_vec();
        let rng = s.rng(RNG)?;
        self.adam.t = t;
        self.adam.m = m;
        self.adam.v = v;
        self.rng = rng;
        Ok(())
    }

    /// L(θ) of `pol` on `data` (module docs).
    pub fn loss(pol: &GlobalPolicy, data: &Targets, ws: &mut GlobalPolicyWorkspace) -> f64 {
        let mut total = 0.0;
        for i in 0..data.len() {
            let e = residual(pol, data, i, ws);
            total += 0.5 * quad(data.precision(i), &e);
        }
        total / data.len().max(1) as f64
    }

    /// One S-step on `data`: `cfg.steps` Adam steps on shuffled minibatches, then the variance
    /// update.
    pub fn update(
        &mut self,
        pol: &mut GlobalPolicy,
        data: &Targets,
    ) -> Result<SStepReport, ImitationError> {
        if data.is_empty() {
            return Err(ImitationError::Episodes("an S-step needs samples".into()));
        }
        let (dx, du) = (pol.layout().dx(), pol.layout().du());
        if (data.dx, data.du) != (dx, du) {
            return Err(ImitationError::Episodes(format!(
                "S-step targets of dX = {}, dU = {} for a policy of dX = {dx}, dU = {du}",
                data.dx, data.du
            )));
        }
        let mut ws = pol.workspace();
        let loss_before = Self::loss(pol, data, &mut ws);
        let b = self.cfg.batch_size.min(data.len());
        self.batches.start();
        for _ in 0..self.cfg.steps {
            let batch = self.batches.next(data.len(), b, &mut self.rng);
            self.grad.fill(0.0);
            for &i in batch {
                let e = residual(pol, data, i, &mut ws);
                let p = data.precision(i);
                // ∂L/∂μ = P e / b; the heads' gradients are accumulated per joint.
                let mut c = Joints::splat(du, 0.0);
                for (j, c) in c.iter_mut().enumerate() {
                    *c = (0..du).map(|l| p[j * du + l] * e[l]).sum::<f64>() / b as f64;
                }
                pol.net()
                    .accumulate_mean_grad(&mut ws.net, &c, &mut self.grad);
            }
            pol.net().read_params(&mut self.theta);
            self.adam.step(&mut self.theta, &self.grad);
            pol.net_mut().write_params(&self.theta);
        }
        self.update_variance(pol, data);
        let loss_after = Self::loss(pol, data, &mut ws);
        if !loss_after.is_finite() {
            return Err(ImitationError::Config(format!(
                "the S-step diverged (loss {loss_after}); lower policy.adam.lr"
            )));
        }
        Ok(SStepReport {
            loss_before,
            loss_after,
        })
    }

    /// σ_j² = 1 / mean_i (P_i)_jj, σ_j ≥ `min_std`.
    fn update_variance(&self, pol: &mut GlobalPolicy, data: &Targets) {
        let n = data.len() as f64;
        let du = data.du;
        let mut log_std = Joints::splat(du, 0.0);
        for (j, v) in log_std.iter_mut().enumerate() {
            let mean_prc = (0..data.len())
                .map(|i| data.precision(i)[j * du + j])
                .sum::<f64>()
                / n;
            *v = (1.0 / mean_prc).sqrt().max(self.cfg.min_std).ln();
        }
        pol.net_mut().set_log_std(log_std);
    }
}

/// e_i = μ_θ(u(s_i)) − Δ*_i; leaves the heads' forward passes in `ws` (for the gradient).
fn residual(
    pol: &GlobalPolicy,
    data: &Targets,
    i: usize,
    ws: &mut GlobalPolicyWorkspace,
) -> Joints {
    let mut e = pol.offset(data.state(i), ws);
    for (e, o) in e.iter_mut().zip(data.offset(i)) {
        *e -= o;
    }
    e
}

/// eᵀ P e (P dU × dU row-major).
fn quad(p: &[f64], e: &[f64]) -> f64 {
    let du = e.len();
    (0..du)
        .map(|j| e[j] * (0..du).map(|l| p[j * du + l] * e[l]).sum::<f64>())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The minibatch order of a fit as it was written in the S-step and in BCO's inverse model
    /// before they shared [`Minibatches`]: the reference for the same draws in the same order.
    fn reference(fits: &[(usize, usize, usize)], rng: &mut ChaCha8Rng) -> Vec<Vec<usize>> {
        let mut order: Vec<usize> = Vec::new();
        let mut out = Vec::new();
        for &(n, b, steps) in fits {
            let mut cursor = n;
            for _ in 0..steps {
                if cursor + b > order.len() || order.len() != n {
                    order = (0..n).collect();
                    order.shuffle(rng);
                    cursor = 0;
                }
                out.push(order[cursor..cursor + b].to_vec());
                cursor += b;
            }
        }
        out
    }

    /// Every batch as the reference's, over fits of several sizes (a batch of all samples, a
    /// pass that leaves fewer than b, a fit over the same n as the last); each pass of a fit
    /// is a permutation.
    #[test]
    fn minibatches_draw_as_the_reference() {
        let fits = [(10, 4, 7), (10, 4, 3), (5, 5, 3), (7, 3, 5), (1, 1, 2)];
        let want = reference(&fits, &mut ChaCha8Rng::seed_from_u64(4));
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut mb = Minibatches::default();
        let mut got = Vec::new();
        for &(n, b, steps) in &fits {
            mb.start();
            for _ in 0..steps {
                got.push(mb.next(n, b, &mut rng).to_vec());
            }
        }
        assert_eq!(got, want);
        let mut pass: Vec<usize> = got[0].iter().chain(&got[1]).copied().collect();
        pass.sort_unstable();
        pass.dedup();
        assert_eq!(pass.len(), 8, "{got:?}");
        assert_ne!(
            got[2], got[0],
            "a new permutation after the first two batches of 4 of 10"
        );
    }
}
