//! Reading and checking Python arguments: numpy arrays (any strides, a fixed dtype), cameras,
//! settings. Every failure is a Python exception naming the argument.

use numpy::{
    Element, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use unispine::geometry::{Camera, ConeBeam, Mode};
use unispine::render::{ColorMode, RenderSettings};
use unispine::Real;

/// The most memory one call may ask for, bytes: the binary's cap on a command's outputs
/// (8 GiB). Inputs larger than this and calls whose outputs and working memory would be larger
/// are refused with a `ValueError` naming the argument, instead of an allocation failure that
/// would abort the interpreter.
pub const MAX_BYTES: u128 = unispine::dataset::generate::MAX_PROJECTION_BYTES as u128;

/// Bytes per pixel a rendering call may hold at once: the image and the saved transmittance in
/// f64, the per-pixel contribution count, and the gradient image of a VJP.
pub const BYTES_PER_PIXEL: u128 = 32;

/// `ValueError` when `bytes` is above [`MAX_BYTES`]; `what` names the arguments responsible.
pub fn check_budget(what: &str, bytes: u128) -> PyResult<()> {
    if bytes > MAX_BYTES {
        return Err(PyValueError::new_err(format!(
            "{what}: this call would need {bytes} bytes, more than the {MAX_BYTES} (8 GiB) \
             the module accepts; use fewer or smaller views"
        )));
    }
    Ok(())
}

/// A float type the bindings compute in (f32 or f64), chosen by the dtype of the main input.
pub trait Float: Real + Element {}
impl Float for f32 {}
impl Float for f64 {}

/// Precision of a call, from the dtype of its first array argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    F32,
    F64,
}

/// The numpy array behind `obj`, or a `TypeError` naming `name`.
fn untyped<'py>(name: &str, obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    obj.cast::<PyUntypedArray>().cloned().map_err(|_| {
        PyTypeError::new_err(format!(
            "`{name}` must be a numpy array, got {}",
            obj.get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_else(|_| "an unknown type".into())
        ))
    })
}

/// The dtype of array `name`: float32 or float64, else a `TypeError`.
pub fn dtype_of(name: &str, obj: &Bound<'_, PyAny>) -> PyResult<Dtype> {
    let a = untyped(name, obj)?;
    let py = obj.py();
    let dt = a.dtype();
    if dt.is_equiv_to(&numpy::dtype::<f64>(py)) {
        Ok(Dtype::F64)
    } else if dt.is_equiv_to(&numpy::dtype::<f32>(py)) {
        Ok(Dtype::F32)
    } else {
        Err(PyTypeError::new_err(format!(
            "`{name}` must have dtype float32 or float64, got {dt}"
        )))
    }
}

/// Check array `name` (dtype `R`, expected shape `shape`, `None` = any extent) and hand its
/// elements in row-major order to `f` as one slice: numpy's own buffer when the array is
/// C-contiguous (no copy), else a gathered copy (non-contiguous arrays are fine). Every element
/// must be finite.
pub fn with_slice<R: Float, T>(
    name: &str,
    obj: &Bound<'_, PyAny>,
    shape: &[Option<usize>],
    f: impl FnOnce(&[R], Vec<usize>) -> T,
) -> PyResult<T> {
    let a = untyped(name, obj)?;
    let py = obj.py();
    if !a.dtype().is_equiv_to(&numpy::dtype::<R>(py)) {
        return Err(PyTypeError::new_err(format!(
            "`{name}` must have dtype {} (the precision of this call, set by the first array), got {}",
            R::NAME.replace('f', "float"),
            a.dtype()
        )));
    }
    let got = a.shape().to_vec();
    let ok = got.len() == shape.len()
        && got
            .iter()
            .zip(shape)
            .all(|(g, s)| s.is_none_or(|s| *g == s));
    if !ok {
        let want: Vec<String> = shape
            .iter()
            .map(|s| s.map_or("*".to_string(), |s| s.to_string()))
            .collect();
        return Err(PyValueError::new_err(format!(
            "`{name}` must have shape [{}], got {:?}",
            want.join(", "),
            got
        )));
    }
    // Before anything is copied: a broadcast array can claim far more elements than it stores.
    let elements = got.iter().fold(1u128, |n, &d| n.saturating_mul(d as u128));
    check_budget(
        &format!("`{name}` of shape {got:?}"),
        elements.saturating_mul(std::mem::size_of::<R>() as u128),
    )?;
    let arr = a.cast::<PyArrayDyn<R>>()?;
    let ro = arr
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("`{name}` cannot be read: {e}")))?;
    let view = ro.as_array();
    let gathered: Vec<R>;
    let data: &[R] = match view.as_slice() {
        Some(s) => s,
        None => {
            gathered = view.iter().copied().collect();
            &gathered
        }
    };
    // A branch-free pass over the data; the position is looked up only on failure.
    if !data.iter().fold(true, |ok, x| ok & x.is_finite()) {
        let i = data.iter().position(|x| !x.is_finite()).unwrap_or(0);
        return Err(PyValueError::new_err(format!(
            "`{name}` holds a non-finite value ({}) at flat index {i}",
            data[i]
        )));
    }
    Ok(f(data, got))
}

