//! Finite-difference checks of every derivative, plus Adam and workspace reuse.
//!
//! Central differences `(f(p + h) − f(p − h)) / 2h` with `h = 1e−5` in the net's own units
//! (for raw inputs `h_j = 1e−5 σ_j`, i.e. 1e−5 after normalisation). Truncation error is
//! `O(h²) ≈ 1e−10` and round-off `≈ 1e−16 / h ≈ 1e−11` for values of order 1, so a correct
//! derivative matches to ~1e−9; the tests require `|analytic − fd| / max(|fd|, 1e−4) ≤ 1e−6`
//! entrywise.

use faer::Mat;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::*;

const H: f64 = 1e-5;
const FLOOR: f64 = 1e-4;
const TOL: f64 = 1e-6;

/// `max_i |a_i − f_i| / max(|f_i|, FLOOR)` and `max_i |a_i − f_i|`.
fn rel_err(analytic: &[f64], fd: &[f64]) -> (f64, f64) {
    assert_eq!(analytic.len(), fd.len());
    let mut rel: f64 = 0.0;
    let mut abs: f64 = 0.0;
    for (a, f) in analytic.iter().zip(fd) {
        let e = (a - f).abs();
        abs = abs.max(e);
        rel = rel.max(e / f.abs().max(FLOOR));
    }
    (rel, abs)
}

struct Case {
    d: usize,
    hidden: Vec<usize>,
    normalise: bool,
    seed: u64,
}

fn cases() -> Vec<Case> {
    let mut v = Vec::new();
    for (seed, (d, hidden)) in [
        (24, vec![64, 64]),
        (5, vec![7, 3]),
        (6, vec![8]),
        (4, vec![6, 5, 7]),
    ]
    .into_iter()
    .enumerate()
    {
        for normalise in [false, true] {
            v.push(Case {
                d,
                hidden: hidden.clone(),
                normalise,
                seed: 100 + seed as u64,
            });
        }
    }
    v
}

/// A critic with random (also non-zero bias) weights and, if asked, a normalisation with
/// σ spread over two decades, plus a few inputs drawn around μ.
fn random_critic(c: &Case) -> (Discriminator, Vec<Vec<f64>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(c.seed);
    let norm = if c.normalise {
        Normalizer {
            mean: (0..c.d).map(|_| rng.random_range(-2.0..2.0)).collect(),
            std: (0..c.d)
                .map(|_| 10f64.powf(rng.random_range(-1.0..1.0)))
                .collect(),
        }
    } else {
        Normalizer::identity(c.d)
    };
    let config = DiscriminatorConfig {
        hidden: c.hidden.clone(),
        seed: c.seed,
        ..Default::default()
    };
    let mut disc = Discriminator::new(c.d, config, norm.clone()).unwrap();
    let net = disc.net().clone();
    for k in 0..net.layers() {
        for b in &mut disc.params_mut()[net.bias_range(k)] {
            *b = rng.random_range(-0.5..0.5);
        }
    }
    let xs = (0..3)
        .map(|_| {
            (0..c.d)
                .map(|j| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    norm.mean[j] + 1.5 * norm.std[j] * z
                })
                .collect()
        })
        .collect();
    (disc, xs)
}

