//! Forward pass of the compositor, Eqs. (4)-(5): per tile, front-to-back alpha compositing of
//! the tile's work list in lane vectors of 8 or 16 pixels, recording per pixel the final
//! transmittance and `n_contrib`, and per tile the work-list prefix the backward visits; then
//! the tiles (computed in parallel) are assembled into the image in tile order.

use rayon::prelude::*;

use super::super::lanes::{add_blend, exp_k, mask, power_of, sel};
use super::super::tiles::{self, TileBins, TILE};
use super::dispatch::{self, Kernel};
use super::worklist::{gather, pack, Entry, Packed, WorkLists};
use super::{CompositeSaved, KernelWork, Lines, Phase, Splats, ALPHA_MAX, ALPHA_MIN, TP, T_MIN};
use crate::image2d::Image2d;
use crate::real::Real;
use crate::simd::Simd;

/// Per-tile forward result: colour (without background), final T, n_contrib, tile-local, and
/// the prefix of the work list up to the largest n_contrib (what the backward visits).
#[repr(C)]
pub(super) struct TileOut<R> {
    color: Lines<[R; TP]>,
    t: Lines<[R; TP]>,
    last: Lines<[u32; TP]>,
    blends: u64,
    stats: KernelWork,
    work: Vec<Entry<R>>,
}

/// Per-tile state of the forward kernel, tile-local.
struct State<'a, R> {
    t: &'a mut [R; TP],
    color: &'a mut [R; TP],
    last: &'a mut [u32; TP],
    done: &'a mut [u32; TP],
    nblend: &'a mut [u32; TP],
}

/// Eqs. (4)-(5) for entry `e` (list position `tag` - 1) at one pixel with centre offsets
/// (`dx`, `dy`), lane mask `act` and state T `t`, colour `c`, n_contrib `l`, done `d`, blends
/// `n`; returns the stop mask. Branch-free (so that the loops calling it vectorise): selects
/// reproduce the sequential skip / stop / blend logic exactly.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn blend_pixel<R: Real>(
    e: &Entry<R>,
    tag: u32,
    dx: R,
    dy: R,
    act: u32,
    t: &mut R,
    c: &mut R,
    l: &mut u32,
    d: &mut u32,
    n: &mut u32,
) -> u32 {
    let (amax, amin, tmin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN), R::c(T_MIN));
    let pw = power_of(e.a, e.b, e.c, dx, dy);
    let og = e.o * exp_k(pw);
    let alpha = sel(mask(og > amax), amax, og);
    let tt = *t;
    let next = tt * (R::one() - alpha);
    let valid = act & !*d & mask(pw <= R::zero()) & mask(alpha >= amin);
    let stop = valid & mask(next < tmin);
    let blend = valid & !stop;
    let c_new = add_blend(*c, e.col, alpha, tt);
    *c = sel(blend, c_new, *c);
    *t = sel(blend, next, tt);
    *l = (tag & blend) | (*l & !blend);
    *d |= stop;
    *n += blend & 1;
    stop
}

/// Eqs. (4)-(5) for entry `e` (list position `tag` - 1) at the `L` pixels from tile-local
/// offset `o`, with pixel-centre offsets `xh` (columns) and `dy` (rows) per lane and the lanes
/// `act`; returns the lanes that stopped (1) or not (0). Branch-free over the lanes
/// (vectorises; masked-out lanes keep their values); selects reproduce the sequential skip /
/// stop / blend logic exactly, and every lane does the same IEEE operations whatever `L`.
#[inline(always)]
fn blend_lanes<R: Real, const L: usize>(
    e: &Entry<R>,
    tag: u32,
    xh: &[R; L],
    dy: &[R; L],
    act: &[u32; L],
    st: &mut State<'_, R>,
    o: usize,
) -> [u32; L] {
    let tr: &mut [R; L] = (&mut st.t[o..o + L]).try_into().unwrap();
    let cr: &mut [R; L] = (&mut st.color[o..o + L]).try_into().unwrap();
    let lr: &mut [u32; L] = (&mut st.last[o..o + L]).try_into().unwrap();
    let dr: &mut [u32; L] = (&mut st.done[o..o + L]).try_into().unwrap();
    let nr: &mut [u32; L] = (&mut st.nblend[o..o + L]).try_into().unwrap();
    let mut stops = [0u32; L];
    for k in 0..L {
        let (t, c, l, d, n) = (&mut tr[k], &mut cr[k], &mut lr[k], &mut dr[k], &mut nr[k]);
        stops[k] = blend_pixel(e, tag, xh[k] - e.mx, dy[k], act[k], t, c, l, d, n) & 1;
    }
    stops
}

