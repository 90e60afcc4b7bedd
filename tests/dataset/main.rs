//! Projection datasets (`src/dataset/`): folders, NAF pickles, `unispine data`, pose noise, and
//! hostile dataset files.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod hostile;
mod pickle;
mod pose_noise;
mod store;
