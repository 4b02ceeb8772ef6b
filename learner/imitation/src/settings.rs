//! The settings the learners share, below all of them, so that no learner imports another's
//! (docs/design.md §1.7):
//!
//! - [`MAX_COUNT`]: the bound on every count setting (episodes, iterations, updates);
//! - [`CriticSettings`]: the critic D(s, s') and its schedule as LQR+GAIfO, MDGPS and GAIfO (PPO)
//!   hold it, checked and built into each one's [`crate::critic::Critic`] in one place;
//! - [`GaifoConfig`]: a linear-Gaussian controller improved by KL-bounded LQR on the critic's
//!   composite cost: the settings of an LQR+GAIfO run, and of each MDGPS condition (MDGPS's
//!   `[lqr_gaifo]` table); GAIfO (PPO) takes the values it shares with LQR+GAIfO from them
//!   (`GaifoPpoConfig::from_gaifo`, docs/design.md §5 D14).
//!
//! The task (goal, start pose, T, dt) is not a setting of these learners: it comes with the
//! demonstrations ([`crate::demos::Demos::task`]).
//!
//! The critic's keys stay fields of each learner's settings (`critic_updates`,
//! `critic_lr_half_life`, `[discriminator]` at the top of the file), not a flattened struct:
//! serde's `flatten` buffers the values, and TOML's errors then lose the key path ("... in
//! discriminator.adam", docs/reliability.md class 6); [`CriticSettings`] is a view of those
//! fields.

use serde::{Deserialize, Serialize};
use ur5_shared::config::SimConfig;

use crate::discriminator::{AdamConfig, DiscriminatorConfig, PenaltySpace};
use crate::ImitationError;
use gps::algorithm::AlgorithmConfig;
use gps::dynamics::lr_prior::LrPriorConfig;
use gps::dynamics::prior_gmm::PriorGmmConfig;
use gps::traj_opt::lqr::TrajOptConfig;

/// Largest accepted count setting of every learner (`samples`, `iterations`,
/// `critic_updates`, …; the critic's own bounds: [`DiscriminatorConfig::validate`]): far above
/// any use, low enough that a typo cannot ask for terabytes up front.
pub const MAX_COUNT: usize = DiscriminatorConfig::MAX_COUNT;

/// The critic of an imitation learner and its schedule (docs/design.md §1.3 step 3): a view of
/// the learner's settings `critic_updates`, `critic_lr_half_life` and `[discriminator]`
/// ([`GaifoConfig::critic`], `GaifoPpoConfig::critic`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CriticSettings<'a> {
    /// `Discriminator::train` calls per iteration, each `discriminator.n_critic` Adam steps
    /// (docs/design.md §5 D6).
    pub updates: usize,
    /// Half-life of the critic's learning rate, iterations: iteration i trains at
    /// `discriminator.adam.lr · 2^(−i / h)`; 0 keeps it constant (docs/design.md §5 D25).
    pub lr_half_life: f64,
    /// The critic's net, optimiser and input warp.
    pub discriminator: &'a DiscriminatorConfig,
}

impl<'a> CriticSettings<'a> {
    /// The settings `critic_updates`, `critic_lr_half_life` and `[discriminator]` of a learner.
    pub fn new(updates: usize, lr_half_life: f64, discriminator: &'a DiscriminatorConfig) -> Self {
        Self {
            updates,
            lr_half_life,
            discriminator,
        }
    }

    /// Refuses settings that cannot work, naming the setting (by its key) and its range.
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_counts(&[("critic_updates", self.updates, 1)], MAX_COUNT)
            .and_then(|()| {
                crate::error::check_reals(&[(
                    "critic_lr_half_life",
                    self.lr_half_life,
                    self.lr_half_life.is_finite() && self.lr_half_life >= 0.0,
                    "finite and >= 0 (0 = constant)",
                )])
            })
            .map_err(ImitationError::Config)?;
        Ok(self.discriminator.validate()?)
    }
}

