//! Cone-beam (and parallel-beam) scanner geometry with the TIGRE / NAF field names, and the
//! per-angle pinhole [`Camera`] used by both the DRR ray-marcher and the Gaussian rasterizer.
//!
//! Conventions (NAF `Ruyi-Zha/naf_cbct` `src/dataset/tigre.py`: `angle2pose`, `get_rays`; the
//! same pose in X-Gaussian `caiyuanhao1998/X-Gaussian` `scene/dataset_readers.py`):
//! - Lengths in millimetres, angles in radians.
//! - Source on the circle of radius `DSO` in the z = 0 plane at angle θ, rotating about world +z:
//!   camera centre c = (DSO cos θ, DSO sin θ, 0).
//! - Camera axes (OpenCV: x right, y down, z forward): x = (-sin θ, cos θ, 0), y = (0, 0, -1),
//!   z = (-cos θ, -sin θ, 0). World to camera: t = R (p - c) with the axes as rows of R.
//! - Detector: `nDetector` and `dDetector` are TIGRE `[v, u]` (rows, columns); `offDetector` is
//!   `[u, v]` in mm. Pixel (row r, column c) has its centre at detector coordinates
//!   u = (c + 0.5 - W/2) du + offU, v = (r + 0.5 - H/2) dv + offV (NAF `get_rays`), u along camera
//!   x and v along camera y (down). Row 0 is the top of the image (+z).
//! - Intrinsics in pixels: fx = DSD / du, fy = DSD / dv (the physical focal length; X-Gaussian
//!   assumes du = 1 mm), cx = W/2 - offU/du, cy = H/2 - offV/dv, with pixel centres at
//!   (c + 0.5, r + 0.5): u_pix = fx X/Z + cx.
//! - Volume: `nVoxel`, `dVoxel`, `offOrigin` are `[x, y, z]`; voxel (i, j, k) has its centre at
//!   (-sX/2 + (i + 1/2) dX, ...) + offOrigin with sX = nX dX (TIGRE / NAF).
//! - Parallel beam: rays along camera z through the same detector coordinates (no divergence).
//!
//! [`Camera`]: crate::geometry::Camera

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Beam shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Divergent cone beam from a point source.
    #[default]
    Cone,
    /// Parallel rays along the camera axis.
    Parallel,
}

fn default_accuracy() -> f64 {
    0.5
}

/// TIGRE / NAF scanner geometry (the JSON field names are TIGRE's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConeBeam {
    /// Source to detector distance, mm.
    #[serde(rename = "DSD")]
    pub dsd: f64,
    /// Source to origin (rotation centre) distance, mm.
    #[serde(rename = "DSO")]
    pub dso: f64,
    /// Detector pixel counts `[v, u]` (rows, columns).
    #[serde(rename = "nDetector")]
    pub n_detector: [usize; 2],
    /// Detector pixel pitch `[v, u]`, mm.
    #[serde(rename = "dDetector")]
    pub d_detector: [f64; 2],
    /// Volume voxel counts `[x, y, z]`.
    #[serde(rename = "nVoxel")]
    pub n_voxel: [usize; 3],
    /// Voxel size `[x, y, z]`, mm.
    #[serde(rename = "dVoxel")]
    pub d_voxel: [f64; 3],
    /// Offset of the volume centre from the rotation centre `[x, y, z]`, mm.
    #[serde(rename = "offOrigin", default)]
    pub off_origin: [f64; 3],
    /// Detector offset `[u, v]`, mm.
    #[serde(rename = "offDetector", default)]
    pub off_detector: [f64; 2],
    /// `cone` or `parallel`.
    #[serde(default)]
    pub mode: Mode,
    /// Ray-march step in voxels for the trilinear projector (TIGRE 'interpolated', 0.5).
    #[serde(default = "default_accuracy")]
    pub accuracy: f64,
}

/// Source-to-detector distance of every SAX-NeRF / UniSpine-GS data config, mm
/// (SAX-NeRF `dataGenerator/raw_data/*/config.yml`: `DSD: 1500`).
pub const DSD_MM: f64 = 1500.0;
/// Source-to-origin distance of every SAX-NeRF / UniSpine-GS data config, mm (`DSO: 1000`).
pub const DSO_MM: f64 = 1000.0;

