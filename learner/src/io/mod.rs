//! Files that leave the program (docs/design.md §4): `.npz` containers, demonstrations, gain tables, the
//! MDGPS policy.

pub mod checkpoint;
pub mod demos;
pub mod episode;
pub mod log;
pub mod manifest;
pub mod npz;
pub mod policy;
pub mod table;
