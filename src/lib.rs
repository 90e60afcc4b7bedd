//! # unispine: a CPU reference for X-ray / ultrasound Gaussian splatting (UniSpine-GS)
//!
//! Pure-CPU, deterministic (bit-identical for any thread count), numerically audited.
//! The modules below are listed in data-flow order; reading them top to bottom is the pipeline:
//!
//! ```text
//! geometry (TIGRE cone beam, per-angle cameras, voxel placement)
//!   -> volume (CT NIfTI / US MetaImage / built-in phantom / US-like proxy)
//!   -> drr (Siddon and trilinear line integrals)
//!   -> dataset (train/test views, stored as json + npy)
//!   -> gaussians (Eq. 1 model, Eq. 2 RIRF, ACUI init, PLY)
//!   -> render (Eqs. 3-5: projection, tiles, compositing; forward + backward)
//!   -> loss (Eqs. 6-9: SPWM, weighted Charbonnier, SSIM)
//!   -> optim (Adam, schedules) -> densify -> eval (PSNR, SSIM, fps) -> train
//!   -> baseline (FDK, neural fields behind `train --method`) -> reproduce -> report
//! ```

// The library never prints (progress leaves as events, `train::event`); only the binary
// (`src/main.rs` and its `cli` modules) does.
#![cfg_attr(not(test), warn(clippy::print_stdout, clippy::print_stderr))]

// Foundations shared by every stage.
pub mod error;
/// Fingerprints (FNV-1a) of bytes, configs and datasets: identity checks, not security.
pub mod fingerprint;
/// Atomic file writes (temporary name + rename) and output-folder hygiene.
pub mod fsio;
// A typed document (headings, paragraphs, lists, tables) rendered as Markdown or HTML: what
// `tables.md`, `docs/claims.md` and `report.html` are made of.
pub mod doc;
// Settings as command-line flags, declared as data (names, help, parsers, named choices).
#[macro_use]
pub mod flags;
pub mod real;

pub mod image2d;
pub mod math;
pub mod par;
pub mod preview;
pub mod simd;
// The clocks of the stage timers (wall and CPU time).
pub mod timer;

// The pipeline, in data-flow order (one stage per module).

/// TIGRE cone-beam geometry and the per-angle camera (and where a volume's voxels lie).
pub mod geometry;

/// Volumes: NIfTI / MetaImage / npy readers, HU conversion, crop, resampling, the phantom and
/// the ultrasound-like proxy.
pub mod volume;

/// Our DRR ray-marchers (Siddon, trilinear).
pub mod drr;

/// Projection datasets: generation with the paper protocol, storage, pickle import.
pub mod dataset;

/// Classical baseline: FDK reconstruction with TIGRE's semantics.
pub mod fdk;

/// Radiative Gaussians (Eq. 1), RIRF (Eq. 2), ACUI initialisation, PLY.
pub mod gaussians;

/// The differentiable tile rasterizer (Eqs. 3-5), forward and backward.
pub mod render;

/// SPWM (Eqs. 6-7), Charbonnier / weighted Charbonnier, SSIM, the hybrid loss (Eqs. 8-9).
pub mod loss;

/// Adam and learning-rate schedules.
pub mod optim;

/// Adaptive density control: clone, split, prune, opacity reset.
pub mod densify;

/// Evaluation: PSNR, SSIM, fps (also run inside the training loop).
pub mod eval;

// What one training iteration of any method did: the one step record.
pub mod record;

/// Neural attenuation fields (NAF, IntraTomo, NeRF baselines): encoders, MLP, line-integral
/// renderer, trainer; forward + backward.
pub mod field;

/// Method presets and the Gaussian trainer.
pub mod train;

/// Table 1's baselines behind `train --method`: scoring of predicted line integrals, the
/// baseline settings and run-folder files.
pub mod baseline;

// The registry of every method (Gaussian presets and baselines) and the interface a method
// implements for the session driver: step, evaluate, checkpoint, restore, describe.
pub mod method;

// The one driver of any method: iterations, stop requests, progress events, the run folder,
// checkpoints and resume.
pub mod session;

/// `unispine reproduce`: plans of datasets x methods x seeds, tables with verdicts, charts.
pub mod reproduce;

/// Tables of finished runs and the reproduction report (Markdown, HTML, SVG charts).
pub mod report;

/// Numerical audits: gradient checks against finite differences.
pub mod audit;

/// Benchmarks of every stage (scenes, timers, the figures `unispine bench` prints).
pub mod bench;

pub use error::{Error, Result};
pub use real::Real;
