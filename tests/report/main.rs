//! `unispine report` (`src/report/`).

#[path = "../common/mod.rs"]
mod common;

mod cli;
