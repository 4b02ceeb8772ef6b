//! learner
pub mod io;
