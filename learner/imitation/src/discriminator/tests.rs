//! Finite-difference checks of every derivative, plus Adam and workspace reuse.
//!
//! Fourth-order central differences
//! `f'(p) ≈ [8 (f(p+h) − f(p−h)) − (f(p+2h) − f(p−2h))] / 12h` with `h = 1e−3` in the net's
//! own units (for a raw input `h_j = 1e−3 σ_j`, i.e. 1e−3 after normalisation); truncation is
//! `O(h⁴)`. The tests require `|analytic − fd| / max(|fd|, 1e−4) ≤ 1e−6` entrywise.
//! Step choice, measured: the two-point stencil with h = 1e−5 left 3.5e−6 on the penalty
//! gradient (its `h² f'''` truncation, large with σ = 0.1 inputs); with the four-point
//! stencil the worst error falls as h grows from 3e−5 (> 1e−6) through 1e−4 (5.8e−7) and
//! 3e−4 (2.4e−7) to 1e−3 (1.7e−7), so it is round-off, not truncation, at 1e−3.

use faer::Mat;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::*;
use ur5_shared::layout::DX;

const H: f64 = 5e-4;
const FLOOR: f64 = 1e-4;
const TOL: f64 = 1e-6;

/// Fourth-order central difference of `f` at 0 with step `h`.
fn central_diff(mut f: impl FnMut(f64) -> f64, h: f64) -> f64 {
    let d1 = f(h) - f(-h);
    let d2 = f(2.0 * h) - f(-2.0 * h);
    (8.0 * d1 - d2) / (12.0 * h)
}

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

#[derive(Clone)]
struct Case {
    d: usize,
    hidden: Vec<usize>,
    normalise: bool,
    seed: u64,
    space: PenaltySpace,
    /// `near_goal_scale` (m; 0 = off).
    warp: f64,
    /// `near_goal_far_slope`.
    far_slope: f64,
    /// `near_goal_keep_raw`.
    keep_raw: bool,
}

/// Every case once per gradient-penalty space.
fn cases_both_spaces() -> Vec<Case> {
    let mut v = Vec::new();
    for space in [PenaltySpace::Raw, PenaltySpace::Normalised] {
        v.extend(cases().into_iter().map(|c| Case { space, ..c }));
    }
    v
}

/// The penalty `λ (‖v‖ − 1)²` as its definition states, from D's raw-input gradient `g`:
/// `v = g` (raw) or `v = g ⊙ σ = ∇_u D` (normalised).
fn penalty_by_definition(d: &Discriminator, x: &[f64]) -> f64 {
    let mut ws = d.workspace();
    let mut g = vec![0.0; d.input_dim()];
    d.value_gradient(x, &mut ws, &mut g);
    if d.config().penalty_space == PenaltySpace::Normalised {
        for (gi, s) in g.iter_mut().zip(&d.normalizer().std) {
            *gi *= s;
        }
    }
    let n = g.iter().map(|v| v * v).sum::<f64>().sqrt();
    d.config().lambda_gp * (n - 1.0) * (n - 1.0)
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
                space: PenaltySpace::Raw,
                warp: 0.0,
                far_slope: 0.0,
                keep_raw: false,
            });
        }
    }
    v
}

