//! `unispine._native`: the Python bindings of the unispine library (PyO3, abi3).
//!
//! Every function reads its arrays (any strides; float32 or float64, the precision of the call
//! set by the first array argument), releases the GIL for the computation, and returns numpy
//! arrays that own the library's output buffers (no copy). Bad arguments raise `TypeError` or
//! `ValueError` naming the argument; the library's own errors become `ValueError`.
//! The user-facing docstrings are those of the Python wrappers in `unispine/__init__.py`.

mod args;
mod golden;
mod raster;
mod stages;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use args::{Dtype, Float};
use raster::{dict, out};

/// Run `$body` with `R` the float type of the call.
macro_rules! with_dtype {
    ($dt:expr, $R:ident, $body:block) => {
        match $dt {
            Dtype::F64 => {
                type $R = f64;
                $body
            }
            Dtype::F32 => {
                type $R = f32;
                $body
            }
        }
    };
}

#[allow(clippy::too_many_arguments)]
fn gaussians_and_cameras<'py, R: Float>(
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    log_scales: &Bound<'py, PyAny>,
    opacity_logits: &Bound<'py, PyAny>,
    features: &Bound<'py, PyAny>,
    viewmats: Option<&Bound<'py, PyAny>>,
    ks: Option<&Bound<'py, PyAny>>,
    width: Option<usize>,
    height: Option<usize>,
    camera_model: &str,
    geometry: Option<&Bound<'py, PyAny>>,
    angles: Option<&Bound<'py, PyAny>>,
) -> PyResult<(
    unispine::gaussians::Gaussians<R>,
    Vec<unispine::geometry::Camera>,
)> {
    let g = raster::gaussians::<R>(means, quats, log_scales, opacity_logits, features)?;
    let cams = args::cameras(viewmats, ks, width, height, camera_model, geometry, angles)?;
    Ok((g, cams))
}