#[test]
fn discriminator_input_gradient_matches_finite_differences() {
    let mut worst: f64 = 0.0;
    for c in cases() {
        let (disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        for x in &xs {
            let mut g = vec![0.0; c.d];
            disc.value_gradient(x, &mut ws, &mut g);
            let mut fd = vec![0.0; c.d];
            let mut xp = x.clone();
            for j in 0..c.d {
                let h = H * disc.normalizer().std[j];
                xp[j] = x[j] + h;
                let fp = disc.value(&xp, &mut ws);
                xp[j] = x[j] - h;
                let fm = disc.value(&xp, &mut ws);
                xp[j] = x[j];
                fd[j] = (fp - fm) / (2.0 * h);
            }
            let (rel, _) = rel_err(&g, &fd);
            assert!(
                rel <= TOL,
                "input gradient rel err {rel:e}, sizes {:?}",
                c.hidden
            );
            worst = worst.max(rel);
        }
    }
    eprintln!("input gradient: max rel err {worst:.2e}");
}

#[test]
fn discriminator_input_hessian_matches_finite_differences() {
    let mut worst: f64 = 0.0;
    for c in cases() {
        let (disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        for x in &xs {
            let d = c.d;
            let mut g = vec![0.0; d];
            let mut hess = Mat::<f64>::zeros(d, d);
            let y = disc.value_gradient_hessian(x, &mut ws, &mut g, hess.as_mut());
            assert_eq!(y, disc.value(x, &mut ws));
            let mut fd = vec![0.0; d * d];
            let (mut gp, mut gm) = (vec![0.0; d], vec![0.0; d]);
            let mut xp = x.clone();
            for j in 0..d {
                let h = H * disc.normalizer().std[j];
                xp[j] = x[j] + h;
                disc.value_gradient(&xp, &mut ws, &mut gp);
                xp[j] = x[j] - h;
                disc.value_gradient(&xp, &mut ws, &mut gm);
                xp[j] = x[j];
                for i in 0..d {
                    fd[i * d + j] = (gp[i] - gm[i]) / (2.0 * h);
                }
            }
            let mut an = vec![0.0; d * d];
            for i in 0..d {
                for j in 0..d {
                    an[i * d + j] = hess[(i, j)];
                    assert_eq!(hess[(i, j)], hess[(j, i)], "Hessian not symmetric");
                }
            }
            let (rel, _) = rel_err(&an, &fd);
            assert!(
                rel <= TOL,
                "input Hessian rel err {rel:e}, sizes {:?}",
                c.hidden
            );
            worst = worst.max(rel);
        }
    }
    eprintln!("input Hessian: max rel err {worst:.2e}");
}

/// FD of `θ ↦ f(θ)` over every parameter.
fn fd_params(disc: &mut Discriminator, f: impl Fn(&Discriminator) -> f64) -> Vec<f64> {
    let n = disc.params().len();
    let mut out = vec![0.0; n];
    for (p, o) in out.iter_mut().enumerate() {
        let t = disc.params()[p];
        disc.params_mut()[p] = t + H;
        let fp = f(disc);
        disc.params_mut()[p] = t - H;
        let fm = f(disc);
        disc.params_mut()[p] = t;
        *o = (fp - fm) / (2.0 * H);
    }
    out
}

#[test]
fn discriminator_weight_gradient_of_a_loss_matches_finite_differences() {
    let mut worst: f64 = 0.0;
    let coefs = [0.7, -1.3, 0.4];
    for c in cases() {
        let (mut disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        let mut grad = vec![0.0; disc.params().len()];
        for (x, &k) in xs.iter().zip(&coefs) {
            disc.accumulate_param_gradient(x, k, &mut ws, &mut grad);
        }
        let fd = fd_params(&mut disc, |d| {
            let mut ws = d.workspace();
            xs.iter()
                .zip(&coefs)
                .map(|(x, &k)| k * d.value(x, &mut ws))
                .sum()
        });
        let (rel, _) = rel_err(&grad, &fd);
        assert!(
            rel <= TOL,
            "weight gradient rel err {rel:e}, sizes {:?}",
            c.hidden
        );
        worst = worst.max(rel);
    }
    eprintln!("weight gradient of a loss: max rel err {worst:.2e}");
}

#[test]
fn discriminator_penalty_gradient_matches_finite_differences() {
    let mut worst: f64 = 0.0;
    for c in cases() {
        let (mut disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        for x in &xs {
            let mut grad = vec![0.0; disc.params().len()];
            let p = disc.accumulate_penalty_gradient(x, 0.8, &mut ws, &mut grad);
            let lambda = disc.config().lambda_gp;
            let penalty = |d: &Discriminator| {
                let mut ws = d.workspace();
                let mut g = vec![0.0; d.input_dim()];
                d.value_gradient(x, &mut ws, &mut g);
                let n = g.iter().map(|v| v * v).sum::<f64>().sqrt();
                lambda * (n - 1.0) * (n - 1.0)
            };
            assert!((p - penalty(&disc)).abs() <= 1e-12 * p.abs().max(1.0));
            let fd: Vec<f64> = fd_params(&mut disc, penalty)
                .into_iter()
                .map(|v| 0.8 * v)
                .collect();
            let (rel, _) = rel_err(&grad, &fd);
            assert!(
                rel <= TOL,
                "penalty gradient rel err {rel:e}, sizes {:?}",
                c.hidden
            );
            worst = worst.max(rel);
        }
    }
    eprintln!("penalty gradient: max rel err {worst:.2e}");
}

#[test]
fn discriminator_workspace_reuse_leaves_no_stale_state() {
    let c = &cases()[1];
    let (disc, xs) = random_critic(c);
    let mut ws = disc.workspace();
    let d = c.d;
    let (mut g1, mut g2) = (vec![0.0; d], vec![0.0; d]);
    let (mut h1, mut h2) = (Mat::<f64>::zeros(d, d), Mat::<f64>::zeros(d, d));
    let mut pg1 = vec![0.0; disc.params().len()];
    let mut pg2 = pg1.clone();
    disc.value_gradient_hessian(&xs[0], &mut ws, &mut g1, h1.as_mut());
    disc.accumulate_penalty_gradient(&xs[0], 1.0, &mut ws, &mut pg1);
    let y1 = disc.value_gradient_hessian(&xs[1], &mut ws, &mut g1, h1.as_mut());
    pg1.fill(0.0);
    disc.accumulate_penalty_gradient(&xs[1], 1.0, &mut ws, &mut pg1);
    let mut fresh = disc.workspace();
    let y2 = disc.value_gradient_hessian(&xs[1], &mut fresh, &mut g2, h2.as_mut());
    let mut fresh = disc.workspace();
    disc.accumulate_penalty_gradient(&xs[1], 1.0, &mut fresh, &mut pg2);
    assert_eq!(y1, y2);
    assert_eq!(g1, g2);
    assert_eq!(h1, h2);
    assert_eq!(pg1, pg2);
}

#[test]
fn discriminator_adam_matches_kingma_ba_by_hand() {
    let config = AdamConfig {
        lr: 0.1,
        beta1: 0.5,
        beta2: 0.9,
        eps: 1e-8,
    };
    let mut adam = Adam::new(config, 1);
    let mut theta = [1.0];
    adam.step(&mut theta, &[2.0]);
    // m = 1, v = 0.4, m̂ = 2, v̂ = 4: θ = 1 − 0.1 · 2 / (2 + 1e−8).
    assert!((theta[0] - (1.0 - 0.1 * 2.0 / (2.0 + 1e-8))).abs() < 1e-15);
    adam.step(&mut theta, &[-1.0]);
    // m = 0, v = 0.46: θ unchanged.
    let after_first = 1.0 - 0.1 * 2.0 / (2.0 + 1e-8);
    assert!((theta[0] - after_first).abs() < 1e-15);
    assert_eq!(adam.steps(), 2);
}