/// A critic with random (also non-zero bias) weights and, if asked, a normalisation with
/// σ spread over two decades, plus a few inputs drawn around μ.
fn random_critic(c: &Case) -> (Discriminator, Vec<Vec<f64>>) {
    let mut rng = ChaCha8Rng::seed_from_u64(c.seed);
    let config = DiscriminatorConfig {
        hidden: c.hidden.clone(),
        seed: c.seed,
        penalty_space: c.space,
        near_goal_scale: c.warp,
        near_goal_far_slope: c.far_slope,
        near_goal_keep_raw: c.keep_raw,
        ..Default::default()
    };
    let dn = config.net_inputs(c.d);
    let norm = if c.normalise {
        Normalizer {
            mean: (0..dn).map(|_| rng.random_range(-2.0..2.0)).collect(),
            std: (0..dn)
                .map(|_| 10f64.powf(rng.random_range(-1.0..1.0)))
                .collect(),
        }
    } else {
        Normalizer::identity(dn)
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

/// [`cases`], plus the 2 dX-input ones again with the tool-point inputs warped
/// (`near_goal_scale` 0.3, on the scale of the inputs' spread so that g'' matters), without
/// and with a far slope, and with raw copies beside the warped inputs; for the point task
/// (dX = 12) and the six-joint pose task (dX = 30, three tool points).
fn cases_with_warp() -> Vec<Case> {
    let mut v = cases();
    let pose_d = 2 * ur5_shared::StateLayout::POSE6.dx();
    let warped: Vec<Case> = v
        .iter()
        .filter(|c| c.d == 2 * DX)
        .flat_map(|c| {
            [
                c.clone(),
                Case {
                    d: pose_d,
                    ..c.clone()
                },
            ]
        })
        .flat_map(|c| {
            [(0.0, false), (0.2, false), (0.0, true)].map(|(far_slope, keep_raw)| Case {
                space: PenaltySpace::Normalised,
                warp: 0.3,
                far_slope,
                keep_raw,
                ..c.clone()
            })
        })
        .collect();
    assert!(!warped.is_empty());
    v.extend(warped);
    v
}

#[test]
fn discriminator_input_gradient_matches_finite_differences() {
    let mut worst: f64 = 0.0;
    for c in cases_with_warp() {
        let (disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        for x in &xs {
            let mut g = vec![0.0; c.d];
            disc.value_gradient(x, &mut ws, &mut g);
            let mut fd = vec![0.0; c.d];
            let mut xp = x.clone();
            for j in 0..c.d {
                let h = H * disc.normalizer().std[j];
                fd[j] = central_diff(
                    |t| {
                        xp[j] = x[j] + t;
                        disc.value(&xp, &mut ws)
                    },
                    h,
                );
                xp[j] = x[j];
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
    for c in cases_with_warp() {
        let (disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        for x in &xs {
            let d = c.d;
            let mut g = vec![0.0; d];
            let mut hess = Mat::<f64>::zeros(d, d);
            let y = disc.value_gradient_hessian(x, &mut ws, &mut g, hess.as_mut());
            assert_eq!(y, disc.value(x, &mut ws));
            let mut fd = vec![0.0; d * d];
            let mut gp = vec![0.0; d];
            let mut xp = x.clone();
            for j in 0..d {
                let h = H * disc.normalizer().std[j];
                let mut cols = [vec![0.0; d], vec![0.0; d], vec![0.0; d], vec![0.0; d]];
                for (col, t) in cols.iter_mut().zip([h, -h, 2.0 * h, -2.0 * h]) {
                    xp[j] = x[j] + t;
                    disc.value_gradient(&xp, &mut ws, &mut gp);
                    col.copy_from_slice(&gp);
                }
                xp[j] = x[j];
                for i in 0..d {
                    let (d1, d2) = (cols[0][i] - cols[1][i], cols[2][i] - cols[3][i]);
                    fd[i * d + j] = (8.0 * d1 - d2) / (12.0 * h);
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
        *o = central_diff(
            |s| {
                disc.params_mut()[p] = t + s;
                f(disc)
            },
            H,
        );
        disc.params_mut()[p] = t;
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
    for c in cases_both_spaces() {
        let (mut disc, xs) = random_critic(&c);
        let mut ws = disc.workspace();
        for x in &xs {
            let mut grad = vec![0.0; disc.params().len()];
            let p = disc.accumulate_penalty_gradient(x, 0.8, &mut ws, &mut grad);
            let penalty = |d: &Discriminator| penalty_by_definition(d, x);
            assert!((p - penalty(&disc)).abs() <= 1e-12 * p.abs().max(1.0));
            let fd: Vec<f64> = fd_params(&mut disc, penalty)
                .into_iter()
                .map(|v| 0.8 * v)
                .collect();
            let (rel, _) = rel_err(&grad, &fd);
            assert!(
                rel <= TOL,
                "penalty gradient rel err {rel:e}, sizes {:?}, {:?}",
                c.hidden,
                c.space
            );
            worst = worst.max(rel);
        }
    }
    eprintln!("penalty gradient: max rel err {worst:.2e}");
}

#[test]
fn discriminator_penalty_spaces_differ_only_under_normalisation() {
    // Without normalisation (σ = 1) the two spaces are the same penalty; with σ ≠ 1 they are not.
    for c in cases().into_iter().take(2) {
        let raw = random_critic(&c);
        let nrm = random_critic(&Case {
            space: PenaltySpace::Normalised,
            ..c.clone()
        });
        let x = raw.1[0].clone();
        let (pr, pn) = (
            penalty_by_definition(&raw.0, &x),
            penalty_by_definition(&nrm.0, &x),
        );
        let (mut wr, mut wn) = (raw.0.workspace(), nrm.0.workspace());
        let mut g = vec![0.0; raw.0.params().len()];
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(1.0);
        let got_r = raw.0.accumulate_penalty_gradient(&x, 1.0, &mut wr, &mut g);
        let got_n = nrm.0.accumulate_penalty_gradient(&x, 1.0, &mut wn, &mut g);
        assert!(
            close(got_r, pr) && close(got_n, pn),
            "{got_r} {pr} {got_n} {pn}"
        );
        if c.normalise {
            assert!(
                (pr - pn).abs() > 1e-6 * pr.abs().max(pn.abs()),
                "{pr} vs {pn}"
            );
        } else {
            assert!((pr - pn).abs() <= 1e-12 * pr.abs().max(1.0), "{pr} vs {pn}");
        }
    }
}

#[test]
fn discriminator_critic_loss_gradient_matches_finite_differences() {
    // The whole per-sample WGAN-GP loss as `train` uses it: sign and composition included.
    let mut worst: f64 = 0.0;
    for c in cases_both_spaces().iter().filter(|c| c.normalise) {
        let (mut disc, xs) = random_critic(c);
        let mut ws = disc.workspace();
        let triples = [(0, 1, 0.3), (1, 2, 0.9), (2, 0, 0.05)];
        let mut grad = vec![0.0; disc.params().len()];
        let mut total = 0.0;
        for &(e, k, eps) in &triples {
            let (l, p) =
                disc.accumulate_critic_loss_gradient(&xs[e], &xs[k], eps, 0.5, &mut ws, &mut grad);
            let x_hat: Vec<f64> = xs[e]
                .iter()
                .zip(&xs[k])
                .map(|(a, b)| eps * a + (1.0 - eps) * b)
                .collect();
            let want_p = penalty_by_definition(&disc, &x_hat);
            let want_l = disc.value(&xs[e], &mut ws) - disc.value(&xs[k], &mut ws) + want_p;
            assert!((p - want_p).abs() <= 1e-12 * want_p.max(1.0));
            assert!((l - want_l).abs() <= 1e-12 * want_l.abs().max(1.0));
            total += l;
        }
        let loss = |d: &Discriminator| {
            let mut ws = d.workspace();
            let mut sink = vec![0.0; d.params().len()];
            triples
                .iter()
                .map(|&(e, k, eps)| {
                    0.5 * d
                        .accumulate_critic_loss_gradient(
                            &xs[e], &xs[k], eps, 0.0, &mut ws, &mut sink,
                        )
                        .0
                })
                .sum::<f64>()
        };
        assert_eq!(loss(&disc), 0.5 * total);
        let fd = fd_params(&mut disc, loss);
        let (rel, _) = rel_err(&grad, &fd);
        assert!(
            rel <= TOL,
            "critic loss gradient rel err {rel:e}, sizes {:?}",
            c.hidden
        );
        worst = worst.max(rel);
    }
    eprintln!("critic loss gradient: max rel err {worst:.2e}");
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

/// `max |a − b| / max |b|` over two equally long slices.
fn scaled_diff(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    diff / scale
}

#[test]
fn first_layer_hessian_through_the_first_weights_is_the_input_hessian() {
    let mut worst: f64 = 0.0;
    for c in cases_with_warp() {
        let (disc, xs) = random_critic(&c);
        let net = disc.net();
        let (n0, h1) = (net.input_dim(), net.sizes()[1]);
        let w0 = net.first_weights();
        let mut ws = net_workspace(&disc);
        for x in &xs {
            // The net's own input u: any point will do, these are the critic's raw inputs
            // padded with the raw copies' columns.
            ws.u.copy_from_slice(&pad(x, n0));
            net.forward(&mut ws);
            net.backward(&mut ws, true);
            let mut hess_u = vec![0.0; n0 * n0];
            net.input_hessian(&mut ws, &mut hess_u);
            let mut b = vec![0.0; h1 * h1];
            net.first_layer_hessian(&mut ws, &mut b);
            // W_0ᵀ B W_0 by the definition, entry by entry.
            let mut through = vec![0.0; n0 * n0];
            for p in 0..n0 {
                for q in 0..n0 {
                    let mut v = 0.0;
                    for i in 0..h1 {
                        for j in 0..h1 {
                            v += w0[i * n0 + p] * b[i * h1 + j] * w0[j * n0 + q];
                        }
                    }
                    through[p * n0 + q] = v;
                }
            }
            for p in 0..h1 {
                for q in 0..h1 {
                    assert_eq!(b[p * h1 + q], b[q * h1 + p], "B symmetric bit for bit");
                }
            }
            worst = worst.max(scaled_diff(&through, &hess_u));
        }
    }
    assert!(worst <= 1e-12, "W0ᵀ B W0 against ∇²_u: {worst:.2e}");
}

fn net_workspace(disc: &Discriminator) -> MlpWorkspace {
    MlpWorkspace::new(disc.net().sizes())
}

fn pad(x: &[f64], n: usize) -> Vec<f64> {
    (0..n).map(|i| x[i % x.len()]).collect()
}

/// Adds more points around the case's own, so that a mean is over several.
fn points(disc: &Discriminator, xs: &[Vec<f64>], seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let s = &disc.normalizer().std;
    let mut v = xs.to_vec();
    for x in xs {
        v.push(
            x.iter()
                .zip(s)
                .map(|(xi, si)| xi + 0.5 * si * rng.random_range(-1.0..1.0))
                .collect(),
        );
    }
    v
}

#[test]
fn the_mean_hessian_through_the_first_layer_equals_the_mean_per_point() {
    let mut worst: f64 = 0.0;
    let mut wide = cases_with_warp();
    // Wider inputs than the first layer without the warp too (every column fixed).
    wide.push(Case {
        d: 60,
        hidden: vec![16, 8],
        normalise: true,
        seed: 7,
        space: PenaltySpace::Raw,
        warp: 0.0,
        far_slope: 0.0,
        keep_raw: false,
    });
    for c in wide {
        let (disc, xs) = random_critic(&c);
        let d = disc.input_dim();
        let xs = points(&disc, &xs, c.seed + 1);
        let mut ws = disc.workspace();
        let (mut g, mut g2) = (vec![0.0; d], vec![0.0; d]);
        // The per-point mean as the composite cost formed it before: sum, then × 1/N.
        let mut by_hand = Mat::<f64>::zeros(d, d);
        let mut one = Mat::<f64>::zeros(d, d);
        for x in &xs {
            disc.value_gradient_hessian(x, &mut ws, &mut g, one.as_mut());
            by_hand += &one;
        }
        by_hand *= faer::Scale(1.0 / xs.len() as f64);
        for factored in [false, true] {
            let mut acc = disc.mean_hessian_on(factored);
            let mut mean = Mat::<f64>::zeros(d, d);
            // Twice: the accumulator empties itself after each mean.
            for _ in 0..2 {
                acc.prepare(&disc);
                for x in &xs {
                    let y = disc.value_gradient_add_hessian(x, &mut ws, &mut g2, &mut acc);
                    let y_ref = disc.value_gradient(x, &mut ws, &mut g);
                    assert_eq!(y.to_bits(), y_ref.to_bits());
                    assert_eq!(g2, g, "same gradient");
                }
                acc.mean_into(mean.as_mut());
            }
            let a: Vec<f64> = (0..d * d).map(|k| mean[(k / d, k % d)]).collect();
            let b: Vec<f64> = (0..d * d).map(|k| by_hand[(k / d, k % d)]).collect();
            if factored {
                worst = worst.max(scaled_diff(&a, &b));
            } else {
                assert_eq!(a, b, "the per-point route keeps the bits ({} inputs)", d);
            }
        }
    }
    assert!(
        worst <= 1e-12,
        "through the first layer against per point: {worst:.2e}"
    );
}

#[test]
fn the_mean_hessian_goes_through_the_first_layer_only_where_that_is_cheaper() {
    let pose_d = 2 * ur5_shared::StateLayout::POSE6.dx();
    let route = |d: usize, keep_raw: bool| {
        let c = Case {
            d,
            hidden: vec![64, 64],
            normalise: false,
            seed: 1,
            space: PenaltySpace::Normalised,
            warp: 0.3,
            far_slope: 0.0,
            keep_raw,
        };
        random_critic(&c).0.mean_hessian().factored()
    };
    // Three joints and a point: 24 (+ 6 raw copies) inputs into 64 units: per point.
    assert!(!route(2 * DX, true));
    // Six joints and a pose: 60 + 18 inputs into 64 units: through the first layer.
    assert!(route(pose_d, true));
    assert!(!route(pose_d, false));
}
