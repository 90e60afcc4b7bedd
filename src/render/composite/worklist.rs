//! The per-tile work lists of the compositor (Eqs. 4-5): each drawn splat's pixel box (the
//! bounding box of the ellipse o G >= (1/255) e^-0.001, widened by one pixel, clipped to the
//! image), the per-row chord test that rules out 8-column halves of a tile row, and the list of
//! (tile, splat) entries in depth order that the forward and backward kernels walk. Outside a
//! box or a chord alpha < 1/255, so these limits change no bit of the result.

use rayon::prelude::*;

use super::super::tiles::{self, TileBins, TILE};
use super::Splats;
use crate::math::round;
use crate::real::Real;

/// Safety margin (in log space) of the per-splat pixel box.
const BOX_LOG_MARGIN: f64 = 1e-3;

/// Per tile, the prefix of its work list that [`backward`](fn@super::backward) visits: the entries
/// up to the largest `n_contrib` of the tile's pixels (later entries blend nowhere in the tile).
/// Built by [`forward`](fn@super::forward) from the splats it composited;
/// [`backward`](fn@super::backward) must be given the same splats.
#[derive(Clone, Debug, Default)]
pub struct WorkLists<R> {
    pub(super) tiles: Vec<Vec<Entry<R>>>,
}

/// One (tile, splat) pair with the splat's fields and its pixel box inside the tile.
#[derive(Clone, Copy, Debug)]
pub(super) struct Entry<R> {
    pub(super) id: u32,
    pub(super) mx: R,
    pub(super) my: R,
    pub(super) a: R,
    pub(super) b: R,
    pub(super) c: R,
    pub(super) o: R,
    pub(super) col: R,
    /// Pixel box [x0, x1) x [y0, y1), image coordinates.
    pub(super) x0: u32,
    pub(super) x1: u32,
    pub(super) y0: u32,
    pub(super) y1: u32,
    /// Bit `2 r + h`: the 8-column half `h` of tile row `r` (tile-local) may hold a pixel with
    /// alpha >= 1/255 ([`halves_word`]). Set by [`tile_entries`] and read by both kernels, so
    /// the chord test (a square root) runs once per (tile, splat, row), outside the pixel loops.
    pub(super) halves: u32,
}

/// Per-splat record of [`pack`]: the entry (box clipped to the image, `halves` unset) and the
/// f64 data of the per-row chord of the ellipse A dx^2 + 2 B dx dy + C dy^2 <= 2 l:
/// (mx, my, 1 / A, B / A, 2 l A, det) (det = 0: no chord test).
#[derive(Clone, Copy, Debug)]
pub(super) struct Packed<R> {
    pub(super) e: Entry<R>,
    pub(super) chord: [f64; 6],
}

/// The [`Entry::halves`] word of a splat with chord data `chord` ([`Packed`]) in the tile whose
/// top-left pixel is (`rx0`, `ry0`), for the tile rows of the image rows `y0..y1`: the bits of
/// the 8-column halves that meet the ellipse's chord on that row widened by one pixel (the same
/// margin as the box). Outside it alpha < 1/255, so skipping a half changes no bit (the margin
/// also covers the rounding of the chord, a few ulp). Branch-free over the 16 rows, so that it
/// vectorises.
#[inline(always)]
pub(super) fn halves_word(chord: &[f64; 6], y0: u32, y1: u32, rx0: u32, ry0: u32) -> u32 {
    let [mx, my, inv_a, b_a, two_la, det] = *chord;
    let w = [rx0 as f64, rx0 as f64 + 8.0, rx0 as f64 + 16.0];
    let mut bits = 0u32;
    for r in 0..TILE as u32 {
        let row = ry0 + r;
        let dy = row as f64 + 0.5 - my;
        // Negative when the row misses the (log-margin widened) ellipse: the square root is
        // then NaN and both tests below fail (alpha < 1/255 on all of the row).
        let disc = two_la - det * dy * dy;
        let half_w = disc.sqrt() * inv_a;
        let c = mx - b_a * dy;
        // Pixel centres col + 0.5 within [c - half_w - 1, c + half_w + 1].
        let (lo, hi) = (c - half_w - 1.5, c + half_w + 0.5);
        let in_box = (y0 <= row) & (row < y1);
        let h0 = (hi >= w[0]) & (lo <= w[1] - 1.0) & in_box;
        let h1 = (hi >= w[1]) & (lo <= w[2] - 1.0) & in_box;
        bits |= (h0 as u32 | (h1 as u32) << 1) << (2 * r);
    }
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(det > 0.0) {
        // No chord test: every half of the box's rows.
        bits =
            (y0.max(ry0)..y1.min(ry0 + TILE as u32)).fold(0, |b, row| b | 3 << (2 * (row - ry0)));
    }
    bits
}

