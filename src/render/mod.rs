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
//!
//! [`project`]: crate::render::project
//! [`composite`]: crate::render::composite
//! [`forward`]: crate::render::forward
//! [`backward`]: crate::render::backward

pub mod composite;
pub mod conventions;
pub mod lanes;
pub mod project;
pub mod reference;
pub mod tiles;

pub use conventions::Conventions;

use serde::{Deserialize, Serialize};

use crate::real::Real;

/// The intensity model lives with Eq. (2) in [`crate::gaussians::rirf`].
pub use crate::gaussians::rirf::ColorMode;

/// Rasterizer settings that are not part of the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Intensity model.
    pub color: ColorMode,
    /// Number of active features / SH coefficients: 1, 4, 9 or 16 (progressive enabling).
    pub active_features: usize,
    /// Background value added with the final transmittance (black = 0).
    pub background: f64,
    /// Rasterizer conventions (alpha clamp, radius, stop test, ...). The default keeps every
    /// output's bits and the fast kernels; another value renders through [`mod@reference`].
    #[serde(default, skip_serializing_if = "Conventions::is_default")]
    pub conventions: Conventions,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            color: ColorMode::RirfPaper,
            active_features: 16,
            background: 0.0,
            conventions: Conventions::default(),
        }
    }
}

/// Start of the PLY header comment that records how a model is rendered (see
/// [`RenderSettings::to_ply_comment`]).
pub const PLY_RENDER_COMMENT: &str = "unispine-render ";

impl RenderSettings {
    /// The PLY header comment that records these settings: `unispine-render ` followed by the
    /// settings as one-line JSON, e.g.
    /// `unispine-render {"color":"rirf-xgaussian","active_features":16,"background":0.0}`.
    /// Models written by `unispine train` carry it; `unispine render` and `unispine eval` use it.
    pub fn to_ply_comment(&self) -> String {
        format!(
            "{PLY_RENDER_COMMENT}{}",
            serde_json::to_string(self).expect("render settings serialise")
        )
    }

    /// The settings recorded in PLY header comments (`None` when no comment records them, as in
    /// PLYs from other tools). A malformed record is an error naming `path`.
    pub fn from_ply_comments(
        path: &std::path::Path,
        comments: &[String],
    ) -> crate::error::Result<Option<Self>> {
        let Some(c) = comments
            .iter()
            .find_map(|c| c.strip_prefix(PLY_RENDER_COMMENT))
        else {
            return Ok(None);
        };
        let s: RenderSettings = serde_json::from_str(c).map_err(|e| {
            crate::error::Error::format(path, "comment unispine-render", e.to_string())
        })?;
        s.validate().map_err(|e| {
            crate::error::Error::format(path, "comment unispine-render", e.to_string())
        })?;
        Ok(Some(s))
    }

    /// Error unless `active_features` is 1, 4, 9 or 16 and the background is finite.
    pub fn validate(&self) -> crate::error::Result<()> {
        if !crate::gaussians::rirf::valid_active(self.active_features) {
            return Err(crate::error::Error::invalid(
                "active_features",
                format!("must be 1, 4, 9 or 16, got {}", self.active_features),
            ));
        }
        if !self.background.is_finite() {
            return Err(crate::error::Error::invalid(
                "background",
                format!("must be finite, got {}", self.background),
            ));
        }
        self.conventions.validate()
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

impl<R: Real> Splats<R> {
    /// `n` splats with every field zero (all culled).
    pub fn zeros(n: usize) -> Self {
        let z = R::zero();
        Splats {
            mean2d: vec![[z; 2]; n],
            conic: vec![[z; 3]; n],
            depth: vec![z; n],
            radius: vec![0u32; n],
            opacity: vec![z; n],
            color: vec![z; n],
        }
    }
}

/// Gradient of a scalar loss with respect to the splat fields (same layout as [`Splats`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatGrads<R: Real> {
    pub mean2d: Vec<[R; 2]>,
    pub conic: Vec<[R; 3]>,
    pub opacity: Vec<R>,
    pub color: Vec<R>,
}

/// What [`backward`] needs from [`forward`].
#[derive(Clone, Debug)]
pub struct RenderSaved<R: Real> {
    pub splats: Splats<R>,
    pub project: project::ProjectSaved<R>,
    pub composite: composite::CompositeSaved<R>,
    /// The per-pixel blend lists of the reference path (non-default conventions), else `None`.
    pub reference: Option<Box<reference::ReferenceSaved<R>>>,
}

/// Gradients of a scalar loss from [`backward`].
#[derive(Clone, Debug)]
pub struct RenderGrads<R: Real> {
    /// d loss / d parameter, same layout as the model (pre-activation).
    pub params: crate::gaussians::Gaussians<R>,
    /// |d loss / d mean2d| with the mean in NDC (3DGS's densification statistic).
    pub mean2d_ndc_norm: Vec<R>,
    /// Gaussian drawn in this view (radius > 0).
    pub visible: Vec<bool>,
    /// Screen radius in pixels (0 = culled), for the screen-size prune.
    pub radius: Vec<u32>,
}

/// Render `g` from `cam`: projection then compositing. Non-default conventions render through
/// the scalar [`mod@reference`] path (validated first).
pub fn forward<R: Real>(
    g: &crate::gaussians::Gaussians<R>,
    cam: &crate::geometry::Camera,
    settings: &RenderSettings,
) -> crate::error::Result<(crate::image2d::Image2d<R>, RenderSaved<R>)> {
    if !settings.conventions.is_default() {
        return reference::forward(g, cam, settings);
    }
    let (splats, ps) = project::forward(g, cam, settings)?;
    let (img, cs) = composite::forward(&splats, cam.width, cam.height, R::c(settings.background));
    Ok((
        img,
        RenderSaved {
            splats,
            project: ps,
            composite: cs,
            reference: None,
        },
    ))
}

/// The compositing stage's VJP of a [`forward`]: the tile kernels, or the reference path's
/// per-pixel lists when the forward took it.
pub fn composite_backward<R: Real>(
    saved: &RenderSaved<R>,
    d_image: &crate::image2d::Image2d<R>,
) -> SplatGrads<R> {
    match &saved.reference {
        Some(r) => reference::composite_backward(&saved.splats, r, d_image),
        None => composite::backward(&saved.splats, &saved.composite, d_image),
    }
}

/// Gradients of sum(d_image * image) with respect to every parameter of `g`.
pub fn backward<R: Real>(
    g: &crate::gaussians::Gaussians<R>,
    cam: &crate::geometry::Camera,
    settings: &RenderSettings,
    saved: &RenderSaved<R>,
    d_image: &crate::image2d::Image2d<R>,
) -> RenderGrads<R> {
    let ds = composite_backward(saved, d_image);
    let params = project::backward(g, cam, settings, &saved.splats, &saved.project, &ds);
    let (w, h) = (R::c(cam.width as f64), R::c(cam.height as f64));
    let half = R::c(0.5);
    let mean2d_ndc_norm = ds
        .mean2d
        .iter()
        .map(|d| ((d[0] * w * half).powi(2) + (d[1] * h * half).powi(2)).sqrt())
        .collect();
    RenderGrads {
        params,
        mean2d_ndc_norm,
        visible: saved.splats.radius.iter().map(|&r| r > 0).collect(),
        radius: saved.splats.radius.clone(),
    }
}
