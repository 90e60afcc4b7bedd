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

pub mod bench;
mod lanes;
mod padded_lanes;
pub mod siddon;
mod siddon_lanes;
pub mod trilinear;
mod trilinear_lanes;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::{Camera, ConeBeam, Mode};
use crate::image2d::Image2d;
use crate::real::Real;
use crate::simd::Simd;
use crate::volume::Volume;

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

/// Relative tolerance when comparing the geometry's `dVoxel` / `offOrigin` with the volume's
/// `spacing` / `offset` (the two usually come from different files, one of them JSON text).
pub const GRID_REL_TOL: f64 = 1e-6;

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
    if bytes > crate::dataset::generate::MAX_PROJECTION_BYTES {
        return Err(Error::invalid(
            "angles",
            format!(
                "{} views of {} x {} pixels is {bytes} bytes of projections, above the allowed \
                 {} (8 GiB): use fewer angles or a smaller nDetector",
                angles.len(),
                geo.n_detector[0],
                geo.n_detector[1],
                crate::dataset::generate::MAX_PROJECTION_BYTES
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
    grid: Grid<'a, R>,
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

/// Whether to visit the pixels of a tile row by row (columns inner) rather than column by
/// column: the detector axis along which neighbouring rays share more cache lines goes inner.
/// This only orders the work (speed); the pixel values do not depend on it.
fn cols_inner<R: Real>(grid: &Grid<R>, cam: &Camera) -> bool {
    // Cache lines (16 f32 values along x, one along y or z) crossed per pixel step along a
    // detector axis with world direction `e` and pitch `p` (magnification ignored: it scales
    // both axes alike).
    let lines = |e: [f64; 3], p: f64| {
        (e[0] * p / grid.s[0]).abs() / 16.0
            + (e[1] * p / grid.s[1]).abs()
            + (e[2] * p / grid.s[2]).abs()
    };
    lines(cam.rot[0], cam.pitch[1]) <= lines(cam.rot[1], cam.pitch[0])
}

/// The grid and output band as f32 when the vector kernels can run them: an f32 volume of fewer
/// than 2^31 voxels (i32 lane indices) and a vector path.
fn lanes_f32<'g, 'o, R: Real>(
    simd: Simd,
    grid: &Grid<'g, R>,
    out: &'o mut [R],
) -> Option<(Grid<'g, f32>, &'o mut [f32])> {
    let data = lane_data(simd, grid.data)?;
    // SAFETY: R is f32 (`lane_data` checked it): same size, alignment and bits.
    let out = unsafe { std::slice::from_raw_parts_mut(out.as_mut_ptr().cast::<f32>(), out.len()) };
    Some((
        Grid {
            data,
            n: grid.n,
            s: grid.s,
            lo: grid.lo,
            hi: grid.hi,
        },
        out,
    ))
}

/// The voxel values as f32 when the vector kernels can run them: `simd` is a vector path, the
/// values are f32 and fewer than 2^31 (i32 lane indices).
fn lane_data<R: Real>(simd: Simd, data: &[R]) -> Option<&[f32]> {
    if simd == Simd::Scalar
        || std::any::TypeId::of::<R>() != std::any::TypeId::of::<f32>()
        || data.len() >= 1 << 31
    {
        return None;
    }
    // SAFETY: R is f32 (checked above): same size, alignment and bits.
    Some(unsafe { std::slice::from_raw_parts(data.as_ptr().cast::<f32>(), data.len()) })
}

/// The pixels of a band of `rows` rows of `w` pixels as `(col, row in band)`, tile by tile in
/// the order of [`for_each_pixel`].
fn tile_order(
    w: usize,
    rows: usize,
    tile: usize,
    cols_inner: bool,
) -> impl Iterator<Item = (usize, usize)> {
    (0..w)
        .step_by(tile)
        .flat_map(move |c0| tile_pixels(c0, (c0 + tile).min(w) - c0, rows, cols_inner))
}

/// The pixels of the tile of columns `c0..c0 + tw` of a band of `rows` rows as `(col, row in
/// band)`, in the order of [`for_each_pixel`].
fn tile_pixels(
    c0: usize,
    tw: usize,
    rows: usize,
    cols_inner: bool,
) -> impl Iterator<Item = (usize, usize)> {
    (0..tw * rows).map(move |k| {
        if cols_inner {
            (c0 + k % tw, k / tw)
        } else {
            (c0 + k / rows, k % rows)
        }
    })
}

/// Siddon on the vector lanes of `simd` for the band `out` (first row `row0`); returns the
/// number of rays that met the box. Pixels whose ray misses the box keep their 0.
fn siddon_band(
    simd: Simd,
    grid: &Grid<f32>,
    cam: &Camera,
    out: &mut [f32],
    w: usize,
    row0: usize,
    cols_inner: bool,
) -> usize {
    let rows = out.len() / w;
    let mut hits = 0;
    let mut rays = tile_order(w, rows, TILE, cols_inner).filter_map(|(col, r)| {
        let (o, d) = cam.pixel_ray(col as f64, (row0 + r) as f64);
        let (t0, _) = clip_ray(cam, o, d, grid.lo, grid.hi)?;
        hits += 1;
        Some((r * w + col, siddon::start(grid, o, d, t0)))
    });
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `simd` is supported (`or_narrower`); the walks come from `siddon::start` on this
    // grid, which has fewer than 2^31 voxels; every slot `r * w + col` is in the band.
    unsafe {
        match simd {
            Simd::Avx512 => siddon_lanes::run_avx512(grid.data, &mut rays, out),
            Simd::Avx2 => siddon_lanes::run_avx2(grid.data, &mut rays, out),
            Simd::Scalar => unreachable!("the scalar path runs the per-ray loop"),
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("vector paths exist on x86-64 only");
    drop(rays);
    hits
}

/// The trilinear ray-march on the vector lanes of `simd` for the band `(out, w, row0)` (rows of
/// `w` pixels, the first one being `row0`); returns the number of rays that met the box. Tile by
/// tile of [`LANE_TILE`] rays, one ray per lane: each ray's set-up ([`trilinear::plan_runs`])
/// runs per ray, its zero-padded samples before and after its inner loop on the lanes of
/// [`padded_lanes`] (one run per lane), and its inner loop on those of [`trilinear_lanes`],
/// which start together on the tile and end with it; the pieces are added in the per-ray
/// loop's order ([`trilinear::finish_start`]).
fn trilinear_band(
    simd: Simd,
    march: MarchLanes,
    grid: &Grid<f32>,
    setup: &trilinear::Setup,
    cam: &Camera,
    (out, w, row0): (&mut [f32], usize, usize),
) -> usize {
    let rows = out.len() / w;
    let mut hits = 0;
    let wide = simd == Simd::Avx512 && march == MarchLanes::Sixteen;
    let (tile_rows, tile_cols) = if wide { LANE_TILE_16 } else { LANE_TILE };
    let mut plans = Vec::with_capacity(tile_rows * tile_cols);
    let mut inner = [0.0f32; lanes::MAXW];
    let (mut before, mut after) = ([0.0f32; lanes::MAXW], [0.0f32; lanes::MAXW]);
    let mut runs = Vec::with_capacity(lanes::MAXW);
    for r0 in (0..rows).step_by(tile_rows) {
        for c0 in (0..w).step_by(tile_cols) {
            plans.clear();
            for r in r0..(r0 + tile_rows).min(rows) {
                for col in c0..(c0 + tile_cols).min(w) {
                    let plan = trilinear::plan_runs(grid, setup, cam, col, row0 + r);
                    plans.push((r * w + col, plan));
                }
            }
            // The samples before the inner loops, from 0.
            let mut sums = [0.0f32; lanes::MAXW];
            padded_runs(
                simd,
                wide,
                grid,
                &plans,
                |p| p.before_run,
                &sums,
                &mut runs,
                &mut before,
            );
            for (k, (_, p)) in plans.iter_mut().enumerate() {
                p.before = if lane_run(p.before_run) {
                    before[k]
                } else {
                    trilinear::sum_padded(grid, p.q0, p.dq, p.before_run, 0.0)
                };
            }
            // Empty marches, and marches of 2^31 samples or more (a step far below the voxel
            // size), stay per ray.
            let lanes = |m: &trilinear::March| m.count > 0 && m.count < 1 << 31;
            let mut rays = plans
                .iter()
                .enumerate()
                .filter(|(_, (_, p))| lanes(&p.march))
                .map(|(k, (_, p))| (k, p.march));
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `simd` is supported (`or_narrower`); the grid has fewer than 2^31 voxels
            // (`lanes_f32`); every march comes from `trilinear::plan_runs` on this grid with a
            // count in [1, 2^31); every slot `k` is in `inner` (one per pixel of the tile).
            unsafe {
                match simd {
                    Simd::Avx512 if wide => {
                        trilinear_lanes::run_avx512_16(grid.data, grid.n, &mut rays, &mut inner)
                    }
                    Simd::Avx512 => {
                        trilinear_lanes::run_avx512(grid.data, grid.n, &mut rays, &mut inner)
                    }
                    Simd::Avx2 => {
                        trilinear_lanes::run_avx2(grid.data, grid.n, &mut rays, &mut inner)
                    }
                    Simd::Scalar => unreachable!("the scalar path runs the per-ray loop"),
                }
            }
            #[cfg(not(target_arch = "x86_64"))]
            unreachable!("vector paths exist on x86-64 only");
            drop(rays);
            // The sums up to the samples after the inner loops, then those samples.
            for (k, (_, p)) in plans.iter().enumerate() {
                let inner = if lanes(&p.march) {
                    inner[k]
                } else {
                    trilinear::march_scalar(grid, &p.march)
                };
                sums[k] = trilinear::finish_start(p, inner);
            }
            padded_runs(
                simd,
                wide,
                grid,
                &plans,
                |p| p.after,
                &sums,
                &mut runs,
                &mut after,
            );
            for (k, (slot, p)) in plans.iter().enumerate() {
                let sum = if lane_run(p.after) {
                    after[k]
                } else {
                    trilinear::sum_padded(grid, p.q0, p.dq, p.after, sums[k])
                };
                out[*slot] = trilinear::scale(p, sum);
                hits += p.hit as usize;
            }
        }
    }
    hits
}

/// Whether the lanes of [`padded_lanes`] take a run of samples `first..=last`: empty, or fewer
/// than 2^31 samples of index below 2^52 in magnitude (any real geometry's); the others are
/// summed per ray.
fn lane_run((first, last): (i64, i64)) -> bool {
    first > last || (first.abs() < 1 << 52 && last.abs() < 1 << 52 && last - first < (1 << 31) - 1)
}

/// `out[k]` = `init[k]` plus the zero-padded samples `run(plan k)` of the tile's plans, for
/// the runs that [`lane_run`] gives to the lanes of `simd` (`init[k]` for the others, which
/// are summed per ray): with `wide` (16 march lanes) on AVX-512's 8 lanes, else on AVX2's 4.
/// `runs` is scratch space.
#[allow(clippy::too_many_arguments)]
fn padded_runs(
    simd: Simd,
    wide: bool,
    grid: &Grid<f32>,
    plans: &[(usize, trilinear::Plan<f32>)],
    run: impl Fn(&trilinear::Plan<f32>) -> (i64, i64),
    init: &[f32],
    runs: &mut Vec<(usize, trilinear::Run)>,
    out: &mut [f32],
) {
    let n = plans.len();
    out[..n].copy_from_slice(&init[..n]);
    // The runs with samples (an empty run adds nothing).
    runs.clear();
    runs.extend(plans.iter().enumerate().filter_map(|(k, (_, p))| {
        let (first, last) = run(p);
        (lane_run((first, last)) && first <= last).then_some((
            k,
            trilinear::Run {
                q0: p.q0,
                dq: p.dq,
                first,
                last,
                acc: init[k],
            },
        ))
    }));
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `simd` is supported (`or_narrower`); the grid has fewer than 2^31 voxels
    // (`lanes_f32`); every run has from 1 to 2^31 - 1 samples of index below 2^52
    // (`lane_run`); every slot `k` is in `out` (one per plan).
    unsafe {
        match simd {
            Simd::Avx512 if wide => padded_lanes::sum_runs_avx512(grid.data, grid.n, runs, out),
            Simd::Avx512 | Simd::Avx2 => padded_lanes::sum_runs_avx2(grid.data, grid.n, runs, out),
            Simd::Scalar => unreachable!("the scalar path runs the per-ray loop"),
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("vector paths exist on x86-64 only");
}

/// A `dyn Iterator` as a sized one (the ray source is called once per ray, not per step).
struct DynIter<'a, T>(&'a mut dyn Iterator<Item = T>);

impl<T> Iterator for DynIter<'_, T> {
    type Item = T;
    fn next(&mut self) -> Option<T> {
        self.0.next()
    }
}

/// Image rows per parallel task. With a tile of `BAND` x `TILE` rays the voxels read by one tile
/// fit in a core's cache, whereas one whole row of rays crossing the volume along its fast axis
/// (the lateral view) reads a slab of about 2 MB that is gone before the next row reuses it.
/// Measured on the 512 x 512 x 133 CT: trilinear lateral view 0.70 -> 0.39 s CPU.
const BAND: usize = 8;
/// Columns per tile.
const TILE: usize = 32;
/// Rows and columns of detector pixels per tile of the trilinear lanes: as many rays as the
/// lanes (8), which start together on a tile and end with it. Neighbouring rays at the same
/// depth read the same cache lines; lanes that take the next ray as soon as theirs ends drift
/// apart in depth. The inner loop's time per sample on the example CT (one thread, cycles at
/// the machine's 3.66 GHz), against tiles of 8 x 8 pixels through which the lanes ran without
/// waiting for each other: AP view 8.3 against 10.5, lateral 11.5 against 12.4, 30 / 45 / 135 /
/// 200 deg 11.4 / 12.5 / 11.0 / 9.7 against 11.8 / 13.9 / 11.8 / 9.3; 2 x 4 tiles: AP 8.4,
/// lateral 12.6; 8 x 1: AP 15.2 (`bench drr`: 0.093 s against 0.052 s).
const LANE_TILE: (usize, usize) = (4, 2);
/// The same for 16 lanes ([`MarchLanes::Sixteen`]). On AMD Zen 5 (`bench drr`, cpu/thr, AP /
/// lateral): 8 x 2 0.039 / 0.050 s, 4 x 4 0.035 / 0.051 s (but 10-20 % slower than 8 lanes at
/// 30 and 135 deg, where 8 x 2 is within 5 %), 2 x 8 0.038 / 0.063 s, 16 x 1 1.4-1.8x slower at 0,
/// 30 and 90 deg. Tiles stack rows of the detector (v, along z in these views), whose neighbouring
/// rays share z planes in the lateral view.
const LANE_TILE_16: (usize, usize) = (8, 2);

/// Fill the band `out` (whole image rows, the first one being `row0`, `w` pixels each) with
/// `f(col, row) = (value, hit)` tile by tile: for each block of `tile` columns, row by row
/// (`cols_inner`) or column by column. Returns the number of hits. Each pixel is written once
/// from its own ray, so the order is free.
#[inline]
fn for_each_pixel<R: Real>(
    out: &mut [R],
    w: usize,
    row0: usize,
    tile: usize,
    cols_inner: bool,
    f: impl Fn(usize, usize) -> (R, bool),
) -> usize {
    let rows = out.len() / w;
    let mut hits = 0;
    for c0 in (0..w).step_by(tile) {
        let c1 = (c0 + tile).min(w);
        if cols_inner {
            for r in 0..rows {
                for col in c0..c1 {
                    let (v, hit) = f(col, row0 + r);
                    out[r * w + col] = v;
                    hits += hit as usize;
                }
            }
        } else {
            for col in c0..c1 {
                for r in 0..rows {
                    let (v, hit) = f(col, row0 + r);
                    out[r * w + col] = v;
                    hits += hit as usize;
                }
            }
        }
    }
    hits
}

/// The voxel grid as the ray-marchers see it.
pub(crate) struct Grid<'a, R: Real> {
    /// Voxel values, x fastest.
    pub data: &'a [R],
    /// Voxel counts `[x, y, z]`.
    pub n: [usize; 3],
    /// Voxel size `[x, y, z]`, mm.
    pub s: [f64; 3],
    /// Box corners (world, mm).
    pub lo: [f64; 3],
    pub hi: [f64; 3],
}

impl<'a, R: Real> Grid<'a, R> {
    fn new(vol: &'a Volume<R>) -> Self {
        let (lo, hi) = vol.bounds();
        Grid {
            data: &vol.data,
            n: vol.dims,
            s: vol.spacing,
            lo,
            hi,
        }
    }

    /// The grid of `data` with `n` voxels of 1 mm from the origin.
    #[cfg(test)]
    fn unit(data: &'a [R], n: [usize; 3]) -> Self {
        Grid {
            data,
            n,
            s: [1.0; 3],
            lo: [0.0; 3],
            hi: n.map(|v| v as f64),
        }
    }
}

/// Voxel counts in `1..=max` per axis and values for them: both signs, zeros of both signs and
/// tiny ones (products that underflow).
#[cfg(test)]
fn random_values<R: Real>(rng: &mut impl rand::Rng, max: usize) -> ([usize; 3], Vec<R>) {
    use rand::RngExt;
    let n = [0; 3].map(|_| rng.random_range(1..=max));
    let data = (0..n[0] * n[1] * n[2])
        .map(|_| match rng.random_range(0..6) {
            0 => R::c(0.0),
            1 => R::c(-0.0),
            2 => R::c(rng.random_range(-1e-38..1e-38)),
            _ => R::c(rng.random_range(-3.0..3.0)),
        })
        .collect();
    (n, data)
}

/// Parameter interval `(t_near, t_far)` of the line `o + t d` inside the box `[lo, hi]` (slab
/// test). The interval is empty when `t_far <= t_near`. For a direction component that is
/// exactly 0 the line is inside the slab when `lo <= o < hi` (half-open, as voxel indices are).
#[inline]
pub(crate) fn clip_line(o: [f64; 3], d: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> (f64, f64) {
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        if d[a] == 0.0 {
            if !(o[a] >= lo[a] && o[a] < hi[a]) {
                return (f64::INFINITY, f64::NEG_INFINITY);
            }
        } else {
            let inv = 1.0 / d[a];
            let (ta, tb) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
            let (ta, tb) = if ta <= tb { (ta, tb) } else { (tb, ta) };
            t0 = t0.max(ta);
            t1 = t1.min(tb);
        }
    }
    (t0, t1)
}

/// The part of the ray of `cam` (origin `o`, unit direction `d`) inside `[lo, hi]`: the whole
/// line for a parallel beam, the half-line beyond the source for a cone beam.
#[inline]
pub(crate) fn clip_ray(
    cam: &Camera,
    o: [f64; 3],
    d: [f64; 3],
    lo: [f64; 3],
    hi: [f64; 3],
) -> Option<(f64, f64)> {
    let (mut t0, t1) = clip_line(o, d, lo, hi);
    if cam.mode == Mode::Cone {
        t0 = t0.max(0.0);
    }
    (t1 > t0).then_some((t0, t1))
}

/// `geo`'s grid fields must describe `vol`'s grid.
fn check_grid<R: Real>(vol: &Volume<R>, geo: &ConeBeam) -> Result<()> {
    if geo.n_voxel != vol.dims {
        return Err(Error::invalid(
            "nVoxel",
            format!(
                "the geometry says {:?} but the volume has {:?} voxels [x, y, z]",
                geo.n_voxel, vol.dims
            ),
        ));
    }
    if vol.data.len() != vol.dims.iter().product::<usize>() {
        return Err(Error::invalid(
            "volume",
            format!("{} values for dims {:?}", vol.data.len(), vol.dims),
        ));
    }
    for a in 0..3 {
        let (g, v) = (geo.d_voxel[a], vol.spacing[a]);
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(
                format!("volume spacing[{a}]"),
                format!("must be finite and > 0, got {v}"),
            ));
        }
        if (g - v).abs() > GRID_REL_TOL * v {
            return Err(Error::invalid(
                format!("dVoxel[{a}]"),
                format!("the geometry says {g} mm but the volume's voxel size is {v} mm"),
            ));
        }
        let (g, v) = (geo.off_origin[a], vol.offset[a]);
        let scale = vol.dims[a] as f64 * vol.spacing[a];
        if !v.is_finite() || (g - v).abs() > GRID_REL_TOL * scale {
            return Err(Error::invalid(
                format!("offOrigin[{a}]"),
                format!("the geometry says {g} mm but the volume's offset is {v} mm"),
            ));
        }
    }
    Ok(())
}

/// Error naming the first NaN / infinite voxel; the scan is parallel over fixed chunks and the
/// first bad chunk is found in order, so the voxel named does not depend on the thread count.
fn check_finite_par<R: Real>(vol: &Volume<R>) -> Result<()> {
    const C: usize = 1 << 16;
    let bad = vol
        .data
        .par_chunks(C)
        .position_first(|c| c.iter().any(|v| !v.is_finite()));
    match bad {
        None => Ok(()),
        Some(_) => vol.check_finite("volume"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_line_slab() {
        let (t0, t1) = clip_line([-5.0, 0.5, 0.5], [1.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
        assert_eq!((t0, t1), (5.0, 6.0));
        // On the upper face (half-open): outside.
        let (t0, t1) = clip_line([-5.0, 1.0, 0.5], [1.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
        assert!(t1 <= t0);
        // On the lower face: inside.
        let (t0, t1) = clip_line([-5.0, 0.0, 0.5], [1.0, 0.0, 0.0], [0.0; 3], [1.0; 3]);
        assert!(t1 > t0);
    }
}