/// The elements of array `name` in row-major order (see [`with_slice`]) and its shape.
pub fn read<R: Float>(
    name: &str,
    obj: &Bound<'_, PyAny>,
    shape: &[Option<usize>],
) -> PyResult<(Vec<R>, Vec<usize>)> {
    with_slice(name, obj, shape, |d, s| (d.to_vec(), s))
}

/// Array `name` with rows of `K` values: shape [n, K] (`n` = None: any), copied once into the
/// library's layout.
pub fn rows<R: Float, const K: usize>(
    name: &str,
    obj: &Bound<'_, PyAny>,
    n: Option<usize>,
) -> PyResult<Vec<[R; K]>> {
    with_slice(name, obj, &[n, Some(K)], |d, _| {
        d.chunks_exact(K)
            .map(|c| <[R; K]>::try_from(c).expect("chunks of K"))
            .collect()
    })
}

/// Array `name` read as f64 whatever its float dtype (cameras, which the library keeps in f64).
pub fn read_f64(
    name: &str,
    obj: &Bound<'_, PyAny>,
    shape: &[Option<usize>],
) -> PyResult<(Vec<f64>, Vec<usize>)> {
    match dtype_of(name, obj)? {
        Dtype::F64 => read::<f64>(name, obj, shape),
        Dtype::F32 => {
            read::<f32>(name, obj, shape).map(|(d, s)| (d.into_iter().map(f64::from).collect(), s))
        }
    }
}

/// A library error as a Python `ValueError`.
pub fn lib_err(e: unispine::Error) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// The colour model named `name` (`rirf-paper`, `rirf-xgaussian`, `sh`).
pub fn settings(
    color_mode: &str,
    active_features: usize,
    background: f64,
) -> PyResult<RenderSettings> {
    let color = match color_mode {
        "rirf-paper" => ColorMode::RirfPaper,
        "rirf-xgaussian" => ColorMode::RirfXgaussian,
        "sh" => ColorMode::Sh,
        other => {
            return Err(PyValueError::new_err(format!(
                "`color_mode` must be 'rirf-paper', 'rirf-xgaussian' or 'sh', got '{other}'"
            )))
        }
    };
    if ![1, 4, 9, 16].contains(&active_features) {
        return Err(PyValueError::new_err(format!(
            "`active_features` must be 1, 4, 9 or 16, got {active_features}"
        )));
    }
    if !background.is_finite() {
        return Err(PyValueError::new_err(format!(
            "`background` must be finite, got {background}"
        )));
    }
    Ok(RenderSettings {
        color,
        active_features,
        background,
        ..Default::default()
    })
}

/// A TIGRE / NAF geometry from a dict with the JSON file's fields, validated.
pub fn geometry(obj: &Bound<'_, PyAny>) -> PyResult<ConeBeam> {
    let py = obj.py();
    if obj.cast::<PyDict>().is_err() {
        return Err(PyTypeError::new_err(
            "`geometry` must be a dict with the TIGRE fields (DSD, DSO, nDetector, dDetector, nVoxel, dVoxel, ...)",
        ));
    }
    let text: String = py
        .import("json")?
        .call_method1("dumps", (obj,))
        .map_err(|e| PyValueError::new_err(format!("`geometry` is not JSON-serialisable: {e}")))?
        .extract()?;
    let geo: ConeBeam = serde_json::from_str(&text)
        .map_err(|e| PyValueError::new_err(format!("`geometry`: not a TIGRE/NAF geometry: {e}")))?;
    geo.validate()
        .map_err(|e| PyValueError::new_err(format!("`geometry`: {e}")))?;
    Ok(geo)
}

