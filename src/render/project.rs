//! Eqs. (1)-(3), per Gaussian: parameters and a camera to a screen-space splat.
//!
//! Forward, for Gaussian i (all in precision `R`):
//! 1. Eq. (1): Sigma = R(q/|q|) diag(exp(log_scale))^2 R^T ([`crate::math::covariance`]).
//! 2. Eq. (3), EWA: t = W (mu - c) (W = world-to-camera rotation). Cull if t_z <= 0.2 (3DGS
//!    near plane; also used for the parallel beam, where it means "behind the source plane").
//!    - Cone beam: mean2d = (fx t_x/t_z + cx, fy t_y/t_z + cy) in pixels with pixel centres at
//!      +0.5 (cx = W/2 - offU/du, see `geometry.rs`). J = [[fx/z, 0, -fx x~/z^2],
//!      [0, fy/z, -fy y~/z^2]] with x~ = z clamp(x/z, -lim_x, lim_x), lim_x = 1.3 tan(fov_x/2),
//!      tan(fov_x/2) = W / (2 fx) (3DGS: symmetric limits, only inside J).
//!    - Parallel beam: mean2d = (t_x/du + cx, t_y/dv + cy) (= `Camera::project_cam`, which
//!      agrees with `Camera::pixel_ray`), J = diag(1/du, 1/dv) (no clamp, no depth dependence).
//!    - Sigma2D = J W Sigma W^T J^T + 0.3 I; cull unless det > 0 (and finite); conic = inverse.
//!    - radius = ceil(3 sqrt(lambda_max)) with 3DGS's lambda_max = mid + sqrt(max(0.1, mid^2 -
//!      det)). Cull (radius 0) when the square [u - r, u + r] x [v - r, v + r] misses the image
//!      [0, W] x [0, H] (gsplat's off-screen test; 3DGS gets the same through an empty tile
//!      rect).
//! 3. opacity = sigmoid(logit); intensity by Eq. (2) (paper or X-Gaussian RIRF) or SH colour
//!    ([`crate::gaussians::rirf`]).
//!
//! Culled Gaussians have `radius == 0` and every other splat field 0 except `depth` (t_z when
//! it could be computed); their parameter gradients are exactly 0.
//!
//! Degenerate input: a NaN/infinite parameter is an error naming the Gaussian and group
//! (`Gaussians::check_finite`); a quaternion with |q|^2 < 1e-24 is culled (no rotation can be
//! defined; its gradient is 0); a tiny scale is fine (the 0.3 dilation keeps Sigma2D
//! invertible); a scale whose covariance overflows `R` fails the det test and is culled.
//!
//! Backward ([`backward`]) is the exact derivative of what forward computes: the quaternion
//! normalisation VJP, the full conic VJP (no 1e-7 regulariser), the zero derivative through a
//! clamped coordinate of J and its exact z-term (3DGS is a factor 2 off there), the mean
//! projection, and the SH direction (gradient into the mean). Everything is recomputed from the
//! parameters except what the forward's splats hold (which Gaussians were drawn, the opacity,
//! the intensity) and exp(log_scale), which `ProjectSaved` keeps.
//!
//! Parallelism: rayon over fixed chunks of `par::CHUNK` Gaussians; each Gaussian is an
//! independent pure function, so the output is bit-identical for any thread count. Within a
//! chunk, blocks of 16 Gaussians run the geometry (forward and backward) as one branch-free
//! loop over the lanes, compiled for each instruction set (`project/blocks.rs`): every lane
//! performs the per-Gaussian operations ([`project_geom`], `geom_core`, `backward_geom`), so
//! every path gives the same bits.
//!
//! Longer than 600 lines: the forward and the backward of Eqs. (1)-(3) for one Gaussian stay
//! side by side, each backward step beside the forward step it differentiates.

#![allow(clippy::needless_range_loop)] // small fixed-size matrix loops read best indexed

use rayon::prelude::*;

