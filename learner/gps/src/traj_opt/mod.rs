//! Trajectory optimisation (GPS python/gps/algorithm/traj_opt/): the KL-bounded LQR step
//! ([`lqr`]), PI2 ([`pi2`]) and PILQR, LQR followed by PI2 on the residual cost ([`pilqr`]).
pub mod config;
pub mod lqr;
pub mod pi2;
pub mod pilqr;