impl ConeBeam {
    /// A centred cone beam at the protocol distances ([`DSD_MM`], [`DSO_MM`]): no volume or
    /// detector offset, trilinear step 0.5 voxel. Other fields by struct update, e.g.
    /// `ConeBeam { mode: Mode::Parallel, ..ConeBeam::centred(..) }`.
    pub fn centred(
        n_detector: [usize; 2],
        d_detector: [f64; 2],
        n_voxel: [usize; 3],
        d_voxel: [f64; 3],
    ) -> Self {
        ConeBeam {
            dsd: DSD_MM,
            dso: DSO_MM,
            n_detector,
            d_detector,
            n_voxel,
            d_voxel,
            off_origin: [0.0; 3],
            off_detector: [0.0; 2],
            mode: Mode::Cone,
            accuracy: default_accuracy(),
        }
    }

    /// Check every field for sign and finiteness; the error names the field.
    pub fn validate(&self) -> Result<()> {
        let pos = |name: &str, v: f64| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(
                    name,
                    format!("must be finite and > 0, got {v}"),
                ))
            }
        };
        let fin = |name: &str, v: f64| -> Result<()> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(Error::invalid(name, format!("must be finite, got {v}")))
            }
        };
        pos("DSD", self.dsd)?;
        pos("DSO", self.dso)?;
        pos("dDetector[0]", self.d_detector[0])?;
        pos("dDetector[1]", self.d_detector[1])?;
        for a in 0..3 {
            pos(&format!("dVoxel[{a}]"), self.d_voxel[a])?;
            fin(&format!("offOrigin[{a}]"), self.off_origin[a])?;
            if self.n_voxel[a] == 0 {
                return Err(Error::invalid(format!("nVoxel[{a}]"), "must be > 0"));
            }
        }
        fin("offDetector[0]", self.off_detector[0])?;
        fin("offDetector[1]", self.off_detector[1])?;
        for a in 0..2 {
            if self.n_detector[a] == 0 {
                return Err(Error::invalid(format!("nDetector[{a}]"), "must be > 0"));
            }
        }
        if !(ACCURACY_RANGE.0..=ACCURACY_RANGE.1).contains(&self.accuracy) {
            return Err(Error::invalid(
                "accuracy",
                format!(
                    "{} is outside the allowed range [{}, {}] (trilinear step = accuracy x \
                     voxel size; TIGRE's default is 0.5)",
                    self.accuracy, ACCURACY_RANGE.0, ACCURACY_RANGE.1
                ),
            ));
        }
        for a in 0..2 {
            if self.n_detector[a] > MAX_DETECTOR {
                return Err(Error::invalid(
                    format!("nDetector[{a}]"),
                    format!(
                        "{} pixels is outside the allowed range [1, {MAX_DETECTOR}]",
                        self.n_detector[a]
                    ),
                ));
            }
        }
        for a in 0..3 {
            if self.n_voxel[a] > MAX_VOXELS_PER_AXIS {
                return Err(Error::invalid(
                    format!("nVoxel[{a}]"),
                    format!(
                        "{} voxels is outside the allowed range [1, {MAX_VOXELS_PER_AXIS}]",
                        self.n_voxel[a]
                    ),
                ));
            }
        }
        if self.mode == Mode::Cone && self.dsd < self.dso {
            return Err(Error::invalid(
                "DSD",
                format!(
                    "DSD ({}) must be >= DSO ({}): the detector sits behind the rotation centre",
                    self.dsd, self.dso
                ),
            ));
        }
        Ok(())
    }

    /// Physical size of the volume `[x, y, z]` in mm (sVoxel).
    pub fn volume_size(&self) -> [f64; 3] {
        [
            self.n_voxel[0] as f64 * self.d_voxel[0],
            self.n_voxel[1] as f64 * self.d_voxel[1],
            self.n_voxel[2] as f64 * self.d_voxel[2],
        ]
    }

    /// The volume box `(lo, hi)` in world mm: `offOrigin -+ sVoxel / 2` per axis (as
    /// [`crate::volume::Volume::bounds`] computes it for a volume on this grid).
    pub fn volume_box(&self) -> ([f64; 3], [f64; 3]) {
        let s = self.volume_size();
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for a in 0..3 {
            lo[a] = self.off_origin[a] - s[a] / 2.0;
            hi[a] = self.off_origin[a] + s[a] / 2.0;
        }
        (lo, hi)
    }

    /// [`check_view`] of the camera at `angle` (radians) against this geometry's volume box.
    pub fn check_view(&self, angle: f64) -> Result<()> {
        check_view(&self.camera(angle), self.volume_box())
    }

    /// Image width (u, columns) and height (v, rows) in pixels.
    pub fn image_size(&self) -> (usize, usize) {
        (self.n_detector[1], self.n_detector[0])
    }

    /// Camera at projection angle `angle` (radians).
    pub fn camera(&self, angle: f64) -> Camera {
        Camera::new(self, angle)
    }
}