use super::{ColorMode, RenderSettings, SplatGrads, Splats};
use crate::error::{Error, Result};
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::rirf;
use crate::gaussians::Gaussians;
use crate::geometry::{Camera, Mode};
use crate::math::activations::sigmoid_grad_from_output;
use crate::math::covariance::{covariance_scaled, covariance_vjp, CovParts};
use crate::math::inverse2::{sym2_inverse_unchecked, sym2_inverse_vjp};
use crate::math::quat::normalize_unchecked;
use crate::math::round;
use crate::math::{mat3_cast, mat3_t_vec, mat3_vec, Mat3};
use crate::par::CHUNK;
use crate::real::Real;
use crate::simd::Simd;

mod blocks;

pub use super::conventions::{DILATION, NEAR, RADIUS_SIGMAS};
/// Jacobian clamp factor: |x/z| <= CLAMP tan(fov/2) inside J.
pub const CLAMP: f64 = 1.3;
/// 3DGS's floor on the eigenvalue discriminant mid^2 - det.
pub const DISCRIMINANT_FLOOR: f64 = 0.1;

/// What [`backward`] needs from [`forward`] besides the splats (whose radius says which
/// Gaussians were drawn, and whose opacity and colour their gradients need).
#[derive(Clone, Debug, Default)]
pub struct ProjectSaved<R: Real> {
    /// exp(log_scale) (Eq. 1) of the drawn Gaussians (0 for the others): kept rather than
    /// recomputed, three C library exponentials per Gaussian.
    pub scale: Vec<[R; 3]>,
}

/// Camera constants in precision `R`.
#[derive(Clone, Copy, Debug)]
pub struct CamConsts<R: Real> {
    /// World-to-camera rotation W (rows = camera axes).
    pub rot: Mat3<R>,
    /// Camera centre (source), world.
    pub centre: [R; 3],
    /// Focal lengths in pixels for the cone beam (DSD / pitch), 1 / pitch for the parallel
    /// beam (pixels per mm).
    pub fx: R,
    pub fy: R,
    pub cx: R,
    pub cy: R,
    /// Jacobian clamp limits 1.3 tan(fov/2) on x/z and y/z (cone beam only).
    pub lim_x: R,
    /// Lower limit of x/z inside J, negated (= `lim_x` unless the conventions say
    /// `principal-point`).
    pub lim_x_neg: R,
    pub lim_y: R,
    /// Lower limit of y/z inside J, negated.
    pub lim_y_neg: R,
    /// Near plane: drawn only when t_z > `near`.
    pub near: R,
    /// Sigma2D dilation (eps2d).
    pub dilation: R,
    pub width: f64,
    pub height: f64,
    pub parallel: bool,
}

impl<R: Real> CamConsts<R> {
    /// Constants of `cam`.
    pub fn new(cam: &Camera) -> Self {
        Self::with_conventions(cam, &super::Conventions::default())
    }

    /// The constants of `cam` under the projection conventions of `conv` (near plane, eps2d,
    /// Jacobian limits); the defaults give [`CamConsts::new`].
    pub fn with_conventions(cam: &Camera, conv: &super::Conventions) -> Self {
        let parallel = cam.mode == Mode::Parallel;
        let (fx, fy) = if parallel {
            (1.0 / cam.pitch[1], 1.0 / cam.pitch[0])
        } else {
            (cam.fx, cam.fy)
        };
        let tan_x = cam.width as f64 / (2.0 * cam.fx);
        let tan_y = cam.height as f64 / (2.0 * cam.fy);
        let (lim_x, lim_x_neg, lim_y, lim_y_neg) = match conv.jacobian_limits {
            super::conventions::JacobianLimits::Symmetric => {
                (CLAMP * tan_x, CLAMP * tan_x, CLAMP * tan_y, CLAMP * tan_y)
            }
            // gsplat `_persp_proj`: (W - cx)/fx + 0.3 tan and cx/fx + 0.3 tan.
            super::conventions::JacobianLimits::PrincipalPoint => (
                (cam.width as f64 - cam.cx) / cam.fx + (CLAMP - 1.0) * tan_x,
                cam.cx / cam.fx + (CLAMP - 1.0) * tan_x,
                (cam.height as f64 - cam.cy) / cam.fy + (CLAMP - 1.0) * tan_y,
                cam.cy / cam.fy + (CLAMP - 1.0) * tan_y,
            ),
        };
        CamConsts {
            rot: mat3_cast(&cam.rot),
            centre: cam.centre.map(R::c),
            fx: R::c(fx),
            fy: R::c(fy),
            cx: R::c(cam.cx),
            cy: R::c(cam.cy),
            lim_x: R::c(lim_x),
            lim_x_neg: R::c(lim_x_neg),
            lim_y: R::c(lim_y),
            lim_y_neg: R::c(lim_y_neg),
            near: R::c(conv.near_plane),
            dilation: R::c(conv.eps2d),
            width: cam.width as f64,
            height: cam.height as f64,
            parallel,
        }
    }
}