/// Rasterizer conventions from a dict of `unispine::render::Conventions` fields (`None`: the
/// default), validated; an unknown field or value is a `ValueError` naming it.
pub fn conventions(obj: Option<&Bound<'_, PyAny>>) -> PyResult<unispine::render::Conventions> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(Default::default());
    };
    if obj.cast::<PyDict>().is_err() {
        return Err(PyTypeError::new_err(
            "`conventions` must be a dict (alpha_max, t_stop, radius_sigmas, radius_rule, eps2d, pixel_center, clamp_gradient, near_plane, jacobian_limits)",
        ));
    }
    let text: String = obj
        .py()
        .import("json")?
        .call_method1("dumps", (obj,))
        .map_err(|e| PyValueError::new_err(format!("`conventions` is not JSON-serialisable: {e}")))?
        .extract()?;
    let c: unispine::render::Conventions = serde_json::from_str(&text)
        .map_err(|e| PyValueError::new_err(format!("`conventions`: {e}")))?;
    c.validate().map_err(lib_err)?;
    Ok(c)
}

/// Angles in radians: a float or a 1-D sequence / array of floats, all finite.
pub fn angles(obj: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    let v: Vec<f64> = if let Ok(a) = obj.extract::<f64>() {
        vec![a]
    } else if let Ok(v) = obj.extract::<Vec<f64>>() {
        v
    } else if obj.cast::<PyUntypedArray>().is_ok() {
        read_f64("angles", obj, &[None])?.0
    } else {
        return Err(PyTypeError::new_err(
            "`angles` must be a float or a 1-D sequence of floats (radians)",
        ));
    };
    if v.is_empty() {
        return Err(PyValueError::new_err("`angles` is empty"));
    }
    if let Some(a) = v.iter().find(|a| !a.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "`angles` must be finite, got {a}"
        )));
    }
    Ok(v)
}

/// Memory of `n` views of `pixels` pixels each: the cameras and [`BYTES_PER_PIXEL`] per pixel.
fn views_bytes(n: usize, pixels: u128) -> u128 {
    (n as u128).saturating_mul(
        (std::mem::size_of::<Camera>() as u128)
            .saturating_add(pixels.saturating_mul(BYTES_PER_PIXEL)),
    )
}