/// Per-splat entry with its pixel box clipped to the image, or `None` when the splat cannot
/// reach alpha >= 1/255 anywhere (not drawn, o < 1/255, or an empty box). Computed once per
/// pass (parallel over splats, one packed record per splat, so that the per-tile gathers read
/// one record per entry: 112 bytes in f32, about two cache lines; a 64-byte record that
/// recomputed the chord data from the entry measured no faster).
pub(super) fn pack<R: Real>(s: &Splats<R>, width: usize, height: usize) -> Vec<Option<Packed<R>>> {
    let (w, h) = (width as f64, height as f64);
    (0..s.radius.len())
        .into_par_iter()
        .map(|i| {
            if !tiles::drawn(s, i) {
                return None;
            }
            let o = s.opacity[i].f64();
            // alpha <= o G <= o: nothing to draw unless o >= 1/255 (up to the margin).
            let l = (255.0 * o).ln() + BOX_LOG_MARGIN;
            // Positive phrasing so that NaN fails.
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            if !(l > 0.0) {
                return None;
            }
            let [a, b, c] = s.conic[i].map(|x| x.f64());
            let [mx, my] = s.mean2d[i].map(|x| x.f64());
            // {d : d^T Q d <= 2 l} has half-widths sqrt(2 l (Q^-1)_00), sqrt(2 l (Q^-1)_11).
            let det = a * c - b * b;
            let ok = det > 0.0 && det.is_finite();
            let (hx, hy) = if ok {
                ((2.0 * l * c / det).sqrt(), (2.0 * l * a / det).sqrt())
            } else {
                (f64::INFINITY, f64::INFINITY)
            };
            // Pixel centres col + 0.5 within [mx - hx - 1, mx + hx + 1].
            let x0 = round::ceil(mx - hx - 1.5).max(0.0);
            let x1 = (round::floor(mx + hx + 0.5) + 1.0).min(w);
            let y0 = round::ceil(my - hy - 1.5).max(0.0);
            let y1 = (round::floor(my + hy + 0.5) + 1.0).min(h);
            if !(x0 < x1 && y0 < y1) {
                return None;
            }
            let e = Entry {
                id: i as u32,
                mx: s.mean2d[i][0],
                my: s.mean2d[i][1],
                a: s.conic[i][0],
                b: s.conic[i][1],
                c: s.conic[i][2],
                o: s.opacity[i],
                col: s.color[i],
                x0: x0 as u32,
                x1: x1 as u32,
                y0: y0 as u32,
                y1: y1 as u32,
                halves: 0,
            };
            let chord = if ok {
                [mx, my, 1.0 / a, b / a, 2.0 * l * a, det]
            } else {
                [mx, my, 0.0, 0.0, 0.0, 0.0]
            };
            Some(Packed { e, chord })
        })
        .collect()
}

/// The work list of tile `t`: its splats in depth order, each with the box of pixels where it can
/// reach alpha >= 1/255 clipped to the tile and its [`Entry::halves`] word. Entries that reach
/// no pixel of the tile are dropped. [`backward`](fn@super::backward) reuses the prefix that
/// [`forward_tile`](super::forward::forward_tile) kept, or rebuilds the list with this function.
/// Inlined into the kernels, so that the chord tests are compiled for their instruction set.
#[inline(always)]
pub(super) fn tile_entries<R: Real>(
    packed: &[Option<Packed<R>>],
    bins: &TileBins,
    t: usize,
) -> Vec<Entry<R>> {
    let n = bins.list(t).len();
    let mut entries = Vec::with_capacity(n);
    let mut from = 0;
    while from < n {
        from = gather(packed, bins, t, from, &mut entries);
    }
    entries
}

/// List positions that [`gather`] reads per call.
const GATHER: usize = 64;

/// Appends to `entries` the work-list entries ([`tile_entries`]) of the [`GATHER`] positions
/// of tile `t`'s list from `from` on (fewer at its end), and returns the next position. The
/// forward gathers its list this way as it goes, so that the splats behind a tile whose pixels
/// are all done are never read.
#[inline(always)]
pub(super) fn gather<R: Real>(
    packed: &[Option<Packed<R>>],
    bins: &TileBins,
    t: usize,
    from: usize,
    entries: &mut Vec<Entry<R>>,
) -> usize {
    let [rx0, rx1, ry0, ry1] = bins.pixel_rect(t).map(|x| x as u32);
    // The gather first, in a loop of independent loads with the records `PREFETCH` entries
    // ahead requested early, so that the cache misses of the random per-splat reads overlap;
    // then the chord tests. Entries whose box misses the tile are dropped.
    const PREFETCH: usize = 16;
    let list = bins.list(t);
    let to = (from + GATHER).min(list.len());
    let start = entries.len();
    let mut chords = [[0.0f64; 6]; GATHER];
    let mut n = 0;
    for j in from..to {
        if let Some(&ahead) = list.get(j + PREFETCH) {
            prefetch(&packed[ahead as usize]);
        }
        let Some(Packed { e, chord }) = &packed[list[j] as usize] else {
            continue;
        };
        let (x0, x1) = (e.x0.max(rx0), e.x1.min(rx1));
        let (y0, y1) = (e.y0.max(ry0), e.y1.min(ry1));
        if x0 < x1 && y0 < y1 {
            entries.push(Entry {
                x0,
                x1,
                y0,
                y1,
                ..*e
            });
            chords[n] = *chord;
            n += 1;
        }
    }
    for (e, chord) in entries[start..].iter_mut().zip(&chords[..n]) {
        e.halves = halves_word(chord, e.y0, e.y1, rx0, ry0);
    }
    to
}

/// Ask the CPU to bring the cache lines of `x` into the cache (a hint: no effect on results).
#[inline(always)]
fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p = (x as *const T).cast::<i8>();
        let n = std::mem::size_of::<T>();
        // Every 64-byte line `x` touches: one address per 64 bytes and its last byte.
        let mut off = 0;
        while off < n {
            // SAFETY: a prefetch never faults and `p + off` is inside `x`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.add(off)) };
            off += 64;
        }
        // SAFETY: as above.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.add(n - 1)) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// Number of (pixel, splat) evaluations the kernels may perform: the sum over tiles of the
/// pixel boxes of their work lists (an upper bound; done pixels and rows are skipped).
pub fn box_pixels<R: Real>(splats: &Splats<R>, bins: &TileBins) -> u64 {
    let packed = pack(splats, bins.width, bins.height);
    (0..bins.n_tiles())
        .map(|t| {
            tile_entries(&packed, bins, t)
                .iter()
                .map(|e| ((e.x1 - e.x0) * (e.y1 - e.y0)) as u64)
                .sum::<u64>()
        })
        .sum()
}
