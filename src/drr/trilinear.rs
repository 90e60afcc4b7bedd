//! Trilinear ray-march, after TIGRE's `interpolated` projector
//! (Common/CUDA/ray_interpolated_projection.cu).
//!
//! TIGRE samples the ray on a lattice anchored at the source, `S + i (P - S) / ceil(|P - S| /
//! accuracy)` (P = the detector pixel, lengths in voxel units), reads a trilinear texture whose
//! border value is 0, and returns `sum of samples x step length`. We do the same with:
//! - step `h = L / ceil(L / (accuracy x min(dVoxel)))`, `L` = source-to-pixel distance in mm
//!   (parallel beam: `L = DSD`), so `h <= accuracy x min voxel size` and the lattice ends on the
//!   pixel. For isotropic voxels this is TIGRE's step; for anisotropic voxels TIGRE measures
//!   `|P - S|` in voxel-index units, which gives a step between accuracy x min and
//!   accuracy x max voxel size depending on the direction (we keep the finer one everywhere).
//! - sample `i` at `t_i = i h` from the ray origin (the source; for a parallel beam the point of
//!   the source plane), for every `i` whose sample lies within half a voxel of the box, the only
//!   places where the zero-padded interpolant is non-zero;
//! - the end segments get no special weight (TIGRE neither): the Riemann sum simply runs over the
//!   lattice points where the zero-padded interpolant is non-zero. The interpolant ramps
//!   linearly from 0 to the face voxel's value over the half voxel on each side of a face, so for
//!   a uniform box the sum converges to the exact chord (the ramp's excess outside equals its
//!   deficit inside), with an error of order `h` per face from the lattice phase.
//! - Result: `h x sum_i f(p(t_i))`, in mm x volume value.
//!
//! Samples whose 8 neighbours are all inside the grid take a fast path without bounds logic;
//! the few within one voxel of a face take the zero-padded path.

use super::grid::{clip_ray, Grid};
use crate::geometry::{Camera, Mode};
use crate::math::round::{ceil, floor};
use crate::real::Real;

/// The ray-march of the ray through pixel (`col`, `row`), and whether that ray met the volume
/// box (the per-ray loop of every path that is not the vector lanes').
#[inline]
pub(crate) fn pixel<R: Real>(
    grid: &Grid<R>,
    setup: &Setup,
    cam: &Camera,
    col: usize,
    row: usize,
) -> (R, bool) {
    let plan = plan(grid, setup, cam, col, row);
    let inner = march_scalar(grid, &plan.march);
    (finish(grid, &plan, inner), plan.hit)
}

/// The ray through pixel (`col`, `row`): origin, direction, step, and whether it meets the
/// volume box.
#[inline]
pub(crate) fn ray<R: Real>(
    grid: &Grid<R>,
    setup: &Setup,
    cam: &Camera,
    col: usize,
    row: usize,
) -> ([f64; 3], [f64; 3], f64, bool) {
    let (o, d) = cam.pixel_ray(col as f64, row as f64);
    let hit = clip_ray(cam, o, d, grid.lo, grid.hi).is_some();
    // Source (or source plane) to pixel distance along the ray.
    let len = match cam.mode {
        Mode::Cone => {
            let z = cam.rot[2];
            cam.dsd / (z[0] * d[0] + z[1] * d[1] + z[2] * d[2])
        }
        Mode::Parallel => cam.dsd,
    };
    let h = len / ceil(len / setup.h0);
    (o, d, h, hit)
}

/// Samples of the ray-march of `o + t d` with step `h` (those where the zero-padded
/// interpolant can be non-zero; the benchmark's count).
pub(crate) fn sample_count(setup: &Setup, cam: &Camera, o: [f64; 3], d: [f64; 3], h: f64) -> u64 {
    match clip_ray(cam, o, d, setup.outer.0, setup.outer.1) {
        Some((ta, tb)) => (floor(tb / h) as i64 - ceil(ta / h) as i64 + 1).max(0) as u64,
        None => 0,
    }
}

