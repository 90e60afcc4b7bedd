//! `drr`, `ssim`, `loss`: volumes and images between numpy and the library.

use numpy::{PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use unispine::drr::Method;
use unispine::geometry::ConeBeam;
use unispine::image2d::Image2d;
use unispine::loss::{DataTerm, LossConfig};
use unispine::volume::Volume;

use crate::args::{self, Float};

/// The volume `[nx, ny, nz]` (`volume[i, j, k]` is voxel (x i, y j, z k)) in the library's
/// x-fastest layout, read in one pass through its strides (a Fortran-ordered array is read
/// contiguously). Spacing and offset come from the geometry (`dVoxel`, `offOrigin`).
pub fn volume<R: Float>(obj: &Bound<'_, PyAny>, geo: &ConeBeam) -> PyResult<Volume<R>> {
    // Dtype and rank checks with the common messages (shape checked against the geometry).
    let a = obj.cast::<numpy::PyUntypedArray>().map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err("`volume` must be a numpy array [nx, ny, nz]")
    })?;
    if a.ndim() != 3 {
        return Err(PyValueError::new_err(format!(
            "`volume` must have shape [nx, ny, nz], got {:?}",
            a.shape()
        )));
    }
    let dims = [a.shape()[0], a.shape()[1], a.shape()[2]];
    if dims != geo.n_voxel {
        return Err(PyValueError::new_err(format!(
            "`volume` has shape {dims:?} but the geometry's nVoxel is {:?} ([x, y, z])",
            geo.n_voxel
        )));
    }
    let _ = args::dtype_of("volume", obj)?;
    let arr = obj.cast::<PyArrayDyn<R>>().map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err(format!("`volume` must have dtype {}", R::NAME))
    })?;
    let ro = arr
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("`volume` cannot be read: {e}")))?;
    let view = ro.as_array().reversed_axes();
    let data: Vec<R> = match view.as_slice() {
        Some(s) => s.to_vec(),
        None => view.iter().copied().collect(),
    };
    if let Some(i) = data.iter().position(|x| !x.is_finite()) {
        let (x, y, z) = (
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        );
        return Err(PyValueError::new_err(format!(
            "`volume[{x}, {y}, {z}]` is not finite ({})",
            data[i]
        )));
    }
    let mut v = Volume::zeros(dims, geo.d_voxel);
    v.data = data;
    v.offset = geo.off_origin;
    Ok(v)
}

/// The DRRs of `vol` at `angles`, concatenated.
pub fn drr<R: Float>(
    vol: &Volume<R>,
    geo: &ConeBeam,
    angles: &[f64],
    method: Method,
) -> unispine::Result<Vec<R>> {
    let p = unispine::drr::Projector::new(vol, geo, method)?;
    let mut out = Vec::new();
    for &a in angles {
        out.extend_from_slice(&p.view(a)?.data);
    }
    Ok(out)
}

/// A 2-D image [H, W].
pub fn image<R: Float>(name: &str, obj: &Bound<'_, PyAny>) -> PyResult<Image2d<R>> {
    let (d, s) = args::read::<R>(name, obj, &[None, None])?;
    if s[0] == 0 || s[1] == 0 {
        return Err(PyValueError::new_err(format!(
            "`{name}` is empty: shape {s:?}"
        )));
    }
    Ok(Image2d::from_vec(s[1], s[0], d))
}

/// An image of the same shape as `like`.
pub fn image_like<R: Float>(
    name: &str,
    obj: &Bound<'_, PyAny>,
    like: &Image2d<R>,
) -> PyResult<Image2d<R>> {
    let (d, _) = args::read::<R>(name, obj, &[Some(like.height), Some(like.width)])?;
    Ok(Image2d::from_vec(like.width, like.height, d))
}

/// Two images of the same shape and dtype.
pub fn image_pair<R: Float>(
    a: (&str, &Bound<'_, PyAny>),
    b: (&str, &Bound<'_, PyAny>),
) -> PyResult<(Image2d<R>, Image2d<R>)> {
    let x = image::<R>(a.0, a.1)?;
    let y = image_like::<R>(b.0, b.1, &x)?;
    Ok((x, y))
}

/// The Eq. (8) settings, validated.
pub fn loss_config(
    data_term: &str,
    lambda_dssim: f64,
    charbonnier_eps: f64,
    delta: f64,
) -> PyResult<LossConfig> {
    let data_term = match data_term {
        "l1" => DataTerm::L1,
        "charbonnier" => DataTerm::Charbonnier,
        "weighted-charbonnier" => DataTerm::WeightedCharbonnier,
        other => {
            return Err(PyValueError::new_err(format!(
                "`data_term` must be 'l1', 'charbonnier' or 'weighted-charbonnier', got '{other}'"
            )))
        }
    };
    let cfg = LossConfig {
        data_term,
        lambda_dssim,
        charbonnier_eps,
        delta,
    };
    cfg.validate().map_err(args::lib_err)?;
    Ok(cfg)
}
