//! Optimisation: Adam with per-group learning rates and the learning-rate schedules.

pub mod adam;
pub mod schedule;

pub use adam::{Adam, AdamConfig, Group, GroupLr, N_GROUPS};
pub use schedule::ExponLr;