/// Per-volume constants.
pub(crate) struct Setup {
    /// Largest step allowed, `accuracy x min(dVoxel)` (mm).
    h0: f64,
    /// Box where the zero-padded interpolant can be non-zero (box + half a voxel).
    outer: ([f64; 3], [f64; 3]),
    /// Box of voxel centres (all 8 neighbours inside), or `None` if an axis has 1 voxel.
    inner: Option<([f64; 3], [f64; 3])>,
}

impl Setup {
    pub(crate) fn new<R: Real>(grid: &Grid<R>, accuracy: f64) -> Self {
        let mut olo = [0.0; 3];
        let mut ohi = [0.0; 3];
        let mut ilo = [0.0; 3];
        let mut ihi = [0.0; 3];
        for a in 0..3 {
            olo[a] = grid.lo[a] - grid.s[a] / 2.0;
            ohi[a] = grid.hi[a] + grid.s[a] / 2.0;
            ilo[a] = grid.lo[a] + grid.s[a] / 2.0;
            ihi[a] = grid.hi[a] - grid.s[a] / 2.0;
        }
        Setup {
            h0: accuracy * grid.s[0].min(grid.s[1]).min(grid.s[2]),
            outer: (olo, ohi),
            inner: grid.n.iter().all(|&n| n >= 2).then_some((ilo, ihi)),
        }
    }
}

/// The fast path of one ray: the samples at the 32.32 fixed-point positions `p + k dp`,
/// `0 <= k < count` (voxel units x 2^32, voxel centres at integers), every one with its 8
/// neighbours inside the grid. `count` is 0 when the ray has no such sample.
#[derive(Clone, Copy, Debug)]
pub(crate) struct March {
    pub p: [i64; 3],
    pub dp: [i64; 3],
    pub count: usize,
}

/// One ray's ray-march split around its fast path: the zero-padded samples before it (summed by
/// [`plan`], or by the vector lanes of [`super::padded_lanes`] after [`plan_runs`]), the inner
/// loop's sum ([`march_scalar`] or [`super::trilinear_lanes`]), and the rest added in the
/// per-ray order by [`finish`] (or [`finish_start`], the lanes and [`scale`]):
/// `h x (((before + inner) + moved) + after_1 + after_2 + ...)`. Every path gives the same bits.
pub(crate) struct Plan<R: Real> {
    /// The ray met the volume box.
    pub hit: bool,
    /// The fast path (count 0 when there is none).
    pub march: March,
    /// Step (mm).
    h: f64,
    /// Continuous voxel index of sample `i`: `q0 + i dq`.
    pub q0: [f64; 3],
    pub dq: [f64; 3],
    /// The samples before the fast range (all samples when there is none),
    /// `before_run.0..=before_run.1` (empty if `.0 > .1`), and their sum.
    pub before_run: (i64, i64),
    pub before: R,
    /// Whether the ray has a fast range (then the inner sum and `moved` are added).
    fast: bool,
    /// Sum of the fast range's end samples that rounding put outside the centre box (they
    /// take the zero-padded path).
    moved: R,
    /// The samples after the fast range, `after.0..=after.1` (empty if `after.0 > after.1`).
    pub after: (i64, i64),
}

/// A run of one ray's zero-padded samples for the vector lanes ([`super::padded_lanes`]): the
/// samples `first..=last` at `q0 + i dq`, added in order to `acc`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Run {
    pub q0: [f64; 3],
    pub dq: [f64; 3],
    pub first: i64,
    pub last: i64,
    pub acc: f32,
}

/// [`plan_runs`] with the samples before the fast path summed.
pub(crate) fn plan<R: Real>(
    grid: &Grid<R>,
    setup: &Setup,
    cam: &Camera,
    col: usize,
    row: usize,
) -> Plan<R> {
    let mut plan = plan_runs(grid, setup, cam, col, row);
    plan.before = sum_padded(grid, plan.q0, plan.dq, plan.before_run, R::zero());
    plan
}