/// Settings of an LQR+GAIfO run (TOML: `learner train --config FILE`), and of each condition
/// of an MDGPS run (its `[lqr_gaifo]` table). The task (goal, start pose, T, dt) comes from the
/// demonstrations file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaifoConfig {
    /// The simulated arm of in-process runs (docs/design.md §2).
    pub sim: SimConfig,
    /// Noisy episodes per iteration N; paper §5: 5 (docs/design.md §1.3 step 1).
    pub samples: usize,
    /// Iterations to run (docs/design.md §1.3).
    pub iterations: usize,
    /// Initial controller: hold the start pose with this exploration variance, rad²
    /// (docs/design.md §5 D11).
    pub init_var: f64,
    /// `Discriminator::train` calls per iteration, each `discriminator.n_critic` Adam steps
    /// (docs/design.md §5 D6).
    pub critic_updates: usize,
    /// Half-life of the critic's learning rate, iterations: iteration i trains at
    /// `discriminator.adam.lr · 2^(−i / h)`; 0 keeps it constant (docs/design.md §5 D25).
    pub critic_lr_half_life: f64,
    /// GPS step-size adaptation; off: the critic's cost changes every iteration
    /// (docs/design.md §5 D5).
    pub adapt_step: bool,
    /// Project the samples' mean ∇²D per step on the PSD cone before the chain rule
    /// (docs/design.md §5 D3, D4).
    pub psd_hessian: bool,
    /// The critic: 2 × 32 tanh, Adam 3e-3 / β1 0.5, 100 steps of batch 16 per call, gradient
    /// penalty in normalised inputs (docs/design.md §5 D6–D8, D25).
    pub discriminator: DiscriminatorConfig,
    /// Seed of every random draw of the run: noise, GMM, critic (docs/design.md §3.7).
    pub seed: u64,
    /// GPS algorithm settings; KL step 0.2 per time step of a three-joint arm, scaled by
    /// dU / 3 for the task's joints ([`Self::algorithm_for`]; docs/design.md §1.3 step 6, §5 D40).
    pub algorithm: AlgorithmConfig,
    /// GPS dynamics prior on the last 10 trajectories with ≤ 5 EM iterations, for the
    /// learner-time budget (docs/design.md §5 D9).
    pub prior: PriorGmmConfig,
    /// GPS dynamics fit (docs/design.md §1.3 step 2).
    pub fit: LrPriorConfig,
    /// GPS KL-bounded LQR settings (docs/design.md §1.3 step 6).
    pub traj_opt: TrajOptConfig,
    /// Copies of each final state's resting pair [s_{T−1}; s_{T−1}] among the critic's rows,
    /// for the demonstrations and the controller alike: the pair the last step's cost D(s, s)
    /// evaluates (docs/design.md §5 D10, D44); 0 (the default, the paper's critic) = none.
    /// Left out when 0, so that settings without it print and hash as before.
    #[serde(skip_serializing_if = "is_zero")]
    pub critic_terminal_pairs: usize,
    /// How the cost sees the time along the motion (docs/design.md §5 D39); off by default.
    /// Left out when serialised off, so that settings without it print and hash as before
    /// (a run of an earlier build resumes).
    #[serde(skip_serializing_if = "PathSettings::is_off")]
    pub path: PathSettings,
}

/// How LQR+GAIfO's cost sees the time along the demonstrated motion (TOML table `[path]`;
/// docs/design.md §5 D39). Off (the default) is the paper's cost, D(s, s') alone, which
/// knows no time: it makes the end of a motion, not its path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PathSettings {
    /// The critic also takes the phase t/(T − 1) of the transition's first state:
    /// D(s, s', t/(T − 1)).
    pub critic_phase: bool,
    /// Weight w of the demonstrations' per-step tracking term added to the composite cost
    /// ([`crate::cost::tracking`]); 0 = off.
    pub tracking_weight: f64,
    /// The tracking term's variance floor κ, a fraction of each state input's standard
    /// deviation over all demonstrations and steps.
    pub tracking_floor: f64,
    /// Factor on the critic's composite cost; 1 is the paper's, 0 leaves the tracking term
    /// alone (an ablation: the critic is still trained and logged).
    pub critic_weight: f64,
}

impl Default for PathSettings {
    fn default() -> Self {
        Self {
            critic_phase: false,
            tracking_weight: 0.0,
            tracking_floor: 0.1,
            critic_weight: 1.0,
        }
    }
}

impl PathSettings {
    /// Off: the paper's cost (the default).
    pub fn is_off(&self) -> bool {
        *self == Self::default()
    }

