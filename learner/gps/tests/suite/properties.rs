//! Properties of the KL-bounded LQR beyond the GPS vectors, on seeded random stable linear
//! systems with quadratic cost.

use gps::policy::lin_gauss::LinGaussPolicy;
use gps::synthetic::random_problem;
use gps::traj_opt::lqr::{TrajInfo, TrajOptConfig, TrajOptLqr};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

type M = Vec<Vec<f64>>;

fn mat(rows: usize, cols: usize, f: impl Fn(usize, usize) -> f64) -> M {
    (0..rows)
        .map(|i| (0..cols).map(|j| f(i, j)).collect())
        .collect()
}
fn mul(a: &M, b: &M) -> M {
    mat(a.len(), b[0].len(), |i, j| {
        (0..b.len()).map(|k| a[i][k] * b[k][j]).sum()
    })
}
fn tr(a: &M) -> M {
    mat(a[0].len(), a.len(), |i, j| a[j][i])
}
fn add(a: &M, b: &M) -> M {
    mat(a.len(), a[0].len(), |i, j| a[i][j] + b[i][j])
}
fn sub(a: &M, r0: usize, c0: usize, r: usize, c: usize) -> M {
    mat(r, c, |i, j| a[r0 + i][c0 + j])
}
/// Gauss–Jordan inverse with partial pivoting.
fn inv(a: &M) -> M {
    let n = a.len();
    let mut m: M = (0..n)
        .map(|i| {
            a[i].iter()
                .copied()
                .chain((0..n).map(|j| if i == j { 1.0 } else { 0.0 }))
                .collect()
        })
        .collect();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&x, &y| m[x][c].abs().total_cmp(&m[y][c].abs()))
            .unwrap();
        m.swap(c, p);
        let d = m[c][c];
        m[c].iter_mut().for_each(|x| *x /= d);
        for r in 0..n {
            if r != c {
                let f = m[r][c];
                let row = m[c].clone();
                m[r].iter_mut().zip(row).for_each(|(x, y)| *x -= f * y);
            }
        }
    }
    m.into_iter().map(|r| r[n..].to_vec()).collect()
}

/// Textbook finite-horizon LQR with affine dynamics and linear cost terms (Riccati
/// recursion written independently of the crate). Returns per-step (K, k, Quu⁻¹).
fn riccati(info: &TrajInfo) -> Vec<(M, Vec<f64>, M)> {
    let d = &info.dynamics;
    let (t_len, dx, du) = (d.t, d.dx, d.du);
    let n = dx + du;
    let mut v: M = mat(dx, dx, |_, _| 0.0);
    let mut vv: Vec<f64> = vec![0.0; dx];
    let mut out = vec![(M::new(), Vec::new(), M::new()); t_len];
    for t in (0..t_len).rev() {
        let c = mat(n, n, |i, j| info.cm.slice(t)[i * n + j]);
        let cv: Vec<f64> = info.cv.slice(t).to_vec();
        let f = mat(dx, n, |i, j| d.fm.slice(t)[i * n + j]);
        let fv = d.fv.slice(t);
        let mut q = c.clone();
        let mut qv = cv.clone();
        if t < t_len - 1 {
            q = add(&q, &mul(&tr(&f), &mul(&v, &f)));
            let vf: Vec<f64> = (0..dx)
                .map(|i| vv[i] + (0..dx).map(|j| v[i][j] * fv[j]).sum::<f64>())
                .collect();
            for a in 0..n {
                qv[a] += (0..dx).map(|i| f[i][a] * vf[i]).sum::<f64>();
            }
        }
        let quu = sub(&q, dx, dx, du, du);
        let qux = sub(&q, dx, 0, du, dx);
        let qxx = sub(&q, 0, 0, dx, dx);
        let qiu = inv(&quu);
        let kk = mat(du, dx, |i, j| -mul(&qiu, &qux)[i][j]);
        let kf: Vec<f64> = (0..du)
            .map(|i| -(0..du).map(|j| qiu[i][j] * qv[dx + j]).sum::<f64>())
            .collect();
        // V = Qxx + Kᵀ Qux + Quxᵀ K + Kᵀ Quu K
        v = add(
            &add(&qxx, &mul(&tr(&kk), &qux)),
            &add(&mul(&tr(&qux), &kk), &mul(&tr(&kk), &mul(&quu, &kk))),
        );
        v = mat(dx, dx, |i, j| 0.5 * (v[i][j] + v[j][i]));
        // v = qx + Kᵀ qu + Quxᵀ k + Kᵀ Quu k
        let quk: Vec<f64> = (0..du)
            .map(|i| (0..du).map(|j| quu[i][j] * kf[j]).sum())
            .collect();
        vv = (0..dx)
            .map(|a| {
                qv[a]
                    + (0..du)
                        .map(|i| kk[i][a] * (qv[dx + i] + quk[i]) + qux[i][a] * kf[i])
                        .sum::<f64>()
            })
            .collect();
        out[t] = (kk, kf, qiu);
    }
    out
}

