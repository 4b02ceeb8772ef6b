//! Costs for the KL-bounded LQR step: the true task cost (the expert's) and, later, the
//! discriminator's composite cost (LQR+GAIfO).

pub mod composite;
pub mod task;
