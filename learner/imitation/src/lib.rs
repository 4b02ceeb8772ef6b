//! Imitation from observation on top of the GPS pieces (crate `gps`): LQR+GAIfO (Torabi,
//! Geiger, Warnell, Stone 2019), the expert it imitates, and the GAIfO (PPO) baseline.
//! Algorithm 1 and its step numbering are in docs/design.md §1; every module cites them.
//!
//! - [`rollout`]: step 1, the one episode loop over an [`rollout::Arm`] and a
//!   [`rollout::Policy`]; [`rollout::Episode`] and GPS's [`rollout::SampleList`];
//! - [`discriminator`]: the WGAN-GP critic D(s, s') (MLP, Adam, persistence), step 3;
//! - [`critic`]: its one trainer (refit at iteration 0, the per-iteration update, checkpoint),
//!   owned by each of LQR+GAIfO, MDGPS and GAIfO (PPO);
//! - [`settings`]: the settings the learners share (the critic's, LQR+GAIfO's that MDGPS runs
//!   per condition, the count bound), below all of them so that none imports another's;
//! - [`cost`]: the true task cost ([`cost::task`], the expert's) and the composite cost
//!   C_t(s, a) = D(s, F_t [s; a] + f_t) with its expansion ([`cost::composite`]), steps 4–5;
//! - [`iteration`]: step 6 shared by both LQR learners (cost averaging, step size, KL-bounded
//!   LQR);
//! - [`expert`]: the LQR loop on the task cost, and its demonstrations ([`demos`]);
//! - [`gaifo`]: LQR+GAIfO, steps 1–6 in order in [`gaifo::LqrGaifo::learn`]; its log row
//!   ([`iteration_log::GaifoLog`]) is also the PPO baseline's;
//! - [`mlp_policy`]: the Gaussian MLP policy, GAIfO (PPO)'s actor; on normalised states the
//!   global policy of MDGPS, BCO and GAIfO (TD3) ([`mlp_policy::global`]) and its supervised
//!   fit ([`mlp_policy::opt`]: MDGPS's S-step, BCO's cloning), below all learners so that none
//!   imports another's;
//! - [`ppo`]: the GAIfO (PPO) baseline;
//! - [`offpolicy`]: off-policy GAIfO, the critic as the reward of TD3 with a replay buffer;
//! - [`bco`]: behavioural cloning from observation, BCO(α), a baseline (docs/design.md §7);
//! - [`replay_mean`]: the naive baseline, the demonstrations' mean joint path as commands;
//! - [`mdgps`]: MDGPS with the critic's cost: one global MLP policy for many goals (docs/design.md §6);
//! - [`learn`]: the one driver interface ([`learn::Learn`]) the application runs every learner
//!   through, in process or over IPC; [`controller`]: linear-Gaussian controller ↔ gain table;
//! - [`tool_path`]: measures of a tool path against the demonstrated ones (RMSE, DTW, Fréchet)
//!   and the demonstrations' own spread.
//!
//! Depends on `gps` and `shared` (the contract) only; the simulator, files and IPC are the
//! `learner` application's.

pub mod bco;
pub mod controller;
pub mod cost;
pub mod cpu;
pub mod critic;
pub mod demos;
pub mod discriminator;
pub mod error;
pub mod expert;
pub mod gaifo;
pub mod iteration;
pub mod iteration_log;
pub mod learn;
pub mod mdgps;
pub mod mlp_policy;
pub mod offpolicy;
pub mod ppo;
pub mod replay_mean;
pub mod rollout;
pub mod settings;
pub mod tool_path;

pub use error::ImitationError;
