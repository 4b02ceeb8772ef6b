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

/// Each `(name, value, min)` must lie in `min..=max`; else a [`ImitationError::Config`] naming
/// the first that does not (the counts of the settings types' `validate`).
pub(crate) fn check_counts(
    items: &[(&str, usize, usize)],
    max: usize,
) -> Result<(), ImitationError> {
    for &(name, n, min) in items {
        if !(min..=max).contains(&n) {
            return Err(ImitationError::Config(format!(
                "{name} = {n}: must be in {min}..={max}"
            )));
        }
    }
    Ok(())
}
