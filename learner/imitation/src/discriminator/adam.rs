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
        let c = AdamStep {
            lr,
            beta1,
            beta2,
            eps,
            c1: 1.0 - beta1.powf(t),
            c2: 1.0 - beta2.powf(t),
        };
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: AVX is present (checked above).
            unsafe { adam_lanes_avx(&c, theta, g, &mut self.m, &mut self.v) };
            return;
        }
        adam_lanes(&c, theta, g, &mut self.m, &mut self.v);
    }
}

/// The constants of one Adam step (`c1`, `c2`: the bias corrections 1 − β^t).
struct AdamStep {
    lr: f64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    c1: f64,
    c2: f64,
}

/// The element loop of [`Adam::step`] (any CPU; inlined into [`adam_lanes_avx`], where the
/// compiler vectorises it with the same operations per element, so the same bits: IEEE
/// division and square root are exact, and no multiply-add is fused).
#[inline(always)]
fn adam_lanes(c: &AdamStep, theta: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64]) {
    for (((th, &gi), m), v) in theta.iter_mut().zip(g).zip(m).zip(v) {
        *m = c.beta1 * *m + (1.0 - c.beta1) * gi;
        *v = c.beta2 * *v + (1.0 - c.beta2) * gi * gi;
        *th -= c.lr * (*m / c.c1) / ((*v / c.c2).sqrt() + c.eps);
    }
}

/// [`adam_lanes`] compiled for AVX (docs/design.md §5 D32).
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn adam_lanes_avx(c: &AdamStep, theta: &mut [f64], g: &[f64], m: &mut [f64], v: &mut [f64]) {
    adam_lanes(c, theta, g, m, v);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// `Adam::step` (AVX where the CPU has it) equals the scalar element loop bit for bit over
    /// 50 steps, for lengths around the four-wide blocks and gradients over many binades.
    #[test]
    fn step_is_the_scalar_loop_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let cfg = AdamConfig {
            lr: 3e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-5,
        };
        for n in 0..=13 {
            let mut fast = Adam::new(cfg, n);
            let mut slow = Adam::new(cfg, n);
            let mut th_fast: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut th_slow = th_fast.clone();
            for step in 1..=50u64 {
                let g: Vec<f64> = (0..n)
                    .map(|_| rng.random_range(-1.0..1.0) * 2f64.powi(rng.random_range(-30..10)))
                    .collect();
                fast.step(&mut th_fast, &g);
                let t = step as f64;
                let c = AdamStep {
                    lr: cfg.lr,
                    beta1: cfg.beta1,
                    beta2: cfg.beta2,
                    eps: cfg.eps,
                    c1: 1.0 - cfg.beta1.powf(t),
                    c2: 1.0 - cfg.beta2.powf(t),
                };
                slow.t += 1;
                adam_lanes(&c, &mut th_slow, &g, &mut slow.m, &mut slow.v);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&th_fast), bits(&th_slow), "n {n}, step {step}");
                assert_eq!(bits(&fast.m), bits(&slow.m));
                assert_eq!(bits(&fast.v), bits(&slow.v));
            }
        }
    }
}
