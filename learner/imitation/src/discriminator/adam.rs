//! Adam (Kingma & Ba 2015, Algorithm 1) on a flat parameter vector.

use serde::{Deserialize, Serialize};

/// Adam's hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdamConfig {
    /// Step size α.
    pub lr: f64,
    /// Decay of the first-moment estimate β1.
    pub beta1: f64,
    /// Decay of the second-moment estimate β2.
    pub beta2: f64,
    /// ε in the denominator.
    pub eps: f64,
}

impl Default for AdamConfig {
    /// The WGAN-GP critic's settings (Gulrajani et al. 2017, Algorithm 1 defaults:
    /// α = 1e−4, β1 = 0, β2 = 0.9); ε = 1e−8 is Kingma & Ba's default.
    fn default() -> Self {
        Self {
            lr: 1e-4,
            beta1: 0.0,
            beta2: 0.9,
            eps: 1e-8,
        }
    }
}

impl AdamConfig {
    /// Checks the ranges Adam needs (`α > 0`, `0 ≤ β < 1`, `ε > 0`, all finite).
    pub fn validate(&self) -> Result<(), String> {
        let ok = self.lr.is_finite()
            && self.lr > 0.0
            && (0.0..1.0).contains(&self.beta1)
            && (0.0..1.0).contains(&self.beta2)
            && self.eps.is_finite()
            && self.eps > 0.0;
        if ok {
            Ok(())
        } else {
            Err(format!(
                "Adam needs lr > 0, 0 <= beta1, beta2 < 1 and eps > 0; got {self:?}"
            ))
        }
    }
}

/// Adam's state: step count and the two moment estimates, one entry per parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    pub config: AdamConfig,
    pub(crate) t: u64,
    pub(crate) m: Vec<f64>,
    pub(crate) v: Vec<f64>,
}

impl Adam {
    /// Fresh state (`t = 0`, zero moments) for `n` parameters.
    pub fn new(config: AdamConfig, n: usize) -> Self {
        Self {
            config,
            t: 0,
            m: vec![0.0; n],
            v: vec![0.0; n],
        }
    }

    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// One descent step on `θ` with gradient `g` (Kingma & Ba, Algorithm 1):
    /// `m ← β1 m + (1−β1) g`, `v ← β2 v + (1−β2) g²`,
    /// `θ ← θ − α m̂ / (sqrt(v̂) + ε)` with `m̂ = m/(1−β1ᵗ)`, `v̂ = v/(1−β2ᵗ)`.
    pub fn step(&mut self, theta: &mut [f64], g: &[f64]) {
        assert_eq!(theta.len(), self.m.len());
        assert_eq!(g.len(), self.m.len());
        self.t += 1;
        let AdamConfig {
            lr,
            beta1,
            beta2,
            eps,
        } = self.config;
        let t = self.t as f64;
        let c1 = 1.0 - beta1.powf(t);
        let c2 = 1.0 - beta2.powf(t);
        for (((th, &gi), m), v) in theta.iter_mut().zip(g).zip(&mut self.m).zip(&mut self.v) {
            *m = beta1 * *m + (1.0 - beta1) * gi;
            *v = beta2 * *v + (1.0 - beta2) * gi * gi;
            *th -= lr * (*m / c1) / ((*v / c2).sqrt() + eps);
        }
    }
}
