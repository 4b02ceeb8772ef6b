//! The crate's integration tests as one test binary (linking one binary, not one per file, is
//! most of the build time saved; docs/dev.md). One module per area.

mod baselines_ipc;
mod cli_doc;
mod errors;
mod experiment_ipc;
mod fuzz;
mod killed_setup;
mod learning;
mod live_view;
mod lost_arm;
mod mdgps_ipc;
mod peer_status;
mod policy_run;
mod processes;
mod recorder;
mod reliability;
mod resume_ipc;
mod resume_kill;
mod ros2_backend;
mod serve;
mod soak;
mod teach;
mod teach_motion;
mod teach_pose;
mod ur_backend;
