//! Optimisation: the one Adam kernel (per-group learning rates for the Gaussians, one flat
//! vector for the neural fields) and the learning-rate schedules.

pub mod adam;
pub mod schedule;

pub use adam::{Adam, AdamConfig, FlatAdam, Form, Group, GroupLr, N_GROUPS};
pub use schedule::ExponLr;