fn rel(a: f64, b: f64, scale: f64) -> f64 {
    (a - b).abs() / scale.max(1e-12)
}

#[test]
fn small_eta_reproduces_plain_lqr() {
    for seed in 0..4u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let (t, dx, du) = (15, 6, 2);
        let (_sys, prev, info) = random_problem(&mut rng, t, dx, du);
        let mut opt = TrajOptLqr::new(TrajOptConfig::default(), t, dx, du);
        let mut out = LinGaussPolicy::zeros(t, dx, du);
        let eta = 1e-9;
        let mut e = [eta];
        opt.backward(&prev, &info, &mut e, &mut out).unwrap();
        assert_eq!(e[0], eta, "no PD retry expected on a convex problem");
        let lqr = riccati(&info);
        // Errors are measured against each quantity's largest magnitude over the horizon
        // (the last step's K is 0 for a cost without cross terms).
        let ks = lqr
            .iter()
            .flat_map(|l| l.0.iter().flatten())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        let fs = lqr
            .iter()
            .flat_map(|l| l.1.iter())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        let ps = lqr
            .iter()
            .flat_map(|l| l.2.iter().flatten())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        for s in 0..t {
            let (kk, kf, qiu) = &lqr[s];
            for i in 0..du {
                assert!(
                    rel(out.k.slice(s)[i], kf[i], fs) < 1e-6,
                    "seed {seed} t {s} k"
                );
                for j in 0..dx {
                    assert!(
                        rel(out.gain.slice(s)[i * dx + j], kk[i][j], ks) < 1e-6,
                        "seed {seed} t {s} K"
                    );
                }
                // The cost is scaled by 1/η, so Σ = η Quu⁻¹ of the plain problem.
                for j in 0..du {
                    assert!(
                        rel(out.pol_covar.slice(s)[i * du + j] / eta, qiu[i][j], ps) < 1e-6,
                        "seed {seed} t {s} Σ"
                    );
                }
            }
        }
    }
}

#[test]
fn eta_search_lands_within_ten_percent_of_the_kl_target() {
    for seed in 0..5u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(200 + seed);
        let (t, dx, du) = (20, 6, 2);
        let (_sys, prev, info) = random_problem(&mut rng, t, dx, du);
        let mut opt = TrajOptLqr::new(TrajOptConfig::default(), t, dx, du);
        let mut out = LinGaussPolicy::zeros(t, dx, du);
        for step_mult in [0.1, 1.0, 5.0] {
            let target = 0.2 * step_mult * t as f64;
            let res = opt.update(&prev, &info, 1.0, target, &mut out).unwrap();
            assert!(
                res.converged,
                "seed {seed} mult {step_mult}: {:?}",
                res.trace
            );
            // Recompute the KL of the returned controller independently of the trace.
            let (_, kl) = opt.kl(&out, &info, &out, &prev, false).unwrap();
            assert!(
                (kl - target).abs() <= 0.1 * target,
                "seed {seed}: KL {kl} vs target {target}"
            );
            assert!(res.trace.len() > 1 || (res.trace[0].kl - target).abs() <= 0.1 * target);
        }
    }
}

#[test]
fn per_step_mode_bounds_each_step() {
    let mut rng = ChaCha8Rng::seed_from_u64(300);
    let (t, dx, du) = (10, 4, 2);
    let (_sys, prev, info) = random_problem(&mut rng, t, dx, du);
    let cfg = TrajOptConfig {
        cons_per_step: true,
        ..TrajOptConfig::default()
    };
    let mut opt = TrajOptLqr::new(cfg, t, dx, du);
    let mut out = LinGaussPolicy::zeros(t, dx, du);
    let kl_step = vec![0.2; t];
    let res = opt
        .update_per_step(&prev, &info, &vec![1.0; t], &kl_step, &mut out)
        .unwrap();
    let kl = res.trace_kl.last().unwrap();
    if res.converged {
        for s in 0..t {
            assert!(
                (kl[s] - kl_step[s]).abs() < 0.1 * kl_step[s],
                "step {s}: {kl:?}"
            );
        }
    } else {
        // GPS gives up after 20 bracketing + 200 Adam rounds; the mean KL must still be close.
        let mean: f64 = kl.iter().sum::<f64>() / t as f64;
        assert!((mean - 0.2).abs() < 0.1, "{kl:?}");
    }
}
