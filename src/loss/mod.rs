//! Losses, Eqs. (6)-(9): SPWM weights, (weighted) Charbonnier, L1, SSIM and the hybrid loss.

pub mod charbonnier;
pub mod filters;
pub mod spwm;
pub mod ssim;

use crate::image2d::Image2d;
use crate::real::Real;

/// The data term of the loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DataTerm {
    /// Mean absolute error (3DGS, X-Gaussian).
    L1,
    /// Mean Charbonnier penalty.
    Charbonnier,
    /// SPWM-weighted Charbonnier, Eq. (9).
    WeightedCharbonnier,
}

/// Loss settings (Eq. 8).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossConfig {
    pub data_term: DataTerm,
    /// Weight of D-SSIM, lambda_dssim (0.2).
    pub lambda_dssim: f64,
    /// Charbonnier epsilon (1e-3).
    pub charbonnier_eps: f64,
    /// delta of Eq. (9) (1e-6).
    pub delta: f64,
}

/// Value of the loss and its parts.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossValue {
    pub total: f64,
    pub data: f64,
    pub ssim: f64,
}

/// Loss of `render` against `gt` (with SPWM `weights` for the weighted Charbonnier) and its
/// gradient with respect to `render` (not written yet).
pub fn forward_backward<R: Real>(
    render: &Image2d<R>,
    _gt: &Image2d<R>,
    _weights: Option<&Image2d<R>>,
    _cfg: &LossConfig,
) -> (LossValue, Image2d<R>) {
    (
        LossValue::default(),
        Image2d::filled(render.width, render.height, R::zero()),
    )
}
