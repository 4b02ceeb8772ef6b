//! learner
pub mod io;
pub mod cost;
pub mod rollout;