/// A volume's voxel grid, for the fields a geometry file may leave out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelGrid {
    /// `nVoxel` `[x, y, z]`.
    pub n_voxel: [usize; 3],
    /// `dVoxel` `[x, y, z]`, mm.
    pub d_voxel: [f64; 3],
    /// `offOrigin` `[x, y, z]`, mm.
    pub off_origin: [f64; 3],
}

/// Read a TIGRE / NAF geometry JSON file (the fields of [`ConeBeam`]) and validate it. With
/// `grid`, `nVoxel`, `dVoxel` and `offOrigin` may be omitted and are taken from it. Every error
/// names the file (and the field when one is wrong).
pub fn read_json(path: &Path, grid: Option<&VoxelGrid>) -> Result<ConeBeam> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut value: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| Error::format(path, "json", format!("not valid JSON: {e}")))?;
    let obj = value.as_object_mut().ok_or_else(|| {
        Error::format(path, "json", "expected a JSON object with the TIGRE fields")
    })?;
    if let Some(g) = grid {
        obj.entry("nVoxel")
            .or_insert_with(|| serde_json::json!(g.n_voxel));
        obj.entry("dVoxel")
            .or_insert_with(|| serde_json::json!(g.d_voxel));
        obj.entry("offOrigin")
            .or_insert_with(|| serde_json::json!(g.off_origin));
    }
    let geo: ConeBeam = serde_json::from_value(value).map_err(|e| {
        Error::format(
            path,
            "json",
            format!(
                "not a TIGRE/NAF geometry ({e}; fields DSD, DSO, nDetector, dDetector, nVoxel, \
                 dVoxel, optional offOrigin, offDetector, mode, accuracy)"
            ),
        )
    })?;
    geo.validate().map_err(|e| match e {
        Error::Invalid { field, msg } => Error::format(path, field, msg),
        other => other,
    })?;
    Ok(geo)
}

/// A pinhole (or orthographic) camera for one projection angle.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Projection angle θ, radians.
    pub angle: f64,
    /// World-to-camera rotation; its rows are the camera x, y, z axes in world coordinates.
    pub rot: [[f64; 3]; 3],
    /// Camera centre (the X-ray source for a cone beam) in world coordinates, mm.
    pub centre: [f64; 3],
    /// Focal lengths in pixels (DSD / pitch).
    pub fx: f64,
    pub fy: f64,
    /// Principal point in pixels, with pixel centres at (c + 0.5, r + 0.5).
    pub cx: f64,
    pub cy: f64,
    /// Image width (columns, u) and height (rows, v).
    pub width: usize,
    pub height: usize,
    /// Source-detector distance, mm.
    pub dsd: f64,
    /// Detector pitch `[v, u]`, mm.
    pub pitch: [f64; 2],
    /// Beam shape.
    pub mode: Mode,
}

impl Camera {
    /// The camera of `geo` at angle `angle` (radians).
    pub fn new(geo: &ConeBeam, angle: f64) -> Camera {
        let (s, c) = angle.sin_cos();
        let (w, h) = geo.image_size();
        let [dv, du] = geo.d_detector;
        Camera {
            angle,
            rot: [[-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]],
            centre: [geo.dso * c, geo.dso * s, 0.0],
            fx: geo.dsd / du,
            fy: geo.dsd / dv,
            cx: w as f64 / 2.0 - geo.off_detector[0] / du,
            cy: h as f64 / 2.0 - geo.off_detector[1] / dv,
            width: w,
            height: h,
            dsd: geo.dsd,
            pitch: geo.d_detector,
            mode: geo.mode,
        }
    }