/// Every intermediate of the geometric part of the projection of one Gaussian.
#[derive(Clone, Copy, Debug)]
pub struct Geom<R: Real> {
    pub cov: CovParts<R>,
    /// World-space 3D covariance (Eq. 1).
    pub sigma: Mat3<R>,
    /// Camera-space mean.
    pub t: [R; 3],
    /// T = J W (2x3).
    pub tm: [[R; 3]; 2],
    /// x/z, y/z were clamped inside J.
    pub clamped: [bool; 2],
    /// Sigma2D entries (a, b, c) including the dilation.
    pub cov2d: [R; 3],
    pub conic: [R; 3],
    pub mean2d: [R; 2],
    pub radius: u32,
}

/// Why a Gaussian was culled (for tests and diagnostics).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cull {
    /// |q| ~ 0: no rotation.
    ZeroQuaternion,
    /// z <= 0.2 (behind the camera / source plane, or too close).
    Near,
    /// Sigma2D not positive definite or not finite.
    Degenerate,
    /// The 3-sigma square misses the image.
    OffImage,
}

/// Geometric projection of one Gaussian (Eqs. 1 and 3), or why it is culled. The depth is
/// returned alongside so culled Gaussians still report it when known.
#[inline(always)]
pub fn project_geom<R: Real>(
    cam: &CamConsts<R>,
    mean: [R; 3],
    log_scale: [R; 3],
    quat: [R; 4],
) -> (std::result::Result<Geom<R>, Cull>, R) {
    let scale = [log_scale[0].exp(), log_scale[1].exp(), log_scale[2].exp()];
    let (geo, cull) = if cam.parallel {
        geom_core::<R, true, true>(cam, mean, scale, quat)
    } else {
        geom_core::<R, true, false>(cam, mean, scale, quat)
    };
    let depth = geo.t[2];
    (cull.map_or(Ok(geo), Err), depth)
}