/// Render Gaussians (Eqs. 1-5): projection, 16x16 tiles, front-to-back alpha compositing.
///
/// Gaussians (N of them), Eq. (1), pre-activation as stored (3DGS's PLY parametrisation):
/// ``means`` [N, 3] (world units, mm); ``quats`` [N, 4] (w, x, y, z), unnormalised (normalised
/// inside, with its Jacobian in the backward pass); ``log_scales`` [N, 3] (natural log of the
/// per-axis standard deviations, scale = exp(log_scale)); ``opacity_logits`` [N] (opacity =
/// sigmoid(logit)); ``features`` [N, 16]: the RIRF features of Eq. (2) (``color_mode``
/// 'rirf-paper': i = sigmoid(sum_k lambda_k f_k); 'rirf-xgaussian': i = max(0, 0.5 + sum_k
/// lambda_k f_k)) or 16 single-channel SH coefficients ('sh': i = max(0, 0.5 + SH(d) . f), d
/// the unit direction from the camera centre to the mean); ``active_features`` 1, 4, 9 or 16
/// (only the first ones are used).
///
/// Precision: float64 or float32, set by ``means.dtype``; every Gaussian array must have that
/// dtype (cameras may be either). Arrays may be non-contiguous. NaN / infinite values raise
/// ``ValueError``; a wrong dtype or a non-array raises ``TypeError``.
///
/// Cameras (C of them), either gsplat's convention: ``viewmats`` [C, 4, 4] world-to-camera
/// (OpenCV axes: x right = image columns u, y down = rows v, z forward; last row 0 0 0 1; the
/// library maps a point p to R (p - c) with c = -R^T t), ``Ks`` [C, 3, 3] ([[fx, 0, cx],
/// [0, fy, cy], [0, 0, 1]], pixels; pixel (col, row) has its centre at (col + 0.5, row + 0.5)),
/// ``width``, ``height`` and ``camera_model`` 'pinhole' (cone beam) or 'ortho' (parallel
/// beam; fx, fy in pixels per world unit); or ``geometry`` (a dict with the TIGRE / NAF JSON
/// fields DSD, DSO, nDetector [v, u], dDetector [v, u], offDetector [u, v], mode; mm) and
/// ``angles`` (radians, a float or a sequence): exactly the cameras of ``unispine render
/// --geometry G.json --angle-deg A`` (source at (DSO cos a, DSO sin a, 0)).
///
/// Compositing (3DGS's rules): alpha = min(0.99, o exp(power)), skipped when power > 0 or
/// alpha < 1/255; a pixel stops, without blending, when T (1 - alpha) < 1e-4; image =
/// sum_i c_i alpha_i T_i + T_final * ``background``. ``conventions`` (a dict, default None)
/// switches these rules to another rasterizer's (``alpha_max``, ``t_stop``, ``radius_sigmas``,
/// ``radius_rule``, ``eps2d``, ``pixel_center``, ``clamp_gradient``, ``near_plane``,
/// ``jacobian_limits``; see ``unispine.conformance.CONVENTIONS``); any non-default value
/// renders through the scalar reference path (per pixel, slower than the tile kernels).
///
/// Returns ``(image, transmittance, n_contrib)``, each [C, H, W] (row 0 at the top):
/// the image (dtype of ``means``), the final transmittance T_final per pixel, and (uint32)
/// the number of entries of the pixel's depth-sorted tile list up to and including the last
/// blended one (3DGS's ``n_contrib``; 0 = nothing blended). The GIL is released while
/// rendering.
#[pyfunction]
#[pyo3(signature = (means, quats, log_scales, opacity_logits, features, viewmats=None, Ks=None,
    width=None, height=None, *, camera_model="pinhole", geometry=None, angles=None,
    color_mode="rirf-paper", active_features=16, background=0.0, conventions=None))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn rasterize<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    log_scales: &Bound<'py, PyAny>,
    opacity_logits: &Bound<'py, PyAny>,
    features: &Bound<'py, PyAny>,
    viewmats: Option<&Bound<'py, PyAny>>,
    Ks: Option<&Bound<'py, PyAny>>,
    width: Option<usize>,
    height: Option<usize>,
    camera_model: &str,
    geometry: Option<&Bound<'py, PyAny>>,
    angles: Option<&Bound<'py, PyAny>>,
    color_mode: &str,
    active_features: usize,
    background: f64,
    conventions: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Py<PyAny>, Py<PyAny>, Py<PyAny>)> {
    let mut s = args::settings(color_mode, active_features, background)?;
    s.conventions = args::conventions(conventions)?;
    with_dtype!(args::dtype_of("means", means)?, R, {
        let (g, cams) = gaussians_and_cameras::<R>(
            means,
            quats,
            log_scales,
            opacity_logits,
            features,
            viewmats,
            Ks,
            width,
            height,
            camera_model,
            geometry,
            angles,
        )?;
        let (w, h) = raster::image_size(&cams)?;
        let f = py
            .detach(|| raster::forward(&g, &cams, &s))
            .map_err(args::lib_err)?;
        let shape = [cams.len(), h, w];
        Ok((
            out(py, &shape, f.image)?.into_any().unbind(),
            out(py, &shape, f.transmittance)?.into_any().unbind(),
            out(py, &shape, f.n_contrib)?.into_any().unbind(),
        ))
    })
}

