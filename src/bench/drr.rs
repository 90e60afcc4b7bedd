//! DRR benchmark, printed by `unispine bench drr`: time per view of both projectors on every
//! instruction set, the per-ray loops ([`Simd::Scalar`], the implementation before the vector
//! kernels) measured in the same run as the reference of the ratios.
//!
//! - [`bench_geometry`]: the set-up of the DRR figures in `docs/measurements.md`: DSD 1500 mm,
//!   DSO 1000 mm, a square detector of `size` pixels as wide as the volume's shadow (665 mm for
//!   the 360 mm wide example CT);
//! - [`time_case`]: one projector, one view, one detector size: the first view (checks included)
//!   and the median of `reps` extra views through a checked [`Projector`], process CPU time and
//!   wall time, on each instruction set asked for; rays, voxel steps (Siddon) or samples
//!   (trilinear) of the view; the process's peak resident memory during one projection.

use std::time::Instant;

use super::median;
use crate::drr::grid::clip_ray;
use crate::drr::{siddon, trilinear, MarchLanes, Method, Projector};
use crate::error::Result;
use crate::geometry::ConeBeam;
use crate::real::Real;
use crate::simd::Simd;
use crate::volume::Volume;

/// Target of issue 11: seconds per 256^2 view through the full CT on 2 cores.
pub const TARGET_S: f64 = 0.05;

/// Detector width per mm of the volume's widest side: 665 mm for the example CT's 360 mm.
const DETECTOR_PER_EXTENT: f64 = 665.0 / 360.0;

/// Allowed ranges: detector sizes (pixels per side) and repetitions.
pub const BENCH_SIZES: (usize, usize) = (1, 4096);
pub const BENCH_REPS: (usize, usize) = (1, 1000);

/// The benchmark's cone beam for `vol` and a `size` x `size` detector.
pub fn bench_geometry<R: Real>(vol: &Volume<R>, size: usize) -> ConeBeam {
    let s = vol.size_mm();
    let pitch = DETECTOR_PER_EXTENT * s[0].max(s[1]).max(s[2]) / size as f64;
    ConeBeam {
        off_origin: vol.offset,
        ..ConeBeam::centred([size, size], [pitch, pitch], vol.dims, vol.spacing)
    }
}

/// Times of one instruction set.
#[derive(Clone, Debug)]
pub struct PathTiming {
    pub simd: Simd,
    /// The trilinear march's lanes ([`Projector::march_lanes`]).
    pub march_lanes: usize,
    /// First view: projector checks (every voxel finite) and one view; wall and CPU seconds.
    pub first_wall: f64,
    pub first_cpu: f64,
    /// Median extra view through the checked projector; wall and CPU seconds.
    pub extra_wall: f64,
    pub extra_cpu: f64,
}

/// One case: projector, view angle, detector size.
#[derive(Clone, Debug)]
pub struct DrrTiming {
    pub method: Method,
    pub angle_deg: f64,
    pub size: usize,
    /// Rays that meet the volume box.
    pub rays: u64,
    /// Voxels crossed (Siddon) or samples taken (trilinear) by all rays of the view.
    pub steps: u64,
    /// One entry per instruction set, in the order asked.
    pub paths: Vec<PathTiming>,
    /// Peak resident memory of the process during one projection on the first path (the peak
    /// is reset after loading; Linux), bytes.
    pub peak_rss: Option<u64>,
}

/// Process CPU time (user + system, all threads), seconds.
pub fn cpu_seconds() -> f64 {
    // SAFETY: getrusage writes the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return f64::NAN;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

/// Peak resident memory (VmHWM) of the process in bytes (Linux).
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Reset the peak resident memory to the current one (Linux); false if not possible.
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let (c0, t0) = (cpu_seconds(), Instant::now());
    let v = f();
    (v, t0.elapsed().as_secs_f64(), cpu_seconds() - c0)
}