/// [`blend_lanes`] for two runs of `L` pixels at once (two whole tile rows, or two 8-column
/// halves of rows; per run `i`: tile-local offset `o[i]`, column offsets `xh[i]`, row offset
/// `dy[i]`, lanes `act[i]`), each run's state copied into local arrays so that the two chains
/// run side by side in one lane loop; the same operations per pixel.
#[inline(always)]
fn blend_rows2<R: Real, const L: usize>(
    e: &Entry<R>,
    tag: u32,
    xh: [&[R; L]; 2],
    dy: [R; 2],
    act: [&[u32; L]; 2],
    st: &mut State<'_, R>,
    o: [usize; 2],
) -> [[u32; L]; 2] {
    let get = |v: &[R; TP], i: usize| -> [R; L] { v[o[i]..o[i] + L].try_into().unwrap() };
    let getu = |v: &[u32; TP], i: usize| -> [u32; L] { v[o[i]..o[i] + L].try_into().unwrap() };
    let mut tr = [get(st.t, 0), get(st.t, 1)];
    let mut cr = [get(st.color, 0), get(st.color, 1)];
    let mut lr = [getu(st.last, 0), getu(st.last, 1)];
    let mut dr = [getu(st.done, 0), getu(st.done, 1)];
    let mut nr = [getu(st.nblend, 0), getu(st.nblend, 1)];
    let mut stops = [[0u32; L]; 2];
    for k in 0..L {
        for i in [0, 1] {
            let (t, c, l) = (&mut tr[i][k], &mut cr[i][k], &mut lr[i][k]);
            let (d, n) = (&mut dr[i][k], &mut nr[i][k]);
            let dx = xh[i][k] - e.mx;
            stops[i][k] = blend_pixel(e, tag, dx, dy[i], act[i][k], t, c, l, d, n) & 1;
        }
    }
    for i in [0, 1] {
        let r = o[i]..o[i] + L;
        st.t[r.clone()].copy_from_slice(&tr[i]);
        st.color[r.clone()].copy_from_slice(&cr[i]);
        st.last[r.clone()].copy_from_slice(&lr[i]);
        st.done[r.clone()].copy_from_slice(&dr[i]);
        st.nblend[r].copy_from_slice(&nr[i]);
    }
    stops
}

/// Counts the pixels of half `h` of tile row `r` that stopped (`stops`, one lane per column)
/// into the per-half and tile counts, and marks the half in `done_bits` when it has nothing
/// left to blend.
#[inline(always)]
fn count_half(
    stops: &[u32; 8],
    r: usize,
    h: usize,
    half_len: &[u32; 2],
    half_done: &mut [[u32; 2]; TILE],
    n_done: &mut u32,
    done_bits: &mut u32,
) {
    if stops.iter().fold(0, |a, &s| a | s) != 0 {
        let nd: u32 = stops.iter().sum();
        *n_done += nd;
        half_done[r][h] += nd;
        if half_done[r][h] == half_len[h] {
            *done_bits |= 1 << (2 * r + h);
        }
    }
}

/// Counts the pixels of tile row `r` that stopped (`stops`, one lane per column) into the
/// per-half and tile counts, and marks the halves left with nothing to blend in `done_bits`.
/// Pixels stop rarely (once each): the counts run only when one did.
#[inline(always)]
fn count_stops(
    stops: &[u32; TILE],
    r: usize,
    half_len: &[u32; 2],
    half_done: &mut [[u32; 2]; TILE],
    n_done: &mut u32,
    done_bits: &mut u32,
) {
    if stops.iter().fold(0, |a, &s| a | s) == 0 {
        return;
    }
    for h in 0..2 {
        let s: &[u32; 8] = stops[8 * h..8 * h + 8].try_into().unwrap();
        count_half(s, r, h, half_len, half_done, n_done, done_bits);
    }
}