/// Vector-Jacobian product of ``rasterize``: the gradient of L = sum(d_image * image) with
/// respect to every input group, for an upstream gradient ``d_image`` [C, H, W] (dtype of
/// ``means``). Arguments as ``rasterize`` (below, repeated).
///
/// Gaussians (N of them), Eq. (1), pre-activation as stored (3DGS's PLY parametrisation):
/// ``means`` [N, 3] (world units, mm); ``quats`` [N, 4] (w, x, y, z), unnormalised (normalised
/// inside, with its Jacobian in the backward pass); ``log_scales`` [N, 3] (natural log of the
/// per-axis standard deviations, scale = exp(log_scale)); ``opacity_logits`` [N] (opacity =
/// sigmoid(logit)); ``features`` [N, 16]: the RIRF features of Eq. (2) (``color_mode``
/// 'rirf-paper': i = sigmoid(sum_k lambda_k f_k); 'rirf-xgaussian': i = max(0, 0.5 + sum_k
/// lambda_k f_k)) or 16 single-channel SH coefficients ('sh': i = max(0, 0.5 + SH(d) . f), d
/// the unit direction from the camera centre to the mean); ``active_features`` 1, 4, 9 or 16
/// (only the first ones are used).
///
/// Precision: float64 or float32, set by ``means.dtype``; every Gaussian array must have that
/// dtype (cameras may be either). Arrays may be non-contiguous. NaN / infinite values raise
/// ``ValueError``; a wrong dtype or a non-array raises ``TypeError``.
///
/// Cameras (C of them), either gsplat's convention: ``viewmats`` [C, 4, 4] world-to-camera
/// (OpenCV axes: x right = image columns u, y down = rows v, z forward; last row 0 0 0 1; the
/// library maps a point p to R (p - c) with c = -R^T t), ``Ks`` [C, 3, 3] ([[fx, 0, cx],
/// [0, fy, cy], [0, 0, 1]], pixels; pixel (col, row) has its centre at (col + 0.5, row + 0.5)),
/// ``width``, ``height`` and ``camera_model`` 'pinhole' (cone beam) or 'ortho' (parallel
/// beam; fx, fy in pixels per world unit); or ``geometry`` (a dict with the TIGRE / NAF JSON
/// fields DSD, DSO, nDetector [v, u], dDetector [v, u], offDetector [u, v], mode; mm) and
/// ``angles`` (radians, a float or a sequence): exactly the cameras of ``unispine render
/// --geometry G.json --angle-deg A`` (source at (DSO cos a, DSO sin a, 0)).
///
/// Returns a dict: ``image`` [C, H, W] (the forward image); the parameter gradients, summed
/// over cameras in camera order: ``d_means`` [N, 3], ``d_quats`` [N, 4] (with respect to the
/// unnormalised quaternion), ``d_log_scales`` [N, 3], ``d_opacity_logits`` [N],
/// ``d_features`` [N, 16]; and per camera the gradients of the screen-space splats (the
/// outputs of ``project``) as 3DGS's backward exposes them: ``d_means2d`` [C, N, 2] (pixels;
/// 3DGS's viewspace-point gradient is in NDC: multiply by (W / 2, H / 2)), ``d_conics``
/// [C, N, 3] (conic (A, B, C) of [[A, B], [B, C]], B counted once), ``d_opacities`` [C, N]
/// (post-sigmoid), ``d_colors`` [C, N]; and ``radii`` [C, N] (int32, 0 = culled; culled
/// Gaussians get exact zeros). Hard decisions (culling, tile ranges, alpha skip, T stop) are
/// not differentiated; a clamped alpha (o G > 0.99) has zero derivative (gsplat and brush do
/// the same; 3DGS's CUDA passes the gradient through). The GIL is released.
#[pyfunction]
#[pyo3(signature = (means, quats, log_scales, opacity_logits, features, viewmats=None, Ks=None,
    width=None, height=None, *, d_image, camera_model="pinhole", geometry=None, angles=None,
    color_mode="rirf-paper", active_features=16, background=0.0, conventions=None))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn rasterize_vjp<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    log_scales: &Bound<'py, PyAny>,
    opacity_logits: &Bound<'py, PyAny>,
    features: &Bound<'py, PyAny>,
    viewmats: Option<&Bound<'py, PyAny>>,
    Ks: Option<&Bound<'py, PyAny>>,
    width: Option<usize>,
    height: Option<usize>,
    d_image: &Bound<'py, PyAny>,
    camera_model: &str,
    geometry: Option<&Bound<'py, PyAny>>,
    angles: Option<&Bound<'py, PyAny>>,
    color_mode: &str,
    active_features: usize,
    background: f64,
    conventions: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let mut s = args::settings(color_mode, active_features, background)?;
    s.conventions = args::conventions(conventions)?;
    with_dtype!(args::dtype_of("means", means)?, R, {
        let (g, cams) = gaussians_and_cameras::<R>(
            means,
            quats,
            log_scales,
            opacity_logits,
            features,
            viewmats,
            Ks,
            width,
            height,
            camera_model,
            geometry,
            angles,
        )?;
        let (w, h) = raster::image_size(&cams)?;
        let c = cams.len();
        let (d, _) = args::read::<R>("d_image", d_image, &[Some(c), Some(h), Some(w)])?;
        let v = py
            .detach(|| raster::vjp(&g, &cams, &s, &d))
            .map_err(args::lib_err)?;
        let n = g.len();
        let p = v.params;
        dict(
            py,
            vec![
                ("image", out(py, &[c, h, w], v.image)?.into_any()),
                (
                    "d_means",
                    out(py, &[n, 3], p.means.into_flattened())?.into_any(),
                ),
                (
                    "d_quats",
                    out(py, &[n, 4], p.quats.into_flattened())?.into_any(),
                ),
                (
                    "d_log_scales",
                    out(py, &[n, 3], p.log_scales.into_flattened())?.into_any(),
                ),
                (
                    "d_opacity_logits",
                    out(py, &[n], p.opacity_logits)?.into_any(),
                ),
                (
                    "d_features",
                    out(py, &[n, 16], p.features.into_flattened())?.into_any(),
                ),
                (
                    "d_means2d",
                    out(py, &[c, n, 2], v.means2d.into_flattened())?.into_any(),
                ),
                (
                    "d_conics",
                    out(py, &[c, n, 3], v.conics.into_flattened())?.into_any(),
                ),
                ("d_opacities", out(py, &[c, n], v.opacities)?.into_any()),
                ("d_colors", out(py, &[c, n], v.colors)?.into_any()),
                ("radii", out(py, &[c, n], v.radii)?.into_any()),
            ],
        )
    })
}

