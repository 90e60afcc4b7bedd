//! 16x16 tile binning and the deterministic (tile, depth, index) sort (the first half of the
//! rasterizer of Eqs. 4-5).
//!
//! Each drawn splat (radius > 0, finite mean) covers the axis-aligned square
//! [u - r, u + r] x [v - r, v + r] (pixels, continuous coordinates: pixel (col, row) spans
//! [col, col + 1] x [row, row + 1], centre at +0.5). Its tiles are those the square overlaps,
//! gsplat's rule (`IntersectTile.cu`):
//! `tx0 = floor((u - r) / 16)`, `tx1 = ceil((u + r) / 16)` (exclusive), clamped to the grid, and
//! the same for rows. The square is computed in f64, so the f32 and f64 paths bin alike.
//!
//! The per-tile lists are built by a counting sort over tiles that visits the Gaussians sorted
//! by the key (depth in IEEE total order, index), so each list comes out in key order. The keys
//! are unique, so the (parallel) sort is deterministic: the lists are the same for any thread
//! count. 3DGS sorts
//! `(tile << 32) | depth_bits` with a stable radix sort, which leaves ties in emission (index)
//! order: the same order.

use rayon::prelude::*;

use super::Splats;
use crate::real::Real;

/// Tile side in pixels (3DGS `BLOCK_X = BLOCK_Y = 16`).
pub const TILE: usize = 16;

/// Per-tile, depth-sorted lists of Gaussian indices. Tiles are numbered row-major
/// (`ty * tiles_x + tx`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TileBins {
    pub width: usize,
    pub height: usize,
    pub tiles_x: usize,
    pub tiles_y: usize,
    /// `ids[offsets[t]..offsets[t + 1]]` is the list of tile `t`, front (small depth) first.
    pub offsets: Vec<usize>,
    /// Gaussian indices, concatenated per tile.
    pub ids: Vec<u32>,
}

impl TileBins {
    /// Number of tiles.
    pub fn n_tiles(&self) -> usize {
        self.tiles_x * self.tiles_y
    }

    /// The depth-sorted list of tile `t`.
    pub fn list(&self, t: usize) -> &[u32] {
        &self.ids[self.offsets[t]..self.offsets[t + 1]]
    }

    /// Pixel rectangle `[x0, x1) x [y0, y1)` of tile `t`, clipped to the image.
    pub fn pixel_rect(&self, t: usize) -> [usize; 4] {
        let (tx, ty) = (t % self.tiles_x, t / self.tiles_x);
        [
            tx * TILE,
            ((tx + 1) * TILE).min(self.width),
            ty * TILE,
            ((ty + 1) * TILE).min(self.height),
        ]
    }
}

/// Tile rectangle `[tx0, tx1) x [ty0, ty1)` of a splat with centre `(u, v)` and radius `r`
/// pixels, or `None` if it is culled (r = 0), not finite, or covers no tile.
pub fn tile_rect(u: f64, v: f64, r: u32, tiles_x: usize, tiles_y: usize) -> Option<[usize; 4]> {
    if r == 0 || !u.is_finite() || !v.is_finite() {
        return None;
    }
    let r = r as f64;
    let t = TILE as f64;
    let clamp = |x: f64, n: usize| x.max(0.0).min(n as f64) as usize;
    let tx0 = clamp(((u - r) / t).floor(), tiles_x);
    let tx1 = clamp(((u + r) / t).ceil(), tiles_x);
    let ty0 = clamp(((v - r) / t).floor(), tiles_y);
    let ty1 = clamp(((v + r) / t).ceil(), tiles_y);
    (tx0 < tx1 && ty0 < ty1).then_some([tx0, tx1, ty0, ty1])
}

/// Sort key of a depth: the IEEE-754 total order of its value rounded to f32 (3DGS sorts the
/// f32 depth bits), as an unsigned integer.
#[inline]
pub fn depth_key(d: f64) -> u32 {
    let b = (d as f32).to_bits();
    if b >> 31 == 1 {
        !b
    } else {
        b | (1 << 31)
    }
}

/// The unique sort key (depth key, Gaussian index) of Gaussian `i` at depth `d`.
#[inline]
pub fn sort_key(d: f64, i: u32) -> u64 {
    ((depth_key(d) as u64) << 32) | i as u64
}

/// A splat is drawn when its radius is positive and its screen-space fields are finite.
#[inline]
pub fn drawn<R: Real>(s: &Splats<R>, i: usize) -> bool {
    s.radius[i] > 0
        && s.mean2d[i].iter().all(|x| x.is_finite())
        && s.conic[i].iter().all(|x| x.is_finite())
        && s.opacity[i].is_finite()
        && s.color[i].is_finite()
        && s.depth[i].is_finite()
}

