//! # unispine: a CPU reference for X-ray / ultrasound Gaussian splatting (UniSpine-GS)
//!
//! Pure-CPU, deterministic (bit-identical for any thread count), numerically audited.
//! The modules below are listed in data-flow order; reading them top to bottom is the pipeline:
//!
//! ```text
//! volume (CT NIfTI / US MetaImage / built-in phantom / US-like proxy)
//!   -> geometry (TIGRE cone beam, per-angle cameras)
//!   -> drr (Siddon and trilinear line integrals)
//!   -> dataset (train/test views, stored as json + npy)
//!   -> gaussians (Eq. 1 model, Eq. 2 RIRF, ACUI init, PLY)
//!   -> render (Eqs. 3-5: projection, tiles, compositing; forward + backward)
//!   -> loss (Eqs. 6-9: SPWM, weighted Charbonnier, SSIM)
//!   -> optim (Adam, schedules) -> densify -> train -> eval -> report
//! ```

// Foundations shared by every stage.
pub mod error;
pub mod image2d;
pub mod math;
pub mod par;
pub mod real;

// The pipeline, in data-flow order.
pub mod dataset;
pub mod densify;
pub mod drr;
pub mod eval;
pub mod gaussians;
pub mod geometry;
pub mod loss;
pub mod optim;
pub mod render;
pub mod report;
pub mod train;
pub mod volume;

// Front end.
pub mod cli;

pub use error::{Error, Result};
pub use real::Real;