/// The projection stage alone (Eqs. 1-3 and the opacity / intensity of each Gaussian).
///
/// Gaussians (N of them), Eq. (1), pre-activation as stored (3DGS's PLY parametrisation):
/// ``means`` [N, 3] (world units, mm); ``quats`` [N, 4] (w, x, y, z), unnormalised (normalised
/// inside, with its Jacobian in the backward pass); ``log_scales`` [N, 3] (natural log of the
/// per-axis standard deviations, scale = exp(log_scale)); ``opacity_logits`` [N] (opacity =
/// sigmoid(logit)); ``features`` [N, 16]: the RIRF features of Eq. (2) (``color_mode``
/// 'rirf-paper': i = sigmoid(sum_k lambda_k f_k); 'rirf-xgaussian': i = max(0, 0.5 + sum_k
/// lambda_k f_k)) or 16 single-channel SH coefficients ('sh': i = max(0, 0.5 + SH(d) . f), d
/// the unit direction from the camera centre to the mean); ``active_features`` 1, 4, 9 or 16
/// (only the first ones are used).
///
/// Precision: float64 or float32, set by ``means.dtype``; every Gaussian array must have that
/// dtype (cameras may be either). Arrays may be non-contiguous. NaN / infinite values raise
/// ``ValueError``; a wrong dtype or a non-array raises ``TypeError``.
///
/// Cameras (C of them), either gsplat's convention: ``viewmats`` [C, 4, 4] world-to-camera
/// (OpenCV axes: x right = image columns u, y down = rows v, z forward; last row 0 0 0 1; the
/// library maps a point p to R (p - c) with c = -R^T t), ``Ks`` [C, 3, 3] ([[fx, 0, cx],
/// [0, fy, cy], [0, 0, 1]], pixels; pixel (col, row) has its centre at (col + 0.5, row + 0.5)),
/// ``width``, ``height`` and ``camera_model`` 'pinhole' (cone beam) or 'ortho' (parallel
/// beam; fx, fy in pixels per world unit); or ``geometry`` (a dict with the TIGRE / NAF JSON
/// fields DSD, DSO, nDetector [v, u], dDetector [v, u], offDetector [u, v], mode; mm) and
/// ``angles`` (radians, a float or a sequence): exactly the cameras of ``unispine render
/// --geometry G.json --angle-deg A`` (source at (DSO cos a, DSO sin a, 0)).
///
/// Returns a dict, per camera and Gaussian: ``means2d`` [C, N, 2] (pixels, u along columns,
/// v along rows, pixel centres at +0.5), ``conics`` [C, N, 3] (A, B, C: the inverse of the
/// 2-D covariance J W Sigma W^T J^T + 0.3 I, px^-2), ``radii`` [C, N] (int32 pixels,
/// ceil(3 sqrt(lambda_max)); 0 = culled: z <= 0.2, degenerate, off image or |q| ~ 0),
/// ``depths`` [C, N] (camera-space z, world units), ``opacities`` [C, N] (sigmoid of the
/// logits), ``colors`` [C, N] (the intensity). Culled entries are 0 except ``depths``.
#[pyfunction]
#[pyo3(signature = (means, quats, log_scales, opacity_logits, features, viewmats=None, Ks=None,
    width=None, height=None, *, camera_model="pinhole", geometry=None, angles=None,
    color_mode="rirf-paper", active_features=16))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn project<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    log_scales: &Bound<'py, PyAny>,
    opacity_logits: &Bound<'py, PyAny>,
    features: &Bound<'py, PyAny>,
    viewmats: Option<&Bound<'py, PyAny>>,
    Ks: Option<&Bound<'py, PyAny>>,
    width: Option<usize>,
    height: Option<usize>,
    camera_model: &str,
    geometry: Option<&Bound<'py, PyAny>>,
    angles: Option<&Bound<'py, PyAny>>,
    color_mode: &str,
    active_features: usize,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let s = args::settings(color_mode, active_features, 0.0)?;
    with_dtype!(args::dtype_of("means", means)?, R, {
        let (g, cams) = gaussians_and_cameras::<R>(
            means,
            quats,
            log_scales,
            opacity_logits,
            features,
            viewmats,
            Ks,
            width,
            height,
            camera_model,
            geometry,
            angles,
        )?;
        let p = py
            .detach(|| raster::project_all(&g, &cams, &s))
            .map_err(args::lib_err)?;
        let (c, n) = (cams.len(), g.len());
        dict(
            py,
            vec![
                (
                    "means2d",
                    out(py, &[c, n, 2], p.means2d.into_flattened())?.into_any(),
                ),
                (
                    "conics",
                    out(py, &[c, n, 3], p.conics.into_flattened())?.into_any(),
                ),
                ("radii", out(py, &[c, n], p.radii)?.into_any()),
                ("depths", out(py, &[c, n], p.depths)?.into_any()),
                ("opacities", out(py, &[c, n], p.opacities)?.into_any()),
                ("colors", out(py, &[c, n], p.colors)?.into_any()),
            ],
        )
    })
}