/// Bin the drawn splats of `s` into the 16x16 tiles of a `width` x `height` image and sort each
/// tile's list by (depth, index).
pub fn bin<R: Real>(s: &Splats<R>, width: usize, height: usize) -> TileBins {
    let n = s.radius.len();
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let n_tiles = tiles_x * tiles_y;
    let rects: Vec<Option<[usize; 4]>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if !drawn(s, i) {
                return None;
            }
            let [u, v] = s.mean2d[i].map(|x| x.f64());
            tile_rect(u, v, s.radius[i], tiles_x, tiles_y)
        })
        .collect();
    // Counting sort over tiles, Gaussians in index order.
    let mut counts = vec![0usize; n_tiles + 1];
    for r in rects.iter().flatten() {
        for ty in r[2]..r[3] {
            for tx in r[0]..r[1] {
                counts[ty * tiles_x + tx + 1] += 1;
            }
        }
    }
    for t in 0..n_tiles {
        counts[t + 1] += counts[t];
    }
    let offsets = counts;
    // The drawn splats in (depth, index) order (unique keys: the same order for any thread
    // count); a stable counting sort in that order leaves every tile's list sorted by the key.
    let mut order: Vec<u64> = rects
        .iter()
        .enumerate()
        .filter(|(_, r)| r.is_some())
        .map(|(i, _)| sort_key(s.depth[i].f64(), i as u32))
        .collect();
    order.par_sort_unstable();
    let mut fill = offsets.clone();
    let mut ids = vec![0u32; offsets[n_tiles]];
    for (i, r) in order
        .iter()
        .filter_map(|&k| Some((k as u32, rects[k as u32 as usize]?)))
    {
        for ty in r[2]..r[3] {
            for tx in r[0]..r[1] {
                let t = ty * tiles_x + tx;
                ids[fill[t]] = i;
                fill[t] += 1;
            }
        }
    }
    TileBins {
        width,
        height,
        tiles_x,
        tiles_y,
        offsets,
        ids,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn splats(m: &[([f64; 2], u32, f64)]) -> Splats<f64> {
        let n = m.len();
        Splats {
            mean2d: m.iter().map(|x| x.0).collect(),
            conic: vec![[1.0, 0.0, 1.0]; n],
            depth: m.iter().map(|x| x.2).collect(),
            radius: m.iter().map(|x| x.1).collect(),
            opacity: vec![0.5; n],
            color: vec![1.0; n],
        }
    }

    #[test]
    fn rect_follows_the_square_and_clips() {
        // 40 x 20 image: 3 x 2 tiles.
        assert_eq!(tile_rect(8.0, 8.0, 3, 3, 2), Some([0, 1, 0, 1]));
        assert_eq!(tile_rect(17.5, 8.0, 1, 3, 2), Some([1, 2, 0, 1]));
        assert_eq!(tile_rect(16.5, 8.0, 1, 3, 2), Some([0, 2, 0, 1]));
        assert_eq!(tile_rect(16.0, 16.0, 1, 3, 2), Some([0, 2, 0, 2]));
        assert_eq!(tile_rect(20.0, 10.0, 100, 3, 2), Some([0, 3, 0, 2]));
        assert_eq!(tile_rect(-5.0, 10.0, 4, 3, 2), None);
        assert_eq!(tile_rect(10.0, 10.0, 0, 3, 2), None);
        assert_eq!(tile_rect(f64::NAN, 10.0, 3, 3, 2), None);
    }

    #[test]
    fn lists_sorted_by_depth_then_index() {
        let s = splats(&[
            ([8.0, 8.0], 20, 5.0),
            ([8.0, 8.0], 3, 2.0),
            ([30.0, 8.0], 3, 2.0),
            ([8.0, 8.0], 3, 5.0),
            ([8.0, 8.0], 0, 1.0), // culled
            ([8.0, 8.0], 2, 1.5),
        ]);
        let b = bin(&s, 40, 20);
        assert_eq!((b.tiles_x, b.tiles_y), (3, 2));
        assert_eq!(b.list(0), &[5, 1, 0, 3]);
        assert_eq!(b.list(1), &[2, 0]);
        assert_eq!(b.list(2), &[2]);
        assert_eq!(b.list(3), &[0]);
        assert_eq!(b.pixel_rect(5), [32, 40, 16, 20]);
        assert!(depth_key(-1.0) < depth_key(0.0));
        assert!(depth_key(0.5) < depth_key(2.0));
    }
}