    /// The settings a motion's demonstrations (a tool-path file) take unless the run's
    /// configuration has a `[path]` table (docs/design.md §5 D39).
    pub fn for_motions() -> Self {
        Self {
            critic_phase: false,
            tracking_weight: 0.1,
            tracking_floor: 0.1,
            critic_weight: 1.0,
        }
    }

    /// Refuses settings that cannot work, naming the setting.
    pub fn validate(&self) -> Result<(), ImitationError> {
        crate::error::check_reals(&[
            (
                "path.tracking_weight",
                self.tracking_weight,
                self.tracking_weight.is_finite() && self.tracking_weight >= 0.0,
                "finite and >= 0 (0 = off)",
            ),
            (
                "path.tracking_floor",
                self.tracking_floor,
                self.tracking_floor.is_finite() && self.tracking_floor > 0.0,
                "finite and > 0",
            ),
            (
                "path.critic_weight",
                self.critic_weight,
                self.critic_weight.is_finite() && self.critic_weight >= 0.0,
                "finite and >= 0 (1 = the paper's cost)",
            ),
        ])
        .map_err(ImitationError::Config)
    }
}

impl Default for GaifoConfig {
    fn default() -> Self {
        Self {
            sim: SimConfig::default(),
            samples: 5,
            iterations: 20,
            init_var: 0.05,
            critic_updates: 1,
            // 40 (25 before): on the five workspace goals × 10 seeds every run stays within
            // 1.5 cm from iteration 20 (49 of 50 with 25; docs/design.md §5 D37).
            critic_lr_half_life: 40.0,
            adapt_step: false,
            psd_hessian: true,
            discriminator: DiscriminatorConfig {
                hidden: vec![32, 32],
                n_critic: 100,
                adam: AdamConfig {
                    lr: 3e-3,
                    beta1: 0.5,
                    beta2: 0.9,
                    eps: 1e-8,
                },
                batch_size: 16,
                penalty_space: PenaltySpace::Normalised,
                // 1 cm, with the raw inputs kept beside the warped ones: on five workspace
                // goals the final distance at iterations 20 / 50 fell from 9.4 / 4.6 mm to
                // 5.4 / 1.1 mm (docs/design.md §5 D36).
                near_goal_scale: 0.01,
                near_goal_keep_raw: true,
                ..DiscriminatorConfig::default()
            },
            seed: 0,
            algorithm: AlgorithmConfig::default(),
            prior: PriorGmmConfig {
                max_samples: 11,
                max_iterations: 5,
                ..PriorGmmConfig::default()
            },
            fit: LrPriorConfig::default(),
            traj_opt: TrajOptConfig::default(),
            critic_terminal_pairs: 0,
            path: PathSettings::default(),
        }
    }
}