/// Vector-Jacobian product of ``project``: the gradient of
/// L = sum(d_means2d * means2d) + sum(d_conics * conics) + sum(d_opacities * opacities)
/// + sum(d_colors * colors) with respect to the Gaussians, summed over cameras in camera order.
/// This is the projection stage's backward on its own (the golden files
/// ``eq03-projection-vjp`` check exactly this with ``d_opacities = d_colors = 0``).
///
/// Gaussians and cameras as ``project``. Upstream gradients, per camera (dtype of ``means``):
/// ``d_means2d`` [C, N, 2] (pixels), ``d_conics`` [C, N, 3] (A, B, C; B one parameter),
/// ``d_opacities`` [C, N] (post-sigmoid; default zeros), ``d_colors`` [C, N] (default zeros).
/// Culled Gaussians (radius 0 in that camera) get exact zeros from that camera.
///
/// Returns a dict: ``d_means`` [N, 3], ``d_quats`` [N, 4], ``d_log_scales`` [N, 3],
/// ``d_opacity_logits`` [N], ``d_features`` [N, 16]. The GIL is released.
#[pyfunction]
#[pyo3(signature = (means, quats, log_scales, opacity_logits, features, viewmats=None, Ks=None,
    width=None, height=None, *, d_means2d, d_conics, d_opacities=None, d_colors=None,
    camera_model="pinhole", geometry=None, angles=None, color_mode="rirf-paper",
    active_features=16))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn project_vjp<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    log_scales: &Bound<'py, PyAny>,
    opacity_logits: &Bound<'py, PyAny>,
    features: &Bound<'py, PyAny>,
    viewmats: Option<&Bound<'py, PyAny>>,
    Ks: Option<&Bound<'py, PyAny>>,
    width: Option<usize>,
    height: Option<usize>,
    d_means2d: &Bound<'py, PyAny>,
    d_conics: &Bound<'py, PyAny>,
    d_opacities: Option<&Bound<'py, PyAny>>,
    d_colors: Option<&Bound<'py, PyAny>>,
    camera_model: &str,
    geometry: Option<&Bound<'py, PyAny>>,
    angles: Option<&Bound<'py, PyAny>>,
    color_mode: &str,
    active_features: usize,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let s = args::settings(color_mode, active_features, 0.0)?;
    with_dtype!(args::dtype_of("means", means)?, R, {
        let (g, cams) = gaussians_and_cameras::<R>(
            means,
            quats,
            log_scales,
            opacity_logits,
            features,
            viewmats,
            Ks,
            width,
            height,
            camera_model,
            geometry,
            angles,
        )?;
        let (c, n) = (cams.len(), g.len());
        let flat = |name: &str, obj: Option<&Bound<'py, PyAny>>| -> PyResult<Vec<R>> {
            match obj {
                Some(o) => Ok(args::read::<R>(name, o, &[Some(c), Some(n)])?.0),
                None => Ok(vec![<R as unispine::Real>::c(0.0); c * n]),
            }
        };
        let with_rows = |name: &str, obj: &Bound<'py, PyAny>, k: usize| -> PyResult<Vec<R>> {
            Ok(args::read::<R>(name, obj, &[Some(c), Some(n), Some(k)])?.0)
        };
        let m2 = with_rows("d_means2d", d_means2d, 2)?;
        let co = with_rows("d_conics", d_conics, 3)?;
        let up = raster::SplatUpstream {
            means2d: m2.chunks_exact(2).map(|x| [x[0], x[1]]).collect(),
            conics: co.chunks_exact(3).map(|x| [x[0], x[1], x[2]]).collect(),
            opacities: flat("d_opacities", d_opacities)?,
            colors: flat("d_colors", d_colors)?,
        };
        let p = py
            .detach(|| raster::project_vjp(&g, &cams, &s, &up))
            .map_err(args::lib_err)?;
        dict(
            py,
            vec![
                (
                    "d_means",
                    out(py, &[n, 3], p.means.into_flattened())?.into_any(),
                ),
                (
                    "d_quats",
                    out(py, &[n, 4], p.quats.into_flattened())?.into_any(),
                ),
                (
                    "d_log_scales",
                    out(py, &[n, 3], p.log_scales.into_flattened())?.into_any(),
                ),
                (
                    "d_opacity_logits",
                    out(py, &[n], p.opacity_logits)?.into_any(),
                ),
                (
                    "d_features",
                    out(py, &[n, 16], p.features.into_flattened())?.into_any(),
                ),
            ],
        )
    })
}

