//! Densification (`src/densify.rs`): clone, split and prune keep every array aligned.

#[path = "../common/mod.rs"]
mod common;

mod steps;
