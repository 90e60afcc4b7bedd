//! Digitally reconstructed radiographs: line integrals of a volume along the rays of a
//! [`crate::geometry::Camera`], exact (Siddon) or sampled (trilinear ray-march).
//!
//! Conventions (shared by both projectors):
//! - The rays are those of [`crate::geometry::Camera::pixel_ray`]: from the source through each
//!   detector pixel centre (cone beam), or parallel to the camera axis through the same detector
//!   coordinates (parallel beam). Detector offsets are honoured there.
//! - The voxel grid is placed by the volume's `spacing` and `offset` (TIGRE / NAF placement:
//!   voxel (i, j, k) fills the box `lo + [i, i+1] x dX, ...` with `lo = offset - size / 2`).
//! - Cone beam: the integral runs over the half-line beyond the source (the detector must not cut
//!   the volume, checked). Parallel beam: over the whole line, so the source plane may cross the
//!   volume.
//! - The result is `sum(length in mm x voxel value)`: no exp, no I0, no log (NAF / X-Gaussian
//!   targets).
//! - Each pixel is computed by one sequential loop that depends only on its own ray; bands of rows
//!   are distributed over threads and written in place, so the image is bit-identical for any
//!   thread count. Within a band the pixels are visited tile by tile (neighbouring rays one after
//!   the other, so that their samples share cache lines); the visiting order changes no bit
//!   because no pixel reads another's result.
//! - For f32 volumes Siddon runs on vector lanes (AVX-512: 16 rays at once, AVX2: 8; chosen at
//!   run time, [`Projector::with_simd`]): each lane walks one ray with the per-ray loop's
//!   comparisons and IEEE operations in its order, so every instruction set gives the per-ray
//!   loop's bits ([`Simd::Scalar`] and f64 volumes run that loop). Trilinear's inner loop runs
//!   the same way, one ray per lane (8 lanes on AVX2; 16 or 8 on AVX-512, [`MarchLanes`]), the
//!   rest of each ray (its set-up and the zero-padded samples near the box faces) per ray, so
//!   it too gives the per-ray loop's bits on every path.
//!
//! [`MarchLanes`]: crate::drr::MarchLanes
//! [`Projector::with_simd`]: crate::drr::Projector::with_simd
//! [`Simd::Scalar`]: crate::simd::Simd::Scalar

pub(crate) mod grid;
mod lane_bands;
mod lanes;
mod padded_lanes;
mod schedule;
pub mod siddon;
mod siddon_lanes;
pub mod trilinear;
mod trilinear_lanes;

pub use grid::GRID_REL_TOL;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::ConeBeam;
use crate::image2d::Image2d;
use crate::real::Real;
use crate::simd::Simd;
use crate::volume::Volume;
use grid::{check_finite_par, check_grid, lanes_f32, Grid};
use lane_bands::{siddon_band, trilinear_band};
use schedule::{cols_inner, for_each_pixel, BAND, TILE};

/// Most bytes of projections (f32) one call may produce, and a dataset may hold: views x
/// detector pixels x 4 (8 GiB).
pub const MAX_PROJECTION_BYTES: u64 = 8 << 30;

/// Projector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Exact line integrals through the voxel grid (piecewise-constant volume).
    #[default]
    Siddon,
    /// Trilinear ray-march with step `accuracy` x voxel (TIGRE 'interpolated').
    Trilinear,
}

/// Line integrals (mm x volume value) of `vol` for the view at `angle` (radians) of `geo`.
/// The volume is placed by its own `spacing` and `offset`; `geo`'s `nVoxel`/`dVoxel`/`offOrigin`
/// must describe the same grid (checked).
pub fn project<R: Real>(
    vol: &Volume<R>,
    geo: &ConeBeam,
    angle: f64,
    method: Method,
) -> Result<Image2d<R>> {
    Projector::new(vol, geo, method)?.view(angle)
}

/// [`project`] for several angles; `progress(done)` is called after each view.
pub fn project_views<R: Real>(
    vol: &Volume<R>,
    geo: &ConeBeam,
    angles: &[f64],
    method: Method,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<Image2d<R>>> {
    let p = Projector::new(vol, geo, method)?;
    let bytes = angles.len() as u64
        * geo.n_detector[0] as u64
        * geo.n_detector[1] as u64
        * std::mem::size_of::<R>() as u64;
    if bytes > MAX_PROJECTION_BYTES {
        return Err(Error::invalid(
            "angles",
            format!(
                "{} views of {} x {} pixels is {bytes} bytes of projections, above the allowed \
                 {} (8 GiB): use fewer angles or a smaller nDetector",
                angles.len(),
                geo.n_detector[0],
                geo.n_detector[1],
                MAX_PROJECTION_BYTES
            ),
        ));
    }
    let mut out = Vec::with_capacity(angles.len());
    for (k, &a) in angles.iter().enumerate() {
        out.push(p.view(a)?);
        progress(k + 1);
    }
    Ok(out)
}

/// A volume and a geometry checked once, projected for any number of angles.
pub struct Projector<'a, R: Real> {
    pub(crate) grid: Grid<'a, R>,
    geo: &'a ConeBeam,
    method: Method,
    simd: Simd,
    march: MarchLanes,
}

