//! The neural-field baselines (`src/field/`): finite differences, encoders, the blocked matrix
//! products, golden files, ray sampling, and the field trainer's StepLR.

#[path = "../common/mod.rs"]
mod common;

mod encoders;
mod gemm;
mod golden;
mod gradcheck;
mod sampling;
mod stages;
mod step_lr;
