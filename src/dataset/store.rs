//! Dataset folders: `dataset.json`, `train.npy`, `test.npy`, `volume.npy`, PNG previews.
//!
//! Layout of a folder written by [`save`] (format version [`FORMAT_VERSION`]):
//!
//! - `dataset.json`:
//!   - `format` = `"unispine-dataset"`, `format_version` = 1;
//!   - `geometry`: the scanner with the TIGRE / NAF field names (`DSD`, `DSO`, `nDetector` [v, u],
//!     `dDetector` [v, u], `nVoxel`, `dVoxel`, `offOrigin` [x, y, z], `offDetector` [u, v],
//!     `mode`, `accuracy`), lengths in mm;
//!   - `train`, `test`: `{ "file", "count", "angles" (radians), "angles_deg" (informational) }`;
//!   - `manifest`: projection units, volume normalisation, provenance, projector, noise, extra
//!     generator settings (see [`super::Manifest`]);
//!   - `volume`: `null`, or `{ "file": "volume.npy", "nVoxel", "dVoxel", "offOrigin",
//!     "provenance", "value_min", "value_max" }`;
//!   - `previews`: the PNG files written (relative paths).
//! - `train.npy`, `test.npy`: f32 `[N, v, u]` (C order), row 0 = top of the detector (+z),
//!   column 0 = left (-u); the projection values as generated (see `manifest.projection_units`).
//! - `volume.npy`: f32 `[x, y, z]` (written in Fortran order so that the bytes are our x-fastest
//!   layout; numpy reads it as an ordinary `[x, y, z]` array).
//! - `previews/`: a few views per split and three central slices of the volume, each min-max
//!   scaled to 8 bits (constant images are black).
//!
//! [`load`] checks everything it reads and names the file and the field of the first problem
//! (missing file, wrong format version, shape that disagrees with the json, NaN in a
//! projection, zero test views, a volume box that disagrees with the geometry).

use std::path::Path;

use ndarray::{Array3, ShapeBuilder};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::{Dataset, Manifest, Split};
use crate::error::{Error, Result};
use crate::geometry::ConeBeam;
use crate::image2d::Image2d;
use crate::preview::{min_max, write_png};
use crate::volume::{Provenance, Volume};

/// Value of the `format` field of `dataset.json`.
pub const FORMAT_NAME: &str = "unispine-dataset";
/// Version of the folder layout written by [`save`] (read: this version and older).
pub const FORMAT_VERSION: u32 = 1;
/// Number of preview PNGs per split (evenly spread over the views).
pub const PREVIEWS_PER_SPLIT: usize = 4;

#[derive(Serialize, Deserialize)]
struct SplitJson {
    file: String,
    count: usize,
    angles: Vec<f64>,
    #[serde(default)]
    angles_deg: Vec<f64>,
}

#[derive(Serialize, Deserialize)]
struct VolumeJson {
    file: String,
    #[serde(rename = "nVoxel")]
    n_voxel: [usize; 3],
    #[serde(rename = "dVoxel")]
    d_voxel: [f64; 3],
    #[serde(rename = "offOrigin")]
    off_origin: [f64; 3],
    #[serde(default)]
    provenance: Provenance,
    #[serde(default)]
    value_min: f64,
    #[serde(default)]
    value_max: f64,
}