/// [`project_geom`] from exp(log_scale), without a branch (so that loops over Gaussians
/// vectorise): every field is computed, and the first cull that applies is returned beside
/// them (`None`: drawn; the fields are meaningless past a cull). `PARALLEL` must be
/// `cam.parallel`. With `SCREEN` false it stops at Sigma2D, all the backward needs of a
/// Gaussian the forward drew: no conic, radius or off-image test (`conic` and `radius` are left
/// 0, and only the zero-quaternion and near-plane culls apply).
#[inline(always)]
pub(crate) fn geom_core<R: Real, const SCREEN: bool, const PARALLEL: bool>(
    cam: &CamConsts<R>,
    mean: [R; 3],
    scale: [R; 3],
    quat: [R; 4],
) -> (Geom<R>, Option<Cull>) {
    let d = [
        mean[0] - cam.centre[0],
        mean[1] - cam.centre[1],
        mean[2] - cam.centre[2],
    ];
    let t = mat3_vec(&cam.rot, d);
    let (quat_ok, norm, qn) = normalize_unchecked(quat);
    let (sigma, cov) = covariance_scaled(norm, qn, scale);
    // Positive phrasing so that NaN fails.
    let near_ok = t[2] > cam.near;
    let zero = R::zero();
    let (j, clamped, mean2d) = if PARALLEL {
        (
            [[cam.fx, zero, zero], [zero, cam.fy, zero]],
            [false, false],
            [cam.fx * t[0] + cam.cx, cam.fy * t[1] + cam.cy],
        )
    } else {
        let z = t[2];
        let iz = R::one() / z;
        let (rx, ry) = (t[0] * iz, t[1] * iz);
        let cxr = rx.max(-cam.lim_x_neg).min(cam.lim_x);
        let cyr = ry.max(-cam.lim_y_neg).min(cam.lim_y);
        let clamped = [cxr != rx, cyr != ry];
        // x~/z^2 = clamp(x/z)/z.
        (
            [
                [cam.fx * iz, zero, -cam.fx * cxr * iz],
                [zero, cam.fy * iz, -cam.fy * cyr * iz],
            ],
            clamped,
            [cam.fx * rx + cam.cx, cam.fy * ry + cam.cy],
        )
    };
    // T = J W.
    let mut tm = [[zero; 3]; 2];
    for r in 0..2 {
        for c in 0..3 {
            tm[r][c] = j[r][0] * cam.rot[0][c] + j[r][1] * cam.rot[1][c] + j[r][2] * cam.rot[2][c];
        }
    }
    // Sigma2D = T Sigma T^T + 0.3 I.
    let s0 = mat3_vec(&sigma, tm[0]);
    let s1 = mat3_vec(&sigma, tm[1]);
    let dil = cam.dilation;
    let a = tm[0][0] * s0[0] + tm[0][1] * s0[1] + tm[0][2] * s0[2] + dil;
    let b = tm[0][0] * s1[0] + tm[0][1] * s1[1] + tm[0][2] * s1[2];
    let c = tm[1][0] * s1[0] + tm[1][1] * s1[1] + tm[1][2] * s1[2] + dil;
    let mut geo = Geom {
        cov,
        sigma,
        t,
        tm,
        clamped,
        cov2d: [a, b, c],
        conic: [zero; 3],
        mean2d,
        radius: 0,
    };
    let cull = if !quat_ok {
        Some(Cull::ZeroQuaternion)
    } else if !near_ok {
        Some(Cull::Near)
    } else {
        None
    };
    if !SCREEN {
        return (geo, cull);
    }
    let (det_ok, conic) = sym2_inverse_unchecked(a, b, c);
    let conic_ok = conic[0].is_finite() & conic[1].is_finite() & conic[2].is_finite();
    // 3DGS radius (f64 so that f32 and f64 agree except at exact integer boundaries).
    let (af, bf, cf) = (a.f64(), b.f64(), c.f64());
    let det = af * cf - bf * bf;
    let mid = 0.5 * (af + cf);
    let lmax = mid + (mid * mid - det).max(DISCRIMINANT_FLOOR).sqrt();
    let rf = round::ceil(RADIUS_SIGMAS * lmax.sqrt());
    let radius_ok = rf.is_finite() & (rf >= 1.0) & (rf < u32::MAX as f64);
    let (u, v) = (mean2d[0].f64(), mean2d[1].f64());
    let on_image = (u + rf > 0.0) & (u - rf < cam.width) & (v + rf > 0.0) & (v - rf < cam.height);
    geo.conic = conic;
    geo.radius = rf as u32;
    let cull = match cull {
        None if !(det_ok & conic_ok & radius_ok) => Some(Cull::Degenerate),
        None if !on_image => Some(Cull::OffImage),
        c => c,
    };
    (geo, cull)
}

/// Intensity of one Gaussian: Eq. (2) (both RIRF variants) or SH colour (direction from the
/// camera centre to the mean, degree from `active`).
#[inline(always)]
pub fn intensity<R: Real>(
    mode: ColorMode,
    active: usize,
    centre: [R; 3],
    mean: [R; 3],
    f: &[R; N_FEATURES],
) -> R {
    match mode {
        ColorMode::RirfPaper => rirf::rirf_paper(f, active),
        ColorMode::RirfXgaussian => rirf::rirf_xgaussian(f, active),
        ColorMode::Sh => {
            let (dir, _) = sh_dir(centre, mean);
            let b = rirf::sh_basis(dir);
            let mut s = R::c(0.5);
            for k in 0..active {
                s += b[k] * f[k];
            }
            s.max(R::zero())
        }
    }
}

