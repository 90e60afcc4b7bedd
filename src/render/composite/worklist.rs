//! The per-tile work lists of the compositor (Eqs. 4-5): each drawn splat's pixel box (the
//! bounding box of the ellipse o G >= (1/255) e^-0.001, widened by one pixel, clipped to the
//! image), the per-row chord test that rules out 8-column halves of a tile row, and the list of
//! (tile, splat) entries in depth order that the forward and backward kernels walk. Outside a
//! box or a chord alpha < 1/255, so these limits change no bit of the result.

use rayon::prelude::*;

use super::super::tiles::{self, TileBins};
use super::Splats;
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
    /// alpha >= 1/255 ([`halves`]). Set by [`forward_tile`](super::forward::forward_tile) for the
    /// rows it visits and read by [`backward_tile`](super::backward::backward_tile), so the chord
    /// test (a square root and two divisions) runs once per (tile, splat, row).
    pub(super) halves: u32,
}

/// Per-splat record of [`pack`]: the entry (box clipped to the image, `halves` unset) and the
/// f64 copies for the per-row chord of the ellipse A dx^2 + 2 B dx dy + C dy^2 <= 2 l:
/// (mx, my, A, B, 2 l A, det) (det = 0: no chord test).
#[derive(Clone, Copy, Debug)]
pub(super) struct Packed<R> {
    pub(super) e: Entry<R>,
    pub(super) chord: [f64; 6],
}

/// Which 8-column halves of tile row `row` (tile origin column `x0`) can hold a pixel with
/// alpha >= 1/255 for the splat with chord data `chord` ([`Packed`]): those meeting the
/// ellipse's chord on that row widened by one pixel (the same margin as the box). Outside it
/// alpha < 1/255, so skipping a half changes no bit.
#[inline(always)]
pub(super) fn halves(chord: &[f64; 6], row: usize, x0: usize) -> [bool; 2] {
    let [mx, my, a, b, two_la, det] = *chord;
    if det <= 0.0 {
        return [true, true];
    }
    let dy = row as f64 + 0.5 - my;
    let disc = two_la - det * dy * dy;
    if disc < 0.0 {
        // The row misses the (log-margin widened) ellipse: alpha < 1/255 on all of it.
        return [false, false];
    }
    let r = disc.sqrt() / a;
    let c = mx - b * dy / a;
    // Pixel centres col + 0.5 within [c - r - 1, c + r + 1].
    let (lo, hi) = (c - r - 1.5, c + r + 0.5);
    let w = [x0 as f64, x0 as f64 + 8.0, x0 as f64 + 16.0];
    [
        hi >= w[0] && lo <= w[1] - 1.0,
        hi >= w[1] && lo <= w[2] - 1.0,
    ]
}

/// Per-splat entry with its pixel box clipped to the image, or `None` when the splat cannot
/// reach alpha >= 1/255 anywhere (not drawn, o < 1/255, or an empty box). Computed once per
/// pass (parallel over splats, one packed record per splat so that the per-tile gathers touch
/// one cache line per entry).
pub(super) fn pack<R: Real>(s: &Splats<R>, bins: &TileBins) -> Vec<Option<Packed<R>>> {
    let (w, h) = (bins.width as f64, bins.height as f64);
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
            let x0 = (mx - hx - 1.5).ceil().max(0.0);
            let x1 = ((mx + hx + 0.5).floor() + 1.0).min(w);
            let y0 = (my - hy - 1.5).ceil().max(0.0);
            let y1 = ((my + hy + 0.5).floor() + 1.0).min(h);
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
                [mx, my, a, b, 2.0 * l * a, det]
            } else {
                [mx, my, a, b, 0.0, 0.0]
            };
            Some(Packed { e, chord })
        })
        .collect()
}

/// The work list of tile `t`: its splats in depth order, each with the box of pixels where it can
/// reach alpha >= 1/255 clipped to the tile. Entries that reach no pixel of the tile are dropped.
/// [`backward`](fn@super::backward) reuses the prefix that
/// [`forward_tile`](super::forward::forward_tile) kept, or rebuilds the list with this function.
///
/// `with_halves`: fill [`Entry::halves`] for every row of each box (what
/// [`backward`](fn@super::backward) needs when it rebuilds the list); otherwise it is left 0 and
/// [`forward_tile`](super::forward::forward_tile) fills it for the rows it visits.
pub(super) fn tile_entries<R: Real>(
    packed: &[Option<Packed<R>>],
    bins: &TileBins,
    t: usize,
    with_halves: bool,
) -> Vec<Entry<R>> {
    let rect = bins.pixel_rect(t).map(|x| x as u32);
    bins.list(t)
        .iter()
        .filter_map(|&id| tile_entry(packed, rect, id, with_halves))
        .collect()
}

/// The work-list entry of splat `id` in the tile with pixel rectangle `rect`, or `None` when
/// its box misses the tile.
#[inline(always)]
fn tile_entry<R: Real>(
    packed: &[Option<Packed<R>>],
    [rx0, rx1, ry0, ry1]: [u32; 4],
    id: u32,
    with_halves: bool,
) -> Option<Entry<R>> {
    let Packed { e, chord } = packed[id as usize].as_ref()?;
    let (x0, x1) = (e.x0.max(rx0), e.x1.min(rx1));
    let (y0, y1) = (e.y0.max(ry0), e.y1.min(ry1));
    if !(x0 < x1 && y0 < y1) {
        return None;
    }
    let mut bits = 0u32;
    if with_halves {
        for row in y0..y1 {
            let [h0, h1] = halves(chord, row as usize, rx0 as usize);
            bits |= half_bits([h0, h1], (row - ry0) as usize);
        }
    }
    Some(Entry {
        x0,
        x1,
        y0,
        y1,
        halves: bits,
        ..*e
    })
}

/// The bits of [`Entry::halves`] for tile row `r`.
#[inline(always)]
pub(super) fn half_bits([h0, h1]: [bool; 2], r: usize) -> u32 {
    ((h0 as u32) << (2 * r)) | ((h1 as u32) << (2 * r + 1))
}

/// Number of (pixel, splat) evaluations the kernels may perform: the sum over tiles of the
/// pixel boxes of their work lists (an upper bound; done pixels and rows are skipped).
pub fn box_pixels<R: Real>(splats: &Splats<R>, bins: &TileBins) -> u64 {
    let packed = pack(splats, bins);
    (0..bins.n_tiles())
        .map(|t| {
            tile_entries(&packed, bins, t, false)
                .iter()
                .map(|e| ((e.x1 - e.x0) * (e.y1 - e.y0)) as u64)
                .sum::<u64>()
        })
        .sum()
}