/// The cameras of a call: either `geometry` + `angles` (TIGRE, exactly as the binary builds
/// them) or `viewmats` [C, 4, 4] + `Ks` [C, 3, 3] + `width` + `height` (gsplat's convention).
#[allow(clippy::too_many_arguments)]
pub fn cameras(
    viewmats: Option<&Bound<'_, PyAny>>,
    ks: Option<&Bound<'_, PyAny>>,
    width: Option<usize>,
    height: Option<usize>,
    camera_model: &str,
    geometry_arg: Option<&Bound<'_, PyAny>>,
    angles_arg: Option<&Bound<'_, PyAny>>,
) -> PyResult<Vec<Camera>> {
    match (geometry_arg, angles_arg) {
        (Some(g), Some(a)) => {
            if viewmats.is_some() || ks.is_some() || width.is_some() || height.is_some() {
                return Err(PyValueError::new_err(
                    "give either `geometry` + `angles`, or `viewmats` + `Ks` + `width` + `height`, not both",
                ));
            }
            let geo = geometry(g)?;
            let angles = angles(a)?;
            let (w, h) = (geo.n_detector[0] as u128, geo.n_detector[1] as u128);
            check_budget(
                &format!(
                    "`angles` ({} views) x the geometry's {w} x {h} detector",
                    angles.len()
                ),
                views_bytes(angles.len(), w * h),
            )?;
            return Ok(angles.into_iter().map(|t| geo.camera(t)).collect());
        }
        (Some(_), None) | (None, Some(_)) => {
            return Err(PyValueError::new_err("`geometry` and `angles` go together"))
        }
        (None, None) => {}
    }
    let (Some(vm), Some(k), Some(w), Some(h)) = (viewmats, ks, width, height) else {
        return Err(PyValueError::new_err(
            "give the cameras: `viewmats` [C, 4, 4], `Ks` [C, 3, 3], `width`, `height` (or `geometry` + `angles`)",
        ));
    };
    if w == 0 || h == 0 || w > 1 << 15 || h > 1 << 15 {
        return Err(PyValueError::new_err(format!(
            "`width` and `height` must be in 1..=32768, got {w} x {h}"
        )));
    }
    let mode = match camera_model {
        "pinhole" => Mode::Cone,
        "ortho" => Mode::Parallel,
        other => {
            return Err(PyValueError::new_err(format!(
                "`camera_model` must be 'pinhole' or 'ortho', got '{other}'"
            )))
        }
    };
    let (vmd, vs) = read_f64("viewmats", vm, &[None, Some(4), Some(4)])?;
    let c = vs[0];
    if c == 0 {
        return Err(PyValueError::new_err("`viewmats` holds no camera (C = 0)"));
    }
    check_budget(
        &format!("`viewmats` ({c} cameras) x `width` x `height` ({w} x {h})"),
        views_bytes(c, w as u128 * h as u128),
    )?;
    let (kd, _) = read_f64("Ks", k, &[Some(c), Some(3), Some(3)])?;
    let mut out = Vec::with_capacity(c);
    for ci in 0..c {
        let v = &vmd[16 * ci..16 * ci + 16];
        let kk = &kd[9 * ci..9 * ci + 9];
        let rot: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|col| v[4 * r + col]));
        let t = [v[3], v[7], v[11]];
        if v[12] != 0.0 || v[13] != 0.0 || v[14] != 0.0 || v[15] != 1.0 {
            return Err(PyValueError::new_err(format!(
                "`viewmats[{ci}]`: the last row must be [0, 0, 0, 1]"
            )));
        }
        for r in 0..3 {
            for s in 0..3 {
                let dot: f64 = (0..3).map(|j| rot[r][j] * rot[s][j]).sum();
                let want = if r == s { 1.0 } else { 0.0 };
                if (dot - want).abs() > 1e-6 {
                    return Err(PyValueError::new_err(format!(
                        "`viewmats[{ci}]`: the 3x3 block must be a rotation (rows orthonormal within 1e-6)"
                    )));
                }
            }
        }
        let det = rot[0][0] * (rot[1][1] * rot[2][2] - rot[1][2] * rot[2][1])
            - rot[0][1] * (rot[1][0] * rot[2][2] - rot[1][2] * rot[2][0])
            + rot[0][2] * (rot[1][0] * rot[2][1] - rot[1][1] * rot[2][0]);
        if det < 0.0 {
            return Err(PyValueError::new_err(format!(
                "`viewmats[{ci}]`: the 3x3 block is a reflection (det < 0)"
            )));
        }
        let (fx, fy, cx, cy) = (kk[0], kk[4], kk[2], kk[5]);
        if kk[1] != 0.0 || kk[3] != 0.0 || kk[6] != 0.0 || kk[7] != 0.0 || kk[8] != 1.0 {
            return Err(PyValueError::new_err(format!(
                "`Ks[{ci}]` must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)"
            )));
        }
        if !(fx > 0.0 && fy > 0.0) {
            return Err(PyValueError::new_err(format!(
                "`Ks[{ci}]`: fx and fy must be > 0, got {fx}, {fy}"
            )));
        }
        // Camera centre c = -R^T t (the library maps a point p to R (p - c)).
        let centre: [f64; 3] =
            std::array::from_fn(|j| -(0..3).map(|r| rot[r][j] * t[r]).sum::<f64>());
        out.push(Camera {
            angle: 0.0,
            rot,
            centre,
            fx,
            fy,
            cx,
            cy,
            width: w,
            height: h,
            // Pinhole: the focal lengths are in pixels, DSD and pitch are not used by the
            // rasterizer. Ortho: fx, fy are pixels per world unit (pitch = 1 / f), DSD = 1.
            dsd: 1.0,
            pitch: [1.0 / fy, 1.0 / fx],
            mode,
        });
    }
    Ok(out)
}
