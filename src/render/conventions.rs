//! The known, legitimate differences between Gaussian-splatting rasterizers, as named settings
//! of the reference renderer ([`super::RenderSettings::conventions`]).
//!
//! The default is this crate's convention (3DGS `graphdeco-inria/diff-gaussian-rasterization`,
//! `cuda_rasterizer/{forward,backward,auxiliary}.cu/h`, with gsplat's pixel centres and tile
//! rule); with it every output keeps its bits and the SIMD tile kernels run. Any other value
//! routes the render through the scalar per-pixel reference path ([`mod@super::reference`]), which
//! implements every setting below (per pixel, over its tile's splats; for audits, not training).
//!
//! | setting | default (3DGS) | gsplat v1.5.3 (`gsplat/cuda/_torch_impl.py`, `csrc/`) |
//! |---|---|---|
//! | `alpha_max` | 0.99 | 0.999 |
//! | `t_stop` | `exclusive`: stop when T (1 - alpha) < 1e-4 | `inclusive`: when <= 1e-4 |
//! | `radius_sigmas` | 3 | 3.33 |
//! | `radius_rule` | `eigen`: one radius ceil(k sqrt(lambda_max)), 0.1 floor | `axes`: ceil(k sqrt(Sigma2D_ii)) per axis |
//! | `eps2d` | 0.3 | 0.3 |
//! | `pixel_center` | 0.5 | 0.5 (3DGS's own CUDA samples at integer coordinates: 0) |
//! | `clamp_gradient` | `zero`: no gradient through min(alpha_max, o G) when clamped | `zero` (3DGS's CUDA: `pass`) |
//! | `near_plane` | 0.2 (cull z <= 0.2) | 0.01 |
//! | `jacobian_limits` | `symmetric`: x/z in +-1.3 tan(fov/2) | `principal-point`: -(cx/fx + 0.3 tan) .. (W - cx)/fx + 0.3 tan |
//!
//! In both the stopping splat is not blended (the test is on the transmittance after it).

use serde::{Deserialize, Serialize};

/// Transmittance stop: which comparison of T (1 - alpha) with 1e-4 ends a pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TStop {
    /// T (1 - alpha) < 1e-4 stops (3DGS; the threshold itself still blends).
    #[default]
    Exclusive,
    /// T (1 - alpha) <= 1e-4 stops (gsplat v1.5.3).
    Inclusive,
}

/// How the screen radius that bounds a splat's tiles is computed from Sigma2D.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RadiusRule {
    /// One radius ceil(k sqrt(lambda_max)), lambda_max = mid + sqrt(max(0.1, mid^2 - det)) (3DGS).
    #[default]
    Eigen,
    /// Per axis ceil(k sqrt(Sigma2D_00)), ceil(k sqrt(Sigma2D_11)) (gsplat v1.5).
    Axes,
}

/// Gradient of alpha = min(alpha_max, o G) where the clamp is active.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ClampGradient {
    /// The exact derivative: 0 (gsplat, brush, this crate).
    #[default]
    Zero,
    /// As if unclamped (3DGS's CUDA backward).
    Pass,
}

/// Limits of x/z inside the EWA Jacobian (cone beam only).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JacobianLimits {
    /// +-1.3 tan(fov/2), tan(fov_x/2) = W / (2 fx) (3DGS).
    #[default]
    Symmetric,
    /// -(cx/fx + 0.3 tan) .. (W - cx)/fx + 0.3 tan (gsplat; equal to the symmetric ones when
    /// cx = W/2).
    PrincipalPoint,
}

/// Rasterizer conventions (see the module docs for each setting's meaning and source).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Conventions {
    pub alpha_max: f64,
    pub t_stop: TStop,
    pub radius_sigmas: f64,
    pub radius_rule: RadiusRule,
    pub eps2d: f64,
    pub pixel_center: f64,
    pub clamp_gradient: ClampGradient,
    pub near_plane: f64,
    pub jacobian_limits: JacobianLimits,
}

/// 3DGS near plane: Gaussians with camera-space depth z <= NEAR are culled.
pub const NEAR: f64 = 0.2;
/// Low-pass dilation added to the diagonal of Sigma2D, px^2.
pub const DILATION: f64 = 0.3;
/// Radius = ceil(RADIUS_SIGMAS sqrt(lambda_max)).
pub const RADIUS_SIGMAS: f64 = 3.0;

impl Default for Conventions {
    fn default() -> Self {
        Conventions {
            alpha_max: super::composite::ALPHA_MAX,
            t_stop: TStop::Exclusive,
            radius_sigmas: RADIUS_SIGMAS,
            radius_rule: RadiusRule::Eigen,
            eps2d: DILATION,
            pixel_center: 0.5,
            clamp_gradient: ClampGradient::Zero,
            near_plane: NEAR,
            jacobian_limits: JacobianLimits::Symmetric,
        }
    }
}

impl Conventions {
    /// The crate's own conventions (the fast tile kernels run).
    pub fn is_default(&self) -> bool {
        *self == Conventions::default()
    }

    /// Error naming the field unless every value is in its valid range.
    pub fn validate(&self) -> crate::error::Result<()> {
        let bad = |field: &str, msg: String| {
            Err(crate::error::Error::invalid(
                format!("conventions.{field}"),
                msg,
            ))
        };
        if !(self.alpha_max > 1.0 / 255.0 && self.alpha_max < 1.0) {
            return bad(
                "alpha_max",
                format!("must be in (1/255, 1), got {}", self.alpha_max),
            );
        }
        if !(self.radius_sigmas > 0.0 && self.radius_sigmas <= 10.0) {
            return bad(
                "radius_sigmas",
                format!("must be in (0, 10], got {}", self.radius_sigmas),
            );
        }
        if !(self.eps2d >= 0.0 && self.eps2d <= 10.0) {
            return bad("eps2d", format!("must be in [0, 10], got {}", self.eps2d));
        }
        if !(self.pixel_center >= 0.0 && self.pixel_center < 1.0) {
            return bad(
                "pixel_center",
                format!("must be in [0, 1), got {}", self.pixel_center),
            );
        }
        if !(self.near_plane >= 0.0 && self.near_plane.is_finite()) {
            return bad(
                "near_plane",
                format!("must be finite and >= 0, got {}", self.near_plane),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_the_crate_constants_and_serialises_by_name() {
        let c = Conventions::default();
        assert!(c.is_default());
        assert_eq!(c.alpha_max, 0.99);
        assert_eq!(c.near_plane, 0.2);
        let s = serde_json::to_string(&c).unwrap();
        assert!(s.contains("\"t_stop\":\"exclusive\""), "{s}");
        let g: Conventions =
            serde_json::from_str(r#"{"alpha_max":0.999,"radius_rule":"axes"}"#).unwrap();
        assert_eq!(g.radius_rule, RadiusRule::Axes);
        assert_eq!(g.t_stop, TStop::Exclusive);
        assert!(!g.is_default());
        assert!(serde_json::from_str::<Conventions>(r#"{"alpha":0.9}"#).is_err());
    }

    #[test]
    fn validate_names_the_field() {
        let mut c = Conventions {
            alpha_max: 1.0,
            ..Default::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("conventions.alpha_max"), "{e}");
        c.alpha_max = 0.99;
        c.near_plane = f64::NAN;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("conventions.near_plane"), "{e}");
    }
}
