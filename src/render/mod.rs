//! Differentiable tile rasterizer, Eqs. (3)-(5).
//!
//! Two stages, each a `forward` / `backward` pair:
//! 1. [`project`]: Gaussians (Eq. 1) and a camera to per-Gaussian screen-space splats: EWA
//!    projection (mean, conic, radius, depth), opacity and intensity (RIRF, Eq. 2, or SH colour).
//! 2. [`composite`]: splats to an image: 16x16 tile binning, deterministic sort by
//!    (tile, depth, index), front-to-back alpha compositing (Eqs. 4-5).
//!
//! [`forward`] and [`backward`] chain the two and add the screen-space (NDC) mean-gradient norm
//! used by densification.

pub mod composite;
pub mod project;
pub mod tiles;

use serde::{Deserialize, Serialize};

use crate::real::Real;

/// How a Gaussian's intensity is computed from its 16 features.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ColorMode {
    /// The paper's Eq. (2): i = Sigmoid(sum_k lambda_k f_k).
    #[default]
    RirfPaper,
    /// X-Gaussian's code: i = max(0, 0.5 + sum_k lambda_k f_k).
    RirfXgaussian,
    /// View-dependent SH colour (3DGS baseline): i = max(0, 0.5 + SH(dir) . f), dir from the
    /// camera centre to the mean.
    Sh,
}

/// Rasterizer settings that are not part of the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Intensity model.
    pub color: ColorMode,
    /// Number of active features / SH coefficients: 1, 4, 9 or 16 (progressive enabling).
    pub active_features: usize,
    /// Background value added with the final transmittance (black = 0).
    pub background: f64,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            color: ColorMode::RirfPaper,
            active_features: 16,
            background: 0.0,
        }
    }
}

/// Per-Gaussian screen-space splats, the output of [`project::forward`] and the input of
/// [`composite::forward`]. A Gaussian with `radius == 0` is culled (not drawn).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Splats<R: Real> {
    /// Projected mean in pixels (u along columns, v along rows; pixel centres at +0.5).
    pub mean2d: Vec<[R; 2]>,
    /// Conic (inverse 2D covariance) entries (A, B, C) of [[A, B], [B, C]].
    pub conic: Vec<[R; 3]>,
    /// Camera-space depth z (sort key).
    pub depth: Vec<R>,
    /// Radius in pixels (0 = culled).
    pub radius: Vec<u32>,
    /// Opacity after the sigmoid.
    pub opacity: Vec<R>,
    /// Intensity i (Eq. 2 or SH colour).
    pub color: Vec<R>,
}

/// Gradient of a scalar loss with respect to the splat fields (same layout as [`Splats`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatGrads<R: Real> {
    pub mean2d: Vec<[R; 2]>,
    pub conic: Vec<[R; 3]>,
    pub opacity: Vec<R>,
    pub color: Vec<R>,
}