/// Check that `ds` is complete and consistent: at least one training and one test view, one
/// projection per angle, every projection of the detector's size and finite, finite angles,
/// a valid geometry, and a finite volume (when present) whose box matches the geometry's.
/// Errors name the split, the view and the field.
pub fn check(ds: &Dataset) -> Result<()> {
    ds.geometry.validate()?;
    let (w, h) = ds.geometry.image_size();
    for (name, split) in [("train", &ds.train), ("test", &ds.test)] {
        if split.angles.is_empty() {
            return Err(Error::invalid(
                format!("{name}.angles"),
                format!("zero {name} views: a dataset needs at least one {name} view"),
            ));
        }
        if split.angles.len() != split.projections.len() {
            return Err(Error::invalid(
                format!("{name}.projections"),
                format!(
                    "{} angles but {} projections",
                    split.angles.len(),
                    split.projections.len()
                ),
            ));
        }
        crate::error::check_finite(&format!("{name}.angles"), &split.angles)?;
        for (k, p) in split.projections.iter().enumerate() {
            if p.width != w || p.height != h || p.data.len() != w * h {
                return Err(Error::invalid(
                    format!("{name}.projections[{k}]"),
                    format!(
                        "image is {}x{} (v x u) but the detector nDetector is [{h}, {w}]",
                        p.height, p.width
                    ),
                ));
            }
            if let Some(i) = p.data.iter().position(|v| !v.is_finite()) {
                return Err(Error::NonFinite {
                    what: format!(
                        "{name} projection {k} (row {}, column {})",
                        i / w.max(1),
                        i % w.max(1)
                    ),
                    index: i,
                    value: p.data[i] as f64,
                });
            }
        }
    }
    if let Some(v) = &ds.volume {
        if v.data.len() != v.dims[0] * v.dims[1] * v.dims[2] || v.data.is_empty() {
            return Err(Error::invalid(
                "volume",
                format!("{} values for dims {:?}", v.data.len(), v.dims),
            ));
        }
        v.check_finite("volume")?;
        check_volume_box(&ds.geometry, v.dims, v.spacing, v.offset)
            .map_err(|msg| Error::invalid("volume", msg))?;
    }
    if let Some(p) = &ds.manifest.pose_noise {
        super::pose::check(p, &ds.geometry, &ds.train.angles)?;
    }
    Ok(())
}

