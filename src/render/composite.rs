//! Eqs. (4)-(5): splats to an image by front-to-back alpha compositing over 16x16 tiles, and the
//! exact vector-Jacobian product of that image.
//!
//! Forward, per pixel p with centre (col + 0.5, row + 0.5) (the convention of `mean2d`), over
//! the splats of p's tile in (depth, index) order ([`super::tiles`]):
//! - d = p - mean2d, power = -0.5 (A dx^2 + C dy^2) - B dx dy (conic (A, B, C)); skip if
//!   power > 0 (3DGS);
//! - Eq. (4): alpha = min(0.99, o exp(power)); skip if alpha < 1/255;
//! - exclusive stop (3DGS): if T (1 - alpha) < 1e-4 the pixel is done and this splat is NOT
//!   blended;
//! - Eq. (5): C += c alpha T, T <- T (1 - alpha); the output is C + T_final * background.
//!
//! Saved for the backward pass (as 3DGS): the final T and the number of entries of the tile's
//! work list up to and including the last blended one (`n_contrib`), per pixel; and, per tile,
//! the work list up to the largest `n_contrib` with the per-row chord tests the forward made
//! ([`WorkLists`]), so that the backward neither re-packs the splats nor redoes the chord tests
//! (square root and divisions) of the rows it visits.
//!
//! Backward, per pixel back to front from the last blended entry, T recovered by division
//! T_k = T_{k+1} / (1 - alpha_k) (alpha <= 0.99, so no blow-up), S_k = sum_{j>k} c_j alpha_j T_j:
//! - dL/dc_k = g alpha_k T_k;
//! - dL/dalpha_k = g (c_k T_k - S_k / (1 - alpha_k)) - g bg T_final / (1 - alpha_k);
//! - where o G > 0.99 the clamp is active and d alpha / d(o G) = 0 (3DGS passes the gradient
//!   through; gsplat and brush zero it as we do); else dL/do = G dL/dalpha, dL/dpower =
//!   o G dL/dalpha, dL/dmean = dL/dpower (A dx + B dy, B dx + C dy), dL/dA = -dx^2/2 dL/dpower,
//!   dL/dB = -dx dy dL/dpower (B is the single off-diagonal parameter), dL/dC = -dy^2/2 dL/dpower.
//!   The hard cutoffs (power > 0, alpha < 1/255, the T stop, the tile box) are not
//!   differentiated: they are the same in both passes.
//!
//! Work limits that do not change any bit of the result: for each (tile, splat) the pixels
//! evaluated are restricted to the bounding box of the ellipse o G >= (1/255) e^-0.001 widened
//! by one pixel (outside it alpha < 1/255, so those pixels would be skipped anyway); splats with
//! o < (1/255) e^-0.001 are dropped; a tile stops when all its pixels are done; the forward
//! skips a row or an 8-column half whose pixels are all done (every lane would fail the `done`
//! test), the backward a row where no pixel has n_contrib > j (every lane would fail
//! `j < n_contrib`).
//!
//! Parallelism: rayon over tiles. Each tile is computed by one task in a fixed order; the
//! per-tile gradient records (one per list entry) are reduced sequentially in tile order, so
//! image and gradients are bit-identical for any thread count. No atomics.

use rayon::prelude::*;

use super::lanes::{exp_k, mask, power_of, sel};
use super::tiles::{self, TileBins, TILE};
use super::{SplatGrads, Splats};
use crate::image2d::Image2d;
use crate::real::Real;
use crate::simd::Simd;

mod naive;
pub use naive::naive_forward;

/// Eq. (4) opacity clamp (3DGS; gsplat since 2026).
pub const ALPHA_MAX: f64 = 0.99;
/// Splats with alpha below this are skipped at a pixel.
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
/// Exclusive transmittance stop.
pub const T_MIN: f64 = 1e-4;
/// Safety margin (in log space) of the per-splat pixel box.
const BOX_LOG_MARGIN: f64 = 1e-3;

/// Pixels per tile.
const TP: usize = TILE * TILE;

/// Floating-point operations (adds, multiplies, divisions, compares and min/selects on floats)
/// per pixel lane of the forward kernel, counted from its source, without the ones that are
/// the same for a whole tile row (hoisted out of the lane loop): dx and Eq. (4)'s exponent 8, `exp_f32`
/// 24, opacity and clamp 2, transmittance 2, three tests 3, Eq. (5)'s colour 3.
pub const FLOPS_PER_BLEND_FORWARD: u64 = 42;
/// The same count for the backward kernel: dx, exponent, exp and alpha 34, three tests 3, T recovery 3,
/// dL/dalpha 8, the two running sums 6, d(power) and the six gradient lanes 20.
pub const FLOPS_PER_BLEND_BACKWARD: u64 = 74;

