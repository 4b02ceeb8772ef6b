//! Files that leave the program (DESIGN.md §5): `.npz` containers, demonstrations, gain tables.

pub mod demos;
pub mod episode;
pub mod npz;
pub mod table;
