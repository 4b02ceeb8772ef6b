//! Error type of the GPS pieces.

/// What went wrong in a GPS piece, and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum GpsError {
    /// Arrays whose sizes do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// A matrix that must be positive definite is not.
    #[error("{what} is not positive definite at index {t}; check the conditioning of the data")]
    NotPositiveDefinite { what: &'static str, t: usize },
    /// GPS `TrajOptLQRPython.backward`: raising η never made Q_uu positive definite.
    #[error(
        "failed to find a PD Q_uu even for eta = {eta:e} (>= 1e16): the cost's Hessians or the \
         fitted dynamics are not finite or absurdly scaled; check the cost (for LQR+GAIfO the \
         critic: its checkpoint and [discriminator] settings) and the dynamics fit settings \
         (fit.regularization, [prior])"
    )]
    EtaOverflow { eta: f64 },
    /// GPS raises this when the PD retry fails on dynamics containing NaN.
    #[error("NaNs encountered in the dynamics (Fm or fv); the dynamics fit failed upstream")]
    NanDynamics,
    /// A setting that cannot work; the message names it and its allowed range.
    #[error("invalid setting: {0}")]
    Config(String),
    /// A learner snapshot (checkpoint) that does not fit this learner; names the array.
    #[error("learner checkpoint: {0}")]
    Snapshot(String),
    /// Too few samples for a regression.
    #[error("cannot fit dynamics on {0} sample(s); need at least 2 trajectories")]
    TooFewSamples(usize),
}

/// `Err(GpsError::Config)` naming `name` unless `ok`; the message says what is allowed.
pub(crate) fn check(
    ok: bool,
    name: &str,
    value: impl std::fmt::Debug,
    allowed: &str,
) -> Result<(), GpsError> {
    if ok {
        Ok(())
    } else {
        Err(GpsError::Config(format!(
            "{name} = {value:?}: must be {allowed}"
        )))
    }
}
