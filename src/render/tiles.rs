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
//! are unique, so their order is unique; the counting sort runs in parallel over runs of that
//! order and the lists are assembled in parallel over bands of tile rows, in ways that give the
//! same lists for any thread count (`banded_lists_match_a_brute_force_for_any_thread_count`).
//! 3DGS sorts
//! `(tile << 32) | depth_bits` with a stable radix sort, which leaves ties in emission (index)
//! order: the same order.

use rayon::prelude::*;

use super::Splats;
use crate::math::round;
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
#[inline]
pub fn tile_rect(u: f64, v: f64, r: u32, tiles_x: usize, tiles_y: usize) -> Option<[usize; 4]> {
    if r == 0 || !u.is_finite() || !v.is_finite() {
        return None;
    }
    let r = r as f64;
    let t = TILE as f64;
    // In [0, n], so the conversion through i64 is exact (cheaper than a direct one to usize).
    let clamp = |x: f64, n: usize| x.max(0.0).min(n as f64) as i64 as usize;
    let tx0 = clamp(round::floor((u - r) / t), tiles_x);
    let tx1 = clamp(round::ceil((u + r) / t), tiles_x);
    let ty0 = clamp(round::floor((v - r) / t), tiles_y);
    let ty1 = clamp(round::ceil((v + r) / t), tiles_y);
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
#[inline(always)]
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
///
/// Parallel, and the same lists whatever the split: the drawn splats are sorted by their
/// unique keys; a few contiguous runs of that order each count-sort their own entries by tile;
/// then bands of tile rows each copy, tile by tile, the runs' segments in run order into their
/// own slice of `ids`. Every list is therefore the key order restricted to its tile.
pub fn bin<R: Real>(s: &Splats<R>, width: usize, height: usize) -> TileBins {
    let n = s.radius.len();
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let n_tiles = tiles_x * tiles_y;
    // The drawn splats with their tile rectangles, in (depth, index) order (unique keys: the
    // same order for any thread count).
    let mut order: Vec<(u64, [u32; 4])> = Vec::with_capacity(n);
    order.par_extend((0..n).into_par_iter().filter_map(|i| {
        if !drawn(s, i) {
            return None;
        }
        let [u, v] = s.mean2d[i].map(|x| x.f64());
        let r = tile_rect(u, v, s.radius[i], tiles_x, tiles_y)?;
        Some((sort_key(s.depth[i].f64(), i as u32), r.map(|x| x as u32)))
    }));
    sort_by_depth(&mut order);
    // Contiguous runs of the key order, each sorted by tile (a stable counting sort). A few per
    // worker, at most 8: each run holds offsets for every tile.
    let n_runs = (2 * rayon::current_num_threads()).min(8);
    let per_run = order.len().div_ceil(n_runs).max(1);
    let runs: Vec<Run> = order
        .par_chunks(per_run)
        .map(|keys| Run::new(keys, tiles_x, n_tiles))
        .collect();
    let mut offsets = Vec::with_capacity(n_tiles + 1);
    offsets.push(0usize);
    for t in 0..n_tiles {
        let len: usize = runs.iter().map(|r| r.len(t)).sum();
        offsets.push(offsets[t] + len);
    }
    // Each band of tile rows (balanced by entries) owns the slice of `ids` of its tiles.
    let row_entries: Vec<usize> = (0..tiles_y)
        .map(|ty| offsets[(ty + 1) * tiles_x] - offsets[ty * tiles_x])
        .collect();
    let mut ids = vec![0u32; offsets[n_tiles]];
    let mut slices = Vec::new();
    let mut rest = ids.as_mut_slice();
    for (r0, r1) in row_bands(tiles_y, &row_entries) {
        let (t0, t1) = (r0 * tiles_x, r1 * tiles_x);
        let (band, tail) = rest.split_at_mut(offsets[t1] - offsets[t0]);
        slices.push((t0..t1, band));
        rest = tail;
    }
    slices.into_par_iter().for_each(|(tiles, band)| {
        let mut at = 0;
        for t in tiles {
            for run in &runs {
                let seg = run.list(t);
                band[at..at + seg.len()].copy_from_slice(seg);
                at += seg.len();
            }
        }
    });
    TileBins {
        width,
        height,
        tiles_x,
        tiles_y,
        offsets,
        ids,
    }
}

/// Sort splats collected in index order by (depth key, index): a stable least-significant-digit
/// radix sort on the depth key's 32 bits (three 11-bit digits, a digit every splat shares is
/// skipped), which keeps equal depths in index order. Linear time; serial, which on 50k splats
/// takes less time than a parallel comparison sort of the full keys.
fn sort_by_depth<T: Copy>(items: &mut Vec<(u64, T)>) {
    const BITS: u32 = 11;
    const BUCKETS: usize = 1 << BITS;
    debug_assert!(items.windows(2).all(|w| (w[0].0 as u32) < (w[1].0 as u32)));
    let mut buf = items.clone();
    for shift in [32, 32 + BITS, 32 + 2 * BITS] {
        let digit = |k: u64| ((k >> shift) as usize) & (BUCKETS - 1);
        let mut start = [0usize; BUCKETS];
        for &(k, _) in items.iter() {
            start[digit(k)] += 1;
        }
        if start.contains(&items.len()) {
            continue;
        }
        let mut at = 0;
        for s in start.iter_mut() {
            let c = *s;
            *s = at;
            at += c;
        }
        for &e in items.iter() {
            let d = digit(e.0);
            buf[start[d]] = e;
            start[d] += 1;
        }
        std::mem::swap(items, &mut buf);
    }
}

/// The entries of a contiguous run of the key order, sorted by tile (key order within a tile).
struct Run {
    /// `ids[offsets[t]..offsets[t + 1]]`: the run's splats in tile `t`.
    offsets: Vec<usize>,
    ids: Vec<u32>,
}

impl Run {
    fn new(keys: &[(u64, [u32; 4])], tiles_x: usize, n_tiles: usize) -> Run {
        let rect = |r: [u32; 4]| r.map(|x| x as usize);
        let mut offsets = vec![0usize; n_tiles + 1];
        for &(_, r) in keys {
            let r = rect(r);
            for ty in r[2]..r[3] {
                for tx in r[0]..r[1] {
                    offsets[ty * tiles_x + tx + 1] += 1;
                }
            }
        }
        for t in 0..n_tiles {
            offsets[t + 1] += offsets[t];
        }
        let mut fill = offsets.clone();
        let mut ids = vec![0u32; offsets[n_tiles]];
        for &(k, r) in keys {
            let r = rect(r);
            for ty in r[2]..r[3] {
                for tx in r[0]..r[1] {
                    let f = &mut fill[ty * tiles_x + tx];
                    ids[*f] = k as u32;
                    *f += 1;
                }
            }
        }
        Run { offsets, ids }
    }

    fn len(&self, t: usize) -> usize {
        self.offsets[t + 1] - self.offsets[t]
    }

    fn list(&self, t: usize) -> &[u32] {
        &self.ids[self.offsets[t]..self.offsets[t + 1]]
    }
}

/// Split tile rows `0..weights.len()` into contiguous bands of about equal total weight, a few
/// per worker thread so that work stealing can even out the rest (the split changes the
/// timing only, never the result).
fn row_bands(rows: usize, weights: &[usize]) -> Vec<(usize, usize)> {
    let k = (2 * rayon::current_num_threads()).clamp(1, rows.max(1));
    let total: usize = weights.iter().sum();
    let mut bands = Vec::with_capacity(k);
    let (mut start, mut acc) = (0, 0);
    for (ty, w) in weights.iter().enumerate() {
        acc += w;
        // Close band j once the running total reaches (j + 1) / k of the whole.
        if ty + 1 < rows && acc * k >= total * (bands.len() + 1) && bands.len() + 1 < k {
            bands.push((start, ty + 1));
            start = ty + 1;
        }
    }
    if start < rows {
        bands.push((start, rows));
    }
    bands
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

    /// Every tile's list against a brute force over all splats (the ones whose rectangle covers
    /// the tile, sorted by key), for pools of 1, 2, 3 and 8 threads: the banded passes must not
    /// drop, repeat or reorder an entry wherever the band edges fall.
    #[test]
    fn banded_lists_match_a_brute_force_for_any_thread_count() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (w, h) = (150usize, 230usize); // 10 x 15 tiles, partial last column and row
        let m: Vec<([f64; 2], u32, f64)> = (0..3000)
            .map(|_| {
                let u = rng.random_range(-40.0..190.0);
                let v = rng.random_range(-40.0..270.0);
                // Radii from culled to image-wide; depths with many ties.
                let r = [0, 1, 3, 8, 20, 90][rng.random_range(0..6usize)];
                let d = (rng.random_range(0..50u32) as f64) * 0.5 - 3.0;
                ([u, v], r, d)
            })
            .collect();
        let s = splats(&m);
        let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let mut want_ids = Vec::new();
        let mut want_offsets = vec![0];
        for t in 0..tx * ty {
            let mut list: Vec<u64> = (0..m.len())
                .filter(|&i| {
                    tile_rect(m[i].0[0], m[i].0[1], m[i].1, tx, ty).is_some_and(|r| {
                        (r[0]..r[1]).contains(&(t % tx)) && (r[2]..r[3]).contains(&(t / tx))
                    })
                })
                .map(|i| sort_key(m[i].2, i as u32))
                .collect();
            list.sort_unstable();
            want_ids.extend(list.iter().map(|&k| k as u32));
            want_offsets.push(want_ids.len());
        }
        assert!(want_ids.len() > 10_000, "the scene must fill the tiles");
        for threads in [1, 2, 3, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let b = pool.install(|| bin(&s, w, h));
            assert_eq!(b.offsets, want_offsets, "{threads} threads");
            assert_eq!(b.ids, want_ids, "{threads} threads");
        }
    }

    #[test]
    fn radix_sort_matches_a_comparison_sort_of_the_keys() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for n in [0, 1, 2, 100, 5000] {
            for spread in [1u32, 40, u32::MAX] {
                // Depths with ties, of both signs, NaN-free; payload = index.
                let mut v: Vec<(u64, u32)> = (0..n as u32)
                    .map(|i| {
                        let d = if spread == u32::MAX {
                            f32::from_bits(rng.random::<u32>() & 0xbfff_ffff) as f64
                        } else {
                            rng.random_range(0..spread) as f64 * 0.37 - 3.0
                        };
                        (sort_key(d, i), i)
                    })
                    .collect();
                let mut want = v.clone();
                want.sort_unstable_by_key(|e| e.0);
                sort_by_depth(&mut v);
                assert_eq!(v, want, "n {n} spread {spread}");
            }
        }
    }

    #[test]
    fn row_bands_cover_every_row_once() {
        for rows in [1, 2, 5, 16, 64] {
            for weights in [
                vec![1; rows],
                (0..rows).map(|r| r * r).collect(),
                vec![0; rows],
            ] {
                let b = row_bands(rows, &weights);
                assert_eq!(b.first().map(|x| x.0), Some(0));
                assert_eq!(b.last().map(|x| x.1), Some(rows));
                assert!(b.windows(2).all(|p| p[0].1 == p[1].0 && p[0].0 < p[0].1));
                assert!(b.iter().all(|x| x.0 < x.1));
            }
        }
        assert!(row_bands(0, &[]).is_empty());
    }
}
