//! Losses, Eqs. (6)-(9): SPWM weights, (weighted) Charbonnier, L1, SSIM and the hybrid loss.
//!
//! ```text
//! Eq. (8)  L = (1 - lambda_dssim) L_data + lambda_dssim (1 - SSIM(render, gt))
//! ```
//!
//! with `L_data` one of L1 (3DGS, X-Gaussian), Charbonnier, or the SPWM-weighted Charbonnier of
//! Eq. (9) (UniSpine-GS). [`forward_backward`] returns the value, its parts, and d L / d render;
//! the SPWM weights (Eqs. 6-7, [`spwm`]) are inputs, built from the ground truth only.
//!
//! [`forward_backward`]: crate::loss::forward_backward
//! [`spwm`]: crate::loss::spwm

pub mod charbonnier;
pub mod filters;
pub mod spwm;
pub mod ssim;

use rayon::prelude::*;

use crate::image2d::Image2d;
use crate::par::CHUNK;
use crate::real::Real;

crate::choice! {
/// The data term of the loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum DataTerm {
    /// Mean absolute error (3DGS, X-Gaussian).
    L1 = "l1",
    /// Mean Charbonnier penalty.
    Charbonnier = "charbonnier",
    /// SPWM-weighted Charbonnier, Eq. (9).
    WeightedCharbonnier = "weighted-charbonnier",
}
}

/// Loss settings (Eq. 8). `Default` is the UniSpine-GS loss
/// ([`LossConfig::weighted_charbonnier_dssim`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossConfig {
    pub data_term: DataTerm,
    /// Weight of D-SSIM, lambda_dssim (0.2).
    pub lambda_dssim: f64,
    /// Charbonnier epsilon (1e-3), squared inside the root: rho = sqrt(e^2 + eps^2).
    pub charbonnier_eps: f64,
    /// delta of Eq. (9) (1e-6).
    pub delta: f64,
}

impl Default for LossConfig {
    fn default() -> Self {
        Self::weighted_charbonnier_dssim()
    }
}

impl LossConfig {
    /// 3DGS / X-Gaussian: 0.8 L1 + 0.2 (1 - SSIM).
    pub fn l1_dssim() -> Self {
        LossConfig {
            data_term: DataTerm::L1,
            ..Self::weighted_charbonnier_dssim()
        }
    }

    /// Plain (unweighted) Charbonnier: 0.8 mean rho + 0.2 (1 - SSIM).
    pub fn charbonnier_dssim() -> Self {
        LossConfig {
            data_term: DataTerm::Charbonnier,
            ..Self::weighted_charbonnier_dssim()
        }
    }

    /// UniSpine-GS, Eqs. (8)-(9): 0.8 L_w-charb + 0.2 (1 - SSIM), eps 1e-3, delta 1e-6.
    pub fn weighted_charbonnier_dssim() -> Self {
        LossConfig {
            data_term: DataTerm::WeightedCharbonnier,
            lambda_dssim: 0.2,
            charbonnier_eps: 1e-3,
            delta: 1e-6,
        }
    }

    /// Check the settings; `Err` names the field.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |field: &str, msg: &str| {
            Err(crate::Error::Invalid {
                field: format!("loss.{field}"),
                msg: msg.to_string(),
            })
        };
        if !(0.0..=1.0).contains(&self.lambda_dssim) {
            return bad("lambda_dssim", "must be in [0, 1]");
        }
        if !(self.charbonnier_eps.is_finite() && self.charbonnier_eps >= 0.0) {
            return bad("charbonnier_eps", "must be finite and >= 0");
        }
        if !(self.delta.is_finite() && self.delta >= 0.0) {
            return bad("delta", "must be finite and >= 0");
        }
        Ok(())
    }
}

/// Value of the loss and its parts.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossValue {
    /// L of Eq. (8).
    pub total: f64,
    /// The data term (L1, Charbonnier or L_w-charb of Eq. 9).
    pub data: f64,
    /// SSIM(render, gt) (not 1 - SSIM).
    pub ssim: f64,
}

/// Loss of `render` against `gt` (Eq. 8) and its gradient with respect to `render`.
///
/// `weights` are the SPWM weights w of Eq. (7) for the weighted Charbonnier (`None` = all ones);
/// they are ignored by the other data terms. Panics if the images differ in size (a programming
/// error: the renderer and the dataset agree on the detector).
pub fn forward_backward<R: Real>(
    render: &Image2d<R>,
    gt: &Image2d<R>,
    weights: Option<&Image2d<R>>,
    cfg: &LossConfig,
) -> (LossValue, Image2d<R>) {
    let (data, mut grad) = match cfg.data_term {
        DataTerm::L1 => charbonnier::l1(render, gt),
        DataTerm::Charbonnier => charbonnier::charbonnier(render, gt, cfg.charbonnier_eps),
        DataTerm::WeightedCharbonnier => {
            charbonnier::weighted_charbonnier(render, gt, weights, cfg.charbonnier_eps, cfg.delta)
        }
    };
    let lam = cfg.lambda_dssim;
    let (s, g_ssim) = if lam != 0.0 {
        ssim::ssim_forward_backward(render, gt)
    } else {
        (
            ssim::ssim(render, gt),
            Image2d::filled(render.width, render.height, R::zero()),
        )
    };
    // Eq. (8).
    let total = (1.0 - lam) * data + lam * (1.0 - s);
    let (a, b) = (R::c(1.0 - lam), R::c(lam));
    grad.data
        .par_chunks_mut(CHUNK)
        .zip(g_ssim.data.par_chunks(CHUNK))
        .for_each(|(gd, gs)| {
            for (d, &s) in gd.iter_mut().zip(gs) {
                *d = a * *d - b * s;
            }
        });
    (
        LossValue {
            total,
            data,
            ssim: s,
        },
        grad,
    )
}
