//! Settings of the trajectory optimisers (GPS python/gps/algorithm/traj_opt/config.py and
//! algorithm/config.py `ALG_PILQR`): which optimiser runs (`[traj_opt] method`), PI2's and
//! PILQR's settings. The KL-bounded LQR step's own settings are
//! [`crate::traj_opt::lqr::TrajOptConfig`], which holds these.

use crate::error::GpsError;

/// GPS `TRAJ_OPT_PI2` settings (traj_opt/config.py).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Pi2Config {
    /// KL bound ε of each time step's sample weights, nats (GPS `kl_threshold`, 1.0).
    pub kl_threshold: f64,
    /// Covariance damping d: the new covariance is the old one times the fitted multiplier to
    /// the power 1/d; 0 takes the weighted maximum-likelihood covariance itself (GPS 2.0).
    pub covariance_damping: f64,
    /// Lower bound of the temperature η (GPS `min_temperature`, 0.001).
    pub min_temperature: f64,
    /// First η increment when a new covariance is not positive definite (GPS `del0`, 1e-4).
    pub del0: f64,
}

impl Default for Pi2Config {
    fn default() -> Self {
        // GPS traj_opt/config.py TRAJ_OPT_PI2.
        Self {
            kl_threshold: 1.0,
            covariance_damping: 2.0,
            min_temperature: 0.001,
            del0: 1e-4,
        }
    }
}

impl Pi2Config {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), GpsError> {
        use crate::error::check;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        check(
            pos(self.kl_threshold),
            "traj_opt.pilqr.kl_threshold",
            self.kl_threshold,
            "finite and > 0 nats",
        )?;
        check(
            self.covariance_damping.is_finite() && self.covariance_damping >= 0.0,
            "traj_opt.pilqr.covariance_damping",
            self.covariance_damping,
            "finite and >= 0",
        )?;
        check(
            pos(self.min_temperature),
            "traj_opt.pilqr.min_temperature",
            self.min_temperature,
            "finite and > 0",
        )?;
        check(
            pos(self.del0),
            "traj_opt.pilqr.del0",
            self.del0,
            "finite and > 0",
        )
    }
}

/// Which trajectory optimiser the LQR learners run (`[traj_opt] method`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrajOptMethod {
    /// The KL-bounded LQR step alone (GPS `TrajOptLQRPython`).
    #[default]
    Lqr,
    /// LQR, then PI2 on the residual cost (GPS `TrajOptPILQR`).
    Pilqr,
}

impl TrajOptMethod {
    /// True for the default (serde leaves it out of written settings, so that settings
    /// written before the setting existed hash the same).
    pub fn is_lqr(&self) -> bool {
        *self == TrajOptMethod::Lqr
    }
}

/// How PILQR adapts the KL step between iterations (GPS `ALG_PILQR['step_rule']`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepRule {
    /// From the residual's share of the sampled cost (GPS's PILQR default).
    #[default]
    ResPercent,
    /// Keep the step multiplier.
    Const,
    /// The learner's own LQR rule (GPS `_stepadjust` on predicted vs actual improvement of
    /// the Laplace cost estimates) where the learner adapts the step (the expert; LQR+GAIfO
    /// with `adapt_step`), else constant.
    Laplace,
}

/// Which costs PI2's temperature is fitted on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TemperatureFrom {
    /// The sampled costs (GPS `TrajOptPILQR.update`), then applied to the residual.
    #[default]
    Sampled,
    /// The residual costs PI2 weighs, so that the KL bound holds for the weights used.
    Residual,
}

/// PILQR settings (`[traj_opt.pilqr]`): the PI2 update's and the step rule's. Defaults are
/// GPS's `TRAJ_OPT_PI2` and `ALG_PILQR`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PilqrConfig {
    /// KL bound of each step's PI2 sample weights, nats (GPS 1.0).
    pub kl_threshold: f64,
    /// Covariance damping (GPS 2.0; 0: the weighted maximum-likelihood covariance).
    pub covariance_damping: f64,
    /// Lowest PI2 temperature (GPS 0.001).
    pub min_temperature: f64,
    /// First temperature increment when a covariance is not positive definite (GPS 1e-4).
    pub del0: f64,
    /// Costs the PI2 temperature is fitted on (GPS: the sampled ones).
    pub temperature_from: TemperatureFrom,
    /// Step rule between iterations.
    pub step_rule: StepRule,
    /// Residual share above which the step multiplier halves (GPS 0.2).
    pub step_rule_res_ratio_dec: f64,
    /// Residual share below which the step multiplier doubles (GPS 0.05).
    pub step_rule_res_ratio_inc: f64,
}

impl Default for PilqrConfig {
    /// Not GPS's `TRAJ_OPT_PI2` / `ALG_PILQR` values (ε = 1, damping 2, temperature from the
    /// sampled costs, `res_percent`), which GPS runs with 20 samples: with our N = 5 they
    /// collapse the covariance (by 1e-49 in the first step on the default task) and the next
    /// LQR step finds no positive-definite Q_uu; these are the settings that kept learning
    /// (docs/design.md §5 D34). GPS's values are `GPS_DEFAULTS`.
    fn default() -> Self {
        Self {
            kl_threshold: 0.2,
            covariance_damping: 10.0,
            min_temperature: 0.001,
            del0: 1e-4,
            temperature_from: TemperatureFrom::Residual,
            step_rule: StepRule::Laplace,
            step_rule_res_ratio_dec: 0.2,
            step_rule_res_ratio_inc: 0.05,
        }
    }
}

impl PilqrConfig {
    /// GPS's own settings (traj_opt/config.py `TRAJ_OPT_PI2`, algorithm/config.py
    /// `ALG_PILQR`, the temperature as `TrajOptPILQR.update` fits it).
    pub const GPS_DEFAULTS: PilqrConfig = PilqrConfig {
        kl_threshold: 1.0,
        covariance_damping: 2.0,
        min_temperature: 0.001,
        del0: 1e-4,
        temperature_from: TemperatureFrom::Sampled,
        step_rule: StepRule::ResPercent,
        step_rule_res_ratio_dec: 0.2,
        step_rule_res_ratio_inc: 0.05,
    };
}

impl PilqrConfig {
    /// The PI2 part.
    pub fn pi2(&self) -> Pi2Config {
        Pi2Config {
            kl_threshold: self.kl_threshold,
            covariance_damping: self.covariance_damping,
            min_temperature: self.min_temperature,
            del0: self.del0,
        }
    }

    /// True for the defaults (left out of written settings, as [`TrajOptMethod::is_lqr`]).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), GpsError> {
        use crate::error::check;
        self.pi2().validate()?;
        let (d, i) = (self.step_rule_res_ratio_dec, self.step_rule_res_ratio_inc);
        check(
            d.is_finite() && i.is_finite() && i >= 0.0 && i <= d,
            "traj_opt.pilqr.step_rule_res_ratio_inc/dec",
            (i, d),
            "finite, 0 <= inc <= dec",
        )
    }
}