/// Digitally reconstructed radiographs: line integrals of ``volume`` along the rays of the
/// cameras of ``geometry`` at ``angles``.
///
/// ``volume`` [nx, ny, nz] (``volume[i, j, k]`` is the voxel at x index i, y index j, z index
/// k; float32 or float64, the output precision; a Fortran-ordered array is read
/// contiguously), attenuation per mm; its shape must equal the geometry's ``nVoxel``, voxel
/// size ``dVoxel`` (mm), centre offset ``offOrigin``. ``geometry``: TIGRE / NAF dict (see
/// ``rasterize``); ``angles``: radians. ``method``: 'siddon' (exact line integrals of the
/// piecewise-constant volume) or 'trilinear' (ray march with step ``accuracy`` voxels, TIGRE
/// 'interpolated', default 0.5).
///
/// Returns [A, H, W] (A angles, H = nDetector[0] rows, W = nDetector[1] columns), in
/// attenuation x mm. The GIL is released.
#[pyfunction]
#[pyo3(signature = (volume, geometry, angles, *, method="siddon"))]
fn drr<'py>(
    py: Python<'py>,
    volume: &Bound<'py, PyAny>,
    geometry: &Bound<'py, PyAny>,
    angles: &Bound<'py, PyAny>,
    method: &str,
) -> PyResult<Py<PyAny>> {
    let geo = args::geometry(geometry)?;
    let angles = args::angles(angles)?;
    let (w, h) = geo.image_size();
    args::check_budget(
        &format!(
            "`angles` ({} views) x the geometry's {w} x {h} detector",
            angles.len()
        ),
        (angles.len() as u128).saturating_mul(w as u128 * h as u128 * 8),
    )?;
    let method = match method {
        "siddon" => unispine::drr::Method::Siddon,
        "trilinear" => unispine::drr::Method::Trilinear,
        other => {
            return Err(PyValueError::new_err(format!(
                "`method` must be 'siddon' or 'trilinear', got '{other}'"
            )))
        }
    };
    with_dtype!(args::dtype_of("volume", volume)?, R, {
        let vol = stages::volume::<R>(volume, &geo)?;
        let imgs = py
            .detach(|| stages::drr(&vol, &geo, &angles, method))
            .map_err(args::lib_err)?;
        let (w, h) = geo.image_size();
        Ok(out(py, &[angles.len(), h, w], imgs)?.into_any().unbind())
    })
}

