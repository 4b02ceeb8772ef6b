use super::*;
use rand::Rng;
use ur5_shared::layout::{DU, DX};

/// Cloning (the regression of step 4 on the project's MLP policy) fits a known linear policy
/// Δ*(s) = K s + k on states spread as an episode's are.
#[test]
fn cloning_fits_a_known_linear_policy() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let k_mat: Vec<[f64; DX]> = (0..DU)
        .map(|_| std::array::from_fn(|_| rng.random_range(-0.05..0.05)))
        .collect();
    let k_vec: [f64; DU] = std::array::from_fn(|_| rng.random_range(-0.05..0.05));
    let scale: [f64; DX] = std::array::from_fn(|i| 0.1 + 0.2 * i as f64);
    let target = |s: &[f64; DX]| -> [f64; DU] {
        std::array::from_fn(|j| k_vec[j] + (0..DX).map(|i| k_mat[j][i] * s[i]).sum::<f64>())
    };
    let states: Vec<[f64; DX]> = (0..2000)
        .map(|_| std::array::from_fn(|i| scale[i] * rng.random_range(-1.0..1.0)))
        .collect();
    let sigma = 0.1;
    let prc = 1.0 / (sigma * sigma);
    let p: Vec<f64> = (0..DU * DU)
        .map(|i| if i / DU == i % DU { prc } else { 0.0 })
        .collect();
    let mut data = Targets::new(DX, DU);
    for s in &states {
        data.push(s, &target(s), &p);
    }
    let cfg = PolicyOptConfig {
        hidden: vec![16],
        steps: 6000,
        batch_size: 64,
        adam: crate::discriminator::AdamConfig {
            lr: 3e-3,
            ..PolicyOptConfig::default().adam
        },
        ..PolicyOptConfig::default()
    };
    let mut pol = GlobalPolicy::new(StateLayout::REACH3, &cfg.hidden, sigma, &mut rng);
    let x = faer::Mat::from_fn(states.len(), DX, |r, c| states[r][c]);
    pol.set_normalizer(Normalizer::from_data(x.as_ref()).unwrap());
    let mut opt = PolicyOpt::new(cfg, &pol, 12);
    opt.update(&mut pol, &data).unwrap();
    let mut ws = pol.workspace();
    let (mut err, mut spread, mut rms) = (0.0f64, 0.0f64, 0.0);
    for _ in 0..200 {
        let s: [f64; DX] = std::array::from_fn(|i| scale[i] * rng.random_range(-0.9..0.9));
        let (got, want) = (pol.offset(&s, &mut ws), target(&s));
        for j in 0..DU {
            err = err.max((got[j] - want[j]).abs());
            rms += (got[j] - want[j]).powi(2) / (200 * DU) as f64;
            spread = spread.max(want[j].abs());
        }
    }
    // Targets reach ~0.25 rad; on fresh states inside the data the fit is within 2 mrad RMS
    // and 10 mrad at worst (measured 1.1 and 5.0 mrad: Adam's noise floor at this
    // step size, not a bias).
    assert!(spread > 0.2, "{spread}");
    let rms = f64::sqrt(rms);
    assert!(
        rms < 2e-3 && err < 1e-2,
        "offset error RMS {rms:e}, largest {err:e} rad"
    );
    // The cloned σ is the one asked for (P = I / σ²).
    assert!(pol.std().iter().all(|s| (s - sigma).abs() < 1e-12));
}

#[test]
fn settings_that_cannot_work_are_refused_naming_the_setting() {
    assert!(BcoConfig::default().validate().is_ok());
    let cases: Vec<(&str, Box<dyn Fn(&mut BcoConfig)>)> = vec![
        ("samples", Box::new(|c| c.samples = 0)),
        ("iterations", Box::new(|c| c.iterations = 0)),
        ("pre_iterations", Box::new(|c| c.pre_iterations = 0)),
        ("explore_std", Box::new(|c| c.explore_std = f64::NAN)),
        ("model.steps", Box::new(|c| c.model.steps = usize::MAX)),
        ("policy.hidden", Box::new(|c| c.policy.hidden = vec![])),
    ];
    crate::error::assert_each_refused_naming(cases, BcoConfig::validate);
}
