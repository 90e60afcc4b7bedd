//! `rasterize`, `rasterize_vjp`, `project`: the library's rasterizer (Eqs. 1-5) per camera.

use ndarray::{Array, IxDyn};
use numpy::PyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use unispine::gaussians::Gaussians;
use unispine::geometry::Camera;
use unispine::image2d::Image2d;
use unispine::render::{self, project, RenderSettings};

use crate::args::{self, Float};

/// The Gaussians of a call, read in precision `R`.
pub fn gaussians<R: Float>(
    means: &Bound<'_, PyAny>,
    quats: &Bound<'_, PyAny>,
    log_scales: &Bound<'_, PyAny>,
    opacity_logits: &Bound<'_, PyAny>,
    features: &Bound<'_, PyAny>,
) -> PyResult<Gaussians<R>> {
    let means = args::rows::<R, 3>("means", means, None)?;
    let n = Some(means.len());
    Ok(Gaussians {
        quats: args::rows::<R, 4>("quats", quats, n)?,
        log_scales: args::rows::<R, 3>("log_scales", log_scales, n)?,
        opacity_logits: args::read::<R>("opacity_logits", opacity_logits, &[n])?.0,
        features: args::rows::<R, 16>("features", features, n)?,
        means,
    })
}

/// A numpy array of shape `shape` owning `data` (no copy).
pub fn out<'py, T: numpy::Element>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<T>,
) -> PyResult<Bound<'py, PyArray<T, IxDyn>>> {
    let a = Array::from_shape_vec(IxDyn(shape), data)
        .map_err(|e| PyValueError::new_err(format!("internal shape error: {e}")))?;
    Ok(PyArray::from_owned_array(py, a))
}

/// Forward outputs of every camera, concatenated in camera order.
pub struct Forward<R: Float> {
    pub image: Vec<R>,
    pub transmittance: Vec<R>,
    pub n_contrib: Vec<u32>,
}

pub fn forward<R: Float>(
    g: &Gaussians<R>,
    cams: &[Camera],
    s: &RenderSettings,
) -> unispine::Result<Forward<R>> {
    let mut f = Forward {
        image: Vec::new(),
        transmittance: Vec::new(),
        n_contrib: Vec::new(),
    };
    for cam in cams {
        let (img, saved) = render::forward(g, cam, s)?;
        f.image.extend_from_slice(&img.data);
        f.transmittance.extend_from_slice(&saved.composite.final_t);
        f.n_contrib.extend_from_slice(&saved.composite.n_contrib);
    }
    Ok(f)
}

/// Gradients of every camera: parameter gradients summed over cameras in camera order, the
/// screen-space ones per camera.
pub struct Vjp<R: Float> {
    pub image: Vec<R>,
    pub params: Gaussians<R>,
    pub means2d: Vec<[R; 2]>,
    pub conics: Vec<[R; 3]>,
    pub opacities: Vec<R>,
    pub colors: Vec<R>,
    pub radii: Vec<i32>,
}

pub fn vjp<R: Float>(
    g: &Gaussians<R>,
    cams: &[Camera],
    s: &RenderSettings,
    d_image: &[R],
) -> unispine::Result<Vjp<R>> {
    let n = g.len();
    let mut v = Vjp {
        image: Vec::new(),
        params: Gaussians::zeros(n),
        means2d: Vec::with_capacity(n * cams.len()),
        conics: Vec::with_capacity(n * cams.len()),
        opacities: Vec::with_capacity(n * cams.len()),
        colors: Vec::with_capacity(n * cams.len()),
        radii: Vec::with_capacity(n * cams.len()),
    };
    let mut off = 0;
    for cam in cams {
        let (img, saved) = render::forward(g, cam, s)?;
        let px = cam.width * cam.height;
        let d = Image2d::from_vec(cam.width, cam.height, d_image[off..off + px].to_vec());
        off += px;
        // The two stages of `render::backward`, kept apart to expose the splat gradients.
        let ds = render::composite_backward(&saved, &d);
        let dp = project::backward(g, cam, s, &saved.splats, &saved.project, &ds);
        if cams.len() == 1 {
            v.params = dp;
        } else {
            add(&mut v.params, &dp);
        }
        v.image.extend_from_slice(&img.data);
        v.means2d.extend_from_slice(&ds.mean2d);
        v.conics.extend_from_slice(&ds.conic);
        v.opacities.extend_from_slice(&ds.opacity);
        v.colors.extend_from_slice(&ds.color);
        v.radii.extend(
            saved
                .splats
                .radius
                .iter()
                .map(|&r| r.min(i32::MAX as u32) as i32),
        );
    }
    Ok(v)
}

