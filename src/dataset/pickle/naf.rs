//! The NAF dataset layout: an unpickled NAF / SAX-NeRF / X-Gaussian / UniSpine-GS dict
//! mapped to a [`Dataset`].
//!
//! The layout (written by NAF `dataGenerator/generateData.py`, SAX-NeRF
//! `dataGenerator/generateData*.py`, UniSpine-GS `tools/convert_*_to_pickle.py`; read by
//! NAF / SAX-NeRF `src/dataset/tigre.py` and X-Gaussian / UniSpine-GS
//! `scene/dataset_readers.py`):
//! `DSD`, `DSO`, `nDetector` [v, u], `dDetector` [v, u], `nVoxel`, `dVoxel`, `offOrigin`
//! [x, y, z], `offDetector` [u, v], `accuracy`, `mode` form the geometry (mm, used as they are);
//! `train` = {`angles` (radians), `projections` [N, v, u], row 0 = top} and `val` (our test
//! split); `image` ([x, y, z], optional) the ground-truth volume. NAF computes the projections
//! with TIGRE in metres (its generator divides every length by 1000), so the stored line
//! integrals are in m x volume value: [`ImportOptions::projection_scale`] (default 1000)
//! converts them to our mm. The other keys (`numTrain`, `numVal`, `totalAngle`, `startAngle`,
//! `randomAngle`, `convert`, `rescale_slope`, `rescale_intercept`, `normalize`, `noise`,
//! `filter`) are checked where they can be and recorded in the manifest.

use std::path::Path;

use super::unpickle::{read, PickleInfo, Py};
use crate::dataset::{Dataset, Manifest, Split};
use crate::error::{Error, Result};
use crate::geometry::{ConeBeam, Mode};
use crate::image2d::Image2d;
use crate::volume::{Provenance, Volume};

/// Options of [`import`].
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// Factor applied to the stored projections. NAF / SAX-NeRF / X-Gaussian / UniSpine-GS
    /// generators run TIGRE with lengths in metres, so their line integrals are in
    /// m x volume value; the default 1000 turns them into our mm x volume value. Use 1 for a
    /// pickle whose projections are already in mm.
    pub projection_scale: f64,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            projection_scale: 1000.0,
        }
    }
}

/// Import a NAF-layout dataset pickle. Errors name the file and the key.
pub fn import(path: &Path, opts: &ImportOptions) -> Result<Dataset> {
    let (root, info) = read(path)?;
    from_naf(&root, &info, path, opts)
}

