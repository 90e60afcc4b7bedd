//! Dataset generation with the paper's protocol (UniSpine-GS §4 / its `tools/convert_*` code).
//!
//! Protocol (defaults): 50 training views every 3.6 deg over [0, 180) deg
//! (`theta_k = k * span / n_train`, NAF's `linspace(0, span, n + 1)[:-1]`) and 50 test views at
//! the midpoints (`theta_k = (k + 1/2) * span / n_test`, i.e. 1.8 + 3.6 k deg: UniSpine-GS's
//! converters; NAF / SAX-NeRF draw random validation angles instead). DSD = 1500 mm,
//! DSO = 1000 mm (every SAX-NeRF / UniSpine-GS config), cone beam, exact Siddon line integrals
//! (TIGRE `Ax`'s default projector), no noise, a square 256 x 256 detector (the paper uses
//! 1024 x 1024 at 1 mm; 256 keeps the CPU schedule tractable).
//!
//! Detector pitch (square pixels, both axes the same, except below): the detector is made just large enough
//! to hold the projection of the volume's bounding box at every angle of a full turn, plus a
//! margin. With R the radius of the smallest z-axis cylinder around the box (the largest
//! distance of a box corner from the rotation axis, offOrigin included) and Z the largest
//! |z| of the box:
//!
//! - cone beam: a point at distance r <= R from the axis projects at most
//!   `u_max = DSD * R / sqrt(DSO^2 - R^2)` from the centre column (the ray tangent to the
//!   cylinder), and at most `v_max = DSD * Z / (DSO - R)` from the centre row (the nearest
//!   point of the cylinder, top or bottom face);
//! - parallel beam: `u_max = R`, `v_max = Z`.
//!
//! `pitch = 2 * max(u_max, v_max) * (1 + margin) / n_detector`, margin 5 % by default. When
//! the volume's projection is thinner than one such pixel in v (`2 v_max < pitch`: a 2-D
//! slice, one voxel in z), the rows get their own pitch `2 v_max (1 + margin) / n_detector`
//! so that every row sees the slice (with square pixels it fell between the two central rows
//! of an even detector, and only the central row of an odd one saw it). The
//! bound is conservative (tight for a cylinder); `tests` check it by projecting the eight box
//! corners at many angles. A volume that reaches the source (R >= DSO) is a geometry error.
//!
//! Noise (off by default) is applied by [`add_noise`], described in [`super::noise`].

use super::{Dataset, Manifest, Split};
use crate::drr::{self, Method};
use crate::error::{Error, Result};
use crate::geometry::{ConeBeam, Mode};
use crate::image2d::Image2d;
use crate::volume::Volume;

pub use super::noise::{add_noise, Noise};

/// Settings of [`generate`]. `Default` is the paper's protocol.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GenerateOptions {
    /// Training views, evenly spaced over `span_deg` starting at `start_deg`.
    pub train_views: usize,
    /// Test views, at the midpoints `(k + 1/2) * span / test_views`.
    pub test_views: usize,
    /// Angular span of the orbit, degrees (180 in the paper).
    pub span_deg: f64,
    /// First training angle, degrees.
    pub start_deg: f64,
    /// Detector pixels per side (square detector).
    pub detector: usize,
    /// Extra detector coverage around the volume's projection (0.05 = 5 %).
    pub margin: f64,
    /// Source-detector distance, mm.
    pub dsd: f64,
    /// Source-origin distance, mm.
    pub dso: f64,
    /// Cone or parallel beam.
    pub mode: Mode,
    /// Projector.
    pub projector: Method,
    /// Trilinear ray-march step in voxels (TIGRE `accuracy`).
    pub accuracy: f64,
    /// Noise model.
    pub noise: Noise,
    /// Seed of the noise.
    pub seed: u64,
    /// Unit of the volume values (for the manifest), e.g. "1/mm" or "normalised [0, 1]".
    pub volume_units: String,
    /// How the volume values were produced (for the manifest).
    pub volume_normalisation: String,
}

