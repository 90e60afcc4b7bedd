//! The front end (`src/cli/`): numeric flags and settings range checked.

#[path = "../common/mod.rs"]
mod common;

mod flag_ranges;