/// Unit direction from the camera centre to the mean and the distance (1 if they coincide:
/// the direction is then (0, 0, 0), which only the degree-0 term survives).
#[inline(always)]
fn sh_dir<R: Real>(centre: [R; 3], mean: [R; 3]) -> ([R; 3], R) {
    let v = [
        mean[0] - centre[0],
        mean[1] - centre[1],
        mean[2] - centre[2],
    ];
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > R::zero() {
        (v.map(|x| x / n), n)
    } else {
        ([R::zero(); 3], R::one())
    }
}

/// VJP of [`intensity`]: (d mean, d features).
#[inline(always)]
pub fn intensity_vjp<R: Real>(
    mode: ColorMode,
    active: usize,
    centre: [R; 3],
    mean: [R; 3],
    f: &[R; N_FEATURES],
    value: R,
    gi: R,
) -> ([R; 3], [R; N_FEATURES]) {
    let zero3 = [R::zero(); 3];
    match mode {
        ColorMode::RirfPaper => (zero3, rirf::rirf_paper_vjp(value, active, gi)),
        ColorMode::RirfXgaussian => (zero3, rirf::rirf_xgaussian_vjp(f, active, gi)),
        ColorMode::Sh => {
            let (dir, n) = sh_dir(centre, mean);
            let b = rirf::sh_basis(dir);
            let mut s = R::c(0.5);
            for k in 0..active {
                s += b[k] * f[k];
            }
            let mut df = [R::zero(); N_FEATURES];
            if s < R::zero() {
                // Clamped at 0 (3DGS): zero gradient.
                return (zero3, df);
            }
            for k in 0..active {
                df[k] = gi * b[k];
            }
            let gf: [R; N_FEATURES] = std::array::from_fn(|k| gi * f[k]);
            let gd = rirf::sh_basis_vjp(dir, active, &gf);
            // d = v / |v|: dv = (I - d d^T) gd / |v|.
            let dot = dir[0] * gd[0] + dir[1] * gd[1] + dir[2] * gd[2];
            let dm = [
                (gd[0] - dir[0] * dot) / n,
                (gd[1] - dir[1] * dot) / n,
                (gd[2] - dir[2] * dot) / n,
            ];
            (dm, df)
        }
    }
}

/// The input checks of [`forward`]: lengths, finite values, active features.
pub(crate) fn check_inputs<R: Real>(g: &Gaussians<R>, settings: &RenderSettings) -> Result<()> {
    let n = g.len();
    for (name, len) in [
        ("log_scales", g.log_scales.len()),
        ("quats", g.quats.len()),
        ("opacity_logits", g.opacity_logits.len()),
        ("features", g.features.len()),
    ] {
        if len != n {
            return Err(Error::invalid(
                name,
                format!("has {len} entries but `means` has {n}"),
            ));
        }
    }
    if !rirf::valid_active(settings.active_features) {
        return Err(Error::invalid(
            "active_features",
            format!("must be 1, 4, 9 or 16, got {}", settings.active_features),
        ));
    }
    g.check_finite()
}

/// Project every Gaussian; a NaN or infinite parameter is an error naming the Gaussian.
pub fn forward<R: Real>(
    g: &Gaussians<R>,
    cam: &Camera,
    settings: &RenderSettings,
) -> Result<(Splats<R>, ProjectSaved<R>)> {
    forward_with(Simd::active(), g, cam, settings)
}