impl Default for GenerateOptions {
    fn default() -> Self {
        GenerateOptions {
            train_views: 50,
            test_views: 50,
            span_deg: 180.0,
            start_deg: 0.0,
            detector: 256,
            margin: 0.05,
            dsd: crate::geometry::DSD_MM,
            dso: crate::geometry::DSO_MM,
            mode: Mode::Cone,
            projector: Method::Siddon,
            accuracy: 0.5,
            noise: Noise::None,
            seed: 0,
            volume_units: "volume value".into(),
            volume_normalisation: "as given".into(),
        }
    }
}

/// Most views per split (training or test).
pub const MAX_VIEWS: usize = 100_000;

/// Most bytes of projections (f32) a dataset may hold: (training + test views) x detector^2 x 4
/// (the projector's own bound).
pub use crate::drr::MAX_PROJECTION_BYTES;

impl GenerateOptions {
    /// Error naming the option when it cannot give a dataset (each bound with its allowed
    /// range).
    pub fn validate(&self) -> Result<()> {
        for (name, n) in [
            ("train_views", self.train_views),
            ("test_views", self.test_views),
        ] {
            if n > MAX_VIEWS {
                return Err(Error::invalid(
                    name,
                    format!("{n} views is outside the allowed range [1, {MAX_VIEWS}]"),
                ));
            }
        }
        if self.train_views == 0 {
            return Err(Error::invalid(
                "train_views",
                "zero training views: at least one is needed",
            ));
        }
        if self.test_views == 0 {
            return Err(Error::invalid(
                "test_views",
                "zero test views: at least one is needed",
            ));
        }
        if !(self.span_deg.is_finite() && self.span_deg > 0.0 && self.span_deg <= 360.0) {
            return Err(Error::invalid(
                "span_deg",
                format!("must be in (0, 360], got {}", self.span_deg),
            ));
        }
        if !self.start_deg.is_finite() {
            return Err(Error::invalid("start_deg", "must be finite"));
        }
        if self.detector == 0 || self.detector > 8192 {
            return Err(Error::invalid(
                "detector",
                format!("must be 1..=8192 pixels, got {}", self.detector),
            ));
        }
        let bytes = (self.train_views + self.test_views) as u64 * (self.detector as u64).pow(2) * 4;
        if bytes > MAX_PROJECTION_BYTES {
            return Err(Error::invalid(
                "detector",
                format!(
                    "{0} x {0} pixels for {1} views is {bytes} bytes of f32 projections, above \
                     the allowed {MAX_PROJECTION_BYTES} (8 GiB): use fewer views or a smaller \
                     detector",
                    self.detector,
                    self.train_views + self.test_views
                ),
            ));
        }
        if !(self.margin.is_finite() && self.margin >= 0.0) {
            return Err(Error::invalid(
                "margin",
                format!("must be finite and >= 0, got {}", self.margin),
            ));
        }
        if !(self.dso.is_finite() && self.dso > 0.0) {
            return Err(Error::invalid(
                "DSO",
                format!("must be > 0, got {}", self.dso),
            ));
        }
        if !(self.dsd.is_finite() && self.dsd >= self.dso) {
            return Err(Error::invalid(
                "DSD",
                format!("must be finite and >= DSO ({}), got {}", self.dso, self.dsd),
            ));
        }
        if !(self.accuracy.is_finite() && self.accuracy > 0.0) {
            return Err(Error::invalid("accuracy", "must be > 0"));
        }
        Ok(())
    }
}

/// Training and test angles (radians) of the protocol: `k * span / n_train` and
/// `(k + 1/2) * span / n_test`, both offset by `start_deg`.
pub fn protocol_angles(opts: &GenerateOptions) -> (Vec<f64>, Vec<f64>) {
    let at = |k: f64, n: usize| (opts.start_deg + k * opts.span_deg / n as f64).to_radians();
    let train = (0..opts.train_views)
        .map(|k| at(k as f64, opts.train_views))
        .collect();
    let test = (0..opts.test_views)
        .map(|k| at(k as f64 + 0.5, opts.test_views))
        .collect();
    (train, test)
}

