//! Where does LQR+GAIfO lose precision near the goal? (docs/design.md §5 D25)
//!
//! Runs LQR+GAIfO in process and prints, per iteration, what the noise-free episode reached
//! and the quantities that could limit it: the spread of the noisy episodes' final distances,
//! the exploration standard deviation at the end of the episode, and the critic's view of
//! the final state (its value and its slope towards the goal, before and after the update).
//!
//!     cargo run --release -p learner --example precision_probe -- DEMOS.npz [SEED] [ITERS] [CONFIG.toml]
use std::path::Path;

use imitation::gaifo::{GaifoConfig, LqrGaifo};
use imitation::learn::Learn;
use imitation::rollout::Episode;
use learner::run::arm_for;
use ur5_shared::layout::{DX, EE_MINUS_GOAL};

/// The transition [s; s] of an arm at rest in `s`.
fn at_rest(s: &[f64; DX]) -> [f64; 2 * DX] {
    let mut x = [0.0; 2 * DX];
    x[..DX].copy_from_slice(s);
    x[DX..].copy_from_slice(s);
    x
}

/// D at the resting transition [s; s] of `s`, and dD/dr along the end effector's offset from
/// the goal (r = ‖ee − goal‖, s and s' moved together: an arm resting a little further out).
fn critic_at_rest(run: &LqrGaifo, s: &[f64; DX]) -> (f64, f64) {
    let disc = run.discriminator();
    let mut ws = disc.workspace();
    let x = at_rest(s);
    let mut g = [0.0; 2 * DX];
    let v = disc.value_gradient(&x, &mut ws, &mut g);
    let e = &s[EE_MINUS_GOAL];
    let r = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt().max(1e-12);
    let mut slope = 0.0;
    for (i, j) in EE_MINUS_GOAL.enumerate() {
        slope += (g[j] + g[DX + j]) * e[i] / r;
    }
    (v, slope)
}