/// Whether a count is 0 (serde's `skip_serializing_if`).
fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl GaifoConfig {
    /// Largest accepted [`Self::critic_terminal_pairs`].
    pub const MAX_TERMINAL_PAIRS: usize = 1000;

    /// The GPS algorithm settings of a task with `du` action dimensions: [`Self::algorithm`]
    /// with `kl_step` × dU / 3 (docs/design.md §5 D40). `kl_step` is the paper's bound per time
    /// step for its three joints; the KL between two trajectory distributions of one dynamics
    /// is the expected KL of their action distributions, a sum over the action dimensions, so
    /// the same bound per joint lets each of six joints move as far per iteration as each of
    /// three. Three joints: `kl_step` × 1, the same bits.
    pub fn algorithm_for(&self, du: usize) -> AlgorithmConfig {
        AlgorithmConfig {
            kl_step: self.algorithm.kl_step * (du as f64 / 3.0),
            ..self.algorithm.clone()
        }
    }

    /// [`MAX_COUNT`], under the name the application uses.
    pub const MAX_COUNT: usize = MAX_COUNT;

    /// The critic's settings.
    pub fn critic(&self) -> CriticSettings<'_> {
        CriticSettings::new(
            self.critic_updates,
            self.critic_lr_half_life,
            &self.discriminator,
        )
    }

    /// Checks every setting's range before anything is allocated or run.
    pub fn validate(&self) -> Result<(), ImitationError> {
        let bad = |name: &str, v: &dyn std::fmt::Debug, allowed: &str| {
            Err(ImitationError::Config(format!(
                "{name} = {v:?}: must be {allowed}"
            )))
        };
        if self.samples < 2 || self.samples > MAX_COUNT {
            return bad(
                "samples",
                &self.samples,
                &format!("in 2..={MAX_COUNT} (the dynamics fit needs 2)"),
            );
        }
        if !(1..=MAX_COUNT).contains(&self.iterations) {
            return bad(
                "iterations",
                &self.iterations,
                &format!("in 1..={MAX_COUNT}"),
            );
        }
        if !(self.init_var.is_finite() && self.init_var > 0.0 && self.init_var <= 10.0) {
            return bad("init_var", &self.init_var, "finite, > 0 and <= 10 rad²");
        }
        if self.critic_terminal_pairs > Self::MAX_TERMINAL_PAIRS {
            return bad(
                "critic_terminal_pairs",
                &self.critic_terminal_pairs,
                &format!("in 0..={}", Self::MAX_TERMINAL_PAIRS),
            );
        }
        self.critic().validate()?;
        self.path.validate()?;
        crate::error::check_arm_and_gps(
            &self.sim,
            &self.algorithm,
            &self.prior,
            &self.fit,
            &self.traj_opt,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The KL bound per time step scales with the action dimensions, and three joints keep
    /// `kl_step` bit for bit (docs/design.md §5 D40).
    #[test]
    fn the_kl_bound_scales_with_the_joints() {
        let cfg = GaifoConfig::default();
        assert_eq!(
            cfg.algorithm_for(3).kl_step.to_bits(),
            cfg.algorithm.kl_step.to_bits()
        );
        assert_eq!(cfg.algorithm_for(6).kl_step, 2.0 * cfg.algorithm.kl_step);
        assert_eq!(
            cfg.algorithm_for(6).max_step_mult,
            cfg.algorithm.max_step_mult
        );
    }

    /// The critic's terminal pairs are off unless set; off, the settings serialise as before
    /// (docs/design.md §5 D44).
    #[test]
    fn terminal_pairs_are_off_unless_set_and_then_serialised() {
        let cfg = GaifoConfig::default();
        assert_eq!(cfg.critic_terminal_pairs, 0);
        let text = serde_json::to_string(&cfg).unwrap();
        assert!(!text.contains("critic_terminal_pairs"), "{text}");
        let set = GaifoConfig {
            critic_terminal_pairs: 10,
            ..GaifoConfig::default()
        };
        let text = serde_json::to_string(&set).unwrap();
        assert!(text.contains("\"critic_terminal_pairs\":10"), "{text}");
        let back: GaifoConfig = serde_json::from_str(&text).unwrap();
        assert_eq!(back, set);
    }

    #[test]
    fn settings_that_cannot_work_are_refused_naming_the_setting() {
        assert!(GaifoConfig::default().validate().is_ok());
        let cases: Vec<(&str, Box<dyn Fn(&mut GaifoConfig)>)> = vec![
            ("kl_step", Box::new(|c| c.algorithm.kl_step = -1.0)),
            ("kl_step", Box::new(|c| c.algorithm.kl_step = f64::NAN)),
            ("init_var", Box::new(|c| c.init_var = 1e300)),
            ("min_eta/max_eta", Box::new(|c| c.traj_opt.max_eta = 1e-9)),
            ("max_clusters", Box::new(|c| c.prior.max_clusters = 0)),
            ("regularization", Box::new(|c| c.fit.regularization = -1.0)),
            (
                "critic_updates",
                Box::new(|c| c.critic_updates = 1_000_000_000),
            ),
            (
                "n_critic/batch_size",
                Box::new(|c| c.discriminator.batch_size = 1_000_000_000),
            ),
            (
                "hidden",
                Box::new(|c| c.discriminator.hidden = vec![1_000_000_000]),
            ),
            ("samples", Box::new(|c| c.samples = 1_000_000_000)),
            (
                "critic_terminal_pairs",
                Box::new(|c| c.critic_terminal_pairs = 1_000_000),
            ),
            ("iterations", Box::new(|c| c.iterations = 1_000_000_000_000)),
            (
                "critic_lr_half_life",
                Box::new(|c| c.critic_lr_half_life = -2.0),
            ),
            (
                "path.tracking_weight",
                Box::new(|c| c.path.tracking_weight = -1.0),
            ),
            (
                "path.tracking_floor",
                Box::new(|c| c.path.tracking_floor = 0.0),
            ),
        ];
        crate::error::assert_each_refused_naming(cases, GaifoConfig::validate);
    }
}
