//! Exact line integrals through a piecewise-constant voxel grid (Siddon 1985, traversed
//! incrementally as Amanatides & Woo 1987 / Jacobs et al. 1998 do; TIGRE's default `Siddon`
//! projector, which made the NAF / X-Gaussian ground-truth projections).
//!
//! For a ray `p(t) = o + t d` (unit `d`, `t` in mm) clipped to the volume box, the integral is
//! `sum_k (t_{k+1} - t_k) v(voxel_k)` over the segments between consecutive voxel-boundary
//! crossings. The entry voxel and the boundary parameters are set up in f64; the traversal runs
//! in the volume's precision `R` with `t` measured from the entry point (so f32 keeps its
//! precision far from the source). The walk ends when an axis crosses its last boundary, which
//! is decided with integer counters, so voxel indices never leave the grid whatever the rounding.

use super::grid::{clip_ray, Grid};
use crate::geometry::Camera;
use crate::real::Real;

/// The line integral of the ray through pixel (`col`, `row`), and whether that ray met the
/// volume box.
#[inline]
pub(crate) fn pixel<R: Real>(grid: &Grid<R>, cam: &Camera, col: usize, row: usize) -> (R, bool) {
    let (o, d) = cam.pixel_ray(col as f64, row as f64);
    match clip_ray(cam, o, d, grid.lo, grid.hi) {
        Some((t0, _)) => (integrate(grid, o, d, t0), true),
        None => (R::zero(), false),
    }
}

/// The start of the walk along `o + t d` from the box entry `t_in`: per axis the distance to the
/// next boundary crossing (from the entry point) and between crossings, the crossings left
/// before the ray leaves the box along the axis (`i64::MAX` for an axis the ray is parallel
/// to), the index step, and the entry voxel's index.
pub(crate) struct Walk<R> {
    pub tm: [R; 3],
    pub dt: [R; 3],
    pub left: [i64; 3],
    pub step: [isize; 3],
    pub idx: isize,
}

/// The [`Walk`] of `o + t d` from the box entry `t_in` (f64 set-up, rounded to `R` once).
#[inline]
pub(crate) fn start<R: Real>(grid: &Grid<R>, o: [f64; 3], d: [f64; 3], t_in: f64) -> Walk<R> {
    let n = grid.n;
    let stride = [1isize, n[0] as isize, (n[0] * n[1]) as isize];
    let mut tm = [R::infinity(); 3]; // next boundary crossing per axis, from the entry point
    let mut dt = [R::zero(); 3]; // distance between crossings per axis
    let mut left = [i64::MAX; 3]; // crossings left before the ray leaves the box along the axis
    let mut step = [0isize; 3];
    let mut idx = 0isize;
    for a in 0..3 {
        let p = o[a] + t_in * d[a];
        let c = (p - grid.lo[a]) / grid.s[a];
        // `as` saturates (negative and NaN to 0), then clamp to the last voxel.
        let i = if c > 0.0 {
            (c as usize).min(n[a] - 1)
        } else {
            0
        };
        idx += i as isize * stride[a];
        if d[a] > 0.0 {
            let b = grid.lo[a] + (i + 1) as f64 * grid.s[a];
            tm[a] = R::c((b - p) / d[a]);
            dt[a] = R::c(grid.s[a] / d[a]);
            left[a] = (n[a] - i) as i64;
            step[a] = stride[a];
        } else if d[a] < 0.0 {
            let b = grid.lo[a] + i as f64 * grid.s[a];
            tm[a] = R::c((b - p) / d[a]);
            dt[a] = R::c(-grid.s[a] / d[a]);
            left[a] = i as i64 + 1;
            step[a] = -stride[a];
        }
    }
    Walk {
        tm,
        dt,
        left,
        step,
        idx,
    }
}

/// The line integral along `o + t d` from the box entry `t_in` to the box exit.
#[inline]
pub(crate) fn integrate<R: Real>(grid: &Grid<R>, o: [f64; 3], d: [f64; 3], t_in: f64) -> R {
    let Walk {
        mut tm,
        dt,
        mut left,
        step,
        mut idx,
    } = start(grid, o, d, t_in);
    let data = grid.data;
    let mut t = R::zero();
    let mut acc = R::zero();
    loop {
        let a = if tm[0] <= tm[1] {
            if tm[0] <= tm[2] {
                0
            } else {
                2
            }
        } else if tm[1] <= tm[2] {
            1
        } else {
            2
        };
        let tn = tm[a];
        acc += (tn - t) * data[idx as usize];
        t = tn;
        left[a] -= 1;
        if left[a] == 0 {
            break;
        }
        tm[a] += dt[a];
        idx += step[a];
    }
    acc
}

/// Voxels crossed by `o + t d` between the box entry `t_in` and exit `t_out`: 1 + the voxel
/// boundary planes between the entry and exit voxels (the benchmark's step count; the walk may
/// differ by a step where the exit lies on a boundary).
pub(crate) fn voxels_crossed<R: Real>(
    grid: &Grid<R>,
    o: [f64; 3],
    d: [f64; 3],
    t_in: f64,
    t_out: f64,
) -> u64 {
    let voxel = |t: f64, a: usize| {
        let c = (o[a] + t * d[a] - grid.lo[a]) / grid.s[a];
        (c.max(0.0) as i64).min(grid.n[a] as i64 - 1)
    };
    let t_mid = 0.5 * (t_in + t_out);
    // Entry and exit voxels, nudged inside the chord so a point on a face counts once.
    let (ta, tb) = (t_in + 1e-9 * (t_mid - t_in), t_out - 1e-9 * (t_out - t_mid));
    1 + (0..3)
        .map(|a| (voxel(tb, a) - voxel(ta, a)).unsigned_abs())
        .sum::<u64>()
}
