//! The order of the work: bands of image rows per parallel task, tiles of pixels within a band,
//! and the axis that runs inner. Each pixel is computed from its own ray alone, so the order
//! changes the speed, never a bit.

use super::grid::Grid;
use crate::geometry::Camera;
use crate::real::Real;

/// Image rows per parallel task. With a tile of `BAND` x `TILE` rays the voxels read by one tile
/// fit in a core's cache, whereas one whole row of rays crossing the volume along its fast axis
/// (the lateral view) reads a slab of about 2 MB that is gone before the next row reuses it.
pub(super) const BAND: usize = 8;
/// Columns per tile.
pub(super) const TILE: usize = 32;

/// Whether to visit the pixels of a tile row by row (columns inner) rather than column by
/// column: the detector axis along which neighbouring rays share more cache lines goes inner.
/// This only orders the work (speed); the pixel values do not depend on it.
pub(super) fn cols_inner<R: Real>(grid: &Grid<R>, cam: &Camera) -> bool {
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

/// Fill the band `out` (whole image rows, the first one being `row0`, `w` pixels each) with
/// `f(col, row) = (value, hit)` tile by tile: for each block of `tile` columns, row by row
/// (`cols_inner`) or column by column. Returns the number of hits. Each pixel is written once
/// from its own ray, so the order is free.
#[inline]
pub(super) fn for_each_pixel<R: Real>(
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

/// The pixels of a band of `rows` rows of `w` pixels as `(col, row in band)`, tile by tile in
/// the order of [`for_each_pixel`].
pub(super) fn tile_order(
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
pub(super) fn tile_pixels(
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ConeBeam;

    /// The axis choice against the cache lines counted by hand: a step along x stays within a
    /// line of 16 values, a step along y or z moves to another line per voxel crossed.
    #[test]
    fn the_detector_axis_crossing_fewer_cache_lines_goes_inner() {
        let data = vec![0f32; 8];
        let grid = |s: [f64; 3]| Grid {
            data: &data,
            n: [2, 2, 2],
            s,
            lo: [0.0; 3],
            hi: [2.0; 3],
        };
        let mut cam = ConeBeam::centred([4, 4], [1.0, 1.0], [2, 2, 2], [1.0; 3]).camera(0.0);
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        // (u axis, v axis, pitch [v, u], voxel size, columns inner): lines per step along u
        // against along v.
        let cases = [
            (x, z, [1.0, 1.0], [1.0; 3], true),         // 1/16 against 1
            (z, x, [1.0, 1.0], [1.0; 3], false),        // 1 against 1/16
            (y, z, [1.0, 2.0], [1.0; 3], false),        // 2 against 1
            (y, z, [2.0, 1.0], [1.0; 3], true),         // 1 against 2
            (y, z, [1.0, 1.0], [1.0, 4.0, 1.0], true),  // 1/4 against 1
            (x, y, [1.0, 1.0], [1.0, 4.0, 1.0], true),  // 1/16 against 1/4
            (x, y, [1.0, 8.0], [1.0, 4.0, 1.0], false), // 1/2 against 1/4
            (z, y, [1.0, 1.0], [1.0, 1.0, 0.5], false), // 2 against 1
            // 0.48 / 16 + 0.6 + 0.64 = 1.27 against 1.
            ([0.48, 0.6, 0.64], z, [1.0, 1.0], [1.0; 3], false),
            // 0.03 + 0.6 + 1.28 = 1.91 against 2.
            ([0.48, 0.6, 0.64], z, [1.0, 1.0], [1.0, 1.0, 0.5], true),
            // Signs and sizes that a sum in place of a product, or a product in place of the
            // division by the voxel size, would order the other way:
            ([-1.0, 0.0, 0.0], y, [1.0, 17.0], [1.0; 3], false), // 17/16 against 1
            (x, y, [1.0, 1.0], [0.25, 8.0, 1.0], false),         // 1/4 against 1/8
            (z, [0.0, -1.0, 0.0], [1.5, 1.0], [1.0; 3], true),   // 1 against 1.5
        ];
        for (k, (u, v, pitch, s, want)) in cases.into_iter().enumerate() {
            cam.rot = [u, v, [0.0; 3]];
            cam.pitch = pitch;
            assert_eq!(cols_inner(&grid(s), &cam), want, "case {k}");
        }
    }

    /// Every pixel is visited once, a block of `tile` columns at a time (the last block
    /// ragged), row by row or column by column within the block; its value lands at its place;
    /// [`tile_order`] lists the same pixels in the same order.
    #[test]
    fn pixels_are_visited_block_by_block_once_each() {
        let (w, rows, tile) = (7usize, 3usize, 3usize);
        for inner in [true, false] {
            let seen = std::cell::RefCell::new(Vec::new());
            let mut out = vec![0f32; w * rows];
            let hits = for_each_pixel(&mut out, w, 10, tile, inner, |c, r| {
                seen.borrow_mut().push((c, r));
                ((r * 100 + c) as f32, c % 2 == 0)
            });
            let mut want = Vec::new();
            for c0 in [0, 3, 6] {
                let cols = c0..(c0 + tile).min(w);
                if inner {
                    for r in 10..13 {
                        want.extend(cols.clone().map(|c| (c, r)));
                    }
                } else {
                    for c in cols {
                        want.extend((10..13).map(|r| (c, r)));
                    }
                }
            }
            assert_eq!(seen.into_inner(), want, "columns inner: {inner}");
            // The lane paths' order, rows counted from the band's first.
            let order: Vec<_> = tile_order(w, rows, tile, inner).collect();
            let want_in_band: Vec<_> = want.iter().map(|&(c, r)| (c, r - 10)).collect();
            assert_eq!(order, want_in_band, "tile_order, columns inner: {inner}");
            // Columns 0, 2, 4 and 6 hit, on each of the 3 rows.
            assert_eq!(hits, 12);
            for r in 0..rows {
                for c in 0..w {
                    assert_eq!(out[r * w + c], ((r + 10) * 100 + c) as f32);
                }
            }
        }
    }
}
