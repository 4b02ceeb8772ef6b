//! Guided Policy Search trajectory optimisation: a faithful port of the pieces of the GPS
//! reference code (cbfinn/gps, commit 82fa6cc) that an LQR-based learner needs, pinned down by
//! the reference vectors in `tests/data/gps-vectors` (see `conformance`, behind the cargo
//! feature of that name).
//!
//! Modules follow GPS's files:
//! - [`dynamics::gmm`] (utility/gmm.py), [`dynamics::prior_gmm`] (dynamics_prior_gmm.py),
//!   [`dynamics::lr_prior`] (dynamics_lr_prior.py + `gauss_fit_joint_prior`),
//!   [`dynamics::lr`] (dynamics_lr.py);
//! - [`traj_opt::lqr`] (traj_opt_lqr_python.py + traj_opt_utils.py KL estimates);
//! - [`algorithm`] (algorithm.py / algorithm_traj_opt.py: cost averaging, x0, step size, and
//!   [`algorithm::update::Learner`], the state one iteration updates);
//! - [`policy::lin_gauss`], [`policy::init`] (lin_gauss_policy.py, lin_gauss_init.py);
//! - [`snapshot`]: the learner state as named arrays (exact checkpoints);
//! - `conformance` (cargo feature `conformance`): the checker against the reference vectors;
//!   [`synthetic`]: random linear-Gaussian test problems.
//!
//! Conventions: GPS's absolute controller form `u = K x + k` throughout; arrays are row-major
//! stacks ([`linalg::MatSeq`]) with numpy's shapes; `y = [x; u]`. Depends on faer, rand, serde
//! and thiserror (and, with the `conformance` feature, serde_json for the vectors files),
//! nothing of the robot.

pub mod algorithm;
#[cfg(feature = "conformance")]
pub mod conformance;
pub mod dynamics;
pub mod error;
pub mod linalg;
pub mod policy;
pub mod snapshot;
pub mod synthetic;
pub mod traj_opt;

pub use error::GpsError;
