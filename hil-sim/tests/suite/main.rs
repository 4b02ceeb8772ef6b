//! The crate's integration tests as one test binary (linking one binary, not one per file, is
//! most of the build time saved; docs/dev.md). One module per area.

mod dashboard;
mod dynamics;
mod inspect_cli;
mod models;
mod servoj;
mod sim;
mod six;
mod step_bits;
mod ur_sim;