/// [`forward`] with the loops compiled for `simd` (or the widest supported narrower set): the
/// same bits on every path.
pub(crate) fn forward_with<R: Real>(
    simd: Simd,
    g: &Gaussians<R>,
    cam: &Camera,
    settings: &RenderSettings,
) -> Result<(Splats<R>, ProjectSaved<R>)> {
    check_inputs(g, settings)?;
    let n = g.len();
    let cc = CamConsts::<R>::with_conventions(cam, &settings.conventions);
    let z = R::zero();
    let mut s = Splats::zeros(n);
    let mut scale = vec![[z; 3]; n];
    s.mean2d
        .par_chunks_mut(CHUNK)
        .zip(s.conic.par_chunks_mut(CHUNK))
        .zip(s.depth.par_chunks_mut(CHUNK))
        .zip(s.radius.par_chunks_mut(CHUNK))
        .zip(s.opacity.par_chunks_mut(CHUNK))
        .zip(s.color.par_chunks_mut(CHUNK))
        .zip(scale.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(ci, ((((((m2, co), de), ra), op), cl), sc))| {
            let out = blocks::SplatsOut {
                mean2d: m2,
                conic: co,
                depth: de,
                radius: ra,
                opacity: op,
                color: cl,
                scale: sc,
            };
            blocks::run_chunk(
                simd,
                &cc,
                settings,
                g,
                ci * CHUNK,
                blocks::Pass::Forward(out),
            );
        });
    let saved = ProjectSaved { scale };
    Ok((s, saved))
}

/// Gradients of the opacity `o` and the intensity `value` of one visible Gaussian (their
/// forward values given): (d mean from the SH direction, d opacity logit, d features).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn backward_appearance<R: Real>(
    cc: &CamConsts<R>,
    settings: &RenderSettings,
    mean: [R; 3],
    f: &[R; N_FEATURES],
    o: R,
    value: R,
    go: R,
    gi: R,
) -> ([R; 3], R, [R; N_FEATURES]) {
    let dlogit = go * sigmoid_grad_from_output(o);
    let (mode, active) = (settings.color, settings.active_features);
    let (dmean, dfeat) = intensity_vjp(mode, active, cc.centre, mean, f, value, gi);
    (dmean, dlogit, dfeat)
}

/// Gradients of the geometry of one visible Gaussian (Eqs. 1 and 3) from d mean2d and d conic:
/// (d mean, d log_scale, d quaternion). Branch-free, like [`geom_core`]; `PARALLEL` must be
/// `cc.parallel`.
#[inline(always)]
pub(crate) fn backward_geom<R: Real, const PARALLEL: bool>(
    cc: &CamConsts<R>,
    geo: &Geom<R>,
    gm: [R; 2],
    gc: [R; 3],
) -> ([R; 3], [R; 3], [R; 4]) {
    let zero = R::zero();
    let two = R::c(2.0);
    let half = R::c(0.5);
    // Conic -> Sigma2D (a, b, c); the dilation passes the gradient through unchanged.
    let [a, b, c] = geo.cov2d;
    let [da, db, dc] = sym2_inverse_vjp(a, b, c, gc);
    // Symmetric G2 = [[da, db/2], [db/2, dc]].
    let g2 = [[da, half * db], [half * db, dc]];
    let tm = &geo.tm;
    // dSigma = T^T G2 T (3x3, symmetric); u_r = (G2 T) row r.
    let mut gt = [[zero; 3]; 2];
    for r in 0..2 {
        for col in 0..3 {
            gt[r][col] = g2[r][0] * tm[0][col] + g2[r][1] * tm[1][col];
        }
    }
    let mut dsig = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            dsig[i][j] = tm[0][i] * gt[0][j] + tm[1][i] * gt[1][j];
        }
    }
    let (dls, dq) = covariance_vjp(&geo.cov, &dsig);
    // Mean: dt from the projection of the mean and from J(t).
    let t = geo.t;
    let mut dt = [zero; 3];
    if PARALLEL {
        dt[0] = cc.fx * gm[0];
        dt[1] = cc.fy * gm[1];
    } else {
        // dT = 2 G2 T Sigma; dJ = dT W^T.
        let mut dj = [[zero; 3]; 2];
        for r in 0..2 {
            let v = mat3_t_vec(&geo.sigma, gt[r]); // Sigma symmetric: (G2 T Sigma) row r
            dj[r] = mat3_vec(&cc.rot, [two * v[0], two * v[1], two * v[2]]);
        }
        let (x, y, z) = (t[0], t[1], t[2]);
        let iz = R::one() / z;
        let iz2 = iz * iz;
        let iz3 = iz2 * iz;
        // mean2d = (fx x/z + cx, fy y/z + cy).
        dt[0] += cc.fx * iz * gm[0];
        dt[1] += cc.fy * iz * gm[1];
        dt[2] -= (cc.fx * x * gm[0] + cc.fy * y * gm[1]) * iz2;
        // J00 = fx/z, J11 = fy/z.
        dt[2] -= (cc.fx * dj[0][0] + cc.fy * dj[1][1]) * iz2;
        // J02 = -fx x~/z^2 with x~ = x (free) or lim z (clamped). Clamped: J02 = -fx lim/z,
        // dJ02/dz = fx lim/z^2 = fx x~/z^3, dJ02/dx = 0. Both cases are computed and one is
        // kept, so the loops over Gaussians stay branch-free.
        let xc = x.max(-cc.lim_x_neg * z).min(cc.lim_x * z);
        let (dt0, dt2) = (dt[0] - cc.fx * iz2 * dj[0][2], dt[2]);
        dt[2] = if geo.clamped[0] {
            dt2 + cc.fx * xc * iz3 * dj[0][2]
        } else {
            dt2 + two * cc.fx * x * iz3 * dj[0][2]
        };
        dt[0] = if geo.clamped[0] { dt[0] } else { dt0 };
        let yc = y.max(-cc.lim_y_neg * z).min(cc.lim_y * z);
        let (dt1, dt2) = (dt[1] - cc.fy * iz2 * dj[1][2], dt[2]);
        dt[2] = if geo.clamped[1] {
            dt2 + cc.fy * yc * iz3 * dj[1][2]
        } else {
            dt2 + two * cc.fy * y * iz3 * dj[1][2]
        };
        dt[1] = if geo.clamped[1] { dt[1] } else { dt1 };
    }
    // t = W (mu - c): dmu = W^T dt.
    (mat3_t_vec(&cc.rot, dt), dls, dq)
}