/// Mean SSIM of ``img1`` against ``img2`` (both [H, W], same dtype) and its gradient with
/// respect to ``img1``: 11 x 11 Gaussian window (sigma 1.5, normalised), zero padding,
/// C1 = 0.01^2, C2 = 0.03^2, mean over all pixels (the 3DGS / UniSpine-GS code).
///
/// Returns ``(ssim, d_ssim_d_img1)``: a float (computed in f64 from the dtype's values) and an
/// [H, W] array.
#[pyfunction]
fn ssim<'py>(
    py: Python<'py>,
    img1: &Bound<'py, PyAny>,
    img2: &Bound<'py, PyAny>,
) -> PyResult<(f64, Py<PyAny>)> {
    with_dtype!(args::dtype_of("img1", img1)?, R, {
        let (a, b) = stages::image_pair::<R>(("img1", img1), ("img2", img2))?;
        let (v, g) = py.detach(|| unispine::loss::ssim::ssim_forward_backward(&a, &b));
        Ok((
            v,
            out(py, &[g.height, g.width], g.data)?.into_any().unbind(),
        ))
    })
}

/// The hybrid loss of Eq. (8), L = (1 - lambda) L_data + lambda (1 - SSIM), and its gradient
/// with respect to ``render``.
///
/// ``render``, ``gt`` [H, W] (same dtype); ``weights`` [H, W], the SPWM weights w of Eq. (7)
/// (constants, no gradient; ``None`` = all ones). ``data_term``: 'weighted-charbonnier'
/// (Eq. 9: sum w rho(e) / (sum w + delta), rho(e) = sqrt(e^2 + eps^2)), 'charbonnier' (mean
/// rho) or 'l1' (mean |e|, subgradient 0 at 0); ``lambda_dssim`` (0.2), ``charbonnier_eps``
/// (1e-3), ``delta`` (1e-6).
///
/// Returns a dict: ``total`` (L), ``data`` (the data term), ``ssim`` (SSIM, not 1 - SSIM),
/// ``grad`` [H, W] = dL / d render.
#[pyfunction]
#[pyo3(signature = (render, gt, weights=None, *, data_term="weighted-charbonnier",
    lambda_dssim=0.2, charbonnier_eps=1e-3, delta=1e-6))]
