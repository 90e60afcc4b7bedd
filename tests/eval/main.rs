//! Evaluation (`src/eval.rs`) in every colour mode and background.

#[path = "../common/mod.rs"]
mod common;

mod clamp;