/// `acc + sample_i + ...` over the zero-padded samples `i` of `run.0..=run.1` at `q0 + i dq`,
/// added in order.
pub(crate) fn sum_padded<R: Real>(
    grid: &Grid<R>,
    q0: [f64; 3],
    dq: [f64; 3],
    run: (i64, i64),
    mut acc: R,
) -> R {
    for i in run.0..=run.1 {
        acc += sample_padded(grid, at(q0, dq, i));
    }
    acc
}

/// The ray through pixel (`col`, `row`) up to its fast path (see [`Plan`]), its zero-padded
/// samples before the fast path not summed yet (`before` is 0).
pub(crate) fn plan_runs<R: Real>(
    grid: &Grid<R>,
    setup: &Setup,
    cam: &Camera,
    col: usize,
    row: usize,
) -> Plan<R> {
    let (o, d, h, hit) = ray(grid, setup, cam, col, row);
    let mut plan = Plan {
        hit,
        march: March {
            p: [0; 3],
            dp: [0; 3],
            count: 0,
        },
        h,
        q0: [0.0; 3],
        dq: [0.0; 3],
        before_run: (1, 0),
        before: R::zero(),
        fast: false,
        moved: R::zero(),
        after: (1, 0),
    };
    let Some((ta, tb)) = clip_ray(cam, o, d, setup.outer.0, setup.outer.1) else {
        return plan;
    };
    let i_lo = ceil(ta / h) as i64;
    let i_hi = floor(tb / h) as i64;
    if i_hi < i_lo {
        return plan;
    }
    // Continuous voxel-index coordinates (voxel centres at integers) of sample i:
    // q(i) = q0 + i * dq.
    for a in 0..3 {
        plan.q0[a] = (o[a] - grid.lo[a]) / grid.s[a] - 0.5;
        plan.dq[a] = h * d[a] / grid.s[a];
    }
    let (q0, dq) = (plan.q0, plan.dq);
    // Fast range [j_lo, j_hi] of samples inside the box of voxel centres.
    let (j_lo, j_hi) = match setup.inner {
        Some((ilo, ihi)) => match clip_ray(cam, o, d, ilo, ihi) {
            Some((tc, td)) => (
                (ceil(tc / h) as i64).max(i_lo),
                (floor(td / h) as i64).min(i_hi),
            ),
            None => (i_hi + 1, i_hi),
        },
        None => (i_hi + 1, i_hi),
    };
    if j_lo <= j_hi {
        plan.before_run = (i_lo, j_lo - 1);
        plan.fast = true;
        plan.march = fast_range(grid, q0, dq, j_lo, j_hi, &mut plan.moved);
        plan.after = (j_hi + 1, i_hi);
    } else {
        plan.before_run = (i_lo, i_hi);
    }
    plan
}

/// The ray's value: `h x sum` of the zero-padded trilinear interpolant at `o + i h d` over all
/// integers `i` (`i >= 0` for a cone beam), given the inner loop's sum `inner` of the plan's
/// fast path.
#[inline]
pub(crate) fn finish<R: Real>(grid: &Grid<R>, plan: &Plan<R>, inner: R) -> R {
    let acc = finish_start(plan, inner);
    scale(plan, sum_padded(grid, plan.q0, plan.dq, plan.after, acc))
}

/// The ray's sum up to its samples after the fast path: `(before + inner) + moved`, or
/// `before` when it has no fast path.
#[inline]
pub(crate) fn finish_start<R: Real>(plan: &Plan<R>, inner: R) -> R {
    let mut acc = plan.before;
    if plan.fast {
        acc += inner;
        acc += plan.moved;
    }
    acc
}

/// The ray's value from its whole sum: `sum x h`.
#[inline]
pub(crate) fn scale<R: Real>(plan: &Plan<R>, sum: R) -> R {
    sum * R::c(plan.h)
}

#[inline(always)]
fn at(q0: [f64; 3], dq: [f64; 3], i: i64) -> [f64; 3] {
    let f = i as f64;
    [q0[0] + f * dq[0], q0[1] + f * dq[1], q0[2] + f * dq[2]]
}