    /// World point to camera coordinates t = R (p - c).
    #[inline]
    pub fn world_to_cam(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.centre[0],
            p[1] - self.centre[1],
            p[2] - self.centre[2],
        ];
        let r = &self.rot;
        [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ]
    }

    /// Camera-space direction to world-space direction (R^T d).
    #[inline]
    pub fn cam_dir_to_world(&self, d: [f64; 3]) -> [f64; 3] {
        let r = &self.rot;
        [
            r[0][0] * d[0] + r[1][0] * d[1] + r[2][0] * d[2],
            r[0][1] * d[0] + r[1][1] * d[1] + r[2][1] * d[2],
            r[0][2] * d[0] + r[1][2] * d[1] + r[2][2] * d[2],
        ]
    }

    /// Pixel coordinates (u along columns, v along rows; pixel (c, r) has its centre at
    /// (c + 0.5, r + 0.5)) of a camera-space point, for a cone beam: u = fx X/Z + cx.
    /// For a parallel beam: u = X / du + cx.
    #[inline]
    pub fn project_cam(&self, t: [f64; 3]) -> [f64; 2] {
        match self.mode {
            Mode::Cone => [
                self.fx * t[0] / t[2] + self.cx,
                self.fy * t[1] / t[2] + self.cy,
            ],
            Mode::Parallel => [
                t[0] / self.pitch[1] + self.cx,
                t[1] / self.pitch[0] + self.cy,
            ],
        }
    }

    /// The ray through the centre of pixel (column `col`, row `row`), as (origin, unit direction)
    /// in world coordinates. For a cone beam the origin is the source; for a parallel beam it is
    /// the point of the source plane (through the camera centre, normal to camera z) on the ray.
    pub fn pixel_ray(&self, col: f64, row: f64) -> ([f64; 3], [f64; 3]) {
        let x = (col + 0.5 - self.cx) / self.fx; // X/Z
        let y = (row + 0.5 - self.cy) / self.fy; // Y/Z
        match self.mode {
            Mode::Cone => {
                let n = (x * x + y * y + 1.0).sqrt();
                (self.centre, self.cam_dir_to_world([x / n, y / n, 1.0 / n]))
            }
            Mode::Parallel => {
                // In the parallel beam, fx * X/Z becomes X / du, so X = x * DSD.
                let off = self.cam_dir_to_world([x * self.dsd, y * self.dsd, 0.0]);
                let o = [
                    self.centre[0] + off[0],
                    self.centre[1] + off[1],
                    self.centre[2] + off[2],
                ];
                (o, self.cam_dir_to_world([0.0, 0.0, 1.0]))
            }
        }
    }
}

/// Voxel centre (i, j, k) in world coordinates (TIGRE / NAF convention).
pub fn voxel_centre(n: [usize; 3], d: [f64; 3], off: [f64; 3], ijk: [f64; 3]) -> [f64; 3] {
    let mut p = [0.0; 3];
    for a in 0..3 {
        p[a] = -(n[a] as f64) * d[a] / 2.0 + (ijk[a] + 0.5) * d[a] + off[a];
    }
    p
}

/// Per-view geometry checks: the source must lie outside the volume, and the detector plane
/// must not cut it (both cone beam only).
///
/// `box_` is the volume box `(lo, hi)` in world mm ([`ConeBeam::volume_box`]). `unispine drr`
/// and `unispine render` both call this, so they accept and refuse the same views with the
/// same message.
pub fn check_view(cam: &Camera, box_: ([f64; 3], [f64; 3])) -> Result<()> {
    let (lo, hi) = box_;
    let angle = cam.angle;
    if cam.mode != Mode::Cone {
        return Ok(());
    }
    let c = cam.centre;
    if (0..3).all(|a| c[a] >= lo[a] && c[a] <= hi[a]) {
        return Err(Error::Geometry(format!(
            "the source at ({:.3}, {:.3}, {:.3}) mm (view at {:.4} deg) lies inside the volume box \
             {}: increase DSO or move the volume (offOrigin)",
            c[0],
            c[1],
            c[2],
            angle.to_degrees(),
            box_mm(lo, hi)
        )));
    }
    for corner in 0..8 {
        let p = [
            if corner & 1 == 0 { lo[0] } else { hi[0] },
            if corner & 2 == 0 { lo[1] } else { hi[1] },
            if corner & 4 == 0 { lo[2] } else { hi[2] },
        ];
        let z = cam.world_to_cam(p)[2];
        if z > cam.dsd {
            return Err(Error::Geometry(format!(
                "the volume reaches {:.3} mm from the source along the axis but the detector is at \
                 DSD = {:.3} mm (view at {:.4} deg): the detector plane cuts the volume",
                z,
                cam.dsd,
                angle.to_degrees()
            )));
        }
    }
    Ok(())
}

/// A world box as errors print it: `[x0, x1] x [y0, y1] x [z0, z1] mm`, 3 decimals.
pub fn box_mm(lo: [f64; 3], hi: [f64; 3]) -> String {
    format!(
        "[{:.3}, {:.3}] x [{:.3}, {:.3}] x [{:.3}, {:.3}] mm",
        lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
    )
}

/// Allowed range of `accuracy` (the trilinear step in voxel sizes). Below 0.01 a ray takes
/// over 100 samples per voxel (hours for a normal volume); above 1 samples skip voxels and far
/// above it every ray misses the volume (all-zero projections).
pub const ACCURACY_RANGE: (f64, f64) = (0.01, 1.0);

/// Most detector pixels per axis (a 16384^2 f32 image is 1 GiB).
pub const MAX_DETECTOR: usize = 16384;