/// What [`backward`] needs from [`forward`].
#[derive(Clone, Debug, Default)]
pub struct CompositeSaved<R: Real> {
    /// The tile lists (depth-sorted Gaussian indices).
    pub bins: TileBins,
    /// Background value of the forward pass.
    pub background: R,
    /// Final transmittance per pixel (row-major).
    pub final_t: Vec<R>,
    /// Per pixel: 1 + position of the last blended entry in its tile's work list (0 = none).
    pub n_contrib: Vec<u32>,
    /// Number of (pixel, splat) blends performed (throughput statistics).
    pub blends: u64,
    /// The tile work lists built by [`forward`], reused by [`backward`] (which rebuilds them
    /// when this is empty, e.g. for a `Default` value).
    pub work: WorkLists<R>,
}

/// Per tile, the prefix of its work list that [`backward`] visits: the entries up to the
/// largest `n_contrib` of the tile's pixels (later entries blend nowhere in the tile). Built by
/// [`forward`] from the splats it composited; [`backward`] must be given the same splats.
#[derive(Clone, Debug, Default)]
pub struct WorkLists<R> {
    tiles: Vec<Vec<Entry<R>>>,
}

/// One (tile, splat) pair with the splat's fields and its pixel box inside the tile.
#[derive(Clone, Copy, Debug)]
struct Entry<R> {
    id: u32,
    mx: R,
    my: R,
    a: R,
    b: R,
    c: R,
    o: R,
    col: R,
    /// Pixel box [x0, x1) x [y0, y1), image coordinates.
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    /// Bit `2 r + h`: the 8-column half `h` of tile row `r` (tile-local) may hold a pixel with
    /// alpha >= 1/255 ([`halves`]). Set by [`forward_tile`] for the rows it visits and read by
    /// [`backward_tile`], so the chord test (a square root and two divisions) runs once per
    /// (tile, splat, row).
    halves: u32,
}

/// Per-splat record of [`pack`]: the entry (box clipped to the image, `halves` unset) and the
/// f64 copies for the per-row chord of the ellipse A dx^2 + 2 B dx dy + C dy^2 <= 2 l:
/// (mx, my, A, B, 2 l A, det) (det = 0: no chord test).
#[derive(Clone, Copy, Debug)]
struct Packed<R> {
    e: Entry<R>,
    chord: [f64; 6],
}

