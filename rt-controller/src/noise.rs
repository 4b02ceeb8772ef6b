//! Exploration noise: defined once in `ur5_shared::noise` (shared with the learner's
//! in-process rollouts) and re-exported here.

pub use ur5_shared::noise::{episode_seed, Noise};
