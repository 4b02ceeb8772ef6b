//! The offline learner: dynamics fitted with a GMM prior and the KL-bounded LQR step, a
//! faithful port of the Guided Policy Search reference code (cbfinn/gps, commit 82fa6cc)
//! as pinned down by shared/gps-vectors.
//!
//! Modules follow GPS's files:
//! - [`dynamics::gmm`] (utility/gmm.py), [`dynamics::prior_gmm`] (dynamics_prior_gmm.py),
//!   [`dynamics::lr_prior`] (dynamics_lr_prior.py + `gauss_fit_joint_prior`),
//!   [`dynamics::lr`] (dynamics_lr.py);
//! - [`traj_opt::lqr`] (traj_opt_lqr_python.py + traj_opt_utils.py KL estimates);
//! - [`algorithm`] (algorithm.py / algorithm_traj_opt.py: cost averaging, x0, step size);
//! - [`policy::lin_gauss`], [`policy::init`] (lin_gauss_policy.py, lin_gauss_init.py);
//! - [`conformance`]: the checker against the reference vectors.
//!
//! Conventions: GPS's absolute controller form `u = K x + k` throughout; arrays are row-major
//! stacks ([`linalg::MatSeq`]) with numpy's shapes; `y = [x; u]`.

pub mod algorithm;
pub mod bench;
pub mod conformance;
pub mod cost;
pub mod discriminator;
pub mod dynamics;
pub mod error;
pub mod experiment;
pub mod experiment_ipc;
pub mod expert;
pub mod expert_cli;
pub mod gaifo;
pub mod io;
pub mod iteration;
pub mod linalg;
pub mod plot;
pub mod policy;
pub mod ppo;
pub mod rollout;
pub mod serve;
pub mod synthetic;
pub mod train_cli;
pub mod traj_opt;

pub use error::LearnerError;