/// Most voxels per volume axis in a geometry.
pub const MAX_VOXELS_PER_AXIS: usize = 16384;

#[cfg(test)]
mod tests {
    use super::*;

    fn geo() -> ConeBeam {
        ConeBeam::centred([64, 80], [2.0, 1.5], [32, 32, 32], [1.0, 1.0, 1.0])
    }

    #[test]
    fn camera_axes_follow_naf_pose() {
        let cam = geo().camera(0.0);
        assert_eq!(cam.centre, [1000.0, 0.0, 0.0]);
        // The origin projects to the principal point.
        let t = cam.world_to_cam([0.0; 3]);
        assert!((t[2] - 1000.0).abs() < 1e-12);
        let uv = cam.project_cam(t);
        assert!((uv[0] - 40.0).abs() < 1e-12 && (uv[1] - 32.0).abs() < 1e-12);
        // +z in the world is up in the image (smaller row), +y is to the right at theta = 0.
        let up = cam.project_cam(cam.world_to_cam([0.0, 0.0, 10.0]));
        assert!(up[1] < 32.0);
        let right = cam.project_cam(cam.world_to_cam([0.0, 10.0, 0.0]));
        assert!(right[0] > 40.0);
        // focal = DSD / pitch
        assert!((cam.fx - 1000.0).abs() < 1e-12 && (cam.fy - 750.0).abs() < 1e-12);
    }

    #[test]
    fn pixel_ray_hits_its_pixel() {
        let mut g = geo();
        g.off_detector = [3.0, -5.0];
        for mode in [Mode::Cone, Mode::Parallel] {
            g.mode = mode;
            let cam = g.camera(0.7);
            let (o, d) = cam.pixel_ray(10.0, 20.0);
            let p = [
                o[0] + 900.0 * d[0],
                o[1] + 900.0 * d[1],
                o[2] + 900.0 * d[2],
            ];
            let uv = cam.project_cam(cam.world_to_cam(p));
            assert!(
                (uv[0] - 10.5).abs() < 1e-9 && (uv[1] - 20.5).abs() < 1e-9,
                "{mode:?} {uv:?}"
            );
        }
    }

    #[test]
    fn geometry_json_uses_tigre_names() {
        let g = geo();
        let s = serde_json::to_string(&g).unwrap();
        assert!(
            s.contains("\"DSD\"") && s.contains("\"nDetector\"") && s.contains("\"offOrigin\"")
        );
        let back: ConeBeam = serde_json::from_str(&s).unwrap();
        assert_eq!(back, g);
    }

    #[test]
    fn validate_names_the_field() {
        let mut g = geo();
        g.d_voxel[1] = f64::NAN;
        let e = g.validate().unwrap_err().to_string();
        assert!(e.contains("dVoxel[1]"), "{e}");
    }

    #[test]
    fn read_json_fills_the_grid_and_names_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g.json");
        let base =
            r#"{"DSD": 1500.0, "DSO": 1000.0, "nDetector": [64, 80], "dDetector": [2.0, 1.5]"#;
        std::fs::write(&p, format!("{base}}}")).unwrap();
        let grid = VoxelGrid {
            n_voxel: [32, 32, 32],
            d_voxel: [1.0; 3],
            off_origin: [0.0; 3],
        };
        assert_eq!(read_json(&p, Some(&grid)).unwrap(), geo());
        // Without a grid the volume fields are required.
        let e = read_json(&p, None).unwrap_err().to_string();
        assert!(e.contains("g.json") && e.contains("nVoxel"), "{e}");
        // Given fields win over the grid.
        std::fs::write(&p, format!(r#"{base}, "nVoxel": [8, 8, 8]}}"#)).unwrap();
        assert_eq!(read_json(&p, Some(&grid)).unwrap().n_voxel, [8, 8, 8]);
        // A bad field: the file and the field are named.
        std::fs::write(&p, base.replace("1500.0", "-1.0") + "}").unwrap();
        let e = read_json(&p, Some(&grid)).unwrap_err().to_string();
        assert!(e.contains("g.json") && e.contains("DSD"), "{e}");
        for (text, needle) in [("[1, 2]", "JSON object"), ("{", "not valid JSON")] {
            std::fs::write(&p, text).unwrap();
            let e = read_json(&p, Some(&grid)).unwrap_err().to_string();
            assert!(e.contains("g.json") && e.contains(needle), "{e}");
        }
        let e = read_json(&dir.path().join("missing.json"), None).unwrap_err();
        assert!(e.to_string().contains("missing.json"), "{e}");
    }
}
