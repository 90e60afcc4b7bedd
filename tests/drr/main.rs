//! The DRR (`src/drr/`): closed forms in f64, the vector kernels against the per-ray loops,
//! the trilinear step's lattice sum, and `unispine drr` end to end.

#[path = "../common/mod.rs"]
mod common;

mod analytic;
mod cli;
mod simd;
mod trilinear_step;
mod views;