/// The volume's physical box must be the geometry's (`nVoxel * dVoxel`, `offOrigin`).
fn check_volume_box(
    geo: &ConeBeam,
    dims: [usize; 3],
    spacing: [f64; 3],
    offset: [f64; 3],
) -> std::result::Result<(), String> {
    let gs = geo.volume_size();
    for a in 0..3 {
        let s = dims[a] as f64 * spacing[a];
        let tol = 1e-6 * gs[a].abs().max(1.0);
        if !(s - gs[a]).abs().le(&tol) || !(offset[a] - geo.off_origin[a]).abs().le(&tol) {
            return Err(format!(
                "axis {a}: the volume spans {s} mm at offset {} but the geometry says \
                 nVoxel * dVoxel = {} mm at offOrigin {}",
                offset[a], gs[a], geo.off_origin[a]
            ));
        }
    }
    Ok(())
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

/// The files [`save`] writes into `dir` (besides `previews/`): a command whose input is one of
/// them must refuse to run (see [`crate::fsio::check_not_output`]).
pub fn output_files(dir: &Path) -> Vec<std::path::PathBuf> {
    ["dataset.json", "train.npy", "test.npy", "volume.npy"]
        .iter()
        .map(|f| dir.join(f))
        .collect()
}

/// Write `ds` into the folder `dir` (created if missing). Refuses an inconsistent dataset
/// (see [`check`]).
///
/// An earlier dataset in `dir` is retired first: `dataset.json` is removed before anything else
/// is written and written again last, and the arrays and previews of the earlier dataset are
/// removed, so a save that fails part-way leaves a folder that [`load`] refuses (no
/// `dataset.json`) rather than new arrays beside an old description. Every file is written
/// atomically ([`crate::fsio::write_atomic`]).
pub fn save(ds: &Dataset, dir: &Path) -> Result<()> {
    check(ds)?;
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    for f in output_files(dir) {
        crate::fsio::remove_if_exists(&f)?;
    }
    let pdir = dir.join("previews");
    for prefix in ["train_", "test_", "volume_"] {
        crate::fsio::remove_matching(&pdir, prefix, ".png")?;
    }
    let (w, h) = ds.geometry.image_size();
    write_split(&dir.join("train.npy"), &ds.train, h, w)?;
    write_split(&dir.join("test.npy"), &ds.test, h, w)?;

    let vol_path = dir.join("volume.npy");
    let volume = match &ds.volume {
        Some(v) => {
            write_volume(&vol_path, v)?;
            let (lo, hi) = min_max(&v.data);
            Some(VolumeJson {
                file: "volume.npy".into(),
                n_voxel: v.dims,
                d_voxel: v.spacing,
                off_origin: v.offset,
                provenance: v.provenance.clone(),
                value_min: lo as f64,
                value_max: hi as f64,
            })
        }
        // A stale volume of an earlier dataset was removed above.
        None => None,
    };

    let previews = write_previews(ds, dir)?;
    let split_json = |s: &Split, file: &str| SplitJson {
        file: file.into(),
        count: s.angles.len(),
        angles: s.angles.clone(),
        angles_deg: s.angles.iter().map(|a| a.to_degrees()).collect(),
    };
    let json = serde_json::json!({
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "geometry": ds.geometry,
        "train": split_json(&ds.train, "train.npy"),
        "test": split_json(&ds.test, "test.npy"),
        "manifest": ds.manifest,
        "volume": volume,
        "previews": previews,
    });
    let path = dir.join("dataset.json");
    crate::fsio::write_json_atomic(&path, &json)
}

fn write_split(path: &Path, s: &Split, h: usize, w: usize) -> Result<()> {
    let mut flat = Vec::with_capacity(s.projections.len() * h * w);
    for p in &s.projections {
        flat.extend_from_slice(&p.data);
    }
    let arr = Array3::from_shape_vec((s.projections.len(), h, w), flat)
        .map_err(|e| Error::format(path, "shape", e.to_string()))?;
    write_npy_atomic(path, &arr)
}

/// An f32 array as `.npy`, written atomically.
fn write_npy_atomic(path: &Path, arr: &Array3<f32>) -> Result<()> {
    use ndarray_npy::WriteNpyExt;
    let mut buf = Vec::new();
    arr.write_npy(&mut buf)
        .map_err(|e| Error::format(path, "npy", e.to_string()))?;
    crate::fsio::write_atomic(path, &buf)
}

fn write_volume(path: &Path, v: &Volume<f32>) -> Result<()> {
    // Our layout is x fastest, i.e. Fortran order of an [x, y, z] array.
    let arr = Array3::from_shape_vec((v.dims[0], v.dims[1], v.dims[2]).f(), v.data.clone())
        .map_err(|e| Error::format(path, "shape", e.to_string()))?;
    write_npy_atomic(path, &arr)
}

/// Indices of `m` views spread evenly over `n` (first and last included).
fn preview_indices(n: usize, m: usize) -> Vec<usize> {
    if n <= m {
        return (0..n).collect();
    }
    let mut v: Vec<usize> = (0..m)
        .map(|k| ((k * (n - 1)) as f64 / (m - 1) as f64).round() as usize)
        .collect();
    v.dedup();
    v
}

fn write_previews(ds: &Dataset, dir: &Path) -> Result<Vec<String>> {
    let pdir = dir.join("previews");
    std::fs::create_dir_all(&pdir).map_err(io(&pdir))?;
    let mut names = Vec::new();
    for (name, split) in [("train", &ds.train), ("test", &ds.test)] {
        for k in preview_indices(split.projections.len(), PREVIEWS_PER_SPLIT) {
            let rel = format!("previews/{name}_{k:03}.png");
            write_png(&dir.join(&rel), &split.projections[k])?;
            names.push(rel);
        }
    }
    if let Some(v) = &ds.volume {
        let [nx, ny, nz] = v.dims;
        // Axial (z = mid; rows y, columns x), coronal (y = mid; rows z top-down, columns x),
        // sagittal (x = mid; rows z top-down, columns y).
        let axial = Image2d::from_vec(
            nx,
            ny,
            (0..ny)
                .flat_map(|j| (0..nx).map(move |i| (i, j)))
                .map(|(i, j)| v.get(i, j, nz / 2))
                .collect(),
        );
        let coronal = Image2d::from_vec(
            nx,
            nz,
            (0..nz)
                .rev()
                .flat_map(|k| (0..nx).map(move |i| (i, k)))
                .map(|(i, k)| v.get(i, ny / 2, k))
                .collect(),
        );
        let sagittal = Image2d::from_vec(
            ny,
            nz,
            (0..nz)
                .rev()
                .flat_map(|k| (0..ny).map(move |j| (j, k)))
                .map(|(j, k)| v.get(nx / 2, j, k))
                .collect(),
        );
        for (n, img) in [
            ("volume_axial", axial),
            ("volume_coronal", coronal),
            ("volume_sagittal", sagittal),
        ] {
            let rel = format!("previews/{n}.png");
            write_png(&dir.join(&rel), &img)?;
            names.push(rel);
        }
    }
    Ok(names)
}

/// Read a dataset folder written by [`save`].
pub fn load(dir: &Path) -> Result<Dataset> {
    let jpath = dir.join("dataset.json");
    let text = std::fs::read_to_string(&jpath).map_err(io(&jpath))?;
    let root: Value = serde_json::from_str(&text)
        .map_err(|e| Error::format(&jpath, "dataset.json", format!("not valid JSON: {e}")))?;
    let field = |name: &str| -> Result<&Value> {
        root.get(name)
            .ok_or_else(|| Error::format(&jpath, name, "missing"))
    };
    match field("format")?.as_str() {
        Some(FORMAT_NAME) => {}
        other => {
            return Err(Error::format(
                &jpath,
                "format",
                format!("expected \"{FORMAT_NAME}\", got {other:?}"),
            ))
        }
    }
    let version = field("format_version")?
        .as_u64()
        .ok_or_else(|| Error::format(&jpath, "format_version", "not an integer"))?;
    if version == 0 || version > FORMAT_VERSION as u64 {
        return Err(Error::format(
            &jpath,
            "format_version",
            format!("version {version} is not supported (this build reads 1..={FORMAT_VERSION})"),
        ));
    }
    let geometry: ConeBeam = serde_json::from_value(field("geometry")?.clone())
        .map_err(|e| Error::format(&jpath, "geometry", e.to_string()))?;
    geometry.validate().map_err(|e| match e {
        Error::Invalid { field, msg } => Error::format(&jpath, format!("geometry.{field}"), msg),
        other => other,
    })?;
    let manifest: Manifest = serde_json::from_value(field("manifest")?.clone())
        .map_err(|e| Error::format(&jpath, "manifest", e.to_string()))?;

    let (w, h) = geometry.image_size();
    let mut splits = Vec::new();
    for name in ["train", "test"] {
        let sj: SplitJson = serde_json::from_value(field(name)?.clone())
            .map_err(|e| Error::format(&jpath, name, e.to_string()))?;
        if sj.angles.len() != sj.count {
            return Err(Error::format(
                &jpath,
                format!("{name}.angles"),
                format!("{} angles but count = {}", sj.angles.len(), sj.count),
            ));
        }
        if sj.count == 0 {
            return Err(Error::format(
                &jpath,
                format!("{name}.count"),
                format!("zero {name} views: a dataset needs at least one {name} view"),
            ));
        }
        if let Some(k) = sj.angles.iter().position(|a| !a.is_finite()) {
            return Err(Error::format(
                &jpath,
                format!("{name}.angles[{k}]"),
                "not a finite number",
            ));
        }
        let npath = dir.join(&sj.file);
        let projections = read_split(&npath, name, sj.count, h, w)?;
        splits.push(Split {
            angles: sj.angles,
            projections,
        });
    }
    let test = splits.pop().expect("two splits");
    let train = splits.pop().expect("two splits");

    let volume = match root.get("volume") {
        None | Some(Value::Null) => None,
        Some(v) => {
            let vj: VolumeJson = serde_json::from_value(v.clone())
                .map_err(|e| Error::format(&jpath, "volume", e.to_string()))?;
            for a in 0..3 {
                if vj.n_voxel[a] == 0 || !(vj.d_voxel[a].is_finite() && vj.d_voxel[a] > 0.0) {
                    return Err(Error::format(
                        &jpath,
                        format!("volume.nVoxel/dVoxel[{a}]"),
                        "must be > 0 and finite",
                    ));
                }
            }
            check_volume_box(&geometry, vj.n_voxel, vj.d_voxel, vj.off_origin)
                .map_err(|msg| Error::format(&jpath, "volume", msg))?;
            let vpath = dir.join(&vj.file);
            let data = read_volume(&vpath, vj.n_voxel)?;
            Some(Volume {
                data,
                dims: vj.n_voxel,
                spacing: vj.d_voxel,
                offset: vj.off_origin,
                provenance: vj.provenance,
            })
        }
    };
    Ok(Dataset {
        geometry,
        train,
        test,
        manifest,
        volume,
    })
}

/// Read a 3-D float npy (f64 files are accepted and rounded) as its shape and f32 values in
/// C order; sizes are checked against the file length before anything is allocated.
fn read_f32_array3(path: &Path) -> Result<Array3<f32>> {
    let a = crate::volume::npy::read(path)?;
    if a.shape.len() != 3 || !a.is_float() {
        return Err(Error::format(
            path,
            "npy",
            format!(
                "expected a 3-D f32 (or f64) npy array, got {} {:?}",
                a.descr, a.shape
            ),
        ));
    }
    let shape = (a.shape[0], a.shape[1], a.shape[2]);
    Array3::from_shape_vec(shape, a.to_f32_c())
        .map_err(|e| Error::format(path, "shape", e.to_string()))
}

fn read_split(path: &Path, name: &str, n: usize, h: usize, w: usize) -> Result<Vec<Image2d<f32>>> {
    let arr = read_f32_array3(path)?;
    let shape = arr.dim();
    if shape != (n, h, w) {
        return Err(Error::format(
            path,
            "shape",
            format!(
                "array is {:?} but dataset.json says [{name}.count, nDetector[0], nDetector[1]] \
                 = [{n}, {h}, {w}]",
                [shape.0, shape.1, shape.2]
            ),
        ));
    }
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let view = arr.index_axis(ndarray::Axis(0), k);
        let data: Vec<f32> = view.iter().copied().collect();
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::format(
                path,
                format!("{name} projection {k}"),
                format!(
                    "non-finite value {} at row {}, column {}",
                    data[i],
                    i / w,
                    i % w
                ),
            ));
        }
        out.push(Image2d::from_vec(w, h, data));
    }
    Ok(out)
}

fn read_volume(path: &Path, dims: [usize; 3]) -> Result<Vec<f32>> {
    let arr = read_f32_array3(path)?;
    let shape = arr.dim();
    if [shape.0, shape.1, shape.2] != dims {
        return Err(Error::format(
            path,
            "shape",
            format!(
                "array is {:?} but dataset.json says volume.nVoxel = {dims:?}",
                [shape.0, shape.1, shape.2]
            ),
        ));
    }
    // Reversed axes iterate in (z, y, x) logical order: x fastest, our layout.
    let data: Vec<f32> = arr.view().reversed_axes().iter().copied().collect();
    if let Some(idx) = data.iter().position(|v| !v.is_finite()) {
        let i = idx % dims[0];
        let j = (idx / dims[0]) % dims[1];
        let k = idx / (dims[0] * dims[1]);
        return Err(Error::format(
            path,
            "volume",
            format!(
                "non-finite value {} at voxel (i, j, k) = ({i}, {j}, {k})",
                data[idx]
            ),
        ));
    }
    Ok(data)
}
