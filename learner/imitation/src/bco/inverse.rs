//! BCO's inverse dynamics model (Torabi, Warnell, Stone 2018, §4: M_θ(a | s, s')), learned
//! from the arm's own transitions and used to label the demonstrations' (s, s') with actions.
//!
//! The model is deterministic (a Gaussian of fixed variance, whose maximum-likelihood fit is
//! least squares) and predicts the action offset Δ = a − base(s) (rad: the executed goal
//! angles minus the current joint angles in goal-angle mode; N·m in torque mode) from the
//! features `f = [s; s' − s]` (2 dX), normalised once, on the first data it is fitted to:
//! `u = (f − m) ⊘ r`. It is a linear map plus a tanh-MLP residual, one scalar head per action
//! dimension (the project's MLP, [`crate::discriminator::mlp`]):
//!
//! ```text
//! Δ̂(s, s') = W [u; 1] + h(u),      W: dU × (2 dX + 1),  h_j: 2 dX → hidden… → 1
//! ```
//!
//! `W` is the ridge solution on every transition seen so far (closed form, exact); the heads
//! are trained by Adam on the residual `Δ − W [u; 1]`, minimising
//! `L = 1/(2b) Σ_i ‖h(u_i) − (Δ_i − W [u_i; 1])‖²` over seeded minibatches of b transitions. A
//! goal-angle servo is close to linear over one control period, so the linear part does most
//! of the work and the heads the rest (gravity, the clamp, the arm's non-linearity); for
//! linear dynamics s' = A s + B a with B of full column rank the model is exact up to the
//! ridge term.
//!
//! Dimensions (dX, dU) are run-time values given at construction.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use gps::snapshot::Snapshot;
use gps::GpsError;

use crate::discriminator::mlp::{Mlp, MlpWorkspace};
use crate::discriminator::{Adam, AdamConfig, Normalizer};
use crate::mlp_policy::opt::{check_fit, Minibatches, FIT_ADAM};
use crate::ImitationError;

/// Settings of the inverse dynamics model (TOML table `[model]` of a BCO run).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InverseModelConfig {
    /// Hidden widths of each residual head (tanh). Ours: 64, 64, the policy's.
    pub hidden: Vec<usize>,
    /// Adam of the residual heads. Ours: lr 1e-3, β 0.9 / 0.999 (the S-step's).
    pub adam: AdamConfig,
    /// Minibatch size. Ours: 64.
    pub batch_size: usize,
    /// Adam steps per fit (each iteration's). Ours: 500.
    pub steps: usize,
    /// Ridge weight λ of the linear part, per transition: `(UᵀU + λ n I) W = UᵀY` on the
    /// normalised features. Ours: 1e-8 (a guard against rank loss, not a prior).
    pub ridge: f64,
}

impl Default for InverseModelConfig {
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            adam: FIT_ADAM,
            batch_size: 64,
            steps: 500,
            ridge: 1e-8,
        }
    }
}

impl InverseModelConfig {
    /// Checks the ranges, naming the setting (keys under `model.`).
    pub fn validate(&self) -> Result<(), ImitationError> {
        check_fit(
            "model",
            &self.hidden,
            &self.adam,
            (self.batch_size, self.steps, 0),
        )?;
        crate::error::check_reals(&[(
            "model.ridge",
            self.ridge,
            self.ridge.is_finite() && self.ridge > 0.0 && self.ridge <= 1e3,
            "in (0, 1e3]",
        )])
        .map_err(ImitationError::Config)
    }
}

/// What one [`InverseModel::fit`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitReport {
    /// Transitions the model has been fitted to (all so far).
    pub transitions: usize,
    /// Root mean square error of the linear part alone over those transitions (action units).
    pub rmse_linear: f64,
    /// Root mean square error of the whole model after the fit.
    pub rmse: f64,
}

/// The inverse dynamics model, its data and its optimiser (module docs).
#[derive(Clone, Debug)]
pub struct InverseModel {
    cfg: InverseModelConfig,
    dx: usize,
    du: usize,
    /// Fitted on the first [`InverseModel::fit`]; `None` before.
    norm: Option<Normalizer>,
    /// W, row-major dU × (2 dX + 1).
    linear: Vec<f64>,
    heads: Vec<Mlp>,
    adam: Adam,
    rng: ChaCha8Rng,
    /// Features f = [s; s' − s] of every transition, (n, 2 dX) row-major (raw, not normalised).
    features: Vec<f64>,
    /// Executed offsets Δ, (n, dU).
    targets: Vec<f64>,
    /// Per-head scratch and the flat parameter / gradient buffers.
    ws: Vec<MlpWorkspace>,
    theta: Vec<f64>,
    grad: Vec<f64>,
    batches: Minibatches,
}