fn add<R: Float>(acc: &mut Gaussians<R>, d: &Gaussians<R>) {
    fn rows<R: Float, const K: usize>(a: &mut [[R; K]], b: &[[R; K]]) {
        for (x, y) in a.iter_mut().zip(b) {
            for k in 0..K {
                x[k] += y[k];
            }
        }
    }
    rows(&mut acc.means, &d.means);
    rows(&mut acc.log_scales, &d.log_scales);
    rows(&mut acc.quats, &d.quats);
    rows(&mut acc.features, &d.features);
    for (x, y) in acc.opacity_logits.iter_mut().zip(&d.opacity_logits) {
        *x += *y;
    }
}

/// Per-camera projection outputs, concatenated in camera order.
pub struct Projected<R: Float> {
    pub means2d: Vec<[R; 2]>,
    pub conics: Vec<[R; 3]>,
    pub depths: Vec<R>,
    pub radii: Vec<i32>,
    pub opacities: Vec<R>,
    pub colors: Vec<R>,
}

pub fn project_all<R: Float>(
    g: &Gaussians<R>,
    cams: &[Camera],
    s: &RenderSettings,
) -> unispine::Result<Projected<R>> {
    let mut p = Projected {
        means2d: Vec::new(),
        conics: Vec::new(),
        depths: Vec::new(),
        radii: Vec::new(),
        opacities: Vec::new(),
        colors: Vec::new(),
    };
    for cam in cams {
        let (sp, _) = project::forward(g, cam, s)?;
        p.means2d.extend_from_slice(&sp.mean2d);
        p.conics.extend_from_slice(&sp.conic);
        p.depths.extend_from_slice(&sp.depth);
        p.radii
            .extend(sp.radius.iter().map(|&r| r.min(i32::MAX as u32) as i32));
        p.opacities.extend_from_slice(&sp.opacity);
        p.colors.extend_from_slice(&sp.color);
    }
    Ok(p)
}

/// Image size shared by all cameras, or an error.
pub fn image_size(cams: &[Camera]) -> PyResult<(usize, usize)> {
    let (w, h) = (cams[0].width, cams[0].height);
    if cams.iter().any(|c| (c.width, c.height) != (w, h)) {
        return Err(PyValueError::new_err(
            "all cameras must have the same image size",
        ));
    }
    Ok((w, h))
}

/// Put `(key, array)` pairs into a new dict.
pub fn dict<'py>(
    py: Python<'py>,
    items: Vec<(&str, Bound<'py, PyAny>)>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in items {
        d.set_item(k, v)?;
    }
    Ok(d)
}

/// Upstream gradients of the splats of every camera, concatenated in camera order (the
/// layout of `project`'s outputs).
pub struct SplatUpstream<R: Float> {
    pub means2d: Vec<[R; 2]>,
    pub conics: Vec<[R; 3]>,
    pub opacities: Vec<R>,
    pub colors: Vec<R>,
}

/// The projection stage's VJP per camera, summed over cameras in camera order.
pub fn project_vjp<R: Float>(
    g: &Gaussians<R>,
    cams: &[Camera],
    s: &RenderSettings,
    up: &SplatUpstream<R>,
) -> unispine::Result<Gaussians<R>> {
    let n = g.len();
    let mut acc = Gaussians::zeros(n);
    for (k, cam) in cams.iter().enumerate() {
        let (splats, saved) = project::forward(g, cam, s)?;
        let r = k * n..(k + 1) * n;
        let d = render::SplatGrads {
            mean2d: up.means2d[r.clone()].to_vec(),
            conic: up.conics[r.clone()].to_vec(),
            opacity: up.opacities[r.clone()].to_vec(),
            color: up.colors[r].to_vec(),
        };
        let dp = project::backward(g, cam, s, &splats, &saved, &d);
        if cams.len() == 1 {
            acc = dp;
        } else {
            add(&mut acc, &dp);
        }
    }
    Ok(acc)
}
