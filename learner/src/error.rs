//! Error type of the learner library.

/// What went wrong in a learner piece, and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum LearnerError {
    /// Arrays whose sizes do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// A GPS piece (dynamics fit, LQR step, step adjustment) failed.
    #[error(transparent)]
    Gps(#[from] gps::GpsError),
    /// A GPS reference-vectors file that cannot be read or does not follow the layout.
    #[error(transparent)]
    Vectors(#[from] gps::conformance::ConformanceError),
}