/// The forward kernel of tile `t`, `W` pixels per lane vector (8: one 8-column half of a tile
/// row, the AVX2 width; 16: a whole tile row, the AVX-512 width, or one half of it where only
/// that half is visited). Both widths do the same IEEE operations per pixel and give the same
/// bits: a vector covering a half the chord test ruled out masks that half's lanes (they would
/// fail `alpha >= 1/255`), one covering a done half masks it through `done`.
#[inline(always)]
pub(super) fn forward_tile<R: Real, const W: usize>(
    packed: &[Option<Packed<R>>],
    bins: &TileBins,
    t: usize,
) -> TileOut<R> {
    const { assert!(W == 8 || W == 16) };
    let [x0, x1, y0, y1] = bins.pixel_rect(t);
    let npix = ((x1 - x0) * (y1 - y0)) as u32;
    let mut out = TileOut {
        color: Lines([R::zero(); TP]),
        t: Lines([R::one(); TP]),
        last: Lines([0u32; TP]),
        blends: 0,
        stats: KernelWork::default(),
        work: Vec::new(),
    };
    let mut done = Lines([0u32; TP]);
    // Blends per pixel (summed at the end of the tile: no horizontal sum per lane vector).
    let mut nblend = Lines([0u32; TP]);
    let mut st = State {
        t: &mut out.t.0,
        color: &mut out.color.0,
        last: &mut out.last.0,
        done: &mut done.0,
        nblend: &mut nblend.0,
    };
    let mut stats = KernelWork::default();
    let mut n_done = 0u32;
    // Pixels done per 8-column half of each tile row; a half (or row) whose pixels are all
    // done is skipped: every lane would fail the `!done` test, so skipping it changes no bit.
    let mut half_done = [[0u32; 2]; TILE];
    // Image pixels per half (fewer at the right edge of the image, 0 beyond it).
    let half_len: [u32; 2] = std::array::from_fn(|h| (x1 - x0).saturating_sub(8 * h).min(8) as u32);
    // Bit 2 r + h: half h of tile row r has no pixel left to blend (all done, or none in the
    // image), in the layout of `Entry::halves`.
    let mut done_bits = (0..TILE).fold(0u32, |b, r| {
        let empty = [half_len[0] == 0, half_len[1] == 0];
        b | (empty[0] as u32) << (2 * r) | (empty[1] as u32) << (2 * r + 1)
    });
    let half = R::c(0.5);
    // Pixel-centre x coordinates of the tile's columns.
    let xs: [R; TILE] = std::array::from_fn(|k| R::c((x0 + k) as f64) + half);
    // The work list is gathered as the loop goes, `GATHER` list positions at a time (the
    // splats behind the point where every pixel is done are never read); its prefix up to the
    // largest n_contrib is kept for the backward.
    let list_len = bins.list(t).len();
    let mut entries = Vec::with_capacity(list_len);
    let mut from = 0;
    let mut j = 0;
    loop {
        if j == entries.len() {
            if from == list_len {
                break;
            }
            from = gather(packed, bins, t, from, &mut entries);
            continue;
        }
        if n_done == npix {
            break;
        }
        let e = &entries[j];
        j += 1;
        let tag = j as u32;
        stats.entries += 1;
        let (k0, k1) = (e.x0 as usize - x0, e.x1 as usize - x0);
        // The entry's columns as lane masks, from a bit word (shifts, no compares).
        let cols = (1u32 << k1) - (1u32 << k0);
        let mut colm = [0u32; TILE];
        for (k, m) in colm.iter_mut().enumerate() {
            *m = 0u32.wrapping_sub(cols >> k & 1);
        }
        // The halves this entry visits: those meeting its chord with a pixel left.
        let todo = e.halves & !done_bits;
        // Its rows: bit 2 r set when row r has a half to visit.
        let rows = (todo | todo >> 1) & 0x5555_5555;
        stats.rows += rows.count_ones() as u64;
        // The 8 lanes of half `h` of tile row `r`, then whether that half is done. (A macro:
        // a closure would hold the state it updates borrowed across the loop.)
        macro_rules! half_row {
            ($r:expr, $h:expr) => {{
                let (r, h) = ($r, $h);
                stats.lanes += 8;
                let c0 = 8 * h;
                let act: &[u32; 8] = colm[c0..c0 + 8].try_into().unwrap();
                let xh: &[R; 8] = xs[c0..c0 + 8].try_into().unwrap();
                let dy = [R::c((y0 + r) as f64) + half - e.my; 8];
                let stops = blend_lanes(e, tag, xh, &dy, act, &mut st, r * TILE + c0);
                count_half(
                    &stops,
                    r,
                    h,
                    &half_len,
                    &mut half_done,
                    &mut n_done,
                    &mut done_bits,
                );
            }};
        }
        // The visits run over the set bits of `todo`: no branch per row or half but the
        // loops' own (about 10 % faster than testing each row, docs/measurements.md); with 16
        // lanes, the rows with one half to visit first, then the whole rows, two per lane
        // loop (the two rows' chains side by side).
        if W == 8 {
            let mut bits = todo;
            while bits != 0 {
                let b = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                half_row!(b / 2, b % 2);
            }
        } else {
            // Rows with one half to visit: 8 lanes (half the work of 16 where the CPU splits
            // 512-bit operations in two, as AMD Zen 4 does; faster on AMD Zen 5 too, where a
            // 16-lane step costs more than an 8-lane one on a real scene).
            let whole = todo & todo >> 1 & 0x5555_5555;
            let mut bits = todo & !(whole | whole << 1);
            while bits != 0 {
                let b = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if bits == 0 {
                    half_row!(b / 2, b % 2);
                    break;
                }
                let b2 = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                stats.lanes += 16;
                let (r, h, r2, h2) = (b / 2, b % 2, b2 / 2, b2 % 2);
                let x8 = |h: usize| -> &[R; 8] { xs[8 * h..8 * h + 8].try_into().unwrap() };
                let a8 = |h: usize| -> &[u32; 8] { colm[8 * h..8 * h + 8].try_into().unwrap() };
                let dyr = |r: usize| R::c((y0 + r) as f64) + half - e.my;
                let stops = blend_rows2(
                    e,
                    tag,
                    [x8(h), x8(h2)],
                    [dyr(r), dyr(r2)],
                    [a8(h), a8(h2)],
                    &mut st,
                    [r * TILE + 8 * h, r2 * TILE + 8 * h2],
                );
                for (s, (r, h)) in stops.iter().zip([(r, h), (r2, h2)]) {
                    count_half(
                        s,
                        r,
                        h,
                        &half_len,
                        &mut half_done,
                        &mut n_done,
                        &mut done_bits,
                    );
                }
            }
            // Whole rows, two per lane loop.
            let mut bits = whole;
            while bits != 0 {
                let r = bits.trailing_zeros() as usize / 2;
                bits &= bits - 1;
                let dyr = |r: usize| R::c((y0 + r) as f64) + half - e.my;
                if bits == 0 {
                    stats.lanes += TILE as u64;
                    let dy = [dyr(r); TILE];
                    let stops = blend_lanes(e, tag, &xs, &dy, &colm, &mut st, r * TILE);
                    count_stops(
                        &stops,
                        r,
                        &half_len,
                        &mut half_done,
                        &mut n_done,
                        &mut done_bits,
                    );
                    break;
                }
                let r2 = bits.trailing_zeros() as usize / 2;
                bits &= bits - 1;
                stats.lanes += 2 * TILE as u64;
                let stops = blend_rows2(
                    e,
                    tag,
                    [&xs; 2],
                    [dyr(r), dyr(r2)],
                    [&colm; 2],
                    &mut st,
                    [r * TILE, r2 * TILE],
                );
                for (s, r) in stops.iter().zip([r, r2]) {
                    count_stops(s, r, &half_len, &mut half_done, &mut n_done, &mut done_bits);
                }
            }
        }
    }
    out.stats = stats;
    out.blends = nblend.0.iter().map(|&n| n as u64).sum();
    // The backward visits the entries before the largest n_contrib only.
    entries.truncate(out.last.0.iter().copied().max().unwrap_or(0) as usize);
    out.work = entries;
    out
}

