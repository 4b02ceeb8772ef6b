//! The contract shared by `hil-sim`, `rt-controller` and `learner` (DESIGN.md §2–§3).
//!
//! One home for each fact: dimensions and the state layout ([`layout`]), … every other crate
//! imports them from here.

pub mod layout;

pub use layout::{DU, DX, MAX_HORIZON};
