//! What one job of an in-process experiment runs ([`Spec`]): LQR+GAIfO, GAIfO (PPO) or one of
//! the baselines (BCO(α), GAIfO (TD3), the mean path), and the comparison's settings of the
//! baselines: the same arm, demonstrations and noisy episodes per iteration as LQR+GAIfO.

use imitation::bco::{Bco, BcoConfig};
use imitation::demos::Demos;
use imitation::gaifo::{GaifoConfig, GaifoLog, LqrGaifo};
use imitation::offpolicy::{GaifoTd3, GaifoTd3Config};
use imitation::ppo::gaifo_ppo::{GaifoPpo, GaifoPpoConfig};
use imitation::replay_mean::{ReplayMean, ReplayMeanConfig};

use super::{ExperimentConfig, ExperimentError};
use crate::run::{arm_for, run_iterations};

/// The comparison's baselines ([`ExperimentConfig::algorithms`]; not in the default list).
pub const BASELINES: [&str; 3] = ["bco", "gaifo-td3", "replay-mean"];

/// What one job runs.
#[derive(Clone)]
pub enum Spec {
    /// LQR+GAIfO with these settings.
    LqrGaifo(GaifoConfig),
    /// GAIfO (PPO) with these settings.
    GaifoPpo(GaifoPpoConfig),
    /// BCO(α) with these settings.
    Bco(BcoConfig),
    /// GAIfO (TD3) with these settings.
    GaifoTd3(GaifoTd3Config),
    /// The demonstrations' mean joint path (no learning).
    ReplayMean(ReplayMeanConfig),
}

impl Spec {
    /// The run seed.
    pub fn seed(&self) -> u64 {
        match self {
            Spec::LqrGaifo(c) => c.seed,
            Spec::GaifoPpo(c) => c.seed,
            Spec::Bco(c) => c.seed,
            Spec::GaifoTd3(c) => c.seed,
            Spec::ReplayMean(c) => c.seed,
        }
    }

    /// The `algorithm` column.
    pub fn algorithm(&self) -> &'static str {
        match self {
            Spec::LqrGaifo(_) => "lqr-gaifo",
            Spec::GaifoPpo(_) => "gaifo-ppo",
            Spec::Bco(_) => "bco",
            Spec::GaifoTd3(_) => "gaifo-td3",
            Spec::ReplayMean(_) => "replay-mean",
        }
    }

    /// Noisy (training) episodes per iteration N.
    pub fn samples(&self) -> usize {
        match self {
            Spec::LqrGaifo(c) => c.samples,
            Spec::GaifoPpo(c) => c.samples,
            Spec::Bco(c) => c.samples,
            Spec::GaifoTd3(c) => c.samples,
            Spec::ReplayMean(c) => c.samples,
        }
    }

    /// Runs every iteration of the settings on `demos` in this thread (no files).
    pub fn logs(&self, demos: Demos) -> Result<Vec<GaifoLog>, ExperimentError> {
        fn go<R>(mut run: R, iterations: usize) -> Result<Vec<GaifoLog>, ExperimentError>
        where
            R: imitation::learn::Learn<Log = GaifoLog> + crate::run::Checkpoint,
        {
            let arm = arm_for(&run)?;
            Ok(run_iterations(&mut run, &arm, iterations, None, |_, _| {})?)
        }
        match self {
            Spec::LqrGaifo(c) => go(LqrGaifo::new(c.clone(), demos)?, c.iterations),
            Spec::GaifoPpo(c) => go(GaifoPpo::new(c.clone(), demos)?, c.iterations),
            Spec::Bco(c) => go(Bco::new(c.clone(), demos)?, c.iterations),
            Spec::GaifoTd3(c) => go(GaifoTd3::new(c.clone(), demos)?, c.iterations),
            Spec::ReplayMean(c) => go(ReplayMean::new(c.clone(), demos)?, c.iterations),
        }
    }
}

/// The comparison's job of baseline `algorithm` (one of [`BASELINES`]) at `seed`: its own
/// settings from `cfg` (`bco`, `gaifo_td3`; the mean path's defaults), with LQR+GAIfO's arm
/// (`lqr_gaifo.sim`) and noisy episodes per iteration (`lqr_gaifo.samples`), so that every
/// learner runs on the same arm with the same episodes; `None` for another name.
pub fn baseline(cfg: &ExperimentConfig, algorithm: &str, seed: u64) -> Option<Spec> {
    let (sim, samples, iterations) = (
        cfg.lqr_gaifo.sim.clone(),
        cfg.lqr_gaifo.samples,
        cfg.iterations,
    );
    Some(match algorithm {
        "bco" => Spec::Bco(BcoConfig {
            sim,
            samples,
            iterations,
            seed,
            ..cfg.bco.clone()
        }),
        "gaifo-td3" => Spec::GaifoTd3(GaifoTd3Config {
            sim,
            samples,
            iterations,
            seed,
            ..cfg.gaifo_td3.clone()
        }),
        "replay-mean" => Spec::ReplayMean(ReplayMeanConfig {
            sim,
            samples,
            iterations,
            seed,
            init_var: cfg.lqr_gaifo.init_var,
        }),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every baseline runs on LQR+GAIfO's arm with its episodes per iteration, the
    /// experiment's iterations and the job's seed; other names are no baseline, and the
    /// settings refuse unknown algorithms.
    #[test]
    fn baselines_run_on_lqr_gaifo_s_arm_with_its_episodes() {
        let mut cfg = ExperimentConfig::default();
        cfg.lqr_gaifo.samples = 3;
        cfg.lqr_gaifo.sim.perturbation = ur5_shared::config::Perturbation::physical_stand_in(1);
        cfg.iterations = 7;
        for a in BASELINES {
            let s = baseline(&cfg, a, 4).unwrap();
            let sim = match &s {
                Spec::Bco(c) => (&c.sim, c.iterations),
                Spec::GaifoTd3(c) => (&c.sim, c.iterations),
                Spec::ReplayMean(c) => (&c.sim, c.iterations),
                _ => panic!("{a}"),
            };
            assert_eq!((s.algorithm(), s.samples(), s.seed()), (a, 3, 4));
            assert_eq!(sim, (&cfg.lqr_gaifo.sim, 7), "{a}");
        }
        assert!(baseline(&cfg, "lqr-gaifo", 0).is_none());
        cfg.algorithms = vec!["bco".into(), "gaifo-td3".into(), "replay-mean".into()];
        cfg.validate(super::super::ExperimentName::Comparison)
            .unwrap();
        cfg.algorithms.push("bcoo".into());
        let e = cfg
            .validate(super::super::ExperimentName::Comparison)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`bcoo`") && e.contains("gaifo-td3"), "{e}");
    }
}
