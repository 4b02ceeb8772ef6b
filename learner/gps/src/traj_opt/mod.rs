//! Trajectory optimisation: the KL-bounded LQR step (GPS python/gps/algorithm/traj_opt/).
pub mod lqr;