#[allow(clippy::too_many_arguments)]
fn loss<'py>(
    py: Python<'py>,
    render: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    weights: Option<&Bound<'py, PyAny>>,
    data_term: &str,
    lambda_dssim: f64,
    charbonnier_eps: f64,
    delta: f64,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let cfg = stages::loss_config(data_term, lambda_dssim, charbonnier_eps, delta)?;
    with_dtype!(args::dtype_of("render", render)?, R, {
        let (a, b) = stages::image_pair::<R>(("render", render), ("gt", gt))?;
        let w = match weights {
            Some(w) => Some(stages::image_like::<R>("weights", w, &a)?),
            None => None,
        };
        let (v, g) = py.detach(|| unispine::loss::forward_backward(&a, &b, w.as_ref(), &cfg));
        dict(
            py,
            vec![
                ("total", v.total.into_pyobject(py)?.into_any()),
                ("data", v.data.into_pyobject(py)?.into_any()),
                ("ssim", v.ssim.into_pyobject(py)?.into_any()),
                ("grad", out(py, &[g.height, g.width], g.data)?.into_any()),
            ],
        )
    })
}

/// The golden files compiled into the module: (folder, case name, JSON text).
#[pyfunction]
fn golden_files() -> Vec<(&'static str, &'static str, &'static str)> {
    golden::FILES.to_vec()
}

/// For the overhead benchmark (`python/benches/overhead.py`): the wall time in seconds of each of
/// `repeats` calls of the library's `render::forward` alone (no argument conversion), on the
/// arguments of `rasterize` (float64 or float32, cameras from `geometry` + `angles`).
#[pyfunction]
#[pyo3(signature = (means, quats, log_scales, opacity_logits, features, *, geometry, angles, repeats))]
#[allow(clippy::too_many_arguments)]
fn _bench_render_forward<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    log_scales: &Bound<'py, PyAny>,
    opacity_logits: &Bound<'py, PyAny>,
    features: &Bound<'py, PyAny>,
    geometry: &Bound<'py, PyAny>,
    angles: &Bound<'py, PyAny>,
    repeats: usize,
) -> PyResult<Vec<f64>> {
    let s = unispine::render::RenderSettings::default();
    with_dtype!(args::dtype_of("means", means)?, R, {
        let (g, cams) = gaussians_and_cameras::<R>(
            means,
            quats,
            log_scales,
            opacity_logits,
            features,
            None,
            None,
            None,
            None,
            "pinhole",
            Some(geometry),
            Some(angles),
        )?;
        py.detach(|| {
            let mut times = Vec::with_capacity(repeats);
            for _ in 0..repeats {
                let t0 = std::time::Instant::now();
                for cam in &cams {
                    let r = unispine::render::forward(&g, cam, &s)?;
                    std::hint::black_box(&r);
                }
                times.push(t0.elapsed().as_secs_f64());
            }
            Ok(times)
        })
        .map_err(args::lib_err)
    })
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(rasterize_vjp, m)?)?;
    m.add_function(wrap_pyfunction!(project, m)?)?;
    m.add_function(wrap_pyfunction!(project_vjp, m)?)?;
    m.add_function(wrap_pyfunction!(drr, m)?)?;
    m.add_function(wrap_pyfunction!(ssim, m)?)?;
    m.add_function(wrap_pyfunction!(loss, m)?)?;
    m.add_function(wrap_pyfunction!(golden_files, m)?)?;
    m.add_function(wrap_pyfunction!(_bench_render_forward, m)?)?;
    Ok(())
}
