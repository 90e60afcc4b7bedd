//! A band of rows on the vector lanes (f32 volumes): the rays of each tile handed to the Siddon
//! and trilinear lane kernels ([`super::siddon_lanes`], [`super::trilinear_lanes`],
//! [`super::padded_lanes`]), and their sums put together in the per-ray loop's order.

use super::grid::{clip_ray, Grid};
use super::schedule::{tile_order, TILE};
use super::{lanes, siddon, trilinear, MarchLanes};
#[cfg(target_arch = "x86_64")]
use super::{padded_lanes, siddon_lanes, trilinear_lanes};
use crate::geometry::Camera;
use crate::simd::Simd;

/// Rows and columns of detector pixels per tile of the trilinear lanes: as many rays as the
/// lanes (8), which start together on a tile and end with it, so that neighbouring rays read
/// the same cache lines at the same depth (lanes that take the next ray as soon as theirs ends
/// drift apart in depth). The shape is the fastest measured over several view angles
/// (`unispine bench drr`); the bits do not depend on it.
pub(super) const LANE_TILE: (usize, usize) = (4, 2);
/// The same for 16 lanes ([`MarchLanes::Sixteen`]): the tiles stack detector rows (v, along z
/// in the AP and lateral views), whose neighbouring rays share z planes.
pub(super) const LANE_TILE_16: (usize, usize) = (8, 2);

/// Siddon on the vector lanes of `simd` for the band `out` (first row `row0`); returns the
/// number of rays that met the box. Pixels whose ray misses the box keep their 0.
pub(super) fn siddon_band(
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
pub(super) fn trilinear_band(
    simd: Simd,
    march: MarchLanes,
    grid: &Grid<f32>,
    setup: &trilinear::Setup,
    cam: &Camera,
    (out, w, row0): (&mut [f32], usize, usize),
) -> usize {
    let rows = out.len() / w;
    let mut hits = 0;
    let wide = sixteen_lanes(simd, march);
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
            let mut rays = plans
                .iter()
                .enumerate()
                .filter(|(_, (_, p))| lane_march(&p.march))
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
                let inner = if lane_march(&p.march) {
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

/// Whether the trilinear march runs on 16 lanes: the AVX-512 path with
/// [`MarchLanes::Sixteen`] (else 8 lanes, or the per-ray loop on the scalar path).
pub(super) fn sixteen_lanes(simd: Simd, march: MarchLanes) -> bool {
    simd == Simd::Avx512 && march == MarchLanes::Sixteen
}

/// Whether the lanes of [`trilinear_lanes`] take a ray's inner march: empty marches, and
/// marches of 2^31 samples or more (a step far below the voxel size; the lanes count in i32),
/// stay per ray.
pub(super) fn lane_march(m: &trilinear::March) -> bool {
    m.count > 0 && m.count < 1 << 31
}

/// Whether the lanes of [`padded_lanes`] take a run of samples `first..=last`: empty, or fewer
/// than 2^31 samples of index below 2^52 in magnitude (any real geometry's); the others are
/// summed per ray.
pub(super) fn lane_run((first, last): (i64, i64)) -> bool {
    first > last || (first.abs() < 1 << 52 && last.abs() < 1 << 52 && last - first < (1 << 31) - 1)
}

/// `out[k]` = `init[k]` plus the zero-padded samples `run(plan k)` of the tile's plans, for
/// the runs that [`lane_run`] gives to the lanes of `simd` (`init[k]` for the others, which
/// are summed per ray): with `wide` (16 march lanes) on AVX-512's 8 lanes, else on AVX2's 4.
/// `runs` is scratch space.
#[allow(clippy::too_many_arguments)]
pub(super) fn padded_runs(
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The routing of rays between the lanes and the per-ray loops at each bound: a wrong
    /// route changes no bit where both can run, so only these predicates can tell; past the
    /// bounds the lanes' i32 counters would overflow.
    #[test]
    fn lanes_take_the_runs_and_marches_within_their_bounds() {
        let p52 = 1i64 << 52;
        let p31 = 1i64 << 31;
        let cases = [
            ((1, 0), true),               // empty
            ((p52 + 9, -p52 - 9), true),  // empty, whatever the indices
            ((3, 3), true),               // one sample
            ((-5, 7), true),              // both signs
            ((p52 - 1, p52 - 1), true),   // the largest index
            ((-p52 + 1, -p52 + 1), true), // the most negative one
            ((p52, p52), false),          // an index of 2^52
            ((-p52, -p52 + 3), false),    // -2^52
            ((p52 - 5, p52), false),      // the last one 2^52
            ((0, p31 - 2), true),         // 2^31 - 1 samples
            ((0, p31 - 1), false),        // 2^31 samples
            ((-p31, p31), false),         // more
        ];
        for (run, want) in cases {
            assert_eq!(lane_run(run), want, "{run:?}");
        }
        let march = |count: usize| trilinear::March {
            p: [0; 3],
            dp: [0; 3],
            count,
        };
        for (count, want) in [
            (0, false),
            (1, true),
            ((1 << 31) - 1, true),
            (1 << 31, false),
        ] {
            assert_eq!(lane_march(&march(count)), want, "{count}");
        }
        for simd in Simd::ALL {
            for march in [MarchLanes::Eight, MarchLanes::Sixteen] {
                let want = simd == Simd::Avx512 && march == MarchLanes::Sixteen;
                assert_eq!(sixteen_lanes(simd, march), want, "{simd:?} {march:?}");
            }
        }
    }
}