/// Build a dataset from an unpickled NAF dict (`path` is only used in messages and provenance).
pub fn from_naf(
    root: &Py,
    info: &PickleInfo,
    path: &Path,
    opts: &ImportOptions,
) -> Result<Dataset> {
    if !matches!(root, Py::Dict(_)) {
        return Err(Error::format(
            path,
            "pickle",
            format!("the top level is a {}, not a dict", root.type_name()),
        ));
    }
    if !(opts.projection_scale.is_finite() && opts.projection_scale > 0.0) {
        return Err(Error::invalid(
            "projection_scale",
            format!("must be finite and > 0, got {}", opts.projection_scale),
        ));
    }
    let fmt = |key: &str, msg: String| Error::format(path, key, msg);
    let req = |key: &str| root.get(key).ok_or_else(|| fmt(key, "missing key".into()));
    let num = |key: &str| -> Result<f64> {
        let v = req(key)?;
        v.as_f64()
            .ok_or_else(|| fmt(key, format!("expected a number, got {}", v.type_name())))
    };
    let vecn = |key: &str, n: usize, default: Option<f64>| -> Result<Vec<f64>> {
        let v = match root.get(key) {
            Some(v) => v,
            None => match default {
                Some(d) => return Ok(vec![d; n]),
                None => return Err(fmt(key, "missing key".into())),
            },
        };
        let x = v
            .as_f64_vec()
            .ok_or_else(|| fmt(key, format!("expected {n} numbers, got {}", v.type_name())))?;
        // TIGRE's offDetector may carry a third (zero) component; NAF stores 2.
        if x.len() != n && !(key == "offDetector" && x.len() == 3) {
            return Err(fmt(key, format!("expected {n} numbers, got {}", x.len())));
        }
        Ok(x[..n].to_vec())
    };
    let counts = |key: &str, n: usize| -> Result<Vec<usize>> {
        let x = vecn(key, n, None)?;
        x.iter()
            .map(|&v| {
                if v >= 1.0 && v.fract() == 0.0 && v < 1e9 {
                    Ok(v as usize)
                } else {
                    Err(fmt(key, format!("expected positive integers, got {x:?}")))
                }
            })
            .collect()
    };
    let mode = match root.get("mode") {
        None => Mode::Cone,
        Some(Py::Str(s)) if s == "cone" => Mode::Cone,
        Some(Py::Str(s)) if s == "parallel" => Mode::Parallel,
        Some(v) => {
            return Err(fmt(
                "mode",
                format!("expected \"cone\" or \"parallel\", got {v:?}"),
            ))
        }
    };
    let nd = counts("nDetector", 2)?;
    let nv = counts("nVoxel", 3)?;
    let dd = vecn("dDetector", 2, None)?;
    let dv = vecn("dVoxel", 3, None)?;
    let oo = vecn("offOrigin", 3, Some(0.0))?;
    let od = vecn("offDetector", 2, Some(0.0))?;
    let geometry = ConeBeam {
        dsd: num("DSD")?,
        dso: num("DSO")?,
        n_detector: [nd[0], nd[1]],
        d_detector: [dd[0], dd[1]],
        n_voxel: [nv[0], nv[1], nv[2]],
        d_voxel: [dv[0], dv[1], dv[2]],
        off_origin: [oo[0], oo[1], oo[2]],
        off_detector: [od[0], od[1]],
        mode,
        accuracy: if root.get("accuracy").is_some() {
            num("accuracy")?
        } else {
            0.5
        },
    };
    geometry.validate().map_err(|e| match e {
        Error::Invalid { field, msg } => {
            let key = field.split('[').next().unwrap_or(&field).to_string();
            Error::format(path, key, format!("{field}: {msg}"))
        }
        other => other,
    })?;

    let (w, h) = geometry.image_size();
    let split = |key: &str, count_key: &str| -> Result<Split> {
        let s = req(key)?;
        if !matches!(s, Py::Dict(_)) {
            return Err(fmt(key, format!("expected a dict, got {}", s.type_name())));
        }
        let ak = format!("{key}.angles");
        let pk = format!("{key}.projections");
        let angles = s
            .get("angles")
            .ok_or_else(|| fmt(&ak, "missing key".into()))?;
        let angles = angles.as_f64_vec().ok_or_else(|| {
            fmt(
                &ak,
                format!("expected a 1-D array, got {}", angles.type_name()),
            )
        })?;
        if let Some(k) = angles.iter().position(|a| !a.is_finite()) {
            return Err(fmt(&ak, format!("angle {k} is not finite")));
        }
        let p = match s.get("projections") {
            Some(Py::Array(a)) => a,
            Some(v) => {
                return Err(fmt(
                    &pk,
                    format!("expected an ndarray, got {}", v.type_name()),
                ))
            }
            None => return Err(fmt(&pk, "missing key".into())),
        };
        if p.shape.len() != 3 || p.shape[1] != h || p.shape[2] != w || p.shape[0] != angles.len() {
            return Err(fmt(
                &pk,
                format!(
                    "shape {:?} does not match [len({ak}), nDetector[0], nDetector[1]] = [{}, {h}, {w}]",
                    p.shape,
                    angles.len()
                ),
            ));
        }
        if angles.is_empty() {
            return Err(fmt(&ak, format!("zero {key} views")));
        }
        if let Some(c) = root.get(count_key) {
            if c.as_f64() != Some(angles.len() as f64) {
                return Err(fmt(
                    count_key,
                    format!("{c:?} but {ak} holds {} angles", angles.len()),
                ));
            }
        }
        let vals = p.to_f32();
        let scale = opts.projection_scale as f32;
        let mut projections = Vec::with_capacity(angles.len());
        for (k, chunk) in vals.chunks(w * h).enumerate() {
            if let Some(i) = chunk.iter().position(|v| !v.is_finite()) {
                return Err(fmt(
                    &pk,
                    format!(
                        "non-finite value {} in view {k} at row {}, column {}",
                        chunk[i],
                        i / w,
                        i % w
                    ),
                ));
            }
            projections.push(Image2d::from_vec(
                w,
                h,
                chunk.iter().map(|v| v * scale).collect(),
            ));
        }
        Ok(Split {
            angles,
            projections,
        })
    };
    let train = split("train", "numTrain")?;
    let test_key = if root.get("val").is_some() {
        "val"
    } else {
        "test"
    };
    let test = split(test_key, "numVal")?;

    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let mut steps = vec![format!(
        "imported from the NAF-layout pickle {name} (protocol {}, {})",
        info.protocol,
        info.numpy_path.as_deref().unwrap_or("no numpy objects")
    )];
    let volume = match root.get("image") {
        None | Some(Py::None) => None,
        Some(Py::Array(a)) if a.shape.len() == 3 && !a.is_empty() => {
            let dims = [a.shape[0], a.shape[1], a.shape[2]];
            let c = a.to_f32();
            let mut data = vec![0f32; c.len()];
            // C order [x, y, z] (z fastest) -> our x-fastest layout.
            for i in 0..dims[0] {
                for j in 0..dims[1] {
                    for k in 0..dims[2] {
                        data[i + dims[0] * (j + dims[1] * k)] = c[(i * dims[1] + j) * dims[2] + k];
                    }
                }
            }
            if let Some(idx) = data.iter().position(|v| !v.is_finite()) {
                return Err(fmt(
                    "image",
                    format!("non-finite voxel value at linear index {idx}"),
                ));
            }
            let size = geometry.volume_size();
            let spacing = [
                size[0] / dims[0] as f64,
                size[1] / dims[1] as f64,
                size[2] / dims[2] as f64,
            ];
            if dims != geometry.n_voxel {
                steps.push(format!(
                    "the stored image is {dims:?}, not nVoxel {:?}: its voxels were resized to \
                     keep the geometry's box (spacing {spacing:?} mm)",
                    geometry.n_voxel
                ));
            }
            Some(Volume {
                data,
                dims,
                spacing: if dims == geometry.n_voxel {
                    geometry.d_voxel
                } else {
                    spacing
                },
                offset: geometry.off_origin,
                provenance: Provenance::default(),
            })
        }
        Some(v) => {
            return Err(fmt(
                "image",
                format!("expected a 3-D ndarray, got {}", v.type_name()),
            ))
        }
    };
    if opts.projection_scale != 1.0 {
        steps.push(format!(
            "projections multiplied by {} (NAF line integrals are in metres; ours in mm)",
            opts.projection_scale
        ));
    }
    let provenance = Provenance {
        source: name,
        file_affine: None,
        steps,
    };
    let volume = volume.map(|mut v| {
        v.provenance = provenance.clone();
        v
    });

    let flag = |k: &str| root.get(k).and_then(|v| v.as_f64()).unwrap_or(0.0) != 0.0;
    let mut norm = Vec::new();
    if flag("convert") {
        let slope = root
            .get("rescale_slope")
            .and_then(|v| v.as_f64())
            .unwrap_or(1.0);
        let icpt = root
            .get("rescale_intercept")
            .and_then(|v| v.as_f64())
            .unwrap_or(0.0);
        norm.push(format!(
            "HU = {slope} * stored + {icpt}; mu = 0.206 + (0.206 - 0.0004) / 1000 * HU (NAF convert)"
        ));
    }
    if flag("normalize") {
        norm.push("min-max normalised to [0, 1] (NAF normalize)".to_string());
    }
    if norm.is_empty() {
        norm.push("as stored in the pickle (no convert / normalize flag set)".into());
    }
    let noise = match root.get("noise").and_then(|v| v.as_f64()) {
        None | Some(0.0) => "none".to_string(),
        Some(s) => format!(
            "upstream TIGRE CTnoise: Poisson I0 = 1e5 + Gaussian sigma {s} (applied before import)"
        ),
    };
    let mut extra = serde_json::Map::new();
    if let Py::Dict(items) = root {
        for (k, v) in items {
            let key = match k {
                Py::Str(s) => s.clone(),
                _ => continue,
            };
            let jv = match v {
                Py::None => serde_json::Value::Null,
                Py::Bool(b) => (*b).into(),
                Py::Int(i) => (*i).into(),
                Py::Float(f) if f.is_finite() => (*f).into(),
                Py::Str(s) => s.clone().into(),
                _ => continue,
            };
            if [
                "numTrain",
                "numVal",
                "totalAngle",
                "startAngle",
                "randomAngle",
                "convert",
                "rescale_slope",
                "rescale_intercept",
                "normalize",
                "noise",
                "filter",
            ]
            .contains(&key.as_str())
            {
                extra.insert(format!("pickle.{key}"), jv);
            }
        }
    }
    extra.insert("pickle.protocol".into(), (info.protocol as u64).into());
    if let Some(p) = &info.numpy_path {
        extra.insert("pickle.numpy_module".into(), p.clone().into());
    }
    extra.insert("projection_scale".into(), opts.projection_scale.into());
    let manifest = Manifest {
        projection_units: if opts.projection_scale == 1000.0 {
            "mm * volume value (line integrals; NAF metres x 1000)".into()
        } else {
            format!("pickle values x {} (line integrals)", opts.projection_scale)
        },
        volume_normalisation: norm.join("; "),
        provenance,
        projector: "upstream TIGRE Ax (Siddon by default), not recomputed".into(),
        noise,
        extra,
        pose_noise: None,
    };
    let ds = Dataset {
        geometry,
        train,
        test,
        manifest,
        volume,
    };
    crate::dataset::store::check(&ds).map_err(|e| Error::format(path, "dataset", e.to_string()))?;
    Ok(ds)
}