/// Half-extents `(u_max, v_max)` in mm, on the detector, of the projection of the box of
/// `vol` over a full turn (see the module header).
pub fn projection_half_extent(vol: &Volume<f32>, opts: &GenerateOptions) -> Result<(f64, f64)> {
    let (lo, hi) = vol.bounds();
    let mut r2: f64 = 0.0;
    for x in [lo[0], hi[0]] {
        for y in [lo[1], hi[1]] {
            r2 = r2.max(x * x + y * y);
        }
    }
    let r = r2.sqrt();
    let z = lo[2].abs().max(hi[2].abs());
    match opts.mode {
        Mode::Parallel => Ok((r, z)),
        Mode::Cone => {
            if r >= opts.dso {
                return Err(Error::Geometry(format!(
                    "the volume reaches {r:.1} mm from the rotation axis but the source orbits at \
                     DSO = {} mm: the source would pass through the volume",
                    opts.dso
                )));
            }
            Ok((
                opts.dsd * r / (opts.dso * opts.dso - r * r).sqrt(),
                opts.dsd * z / (opts.dso - r),
            ))
        }
    }
}

/// The scanner geometry for `vol` with `opts`: TIGRE fields from the volume's grid and a
/// square detector whose pitch covers the volume's projection (see the module header).
pub fn geometry_for(vol: &Volume<f32>, opts: &GenerateOptions) -> Result<ConeBeam> {
    opts.validate()?;
    let (u, v) = projection_half_extent(vol, opts)?;
    let pitch = 2.0 * u.max(v) * (1.0 + opts.margin) / opts.detector as f64;
    // A volume whose projection is thinner than one square pixel in v (a 2-D slice, one voxel
    // in z): rows of their own pitch cover it, else it falls between two row centres (an even
    // detector: no ray hits it) or only the central row sees it (an odd one).
    let pitch_v = if 2.0 * v < pitch {
        2.0 * v * (1.0 + opts.margin) / opts.detector as f64
    } else {
        pitch
    };
    let geo = ConeBeam {
        dsd: opts.dsd,
        dso: opts.dso,
        n_detector: [opts.detector, opts.detector],
        d_detector: [pitch_v, pitch],
        n_voxel: vol.dims,
        d_voxel: vol.spacing,
        off_origin: vol.offset,
        off_detector: [0.0, 0.0],
        mode: opts.mode,
        accuracy: opts.accuracy,
    };
    geo.validate()?;
    Ok(geo)
}