/// Time `method` at `angle_deg` with a `size`^2 detector on each of `paths` (an instruction set
/// and the trilinear march's lanes on AVX-512; unsupported instruction sets run their widest
/// supported narrower one, as [`Projector::with_simd`] does). Checks that
/// every path gives the same bits as the first (an error otherwise). The extra views take turns
/// (one of each path per round), so a drift of the machine's speed during the case affects every
/// path alike and the ratios between paths stay comparable.
pub fn time_case(
    vol: &Volume<f32>,
    method: Method,
    angle_deg: f64,
    size: usize,
    reps: usize,
    paths: &[(Simd, MarchLanes)],
) -> Result<DrrTiming> {
    let geo = bench_geometry(vol, size);
    let angle = angle_deg.to_radians();
    let reset = reset_peak_rss();
    let mut out = DrrTiming {
        method,
        angle_deg,
        size,
        rays: 0,
        steps: 0,
        paths: Vec::new(),
        peak_rss: None,
    };
    let mut first_bits: Option<Vec<u32>> = None;
    let mut projectors = Vec::new();
    for &(simd, lanes) in paths {
        let projector =
            || Projector::new(vol, &geo, method).map(|p| p.with_simd(simd).with_march_lanes(lanes));
        let (img, first_wall, first_cpu) = timed(|| projector().and_then(|p| p.view(angle)));
        let img = img?;
        if out.paths.is_empty() && reset {
            out.peak_rss = peak_rss_bytes();
        }
        let bits: Vec<u32> = img.data.iter().map(|v| v.to_bits()).collect();
        match &first_bits {
            None => first_bits = Some(bits),
            Some(b) if *b != bits => {
                return Err(crate::Error::Geometry(format!(
                    "{method:?} at {angle_deg} deg: the {} path differs from the {} path",
                    simd.name(),
                    paths[0].0.name()
                )))
            }
            Some(_) => {}
        }
        let p = projector()?;
        out.paths.push(PathTiming {
            simd: p.simd(),
            march_lanes: p.march_lanes(),
            first_wall,
            first_cpu,
            extra_wall: 0.0,
            extra_cpu: 0.0,
        });
        projectors.push(p);
    }
    let mut times = vec![(Vec::new(), Vec::new()); projectors.len()];
    for _ in 0..reps {
        for (p, (walls, cpus)) in projectors.iter().zip(times.iter_mut()) {
            let (img, w, c) = timed(|| p.view(angle));
            std::hint::black_box(img?);
            walls.push(w);
            cpus.push(c);
        }
    }
    for (t, (walls, cpus)) in out.paths.iter_mut().zip(times) {
        (t.extra_wall, t.extra_cpu) = (median(walls), median(cpus));
    }
    (out.rays, out.steps) = count_work(vol, &geo, angle, method)?;
    Ok(out)
}

/// Rays meeting the box, and voxels crossed (Siddon: 1 + the boundary planes crossed between
/// entry and exit, per ray) or samples (trilinear) of the view (not timed).
fn count_work(vol: &Volume<f32>, geo: &ConeBeam, angle: f64, method: Method) -> Result<(u64, u64)> {
    let p = Projector::new(vol, geo, method)?;
    let cam = geo.camera(angle);
    let grid = &p.grid;
    let setup = trilinear::Setup::new(grid, geo.accuracy);
    let (mut rays, mut steps) = (0u64, 0u64);
    for row in 0..cam.height {
        for col in 0..cam.width {
            let (o, d) = cam.pixel_ray(col as f64, row as f64);
            let Some((t0, t1)) = clip_ray(&cam, o, d, grid.lo, grid.hi) else {
                continue;
            };
            rays += 1;
            steps += match method {
                Method::Siddon => siddon::voxels_crossed(grid, o, d, t0, t1),
                Method::Trilinear => {
                    let (o, d, h, _) = trilinear::ray(grid, &setup, &cam, col, row);
                    trilinear::sample_count(&setup, &cam, o, d, h)
                }
            };
        }
    }
    Ok((rays, steps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_path_is_timed_on_the_same_view() {
        let mut vol = Volume::<f32>::zeros([12, 10, 8], [1.0, 1.2, 2.0]);
        for (i, v) in vol.data.iter_mut().enumerate() {
            *v = (i % 7) as f32 * 0.25;
        }
        let mut paths: Vec<_> = Simd::supported_paths()
            .into_iter()
            .map(|p| (p, MarchLanes::Eight))
            .collect();
        if Simd::Avx512.supported() {
            paths.push((Simd::Avx512, MarchLanes::Sixteen));
        }
        for method in [Method::Siddon, Method::Trilinear] {
            let t = time_case(&vol, method, 30.0, 16, 3, &paths).unwrap();
            assert_eq!(t.paths.len(), paths.len());
            for (p, &(simd, lanes)) in t.paths.iter().zip(&paths) {
                assert_eq!(p.simd, simd);
                let want = match simd {
                    Simd::Scalar => 1,
                    Simd::Avx2 => 8,
                    Simd::Avx512 => lanes.count(),
                };
                assert_eq!(p.march_lanes, want);
                assert!(p.extra_wall > 0.0 && p.extra_wall.is_finite(), "{p:?}");
                assert!(p.extra_cpu >= 0.0 && p.first_wall > 0.0, "{p:?}");
            }
            assert!(t.rays > 0 && t.steps >= t.rays, "{t:?}");
        }
    }
}
