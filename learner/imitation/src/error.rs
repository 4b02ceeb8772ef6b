//! Error type of the imitation library.

use ur5_shared::config::ConfigError;

/// What went wrong in an imitation piece, and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum ImitationError {
    /// A GPS piece (dynamics fit, LQR step, step adjustment) failed.
    #[error(transparent)]
    Gps(#[from] gps::GpsError),
    /// The critic could not be built or trained.
    #[error("critic: {0}")]
    Critic(#[from] crate::discriminator::DiscriminatorError),
    /// The arm an episode ran on failed (the simulator's own error inside).
    #[error("arm: {0}")]
    Arm(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// The task of the demonstrations (goal, start pose, T, dt) is not valid.
    #[error("demonstrations: {0}")]
    Task(#[source] ConfigError),
    /// An iteration got episodes that are not the ones it asked for.
    #[error("{0}")]
    Episodes(String),
    /// A gain table that is not a learner's controller.
    #[error("gain table: {0}")]
    Table(String),
    /// A checkpoint that does not belong to this run.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    /// Settings that cannot work; the message names the setting and its allowed range.
    #[error("invalid setting: {0}")]
    Config(String),
    /// PPO settings that cannot work.
    #[error("PPO: {0}")]
    Ppo(String),
}

/// Each `(name, value, min)` must lie in `min..=max`; else a message naming the first that
/// does not (the counts of the settings types' `validate`).
pub(crate) fn check_counts(items: &[(&str, usize, usize)], max: usize) -> Result<(), String> {
    match items.iter().find(|(_, n, min)| !(*min..=max).contains(n)) {
        Some((name, n, min)) => Err(format!("{name} = {n}: must be in {min}..={max}")),
        None => Ok(()),
    }
}

/// Each `(name, value, ok, allowed)` must have `ok`; else a message naming the first that does
/// not, with its value and `allowed` (the real-valued settings of the types' `validate`).
pub(crate) fn check_reals(items: &[(&str, f64, bool, &str)]) -> Result<(), String> {
    match items.iter().find(|(_, _, ok, _)| !ok) {
        Some((name, v, _, allowed)) => Err(format!("{name} = {v:?}: must be {allowed}")),
        None => Ok(()),
    }
}

/// The arm and GPS's settings, shared by the expert's and LQR+GAIfO's configs.
pub(crate) fn check_arm_and_gps(
    sim: &ur5_shared::config::SimConfig,
    algorithm: &gps::algorithm::AlgorithmConfig,
    prior: &gps::dynamics::prior_gmm::PriorGmmConfig,
    fit: &gps::dynamics::lr_prior::LrPriorConfig,
    traj_opt: &gps::traj_opt::lqr::TrajOptConfig,
) -> Result<(), ImitationError> {
    sim.validate()
        .map_err(|e| ImitationError::Config(e.to_string()))?;
    algorithm.validate()?;
    prior.validate()?;
    fit.validate()?;
    traj_opt.validate()?;
    Ok(())
}

/// Each case, applied to `C::default()`, must make `validate` fail with a message naming the
/// case (the settings types' `validate` tests).
#[cfg(test)]
#[allow(clippy::type_complexity)]
pub(crate) fn assert_each_refused_naming<C: Default>(
    cases: Vec<(&str, Box<dyn Fn(&mut C)>)>,
    validate: impl Fn(&C) -> Result<(), ImitationError>,
) {
    for (name, set) in cases {
        let mut c = C::default();
        set(&mut c);
        let e = validate(&c).expect_err(name).to_string();
        assert!(e.contains(name), "{name}: {e}");
    }
}