/// Snapshot arrays of the model ([`InverseModel::snapshot`]).
const NORM: &str = "bco.model.norm";
const LINEAR: &str = "bco.model.linear";
const HEADS: &str = "bco.model.heads";
const FEATURES: &str = "bco.model.features";
const TARGETS: &str = "bco.model.targets";
const ADAM_T: &str = "bco.model.adam.t";
const ADAM_M: &str = "bco.model.adam.m";
const ADAM_V: &str = "bco.model.adam.v";
const RNG: &str = "bco.model.rng";

impl InverseModel {
    /// An unfitted model of a task with dX = `dx`, dU = `du`: W = 0, heads Glorot with their
    /// output layers zero (h = 0), weights and minibatch order from `ChaCha8(seed)`.
    pub fn new(
        cfg: InverseModelConfig,
        dx: usize,
        du: usize,
        seed: u64,
    ) -> Result<Self, ImitationError> {
        cfg.validate()?;
        if dx == 0 || du == 0 {
            return Err(ImitationError::Config(format!(
                "an inverse model needs dX, dU > 0, got {dx}, {du}"
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut sizes = vec![2 * dx];
        sizes.extend_from_slice(&cfg.hidden);
        sizes.push(1);
        let heads: Vec<Mlp> = (0..du)
            .map(|_| {
                let mut net = Mlp::glorot(&sizes, &mut rng);
                let r = net.weight_range(net.layers() - 1);
                net.params_mut()[r].fill(0.0);
                net
            })
            .collect();
        let n: usize = heads.iter().map(|h| h.params().len()).sum();
        Ok(Self {
            adam: Adam::new(cfg.adam, n),
            ws: heads.iter().map(|h| MlpWorkspace::new(h.sizes())).collect(),
            theta: vec![0.0; n],
            grad: vec![0.0; n],
            linear: vec![0.0; du * (2 * dx + 1)],
            norm: None,
            features: Vec::new(),
            targets: Vec::new(),
            batches: Minibatches::default(),
            heads,
            rng,
            cfg,
            dx,
            du,
        })
    }

    /// dX.
    pub fn dx(&self) -> usize {
        self.dx
    }

    /// dU.
    pub fn du(&self) -> usize {
        self.du
    }

    /// Transitions held.
    pub fn len(&self) -> usize {
        self.targets.len() / self.du
    }

    /// No transitions held.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// The features `[s; s' − s]` of one transition into `out` (2 dX).
    fn feature(s: &[f64], s_next: &[f64], out: &mut Vec<f64>) {
        out.extend_from_slice(s);
        out.extend(s_next.iter().zip(s).map(|(b, a)| b - a));
    }

    /// Adds the transition s → s' under the executed offset Δ (`s`, `s_next`: dX; `delta`: dU).
    pub fn push(&mut self, s: &[f64], s_next: &[f64], delta: &[f64]) {
        assert_eq!(
            (s.len(), s_next.len(), delta.len()),
            (self.dx, self.dx, self.du)
        );
        Self::feature(s, s_next, &mut self.features);
        self.targets.extend_from_slice(delta);
    }

    /// The normalised input `[u; 1]` of features `f` into `u` (2 dX + 1).
    fn input(&self, f: &[f64], u: &mut [f64]) {
        let norm = self.norm.as_ref().expect("fitted");
        for (i, v) in u[..2 * self.dx].iter_mut().enumerate() {
            *v = (f[i] - norm.mean[i]) / norm.std[i];
        }
        u[2 * self.dx] = 1.0;
    }

    /// W [u; 1] into `out` (dU).
    fn linear_part(&self, u: &[f64], out: &mut [f64]) {
        let p = 2 * self.dx + 1;
        for (j, o) in out.iter_mut().enumerate() {
            *o = ur5_shared::kernels::dot(&self.linear[j * p..(j + 1) * p], u);
        }
    }

    /// h(u) into `out` (dU); leaves every head's forward pass in the workspaces.
    fn heads_part(&mut self, u: &[f64], out: &mut [f64]) {
        for ((h, w), o) in self.heads.iter().zip(&mut self.ws).zip(out.iter_mut()) {
            w.u.copy_from_slice(&u[..2 * self.dx]);
            *o = h.forward(w);
        }
    }

    /// The predicted offset Δ̂(s, s') (dU) of a fitted model.
    pub fn predict(&mut self, s: &[f64], s_next: &[f64]) -> Result<Vec<f64>, ImitationError> {
        if self.norm.is_none() {
            return Err(ImitationError::Episodes(
                "the inverse model labels actions only once it has been fitted".into(),
            ));
        }
        let mut f = Vec::with_capacity(2 * self.dx);
        Self::feature(s, s_next, &mut f);
        let mut u = vec![0.0; 2 * self.dx + 1];
        self.input(&f, &mut u);
        let mut lin = vec![0.0; self.du];
        let mut h = vec![0.0; self.du];
        self.linear_part(&u, &mut lin);
        self.heads_part(&u, &mut h);
        Ok(lin.iter().zip(&h).map(|(a, b)| a + b).collect())
    }

    /// Fits the model to every transition held: the normalisation (on the first fit only, so
    /// that the heads keep their meaning), W in closed form, then `steps` Adam steps on the
    /// heads (module docs).
    pub fn fit(&mut self) -> Result<FitReport, ImitationError> {
        let n = self.len();
        if n == 0 {
            return Err(ImitationError::Episodes(
                "the inverse model needs transitions to fit".into(),
            ));
        }
        let d = 2 * self.dx;
        if self.norm.is_none() {
            let x = faer::Mat::from_fn(n, d, |r, c| self.features[r * d + c]);
            self.norm = Some(Normalizer::from_data(x.as_ref())?);
        }
        self.fit_linear()?;
        // Residual targets of the heads.
        let p = d + 1;
        let mut u = vec![0.0; p];
        let mut lin = vec![0.0; self.du];
        let mut residual = vec![0.0; n * self.du];
        let mut inputs = vec![0.0; n * d];
        for i in 0..n {
            self.input(&self.features[i * d..(i + 1) * d], &mut u);
            self.linear_part(&u, &mut lin);
            inputs[i * d..(i + 1) * d].copy_from_slice(&u[..d]);
            for j in 0..self.du {
                residual[i * self.du + j] = self.targets[i * self.du + j] - lin[j];
            }
        }
        let rmse_linear = (residual.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt();
        let b = self.cfg.batch_size.min(n);
        // Out of `self` while `loss_gradient` borrows it.
        let mut batches = std::mem::take(&mut self.batches);
        batches.start();
        for _ in 0..self.cfg.steps {
            let batch = batches.next(n, b, &mut self.rng);
            self.loss_gradient(&inputs, &residual, batch);
            self.read_params();
            self.adam.step(&mut self.theta, &self.grad);
            self.write_params();
        }
        self.batches = batches;
        let all: Vec<usize> = (0..n).collect();
        let rmse = (2.0 * self.loss_gradient(&inputs, &residual, &all)).sqrt();
        if !rmse.is_finite() {
            return Err(ImitationError::Config(format!(
                "the inverse model's fit diverged (rmse {rmse}); lower model.adam.lr"
            )));
        }
        Ok(FitReport {
            transitions: n,
            rmse_linear,
            rmse,
        })
    }

    /// `L = 1/(2b) Σ_{i ∈ batch} ‖h(u_i) − r_i‖²` (b = batch length) on normalised inputs
    /// `inputs` (n, 2 dX) and residual targets `residual` (n, dU); its gradient w.r.t. the
    /// heads' flat parameters into `self.grad` (overwritten). Returns `L`.
    pub(crate) fn loss_gradient(
        &mut self,
        inputs: &[f64],
        residual: &[f64],
        batch: &[usize],
    ) -> f64 {
        let d = 2 * self.dx;
        let bf = batch.len() as f64;
        self.grad.fill(0.0);
        let mut loss = 0.0;
        for &i in batch {
            let mut off = 0;
            for (j, (h, w)) in self.heads.iter().zip(&mut self.ws).enumerate() {
                w.u.copy_from_slice(&inputs[i * d..(i + 1) * d]);
                let e = h.forward(w) - residual[i * self.du + j];
                loss += 0.5 * e * e / bf;
                let n = h.params().len();
                h.backward(w, false);
                h.accumulate_param_grad(w, e / bf, &mut self.grad[off..off + n]);
                off += n;
            }
        }
        loss
    }

    /// W = (UᵀU + λ n I)⁻¹ UᵀY over every transition held.
    fn fit_linear(&mut self) -> Result<(), ImitationError> {
        let (n, d, du) = (self.len(), 2 * self.dx, self.du);
        let p = d + 1;
        let mut gram = vec![0.0; p * p];
        let mut rhs = vec![0.0; p * du];
        let mut u = vec![0.0; p];
        for i in 0..n {
            self.input(&self.features[i * d..(i + 1) * d], &mut u);
            for a in 0..p {
                for b in a..p {
                    gram[a * p + b] += u[a] * u[b];
                }
                for j in 0..du {
                    rhs[a * du + j] += u[a] * self.targets[i * du + j];
                }
            }
        }
        for a in 0..p {
            gram[a * p + a] += self.cfg.ridge * n as f64;
            for b in 0..a {
                gram[a * p + b] = gram[b * p + a];
            }
        }
        let l = cholesky(&gram, p).ok_or_else(|| {
            ImitationError::Config("the inverse model's linear fit is singular".into())
        })?;
        for j in 0..du {
            let col: Vec<f64> = (0..p).map(|a| rhs[a * du + j]).collect();
            let w = cholesky_solve(&l, p, &col);
            self.linear[j * p..(j + 1) * p].copy_from_slice(&w);
        }
        Ok(())
    }

    /// Number of the heads' parameters.
    pub fn n_head_params(&self) -> usize {
        self.theta.len()
    }

    fn read_params(&mut self) {
        let mut off = 0;
        for h in &self.heads {
            let p = h.params();
            self.theta[off..off + p.len()].copy_from_slice(p);
            off += p.len();
        }
    }

    fn write_params(&mut self) {
        let mut off = 0;
        for h in &mut self.heads {
            let p = h.params_mut();
            let n = p.len();
            p.copy_from_slice(&self.theta[off..off + n]);
            off += n;
        }
    }

    /// Adds everything the next fit depends on to `s`: normalisation, W, the heads, the data,
    /// Adam's state and the minibatch RNG (the order is drawn afresh at the start of every
    /// fit, so it is not state).
    pub fn snapshot(&self, s: &mut Snapshot) {
        if let Some(norm) = &self.norm {
            let both: Vec<f64> = norm.mean.iter().chain(&norm.std).copied().collect();
            s.put(NORM, &[2, 2 * self.dx], &both);
        }
        s.put(LINEAR, &[self.du, 2 * self.dx + 1], &self.linear);
        let mut theta = vec![0.0; self.theta.len()];
        let mut off = 0;
        for h in &self.heads {
            theta[off..off + h.params().len()].copy_from_slice(h.params());
            off += h.params().len();
        }
        s.put(HEADS, &[theta.len()], &theta);
        s.put(FEATURES, &[self.len(), 2 * self.dx], &self.features);
        s.put(TARGETS, &[self.len(), self.du], &self.targets);
        s.put_words(ADAM_T, &[self.adam.t]);
        s.put(ADAM_M, &[self.adam.m.len()], &self.adam.m);
        s.put(ADAM_V, &[self.adam.v.len()], &self.adam.v);
        s.put_rng(RNG, &self.rng);
    }

    /// Restores what [`InverseModel::snapshot`] saved into a model of the same settings and
    /// dimensions; nothing changes on an error.
    pub fn restore(&mut self, s: &Snapshot) -> Result<(), GpsError> {
        let (dx, du) = (self.dx, self.du);
        let norm = if s.has(NORM) {
            let both = s.real(NORM, &[2, 2 * dx])?;
            Some(Normalizer {
                mean: both[..2 * dx].to_vec(),
                std: both[2 * dx..].to_vec(),
            })
        } else {
            None
        };
        let linear = s.real(LINEAR, &[du, 2 * dx + 1])?.to_vec();
        let theta = s.real(HEADS, &[self.theta.len()])?.to_vec();
        let (shape, features) = s.real_any(FEATURES)?;
        let n = shape.first().copied().unwrap_or(0);
        if shape != [n, 2 * dx] {
            return Err(GpsError::Shape(format!(
                "{FEATURES} has shape {shape:?}, expected [n, {}]",
                2 * dx
            )));
        }
        let features = features.to_vec();
        let targets = s.real(TARGETS, &[n, du])?.to_vec();
        let t = s.words(ADAM_T, 1)?[0];
        let m = s.real(ADAM_M, &[self.theta.len()])?.to_vec();
        let v = s.real(ADAM_V, &[self.theta.len()])?.to_vec();
        let rng = s.rng(RNG)?;
        self.norm = norm;
        self.linear = linear;
        self.theta = theta;
        self.write_params();
        self.features = features;
        self.targets = targets;
        self.adam.t = t;
        self.adam.m = m;
        self.adam.v = v;
        self.rng = rng;
        self.batches.start();
        Ok(())
    }
}

/// Lower Cholesky factor of the SPD matrix `a` (row-major p × p); `None` if not positive
/// definite.
fn cholesky(a: &[f64], p: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; p * p];
    for i in 0..p {
        for j in 0..=i {
            let mut v = a[i * p + j];
            for k in 0..j {
                v -= l[i * p + k] * l[j * p + k];
            }
            if i == j {
                if !(v > 0.0) {
                    return None;
                }
                l[i * p + i] = v.sqrt();
            } else {
                l[i * p + j] = v / l[j * p + j];
            }
        }
    }
    Some(l)
}

/// x with L Lᵀ x = b.
fn cholesky_solve(l: &[f64], p: usize, b: &[f64]) -> Vec<f64> {
    let mut y = b.to_vec();
    for i in 0..p {
        for k in 0..i {
            y[i] -= l[i * p + k] * y[k];
        }
        y[i] /= l[i * p + i];
    }
    for i in (0..p).rev() {
        for k in i + 1..p {
            y[i] -= l[k * p + i] * y[k];
        }
        y[i] /= l[i * p + i];
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    /// Small settings: one hidden layer of 8, so that every parameter can be checked.
    fn small() -> InverseModelConfig {
        InverseModelConfig {
            hidden: vec![8],
            steps: 200,
            batch_size: 32,
            ..InverseModelConfig::default()
        }
    }

    /// `n` transitions s' = A s + B g(a) of random s ∈ [−1, 1]^dx, a ∈ [−0.5, 0.5]^du.
    fn transitions(
        a_mat: &[f64],
        b_mat: &[f64],
        g: impl Fn(f64) -> f64,
        (dx, du): (usize, usize),
        n: usize,
        rng: &mut ChaCha8Rng,
    ) -> Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        (0..n)
            .map(|_| {
                let s: Vec<f64> = (0..dx).map(|_| rng.random_range(-1.0..1.0)).collect();
                let a: Vec<f64> = (0..du).map(|_| rng.random_range(-0.5..0.5)).collect();
                let next = (0..dx)
                    .map(|i| {
                        (0..dx).map(|k| a_mat[i * dx + k] * s[k]).sum::<f64>()
                            + (0..du).map(|j| b_mat[i * du + j] * g(a[j])).sum::<f64>()
                    })
                    .collect();
                (s, next, a)
            })
            .collect()
    }

    fn random_mats(dx: usize, du: usize, rng: &mut ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
        let a = (0..dx * dx).map(|_| rng.random_range(-0.6..0.6)).collect();
        // B = [I; random]: full column rank, so a is determined by (s, s').
        let b = (0..dx * du)
            .map(|k| {
                let (i, j) = (k / du, k % du);
                if i < du {
                    if i == j {
                        1.0
                    } else {
                        0.0
                    }
                } else {
                    rng.random_range(-1.0..1.0)
                }
            })
            .collect();
        (a, b)
    }

    #[test]
    fn the_model_recovers_the_actions_of_linear_dynamics() {
        let (dx, du) = (6, 2);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (a, b) = random_mats(dx, du, &mut rng);
        let mut m = InverseModel::new(small(), dx, du, 3).unwrap();
        for (s, next, act) in transitions(&a, &b, |v| v, (dx, du), 300, &mut rng) {
            m.push(&s, &next, &act);
        }
        let report = m.fit().unwrap();
        assert_eq!(report.transitions, 300);
        assert!(report.rmse_linear < 1e-7, "{report:?}");
        let mut worst = 0.0f64;
        for (s, next, act) in transitions(&a, &b, |v| v, (dx, du), 50, &mut rng) {
            let got = m.predict(&s, &next).unwrap();
            for (g, w) in got.iter().zip(&act) {
                worst = worst.max((g - w).abs());
            }
        }
        // The linear part is exact to the ridge term; the heads, trained on residuals of
        // ~1e-9, move by Adam's ε-limited steps.
        assert!(worst < 1e-5, "largest action error {worst:e} rad");
    }

    #[test]
    fn the_residual_heads_learn_what_the_linear_part_cannot() {
        let (dx, du) = (4, 2);
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let (a, b) = random_mats(dx, du, &mut rng);
        let g = |v: f64| v + 2.0 * v * v * v;
        let cfg = InverseModelConfig {
            steps: 3000,
            hidden: vec![16],
            adam: AdamConfig {
                lr: 3e-3,
                ..small().adam
            },
            ..small()
        };
        let mut m = InverseModel::new(cfg, dx, du, 4).unwrap();
        for (s, next, act) in transitions(&a, &b, g, (dx, du), 400, &mut rng) {
            m.push(&s, &next, &act);
        }
        let r = m.fit().unwrap();
        assert!(r.rmse < 0.3 * r.rmse_linear, "{r:?}");
    }

    #[test]
    fn the_loss_gradient_matches_central_differences() {
        let (dx, du) = (3, 2);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut m = InverseModel::new(small(), dx, du, 6).unwrap();
        // Non-zero output layers, so that every parameter matters.
        for h in &mut m.heads {
            for w in h.params_mut() {
                *w += rng.random_range(-0.5..0.5);
            }
        }
        let n = 7;
        let inputs: Vec<f64> = (0..n * 2 * dx)
            .map(|_| rng.random_range(-2.0..2.0))
            .collect();
        let residual: Vec<f64> = (0..n * du).map(|_| rng.random_range(-1.0..1.0)).collect();
        let batch = [0, 3, 4, 6, 3];
        m.loss_gradient(&inputs, &residual, &batch);
        let grad = m.grad.clone();
        m.read_params();
        let theta = m.theta.clone();
        let h = 1e-6;
        let mut worst = 0.0f64;
        for k in 0..theta.len() {
            let mut at = |v: f64| {
                m.theta.copy_from_slice(&theta);
                m.theta[k] = v;
                m.write_params();
                m.loss_gradient(&inputs, &residual, &batch)
            };
            let fd = (at(theta[k] + h) - at(theta[k] - h)) / (2.0 * h);
            worst = worst.max((fd - grad[k]).abs() / (1.0 + fd.abs()));
        }
        assert!(worst < 1e-7, "worst relative error {worst:e}");
    }

    #[test]
    fn snapshot_and_restore_continue_the_fits_bit_for_bit() {
        let (dx, du) = (4, 2);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let (a, b) = random_mats(dx, du, &mut rng);
        let data = transitions(&a, &b, |v| v + v * v, (dx, du), 120, &mut rng);
        let mut whole = InverseModel::new(small(), dx, du, 9).unwrap();
        for (s, next, act) in &data[..60] {
            whole.push(s, next, act);
        }
        whole.fit().unwrap();
        let mut snap = Snapshot::default();
        whole.snapshot(&mut snap);
        let mut resumed = InverseModel::new(small(), dx, du, 9).unwrap();
        resumed.restore(&snap).unwrap();
        for m in [&mut whole, &mut resumed] {
            for (s, next, act) in &data[60..] {
                m.push(s, next, act);
            }
        }
        let (ra, rb) = (whole.fit().unwrap(), resumed.fit().unwrap());
        assert_eq!(ra, rb);
        let (s, next, _) = &data[7];
        assert_eq!(
            whole.predict(s, next).unwrap(),
            resumed.predict(s, next).unwrap()
        );
        // A model of another size refuses the snapshot and is left as it was.
        let mut other = InverseModel::new(small(), dx + 1, du, 9).unwrap();
        assert!(other.restore(&snap).is_err());
        assert!(other.is_empty());
    }

    #[test]
    fn settings_that_cannot_work_are_refused_naming_the_setting() {
        let check = |c: &InverseModelConfig| c.validate();
        assert!(check(&InverseModelConfig::default()).is_ok());
        let cases: Vec<(&str, Box<dyn Fn(&mut InverseModelConfig)>)> = vec![
            ("model.hidden", Box::new(|c| c.hidden = vec![])),
            ("model.batch_size", Box::new(|c| c.batch_size = 0)),
            ("model.ridge", Box::new(|c| c.ridge = 0.0)),
            ("model.adam", Box::new(|c| c.adam.lr = -1.0)),
        ];
        crate::error::assert_each_refused_naming(cases, check);
    }
}
