//! Optimisation: Adam with per-group learning rates and the learning-rate schedules.

pub mod adam;
pub mod schedule;