/// Lanes of the trilinear ray-march on the AVX-512 path (the AVX2 path runs 8; the scalar path
/// the per-ray loop). Every choice gives the same bits; only the speed differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MarchLanes {
    /// 8 lanes (AVX2's operations with AVX-512's unsigned conversion), tiles of 4 x 2 rays.
    Eight,
    /// 16 lanes, tiles of 8 x 2 rays.
    Sixteen,
}

impl MarchLanes {
    /// The faster choice as measured on the CPU kind: 8 where 512-bit operations run as two
    /// halves (AMD Zen 4: 16 lanes were slower there), 16 elsewhere (AMD Zen 5: lateral view
    /// 0.060-0.062 -> 0.047 s per 256^2 view of the example CT, see `docs/measurements.md`;
    /// other CPUs with AVX-512 were not measured).
    pub fn for_this_cpu() -> MarchLanes {
        if crate::simd::splits_512_bit() {
            MarchLanes::Eight
        } else {
            MarchLanes::Sixteen
        }
    }

    /// The number of lanes.
    pub fn count(self) -> usize {
        match self {
            MarchLanes::Eight => 8,
            MarchLanes::Sixteen => 16,
        }
    }
}

impl<'a, R: Real> Projector<'a, R> {
    /// Check the geometry (every field), that it describes the volume's grid, and that every
    /// voxel is finite (the error names the first bad voxel).
    pub fn new(vol: &'a Volume<R>, geo: &'a ConeBeam, method: Method) -> Result<Self> {
        geo.validate()?;
        check_grid(vol, geo)?;
        check_finite_par(vol)?;
        Ok(Projector {
            grid: Grid::new(vol),
            geo,
            method,
            simd: Simd::active(),
            march: MarchLanes::for_this_cpu(),
        })
    }

    /// The same projector running the instruction set `simd` (or the widest supported narrower
    /// one). Every path gives the same bits; [`Simd::Scalar`] runs the per-ray loops.
    pub fn with_simd(mut self, simd: Simd) -> Self {
        self.simd = simd.or_narrower();
        self
    }

    /// The instruction set the projector runs.
    pub fn simd(&self) -> Simd {
        self.simd
    }

    /// The same projector running the trilinear march on `lanes` on the AVX-512 path (default
    /// [`MarchLanes::for_this_cpu`]); no effect on the other paths. The same bits either way.
    pub fn with_march_lanes(mut self, lanes: MarchLanes) -> Self {
        self.march = lanes;
        self
    }

    /// The lanes of the trilinear march: 16 or 8 on the AVX-512 path, 8 on AVX2, 1 on the
    /// scalar path (the per-ray loop).
    pub fn march_lanes(&self) -> usize {
        match self.simd {
            Simd::Avx512 => self.march.count(),
            Simd::Avx2 => 8,
            Simd::Scalar => 1,
        }
    }

    /// The projection at `angle` (radians).
    pub fn view(&self, angle: f64) -> Result<Image2d<R>> {
        if !angle.is_finite() {
            return Err(Error::invalid(
                "angle",
                format!("must be finite, got {angle}"),
            ));
        }
        let cam = self.geo.camera(angle);
        crate::geometry::check_view(&cam, (self.grid.lo, self.grid.hi))?;
        let (w, h) = (cam.width, cam.height);
        let mut data = vec![R::zero(); w * h];
        let setup = trilinear::Setup::new(&self.grid, self.geo.accuracy);
        let cols_inner = cols_inner(&self.grid, &cam);
        let hits: Vec<usize> = data
            .par_chunks_mut(w * BAND)
            .enumerate()
            .map(|(b, out)| match self.method {
                Method::Siddon => {
                    if let Some((grid, out)) = lanes_f32(self.simd, &self.grid, out) {
                        return siddon_band(self.simd, &grid, &cam, out, w, b * BAND, cols_inner);
                    }
                    for_each_pixel(out, w, b * BAND, TILE, cols_inner, |col, row| {
                        siddon::pixel(&self.grid, &cam, col, row)
                    })
                }
                Method::Trilinear => {
                    if let Some((grid, out)) = lanes_f32(self.simd, &self.grid, out) {
                        let band = (out, w, b * BAND);
                        return trilinear_band(self.simd, self.march, &grid, &setup, &cam, band);
                    }
                    for_each_pixel(out, w, b * BAND, TILE, cols_inner, |col, row| {
                        trilinear::pixel(&self.grid, &setup, &cam, col, row)
                    })
                }
            })
            .collect();
        if hits.iter().sum::<usize>() == 0 {
            let (lo, hi) = (self.grid.lo, self.grid.hi);
            return Err(Error::Geometry(format!(
                "no ray of the view at {:.4} deg hits the volume box {} (check DSO, DSD, nDetector, \
                 dDetector, offDetector, offOrigin)",
                angle.to_degrees(),
                crate::geometry::box_mm(lo, hi)
            )));
        }
        Ok(Image2d::from_vec(w, h, data))
    }
}
