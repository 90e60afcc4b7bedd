//! The reproduction harness (`src/reproduce/`): plans run and resumed, hostile plans, a real
//! Slurm, the results regression, and the verdict arithmetic.

#[path = "../common/mod.rs"]
mod common;

mod hostile_plans;
mod results_regression;
mod run;
mod slurm;
mod verdicts;
