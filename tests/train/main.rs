//! Training (`src/train/`, `src/method/`, `src/session.rs`): the trainer end to end, stage
//! timers, checkpoints, run folders, compaction, baselines run as methods, schedules, and
//! every settings range.

#[path = "../common/mod.rs"]
mod common;

mod baselines;
mod checkpoint;
mod compact;
mod run_folder;
mod schedules;
mod settings;
mod stages;
mod trainer;