/// Which 8-column halves of tile row `row` (tile origin column `x0`) can hold a pixel with
/// alpha >= 1/255 for the splat with chord data `chord` ([`Packed`]): those meeting the
/// ellipse's chord on that row widened by one pixel (the same margin as the box). Outside it
/// alpha < 1/255, so skipping a half changes no bit.
#[inline(always)]
fn halves(chord: &[f64; 6], row: usize, x0: usize) -> [bool; 2] {
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
fn pack<R: Real>(s: &Splats<R>, bins: &TileBins) -> Vec<Option<Packed<R>>> {
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

/// The work list of tile `t`: its splats in depth order, each with the box of pixels where it
/// can reach alpha >= 1/255 clipped to the tile. Entries that reach no pixel of the tile are
/// dropped. [`backward`] reuses the prefix that [`forward_tile`] kept, or rebuilds the list
/// with this function.
///
/// `with_halves`: fill [`Entry::halves`] for every row of each box (what [`backward`] needs
/// when it rebuilds the list); otherwise it is left 0 and [`forward_tile`] fills it for the
/// rows it visits.
fn tile_entries<R: Real>(
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
fn half_bits([h0, h1]: [bool; 2], r: usize) -> u32 {
    ((h0 as u32) << (2 * r)) | ((h1 as u32) << (2 * r + 1))
}

/// Per-tile forward result: colour (without background), final T, n_contrib, tile-local, and
/// the prefix of the work list up to the largest n_contrib (what the backward visits).
struct TileOut<R> {
    color: [R; TP],
    t: [R; TP],
    last: [u32; TP],
    blends: u64,
    work: Vec<Entry<R>>,
}

/// The forward kernel of tile `t`, `W` pixels per lane vector (8: one 8-column half of a tile
/// row, the AVX2 width; 16: a whole tile row, the AVX-512 width). Both widths do the same IEEE
/// operations per pixel and give the same bits: a vector covering a half the chord test ruled
/// out masks that half's lanes (they would fail `alpha >= 1/255`), one covering a done half
/// masks it through `done`.
#[inline(always)]
fn forward_tile<R: Real, const W: usize>(
    packed: &[Option<Packed<R>>],
    bins: &TileBins,
    t: usize,
) -> TileOut<R> {
    const { assert!(W == 8 || W == 16) };
    let [x0, x1, y0, y1] = bins.pixel_rect(t);
    let npix = ((x1 - x0) * (y1 - y0)) as u32;
    let mut out = TileOut {
        color: [R::zero(); TP],
        t: [R::one(); TP],
        last: [0u32; TP],
        blends: 0,
        work: Vec::new(),
    };
    let mut done = [0u32; TP];
    let mut n_done = 0u32;
    // Pixels done per 8-column half of each tile row; a half (or row) whose pixels are all
    // done is skipped: every lane would fail the `!done` test, so skipping it changes no bit.
    let mut half_done = [[0u32; 2]; TILE];
    // Image pixels per half (fewer at the right edge of the image, 0 beyond it).
    let half_len: [u32; 2] = std::array::from_fn(|h| (x1 - x0).saturating_sub(8 * h).min(8) as u32);
    let (amax, amin, tmin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN), R::c(T_MIN));
    let one = R::one();
    let half = R::c(0.5);
    // Pixel-centre x coordinates of the tile's columns.
    let xs: [R; TILE] = std::array::from_fn(|k| R::c((x0 + k) as f64) + half);
    // The whole work list is gathered first (independent loads, so the cache misses of the
    // random per-splat reads overlap); its prefix up to the largest n_contrib is kept for the
    // backward.
    let mut entries = tile_entries(packed, bins, t, false);
    for (j, e) in entries.iter_mut().enumerate() {
        if n_done == npix {
            break;
        }
        // The chord test of each visited row, recorded in `halves` for the backward. A row the
        // forward skips here (all its pixels done before entry j) has n_contrib <= j at every
        // pixel, so the backward skips it too and its bits are never read.
        let Some(Packed { chord, .. }) = packed[e.id as usize].as_ref() else {
            unreachable!("work-list entries come from packed splats")
        };
        let mut bits = 0u32;
        let tag = j as u32 + 1;
        let (k0, k1) = (e.x0 as usize - x0, e.x1 as usize - x0);
        let colm: [u32; TILE] = std::array::from_fn(|k| mask(k0 <= k && k < k1));
        for row in e.y0 as usize..e.y1 as usize {
            let hd = &mut half_done[row - y0];
            if *hd == half_len {
                continue;
            }
            let dy = R::c(row as f64) + half - e.my;
            let base = (row - y0) * TILE;
            let hv = halves(chord, row, x0);
            bits |= half_bits(hv, row - y0);
            let go = [hv[0] && hd[0] != half_len[0], hv[1] && hd[1] != half_len[1]];
            for v in 0..TILE / W {
                let (c0, h0) = (v * W, v * W / 8);
                if !go[h0..h0 + W / 8].iter().any(|&g| g) {
                    continue;
                }
                // Lanes in the entry's box and in a half that meets the chord (with 8 lanes
                // the half is visited only when it meets it).
                let act: [u32; W] = if W == 8 {
                    colm[c0..c0 + W].try_into().unwrap()
                } else {
                    std::array::from_fn(|k| colm[c0 + k] & mask(hv[(c0 + k) / 8]))
                };
                let mut nb = 0u32;
                let mut nd = 0u32;
                let mut stops = [0u32; W];
                let o = base + c0;
                let tr: &mut [R; W] = (&mut out.t[o..o + W]).try_into().unwrap();
                let cr: &mut [R; W] = (&mut out.color[o..o + W]).try_into().unwrap();
                let lr: &mut [u32; W] = (&mut out.last[o..o + W]).try_into().unwrap();
                let dr: &mut [u32; W] = (&mut done[o..o + W]).try_into().unwrap();
                let xh: &[R; W] = xs[c0..c0 + W].try_into().unwrap();
                // Branch-free over the W columns (vectorises; masked-out columns keep their
                // values); selects reproduce the sequential skip / stop / blend logic exactly.
                for k in 0..W {
                    let dx = xh[k] - e.mx;
                    let pw = power_of(e.a, e.b, e.c, dx, dy);
                    let og = e.o * exp_k(pw);
                    let alpha = sel(mask(og > amax), amax, og);
                    let tt = tr[k];
                    let next = tt * (one - alpha);
                    let valid = act[k] & !dr[k] & mask(pw <= R::zero()) & mask(alpha >= amin);
                    let stop = valid & mask(next < tmin);
                    let blend = valid & !stop;
                    let c_new = cr[k] + e.col * alpha * tt;
                    cr[k] = sel(blend, c_new, cr[k]);
                    tr[k] = sel(blend, next, tt);
                    lr[k] = (tag & blend) | (lr[k] & !blend);
                    dr[k] |= stop;
                    nb += blend & 1;
                    if W == 8 {
                        nd += stop & 1;
                    } else {
                        stops[k] = stop & 1;
                    }
                }
                out.blends += nb as u64;
                if W == 8 {
                    n_done += nd;
                    hd[h0] += nd;
                } else {
                    for (h, s) in stops.chunks_exact(8).enumerate() {
                        let nd: u32 = s.iter().sum();
                        n_done += nd;
                        hd[h0 + h] += nd;
                    }
                }
            }
        }
        e.halves = bits;
    }
    // The backward visits the entries before the largest n_contrib only.
    entries.truncate(out.last.iter().copied().max().unwrap_or(0) as usize);
    out.work = entries;
    out
}

/// Composite `splats` into a `width` x `height` image over `background` (Eqs. 4-5).
///
/// Splats with radius 0 or any non-finite screen-space field are not drawn (see
/// [`tiles::drawn`]; [`validate`] reports the latter as an error).
pub fn forward<R: Real>(
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> (Image2d<R>, CompositeSaved<R>) {
    forward_with(Simd::active(), splats, width, height, background)
}

/// [`forward`] with the tile kernels compiled for `simd` (or, when the CPU lacks it, for the
/// widest supported narrower set). Every path gives the same bits.
pub fn forward_with<R: Real>(
    simd: Simd,
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> (Image2d<R>, CompositeSaved<R>) {
    forward_kernel(Kernel::of(simd), splats, width, height, background)
}

pub(crate) fn forward_kernel<R: Real>(
    kernel: Kernel,
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> (Image2d<R>, CompositeSaved<R>) {
    let bins = tiles::bin(splats, width, height);
    let packed = pack(splats, &bins);
    let mut outs: Vec<TileOut<R>> = (0..bins.n_tiles())
        .into_par_iter()
        .map(|t| dispatch::forward_tile(kernel, &packed, &bins, t))
        .collect();
    let work = WorkLists {
        tiles: outs
            .iter_mut()
            .map(|o| std::mem::take(&mut o.work))
            .collect(),
    };
    let mut img = Image2d::filled(width, height, R::zero());
    let mut final_t = vec![R::one(); width * height];
    let mut n_contrib = vec![0u32; width * height];
    let mut blends = 0;
    for (t, o) in outs.iter().enumerate() {
        blends += o.blends;
        let [x0, x1, y0, y1] = bins.pixel_rect(t);
        for row in y0..y1 {
            for col in x0..x1 {
                let p = (row - y0) * TILE + col - x0;
                let q = row * width + col;
                img.data[q] = o.color[p] + o.t[p] * background;
                final_t[q] = o.t[p];
                n_contrib[q] = o.last[p];
            }
        }
    }
    (
        img,
        CompositeSaved {
            bins,
            background,
            final_t,
            n_contrib,
            blends,
            work,
        },
    )
}

/// Error if a drawn splat (radius > 0) has a non-finite field, naming the splat and the field.
/// [`forward`] skips such splats; callers that want an error call this first.
pub fn validate<R: Real>(splats: &Splats<R>) -> crate::error::Result<()> {
    for i in 0..splats.radius.len() {
        if splats.radius[i] == 0 {
            continue;
        }
        let fields: [(&str, &[R]); 5] = [
            ("mean2d", &splats.mean2d[i]),
            ("conic", &splats.conic[i]),
            ("opacity", std::slice::from_ref(&splats.opacity[i])),
            ("color", std::slice::from_ref(&splats.color[i])),
            ("depth", std::slice::from_ref(&splats.depth[i])),
        ];
        for (name, v) in fields {
            if let Some(x) = v.iter().find(|x| !x.is_finite()) {
                return Err(crate::error::Error::NonFinite {
                    what: format!("splat {i} `{name}`"),
                    index: i,
                    value: x.f64(),
                });
            }
        }
    }
    Ok(())
}

/// Which compiled tile kernel runs: the instruction set and the lane width (8 or 16 pixels).
/// Every combination gives the same bits; [`Kernel::of`] picks the natural width of a set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Kernel {
    pub simd: Simd,
    pub wide: bool,
}

impl Kernel {
    /// The kernel of `simd` (or of the widest supported narrower set): 16 lanes with AVX-512,
    /// 8 otherwise.
    pub fn of(simd: Simd) -> Kernel {
        let simd = simd.or_narrower();
        Kernel {
            simd,
            wide: simd == Simd::Avx512,
        }
    }
}

/// The tile kernels compiled for each instruction set ([`Simd`]) and chosen at run time: the
/// baseline target with 8 lanes, AVX2 with 8 or 16 lanes, AVX-512 with 16 lanes. No version
/// enables floating-point contraction (Rust never fuses a multiply and an add by itself), so
/// all perform the same IEEE operations per pixel and give the same bits.
mod dispatch {
    use super::*;

    pub(super) fn forward_tile<R: Real>(
        k: Kernel,
        s: &[Option<Packed<R>>],
        bins: &TileBins,
        t: usize,
    ) -> TileOut<R> {
        #[cfg(target_arch = "x86_64")]
        match k.simd {
            // SAFETY: the CPU supports the instruction set (checked by `supported`).
            Simd::Avx512 if Simd::Avx512.supported() => {
                return unsafe { forward_tile_avx512(s, bins, t) };
            }
            Simd::Avx2 if k.wide && Simd::Avx2.supported() => {
                return unsafe { forward_tile_avx2::<R, 16>(s, bins, t) };
            }
            Simd::Avx2 if Simd::Avx2.supported() => {
                return unsafe { forward_tile_avx2::<R, 8>(s, bins, t) };
            }
            _ => {}
        }
        let _ = k;
        super::forward_tile::<R, 8>(s, bins, t)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn forward_tile_avx2<R: Real, const W: usize>(
        s: &[Option<Packed<R>>],
        bins: &TileBins,
        t: usize,
    ) -> TileOut<R> {
        super::forward_tile::<R, W>(s, bins, t)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl")]
    unsafe fn forward_tile_avx512<R: Real>(
        s: &[Option<Packed<R>>],
        bins: &TileBins,
        t: usize,
    ) -> TileOut<R> {
        super::forward_tile::<R, 16>(s, bins, t)
    }

    pub(super) fn backward_tile<R: Real>(
        k: Kernel,
        s: &[Option<Packed<R>>],
        saved: &CompositeSaved<R>,
        d_image: &Image2d<R>,
        t: usize,
    ) -> Vec<Rec<R>> {
        #[cfg(target_arch = "x86_64")]
        match k.simd {
            // SAFETY: the CPU supports the instruction set (checked by `supported`).
            Simd::Avx512 if Simd::Avx512.supported() => {
                return unsafe { backward_tile_avx512(s, saved, d_image, t) };
            }
            Simd::Avx2 if k.wide && Simd::Avx2.supported() => {
                return unsafe { backward_tile_avx2::<R, 16>(s, saved, d_image, t) };
            }
            Simd::Avx2 if Simd::Avx2.supported() => {
                return unsafe { backward_tile_avx2::<R, 8>(s, saved, d_image, t) };
            }
            _ => {}
        }
        let _ = k;
        super::backward_tile::<R, 8>(s, saved, d_image, t)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn backward_tile_avx2<R: Real, const W: usize>(
        s: &[Option<Packed<R>>],
        saved: &CompositeSaved<R>,
        d_image: &Image2d<R>,
        t: usize,
    ) -> Vec<Rec<R>> {
        super::backward_tile::<R, W>(s, saved, d_image, t)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl")]
    unsafe fn backward_tile_avx512<R: Real>(
        s: &[Option<Packed<R>>],
        saved: &CompositeSaved<R>,
        d_image: &Image2d<R>,
        t: usize,
    ) -> Vec<Rec<R>> {
        super::backward_tile::<R, 16>(s, saved, d_image, t)
    }
}

/// Gradient record of one work-list entry: (mean x, mean y, A, B, C, opacity, colour).
type Rec<R> = (u32, [R; 7]);

/// The backward kernel of tile `t`, `W` pixels per lane vector (see [`forward_tile`]; both
/// widths give the same bits: per column, the rows are summed in the same order).
#[inline(always)]
fn backward_tile<R: Real, const W: usize>(
    packed: &[Option<Packed<R>>],
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
    t: usize,
) -> Vec<Rec<R>> {
    const { assert!(W == 8 || W == 16) };
    let bins = &saved.bins;
    let width = bins.width;
    let [x0, x1, y0, y1] = bins.pixel_rect(t);
    let mut tcur = [R::zero(); TP];
    let mut tfin = [R::zero(); TP];
    let mut behind = [R::zero(); TP];
    let mut g = [R::zero(); TP];
    let mut last = [0u32; TP];
    let mut max_last = 0u32;
    // Largest n_contrib per tile row: rows with nothing left to visit are skipped.
    let mut row_last = [0u32; TILE];
    for row in y0..y1 {
        for col in x0..x1 {
            let p = (row - y0) * TILE + col - x0;
            let q = row * width + col;
            tcur[p] = saved.final_t[q];
            tfin[p] = saved.final_t[q];
            g[p] = d_image.data[q];
            last[p] = saved.n_contrib[q];
            row_last[row - y0] = row_last[row - y0].max(last[p]);
        }
        max_last = max_last.max(row_last[row - y0]);
    }
    if max_last == 0 {
        return Vec::new();
    }
    let built;
    let entries: &[Entry<R>] = if saved.work.tiles.len() == bins.n_tiles() {
        &saved.work.tiles[t]
    } else {
        built = tile_entries(packed, bins, t, true);
        &built
    };
    let (amax, amin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN));
    let one = R::one();
    let zero = R::zero();
    let half = R::c(0.5);
    let bg = saved.background;
    let xs: [R; TILE] = std::array::from_fn(|k| R::c((x0 + k) as f64) + half);
    let mut recs = Vec::with_capacity(max_last as usize);
    // Per-column partial sums (each column sums its own rows in order), reduced over the
    // columns in order at the end of the entry.
    let mut lanes = [[zero; TILE]; 7];
    for j in (0..max_last as usize).rev() {
        let e = &entries[j];
        let ju = j as u32;
        let (k0, k1) = (e.x0 as usize - x0, e.x1 as usize - x0);
        let colm: [u32; TILE] = std::array::from_fn(|k| mask(k0 <= k && k < k1));
        let mut any = 0u32;
        for l in lanes.iter_mut() {
            *l = [zero; TILE];
        }
        for row in e.y0 as usize..e.y1 as usize {
            if ju >= row_last[row - y0] {
                continue;
            }
            let dy = R::c(row as f64) + half - e.my;
            let base = (row - y0) * TILE;
            let r2 = 2 * (row - y0);
            let hv = [e.halves >> r2 & 1 != 0, e.halves >> (r2 + 1) & 1 != 0];
            for v in 0..TILE / W {
                let (c0, h0) = (v * W, v * W / 8);
                if !hv[h0..h0 + W / 8].iter().any(|&h| h) {
                    continue;
                }
                let act: [u32; W] = if W == 8 {
                    colm[c0..c0 + W].try_into().unwrap()
                } else {
                    std::array::from_fn(|k| colm[c0 + k] & mask(hv[(c0 + k) / 8]))
                };
                let r = base + c0..base + c0 + W;
                let tc: &mut [R; W] = (&mut tcur[r.clone()]).try_into().unwrap();
                let tf: &[R; W] = (&tfin[r.clone()]).try_into().unwrap();
                let bh: &mut [R; W] = (&mut behind[r.clone()]).try_into().unwrap();
                let gr: &[R; W] = (&g[r.clone()]).try_into().unwrap();
                let lr: &[u32; W] = (&last[r]).try_into().unwrap();
                let xh: &[R; W] = xs[c0..c0 + W].try_into().unwrap();
                let [l0, l1, l2, l3, l4, l5, l6] = &mut lanes;
                let l0: &mut [R; W] = (&mut l0[c0..c0 + W]).try_into().unwrap();
                let l1: &mut [R; W] = (&mut l1[c0..c0 + W]).try_into().unwrap();
                let l2: &mut [R; W] = (&mut l2[c0..c0 + W]).try_into().unwrap();
                let l3: &mut [R; W] = (&mut l3[c0..c0 + W]).try_into().unwrap();
                let l4: &mut [R; W] = (&mut l4[c0..c0 + W]).try_into().unwrap();
                let l5: &mut [R; W] = (&mut l5[c0..c0 + W]).try_into().unwrap();
                let l6: &mut [R; W] = (&mut l6[c0..c0 + W]).try_into().unwrap();
                for k in 0..W {
                    let dx = xh[k] - e.mx;
                    let pw = power_of(e.a, e.b, e.c, dx, dy);
                    let gk = exp_k(pw);
                    let og = e.o * gk;
                    let alpha = sel(mask(og > amax), amax, og);
                    let valid = act[k] & mask(ju < lr[k]) & mask(pw <= zero) & mask(alpha >= amin);
                    let inv = one / (one - alpha);
                    let tk = tc[k] * inv;
                    let gp = gr[k];
                    let d_alpha = gp * (e.col * tk - bh[k] * inv) - gp * bg * tf[k] * inv;
                    bh[k] = sel(valid, bh[k] + e.col * alpha * tk, bh[k]);
                    tc[k] = sel(valid, tk, tc[k]);
                    l6[k] = sel(valid, l6[k] + gp * alpha * tk, l6[k]);
                    // Clamp active (o G > 0.99): d alpha / d (o G) = 0.
                    let live = valid & mask(og <= amax);
                    let d_pw = og * d_alpha;
                    l5[k] = sel(live, l5[k] + gk * d_alpha, l5[k]);
                    l0[k] = sel(live, l0[k] + d_pw * (e.a * dx + e.b * dy), l0[k]);
                    l1[k] = sel(live, l1[k] + d_pw * (e.b * dx + e.c * dy), l1[k]);
                    l2[k] = sel(live, l2[k] - half * dx * dx * d_pw, l2[k]);
                    l3[k] = sel(live, l3[k] - dx * dy * d_pw, l3[k]);
                    l4[k] = sel(live, l4[k] - half * dy * dy * d_pw, l4[k]);
                    any |= valid;
                }
            }
        }
        if any > 0 {
            let mut acc = [zero; 7];
            for (a, l) in acc.iter_mut().zip(&lanes) {
                for v in &l[k0..k1] {
                    *a += *v;
                }
            }
            recs.push((e.id, acc));
        }
    }
    recs
}

/// Vector-Jacobian product of [`forward`]: the gradient of sum(d_image * image) with respect
/// to the splat fields (mean2d in pixels, conic (A, B, C) with B the single off-diagonal
/// parameter, opacity after the sigmoid, colour). Splats that are not drawn get 0.
pub fn backward<R: Real>(
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    backward_with(Simd::active(), splats, saved, d_image)
}

/// [`backward`] with the tile kernels compiled for `simd` (see [`forward_with`]).
pub fn backward_with<R: Real>(
    simd: Simd,
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    backward_kernel(Kernel::of(simd), splats, saved, d_image)
}

pub(crate) fn backward_kernel<R: Real>(
    kernel: Kernel,
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    let n = splats.mean2d.len();
    assert_eq!(
        (d_image.width, d_image.height),
        (saved.bins.width, saved.bins.height),
        "d_image has the size of the rendered image"
    );
    // The work lists saved by forward, or (when absent) rebuilt from the splats.
    let packed = if saved.work.tiles.len() == saved.bins.n_tiles() {
        Vec::new()
    } else {
        pack(splats, &saved.bins)
    };
    let recs: Vec<Vec<Rec<R>>> = (0..saved.bins.n_tiles())
        .into_par_iter()
        .map(|t| dispatch::backward_tile(kernel, &packed, saved, d_image, t))
        .collect();
    let mut out = SplatGrads {
        mean2d: vec![[R::zero(); 2]; n],
        conic: vec![[R::zero(); 3]; n],
        opacity: vec![R::zero(); n],
        color: vec![R::zero(); n],
    };
    // Sequential reduction in tile order (and, within a tile, back-to-front entry order).
    for tile in &recs {
        for (id, a) in tile {
            let i = *id as usize;
            out.mean2d[i][0] += a[0];
            out.mean2d[i][1] += a[1];
            out.conic[i][0] += a[2];
            out.conic[i][1] += a[3];
            out.conic[i][2] += a[4];
            out.opacity[i] += a[5];
            out.color[i] += a[6];
        }
    }
    out
}

#[cfg(test)]
mod tests;

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