/// Fixed-point scale of the fast path: positions in voxel units x 2^32, in `i64`.
pub(crate) const FIX: f64 = 4294967296.0;

/// The fast path of the samples `j_lo..=j_hi` (sample `i` at continuous index `q0 + i dq`, all
/// inside the box of voxel centres up to rounding). The fast path steps positions in 32.32 fixed
/// point: the position of sample `j_lo + k` is `p0 + k dp` exactly (integer arithmetic), so it
/// is a linear function of `k` and lies in `[0, n - 1]` on every axis for all `k` as soon as it
/// does at both ends, which is checked: end samples that fail go to the zero-padded path and are
/// added to `moved` (a sample exactly on the last voxel centre also takes that path). The
/// quantisation of the start and step (2^-33 voxel) moves a sample by less than 1e-6 voxel over
/// 4000 steps.
fn fast_range<R: Real>(
    grid: &Grid<R>,
    q0: [f64; 3],
    dq: [f64; 3],
    mut j_lo: i64,
    mut j_hi: i64,
    moved: &mut R,
) -> March {
    let [nx, ny, nz] = grid.n;
    debug_assert!(grid.data.len() == nx * ny * nz && nx >= 2 && ny >= 2 && nz >= 2);
    let lim = [
        (nx as i64 - 1) << 32,
        (ny as i64 - 1) << 32,
        (nz as i64 - 1) << 32,
    ];
    let fixed = |i: i64| -> [i64; 3] {
        let q = at(q0, dq, i);
        [
            (q[0] * FIX).round() as i64,
            (q[1] * FIX).round() as i64,
            (q[2] * FIX).round() as i64,
        ]
    };
    let dp = [
        (dq[0] * FIX).round() as i64,
        (dq[1] * FIX).round() as i64,
        (dq[2] * FIX).round() as i64,
    ];
    let inside = |p: [i64; 3]| (0..3).all(|a| p[a] >= 0 && p[a] < lim[a]);
    let p0 = fixed(j_lo);
    let pos = |k: i64| -> [i64; 3] { [p0[0] + k * dp[0], p0[1] + k * dp[1], p0[2] + k * dp[2]] };
    // Move end samples that rounding put outside the centre box to the padded path.
    let mut k_lo = 0i64;
    while j_lo + k_lo <= j_hi && !inside(pos(k_lo)) {
        *moved += sample_padded(grid, at(q0, dq, j_lo + k_lo));
        k_lo += 1;
    }
    while j_hi >= j_lo + k_lo && !inside(pos(j_hi - j_lo)) {
        *moved += sample_padded(grid, at(q0, dq, j_hi));
        j_hi -= 1;
    }
    j_lo += k_lo;
    March {
        p: pos(k_lo),
        dp,
        count: if j_hi < j_lo {
            0
        } else {
            (j_hi - j_lo + 1) as usize
        },
    }
}

