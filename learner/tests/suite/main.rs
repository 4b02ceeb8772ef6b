//! The crate's integration tests as one test binary (linking one binary, not one per file, is
//! most of the build time saved; docs/dev.md). One module per area.

mod bco;
mod bounded;
mod common;
mod dataset;
mod experiment;
mod expert;
mod formats;
mod gaifo;
mod golden;
mod mdgps;
mod offpolicy;
mod pictures;
mod ppo;
mod replay;
mod run_dir;
mod shard;
mod six_joints;
mod structure;
mod tool_paths;