/// Project `vol` with the protocol of `opts`. `progress(done, total)` is called after each
/// view (training views first, then test views).
pub fn generate(
    vol: &Volume<f32>,
    opts: &GenerateOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Dataset> {
    opts.validate()?;
    if vol.is_empty() || vol.data.len() != vol.dims.iter().product::<usize>() {
        return Err(Error::invalid(
            "volume",
            format!("{} values for dims {:?}", vol.data.len(), vol.dims),
        ));
    }
    vol.check_finite("volume")?;
    let geometry = geometry_for(vol, opts)?;
    let (train_angles, test_angles) = protocol_angles(opts);
    let total = train_angles.len() + test_angles.len();
    let n_train = train_angles.len();
    let train = drr::project_views(vol, &geometry, &train_angles, opts.projector, &|k| {
        progress(k, total)
    })?;
    let test = drr::project_views(vol, &geometry, &test_angles, opts.projector, &|k| {
        progress(n_train + k, total)
    })?;
    let mut views: Vec<Image2d<f32>> = train.into_iter().chain(test).collect();
    add_noise(&mut views, &opts.noise, opts.seed);
    let test: Vec<Image2d<f32>> = views.split_off(n_train);

    let (u, v) = projection_half_extent(vol, opts)?;
    let mut extra = serde_json::Map::new();
    extra.insert(
        "generator".into(),
        serde_json::to_value(opts).unwrap_or_default(),
    );
    extra.insert(
        "projection_half_extent_mm".into(),
        serde_json::json!({ "u": u, "v": v }),
    );
    extra.insert(
        "trainer_normalisation".into(),
        "per-view min-max to [0, 1] at load time (UniSpine-GS / X-Gaussian scene/cameras.py); \
         the stored values are not normalised"
            .into(),
    );
    let manifest = Manifest {
        projection_units: format!("mm x ({}) (line integrals)", opts.volume_units),
        volume_normalisation: opts.volume_normalisation.clone(),
        provenance: vol.provenance.clone(),
        projector: match opts.projector {
            Method::Siddon => "siddon".into(),
            Method::Trilinear => format!("trilinear (step {} voxel)", opts.accuracy),
        },
        noise: opts.noise.describe(),
        extra,
        pose_noise: None,
    };
    let ds = Dataset {
        geometry,
        train: Split {
            angles: train_angles,
            projections: views,
        },
        test: Split {
            angles: test_angles,
            projections: test,
        },
        manifest,
        volume: Some(vol.clone()),
    };
    super::store::check(&ds)?;
    Ok(ds)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vol(dims: [usize; 3], spacing: [f64; 3], offset: [f64; 3]) -> Volume<f32> {
        let mut v = Volume::<f32>::zeros(dims, spacing);
        v.offset = offset;
        v
    }

    #[test]
    fn paper_protocol_angles() {
        let (tr, te) = protocol_angles(&GenerateOptions::default());
        assert_eq!((tr.len(), te.len()), (50, 50));
        for k in 0..50 {
            assert!((tr[k].to_degrees() - 3.6 * k as f64).abs() < 1e-12, "{k}");
            assert!(
                (te[k].to_degrees() - (1.8 + 3.6 * k as f64)).abs() < 1e-12,
                "{k}"
            );
        }
        assert!(tr[49].to_degrees() < 180.0);
    }

    /// The pitch formula against the camera model: every box corner, at every angle of a full
    /// turn, lands on the detector inside the margin, and the tightest angle uses most of it.
    #[test]
    fn detector_covers_the_box_projection() {
        for mode in [Mode::Cone, Mode::Parallel] {
            for (dims, sp, off) in [
                ([64, 64, 64], [1.0; 3], [0.0; 3]),
                ([100, 60, 150], [0.7, 0.7, 2.5], [5.0, -12.0, 30.0]),
                ([32, 32, 8], [8.0, 8.0, 1.0], [0.0; 3]),
            ] {
                let v = vol(dims, sp, off);
                let opts = GenerateOptions {
                    mode,
                    detector: 128,
                    ..Default::default()
                };
                let geo = geometry_for(&v, &opts).unwrap();
                let (lo, hi) = v.bounds();
                let mut worst: f64 = 0.0;
                for a in 0..720 {
                    let cam = geo.camera((a as f64 * 0.5).to_radians());
                    for c in 0..8 {
                        let p = [
                            if c & 1 == 0 { lo[0] } else { hi[0] },
                            if c & 2 == 0 { lo[1] } else { hi[1] },
                            if c & 4 == 0 { lo[2] } else { hi[2] },
                        ];
                        let uv = cam.project_cam(cam.world_to_cam(p));
                        // Distance from the detector centre in units of the half width.
                        let du = (uv[0] - 64.0).abs() / 64.0;
                        let dv = (uv[1] - 64.0).abs() / 64.0;
                        worst = worst.max(du).max(dv);
                    }
                }
                assert!(worst <= 1.0 / 1.05 + 1e-9, "{mode:?} {dims:?}: {worst}");
                // Corners of a box are inside the circumscribed cylinder; the bound is tight
                // up to that: the corners reach at least 80 % of it here.
                assert!(worst > 0.8 / 1.05, "{mode:?} {dims:?}: {worst}");
            }
        }
    }

    #[test]
    fn source_inside_the_volume_is_a_geometry_error() {
        let v = vol([100, 100, 10], [25.0, 25.0, 1.0], [0.0; 3]);
        let e = geometry_for(&v, &GenerateOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("DSO"), "{e}");
    }

    #[test]
    fn options_are_checked() {
        for (o, field) in [
            (
                GenerateOptions {
                    test_views: 0,
                    ..Default::default()
                },
                "test_views",
            ),
            (
                GenerateOptions {
                    train_views: 0,
                    ..Default::default()
                },
                "train_views",
            ),
            (
                GenerateOptions {
                    span_deg: f64::NAN,
                    ..Default::default()
                },
                "span_deg",
            ),
            (
                GenerateOptions {
                    detector: 0,
                    ..Default::default()
                },
                "detector",
            ),
            (
                GenerateOptions {
                    dsd: 900.0,
                    ..Default::default()
                },
                "DSD",
            ),
        ] {
            let e = o.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
    }
}