/// Vector-Jacobian product of [`forward`]: splat gradients to parameter gradients (same layout
/// as the model, pre-activation), given the forward's `splats` and `saved` of the same
/// Gaussians. Culled Gaussians get exactly zero. Splat-gradient vectors shorter than the model
/// are read as zero.
pub fn backward<R: Real>(
    g: &Gaussians<R>,
    cam: &Camera,
    settings: &RenderSettings,
    splats: &Splats<R>,
    saved: &ProjectSaved<R>,
    d: &SplatGrads<R>,
) -> Gaussians<R> {
    backward_with(Simd::active(), g, cam, settings, splats, saved, d)
}

/// [`backward`] with the loops compiled for `simd` (or the widest supported narrower set): the
/// same bits on every path.
pub(crate) fn backward_with<R: Real>(
    simd: Simd,
    g: &Gaussians<R>,
    cam: &Camera,
    settings: &RenderSettings,
    splats: &Splats<R>,
    saved: &ProjectSaved<R>,
    d: &SplatGrads<R>,
) -> Gaussians<R> {
    let n = g.len();
    let mut out = Gaussians::<R>::zeros(n);
    let cc = CamConsts::<R>::with_conventions(cam, &settings.conventions);
    out.means
        .par_chunks_mut(CHUNK)
        .zip(out.log_scales.par_chunks_mut(CHUNK))
        .zip(out.quats.par_chunks_mut(CHUNK))
        .zip(out.opacity_logits.par_chunks_mut(CHUNK))
        .zip(out.features.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(ci, ((((dm, dls), dq), dlo), df))| {
            let out = blocks::ParamsOut {
                means: dm,
                log_scales: dls,
                quats: dq,
                opacity_logits: dlo,
                features: df,
            };
            let pass = blocks::Pass::Backward {
                splats,
                saved,
                d,
                out,
            };
            blocks::run_chunk(simd, &cc, settings, g, ci * CHUNK, pass);
        });
    out
}

#[cfg(test)]
mod tests;
