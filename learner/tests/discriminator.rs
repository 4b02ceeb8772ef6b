//! Integration tests of the WGAN-GP discriminator.

use faer::Mat;
use learner::discriminator::{AdamConfig, Discriminator, DiscriminatorConfig, Normalizer};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

fn gaussian(n: usize, mean: &[f64], std: f64, rng: &mut ChaCha8Rng) -> Mat<f64> {
    Mat::from_fn(n, mean.len(), |_, j| {
        let z: f64 = StandardNormal.sample(rng);
        mean[j] + std * z
    })
}

#[test]
fn discriminator_explore_toy() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (me, mc) = ([0.0, 0.0], [0.6, 0.8]);
    let s = 0.3;
    let e = gaussian(2000, &me, s, &mut rng);
    let c = gaussian(2000, &mc, s, &mut rng);
    let ee = gaussian(20000, &me, s, &mut rng);
    let ce = gaussian(20000, &mc, s, &mut rng);
    for lr in [1e-4, 1e-3] {
        let config = DiscriminatorConfig {
            adam: AdamConfig {
                lr,
                ..Default::default()
            },
            seed: 3,
            ..Default::default()
        };
        let mut d =
            Discriminator::new(2, config, Normalizer::from_data(e.as_ref()).unwrap()).unwrap();
        let mut ws = d.workspace();
        let t0 = std::time::Instant::now();
        for it in 0..400 {
            let st = d.train(e.as_ref(), c.as_ref(), &mut ws).unwrap();
            if it % 40 == 39 {
                let w = d.wasserstein_estimate(ee.as_ref(), ce.as_ref(), &mut ws);
                eprintln!(
                    "lr {lr} it {it} loss {:.4} gp {:.4} w_train {:.4} w_eval {:.4} t {:?}",
                    st.critic_loss,
                    st.gradient_penalty,
                    st.wasserstein,
                    w,
                    t0.elapsed()
                );
            }
        }
    }
}
