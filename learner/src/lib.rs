//! learner
pub mod io;
pub mod cost;