/// A fresh critic of the run's settings trained for `steps` Adam steps on the expert vs the
/// last iteration's noisy transitions: what a critic of this size can see at all.
fn fresh_critic(
    run: &LqrGaifo,
    noisy: &[Episode],
    eval: &Episode,
    steps: usize,
) -> anyhow::Result<()> {
    use imitation::critic::{episode_transitions, expert_transitions, refit_critic};
    let expert = expert_transitions(run.demos());
    let ctrl = episode_transitions(noisy);
    let mut dcfg = run.discriminator().config().clone();
    dcfg.n_critic = 100;
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    if let Some(v) = env("PROBE_LR") {
        dcfg.adam.lr = v;
    }
    if let Some(v) = env("PROBE_LAMBDA") {
        dcfg.lambda_gp = v;
    }
    if let Some(v) = env("PROBE_BATCH") {
        dcfg.batch_size = v as usize;
    }
    if let Some(v) = env("PROBE_HIDDEN") {
        dcfg.hidden = vec![v as usize; 2];
    }
    let mut d = refit_critic(&expert, &ctrl, &dcfg)?;
    let mut ws = d.workspace();
    {
        // The best linear critic: W1 >= |mean_C - mean_E| in the critic's normalised inputs.
        let sd = &d.normalizer().std;
        let mut diff = vec![0.0; 2 * DX];
        for j in 0..2 * DX {
            let me =
                (0..expert.nrows()).map(|r| expert[(r, j)]).sum::<f64>() / expert.nrows() as f64;
            let mc = (0..ctrl.nrows()).map(|r| ctrl[(r, j)]).sum::<f64>() / ctrl.nrows() as f64;
            diff[j] = (mc - me) / sd[j];
        }
        let n = diff.iter().map(|v| v * v).sum::<f64>().sqrt();
        println!("linear critic W1 lower bound {n:.3}; normalised mean difference by block (s then s'): {:?}",
            diff.chunks(3).map(|c| format!("{:.2}", c.iter().map(|v| v * v).sum::<f64>().sqrt())).collect::<Vec<_>>());
    }
    let t_len = eval.horizon();
    let end = eval.reach3_state(t_len - 1);
    let demo_end = run.demos().reach3_state(0, t_len - 1);
    for k in 0..steps / 100 {
        let st = d.train(expert.as_ref(), ctrl.as_ref(), &mut ws)?;
        if (k + 1) % (steps / 1000).max(1) == 0 {
            let a = d.value(&at_rest(&end), &mut ws);
            let b = d.value(&at_rest(&demo_end), &mut ws);
            println!(
                "fresh critic {:>6} steps: W1 {:.3}  D(eval end) - D(demo end) {:.3}",
                (k + 1) * 100,
                st.wasserstein,
                a - b
            );
        }
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let demos = learner::io::demos::load(Path::new(&args[1]))?;
    let seed: u64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(0);
    let iters: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(30);
    let mut cfg = match args.get(4) {
        Some(p) => ur5_shared::config::from_toml_file_over(Path::new(p), GaifoConfig::default())?,
        None => GaifoConfig::default(),
    };
    cfg.seed = seed;
    cfg.iterations = iters;
    let t_len = demos.horizon;
    let demo_end = demos.reach3_state(0, t_len - 1);
    let mut run = LqrGaifo::new(cfg, demos)?;
    let arm = arm_for(&run)?;
    println!("it  eval_mm  noisy_mm(mean sd)  sd_end_mrad  D(eval)-D(demo)  dD/dr(eval)  dD/dr(demo)  W1     eta");
    for _ in 0..iters {
        let (noisy, evals) = run.execute(&arm)?;
        let eval = &evals[0];
        let pol = run.policy();
        let sd_end = {
            let c = pol.pol_covar.slice(t_len - 2);
            ((c[0] + c[4] + c[8]) / 3.0).sqrt()
        };
        let fd: Vec<f64> = noisy.iter().map(Episode::final_distance).collect();
        let m = fd.iter().sum::<f64>() / fd.len() as f64;
        let sd = (fd.iter().map(|d| (d - m) * (d - m)).sum::<f64>() / fd.len() as f64).sqrt();
        let log = run.learn(&noisy, eval, 0.0)?;
        if log.iteration + 1 == iters {
            if let Some(steps) = std::env::var("PROBE_FRESH")
                .ok()
                .and_then(|v| v.parse::<usize>().ok())
            {
                fresh_critic(&run, &noisy, eval, steps)?;
            }
        }
        let end = eval.reach3_state(t_len - 1);
        let (d_eval, s_eval) = critic_at_rest(&run, &end);
        let (d_demo, s_demo) = critic_at_rest(&run, &demo_end);
        if log.iteration == 0 || log.iteration + 1 == iters {
            let n = run.discriminator().normalizer();
            println!(
                "normaliser sigma of s: {:?}",
                &n.std[..DX]
                    .iter()
                    .map(|v| format!("{v:.3}"))
                    .collect::<Vec<_>>()
            );
        }
        {
            // Normalised gradient of D at the resting transition of the eval end, by block.
            let disc = run.discriminator();
            let mut ws = disc.workspace();
            let x = at_rest(&end);
            let mut g = [0.0; 2 * DX];
            disc.value_gradient(&x, &mut ws, &mut g);
            let sd = &disc.normalizer().std;
            let blk = |r: std::ops::Range<usize>| -> f64 {
                r.map(|j| (g[j] * sd[j]).powi(2) + (g[DX + j] * sd[DX + j]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            print!(
                "   |grad_u| q {:.3} qd {:.3} ee {:.3} eev {:.3}  ",
                blk(0..3),
                blk(3..6),
                blk(6..9),
                blk(9..12)
            );
        }
        println!(
            "{:>2} {:>8.2} {:>8.2} {:>8.2} {:>12.1} {:>15.4} {:>12.3} {:>12.3} {:>6.3} {:>8.1e}",
            log.iteration,
            1e3 * eval.final_distance(),
            1e3 * m,
            1e3 * sd,
            1e3 * sd_end,
            d_eval - d_demo,
            s_eval,
            s_demo,
            log.wasserstein,
            log.eta
        );
    }
    Ok(())
}