/// Composite `splats` into a `width` x `height` image over `background` (Eqs. 4-5).
///
/// Splats with radius 0 or any non-finite screen-space field are not drawn (see
/// [`tiles::drawn`]; [`validate`](super::validate) reports the latter as an error).
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

/// [`forward`] calling `probe` as each of its phases ends ([`Phase::BinPack`] to
/// [`Phase::Assemble`]), e.g. to time them. Same result as [`forward`].
pub fn forward_probed<R: Real>(
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
    probe: &mut dyn FnMut(Phase),
) -> (Image2d<R>, CompositeSaved<R>) {
    let k = Kernel::of(Simd::active());
    forward_kernel_probed(k, splats, width, height, background, probe)
}

pub(crate) fn forward_kernel<R: Real>(
    kernel: Kernel,
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> (Image2d<R>, CompositeSaved<R>) {
    forward_kernel_probed(kernel, splats, width, height, background, &mut |_| {})
}

fn forward_kernel_probed<R: Real>(
    kernel: Kernel,
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
    probe: &mut dyn FnMut(Phase),
) -> (Image2d<R>, CompositeSaved<R>) {
    // Independent of each other: the binning's serial steps (the depth sort) leave the other
    // workers to the packing.
    let (bins, packed) = rayon::join(
        || tiles::bin(splats, width, height),
        || pack(splats, width, height),
    );
    probe(Phase::BinPack);
    let mut outs: Vec<TileOut<R>> = (0..bins.n_tiles())
        .into_par_iter()
        .map(|t| dispatch::forward_tile(kernel, &packed, &bins, t))
        .collect();
    probe(Phase::ForwardTiles);
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
    let mut forward_work = KernelWork::default();
    for (t, o) in outs.iter().enumerate() {
        blends += o.blends;
        forward_work += o.stats;
        let [x0, x1, y0, y1] = bins.pixel_rect(t);
        for row in y0..y1 {
            for col in x0..x1 {
                let p = (row - y0) * TILE + col - x0;
                let q = row * width + col;
                img.data[q] = o.color.0[p] + o.t.0[p] * background;
                final_t[q] = o.t.0[p];
                n_contrib[q] = o.last.0[p];
            }
        }
    }
    let saved = CompositeSaved {
        bins,
        background,
        final_t,
        n_contrib,
        blends,
        forward_work,
        work,
    };
    probe(Phase::Assemble);
    (img, saved)
}