/// The inner loop's sum, the samples of the fast path `m` added in order (0 when it is
/// empty), per ray.
pub(crate) fn march_scalar<R: Real>(grid: &Grid<R>, m: &March) -> R {
    let [nx, ny, _] = grid.n;
    let nxy = nx * ny;
    let data = grid.data;
    let [mut px, mut py, mut pz] = m.p;
    let [dx, dy, dz] = m.dp;
    const MASK: i64 = 0xffff_ffff;
    let inv = R::c(1.0 / FIX);
    let mut acc = R::zero();
    for _ in 0..m.count {
        let ix = (px >> 32) as usize;
        let iy = (py >> 32) as usize;
        let iz = (pz >> 32) as usize;
        let fx = fixed_frac::<R>(px & MASK) * inv;
        let fy = fixed_frac::<R>(py & MASK) * inv;
        let fz = fixed_frac::<R>(pz & MASK) * inv;
        px += dx;
        py += dy;
        pz += dz;
        let b = ix + nx * iy + nxy * iz;
        // SAFETY: every position of this loop is p + k dp with 0 <= k < count, a linear function
        // of k in exact integer arithmetic (no overflow: |p| < 2^63 for any grid below 2^31
        // voxels per axis) whose two ends satisfy 0 <= p < (n - 1) 2^32 on each axis (checked
        // by `fast_range`), so every position does: ix <= nx - 2, iy <= ny - 2, iz <= nz - 2,
        // and the largest index read, b + nxy + nx + 1 <= (nx-1) + nx (ny-1) + nxy (nz-1) =
        // len - 1.
        let (c000, c100, c010, c110, c001, c101, c011, c111) = unsafe {
            (
                *data.get_unchecked(b),
                *data.get_unchecked(b + 1),
                *data.get_unchecked(b + nx),
                *data.get_unchecked(b + nx + 1),
                *data.get_unchecked(b + nxy),
                *data.get_unchecked(b + nxy + 1),
                *data.get_unchecked(b + nxy + nx),
                *data.get_unchecked(b + nxy + nx + 1),
            )
        };
        let c00 = c000 + fx * (c100 - c000);
        let c10 = c010 + fx * (c110 - c010);
        let c01 = c001 + fx * (c101 - c001);
        let c11 = c011 + fx * (c111 - c011);
        let c0 = c00 + fy * (c10 - c00);
        let c1 = c01 + fy * (c11 - c01);
        acc += c0 + fz * (c1 - c0);
    }
    acc
}

#[inline(always)]
fn fixed_frac<R: Real>(f: i64) -> R {
    <R as num_traits::NumCast>::from(f).unwrap_or_else(R::zero)
}

/// The zero-padded trilinear interpolant at continuous index `q` (voxel centres at integers):
/// `sum over the 8 neighbours in the grid, x fastest, of (((1 w_x) w_y) w_z) value`, summed in
/// that corner order.
///
/// Branch-free over the corners: a neighbour outside the grid gets weight 0 and a clamped
/// index (a voxel in the grid), so its term is `0 x value = +-0` and adding it leaves the sum's
/// bits unchanged: the sum starts at +0 and a round-to-nearest sum is -0 only when both terms
/// are -0, so it is never -0, and `s + +-0 = s` for every other `s`. Every value is finite
/// ([`super::Projector::new`] checks). The other corners' weights are the same products as
/// when the outside ones are skipped, so the result is that sum bit for bit
/// (`padded_sample_matches_the_sum_over_the_corners_in_the_grid`).
#[inline]
fn sample_padded<R: Real>(grid: &Grid<R>, q: [f64; 3]) -> R {
    // Per axis: the lower and upper neighbour's index, clamped into the grid, and weight (0
    // for a neighbour outside it).
    let mut at = [[0usize; 2]; 3];
    let mut wt = [[R::zero(); 2]; 3];
    for a in 0..3 {
        let n = grid.n[a];
        if !(q[a] > -1.0 && q[a] < n as f64) {
            return R::zero();
        }
        let fl = floor(q[a]);
        let f = R::c(q[a] - fl);
        // In [-1, n - 1]: the lower neighbour is outside when it is -1, the upper when the
        // lower is n - 1.
        let i = fl as i64;
        let last = n as i64 - 1;
        at[a] = [i.max(0) as usize, (i + 1).min(last) as usize];
        wt[a] = [
            if i >= 0 { R::one() - f } else { R::zero() },
            if i < last { f } else { R::zero() },
        ];
    }
    let [nx, ny, _] = grid.n;
    let data = grid.data;
    let mut acc = R::zero();
    // Corners in the order x, then y, then z up; the weight is 1 x w_x x w_y x w_z.
    for uz in 0..2 {
        for uy in 0..2 {
            let row = nx * (at[1][uy] + ny * at[2][uz]);
            for ux in 0..2 {
                let w = R::one() * wt[0][ux] * wt[1][uy] * wt[2][uz];
                acc += w * data[at[0][ux] + row];
            }
        }
    }
    acc
}

#[cfg(test)]
mod tests;
