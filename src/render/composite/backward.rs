//! Backward pass of the compositor: the exact vector-Jacobian product of Eqs. (4)-(5) (the
//! formulas are in the stage header, [`super`]). Per tile, back to front over the work list
//! saved by the forward, with T recovered by division, an entry's tile rows two per lane loop
//! ([`rows_step`]); one gradient record per entry, reduced sequentially in tile order so that
//! the gradients are bit-identical for any thread count.

use std::sync::Mutex;

use rayon::prelude::*;

use super::super::lanes::{add_blend, exp_k, mask, power_of, sel};
use super::super::tiles::TILE;
use super::super::SplatGrads;
use super::colsum::column_sums;
use super::dispatch::{self, Kernel};
use super::worklist::{pack, tile_entries, Entry, Packed};
use super::{
    slot_index, CompositeSaved, KernelWork, Lines, Phase, SlotLanes, Splats, ALPHA_MAX, ALPHA_MIN,
    TP,
};
use crate::image2d::Image2d;
use crate::par::lock;
use crate::real::Real;
use crate::simd::Simd;

/// Gradient record of one work-list entry: (mean x, mean y, A, B, C, opacity, colour).
pub(super) type Rec<R> = (u32, [R; 7]);

/// Output of the backward kernel of one tile: its gradient records and its work.
pub(super) type TileGrads<R> = (Vec<Rec<R>>, KernelWork);

/// The backward kernel of tile `t`, `W` pixels per lane vector (see
/// [`forward_tile`](super::forward::forward_tile)); `X512`: compiled for AVX-512 (the record
/// sums of [`column_sums`]). Its steps are the pixel pairs of
/// [`slot_index`]: for one 8-column half of the tile, that half of an even tile row and of the
/// row below it, 16 pixels (one step with 16 lanes, two with 8). Per column the backward keeps
/// two sums, over the even and over the odd rows, each adding its rows in ascending order, and
/// adds them (even + odd) at the end of the entry: both widths give the same bits.
#[inline(always)]
pub(super) fn backward_tile<R: Real, const W: usize, const X512: bool>(
    packed: &[Option<Packed<R>>],
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
    t: usize,
) -> TileGrads<R> {
    const { assert!(W == 8 || W == 16) };
    let bins = &saved.bins;
    let width = bins.width;
    let [x0, x1, y0, y1] = bins.pixel_rect(t);
    let mut px = Pixels {
        tcur: [R::zero(); TP],
        tfin: [R::zero(); TP],
        behind: [R::zero(); TP],
        g: [R::zero(); TP],
        last: [0u32; TP],
    };
    // Largest n_contrib per 8-column half of each tile row (index 2 r + h, the layout of
    // `Entry::halves`): halves with nothing left to visit are skipped.
    let mut half_last = [0u32; 2 * TILE];
    for row in y0..y1 {
        for col in x0..x1 {
            let p = slot_index(row - y0, col - x0);
            let q = row * width + col;
            px.tcur[p] = saved.final_t[q];
            px.tfin[p] = saved.final_t[q];
            px.g[p] = d_image.data[q];
            px.last[p] = saved.n_contrib[q];
            let i = 2 * (row - y0) + (col - x0) / 8;
            half_last[i] = half_last[i].max(px.last[p]);
        }
    }
    let max_last = half_last.iter().copied().max().unwrap_or(0);
    if max_last == 0 {
        return (Vec::new(), KernelWork::default());
    }
    // The halves by their largest n_contrib, descending: going back from the last entry, a
    // half becomes live (some pixel has j < n_contrib) at j = its n_contrib - 1 and stays so.
    let mut by_last: [(u32, u32); 2 * TILE] = [(0, 0); 2 * TILE];
    for (i, (b, &l)) in by_last.iter_mut().zip(&half_last).enumerate() {
        *b = (l, i as u32);
    }
    by_last.sort_unstable_by(|a, b| b.cmp(a));
    let mut next_live = 0;
    let mut live = 0u32;
    let built;
    let entries: &[Entry<R>] = if saved.work.tiles.len() == bins.n_tiles() {
        &saved.work.tiles[t]
    } else {
        built = tile_entries(packed, bins, t);
        &built
    };
    let zero = R::zero();
    let bg = saved.background;
    let lanes_xy = SlotLanes::<R>::new(x0, y0);
    let mut recs = Vec::with_capacity(max_last as usize);
    let mut stats = KernelWork::default();
    // Per-column partial sums in the lane order of the steps: index 16 h + 8 p + c % 8 for
    // column c of half h = c / 8 over the rows of parity p, each adding its rows in order;
    // reduced at the end of the entry (even + odd per column, then over the columns in order).
    for j in (0..max_last as usize).rev() {
        let e = &entries[j];
        let ju = j as u32;
        let (k0, k1) = (e.x0 as usize - x0, e.x1 as usize - x0);
        stats.entries += 1;
        let mut lanes = Lines([[zero; 2 * TILE]; 7]);
        // The halves this entry visits: those its chord meets with a pixel where it may still
        // blend (`j < n_contrib`), bit 2 r + h as in `Entry::halves`.
        while next_live < 2 * TILE && ju < by_last[next_live].0 {
            live |= 1 << by_last[next_live].1;
            next_live += 1;
        }
        let visit = e.halves & live;
        stats.rows += ((visit | visit >> 1) & 0x5555_5555).count_ones() as u64;
        let colm = lanes_xy.columns(k0, k1);
        let mut any = 0u32;
        for h in 0..2 {
            // Bit 2 r: row r visits half h; bit 4 m: pair m has a row visiting it.
            let rows = visit >> h & 0x5555_5555;
            let pairs = (rows | rows >> 2) & 0x1111_1111;
            let (xy, c, p, l) = (&lanes_xy, &colm, &mut px, &mut lanes.0);
            if W == 16 {
                // One step per pair, up to four pairs per lane loop (independent dependency
                // chains side by side, adding to the same column sums in row order).
                stats.lanes += (16 * pairs.count_ones()) as u64;
                let mut bits = pairs;
                while bits != 0 {
                    let a = Step::take(&mut bits, h);
                    if bits == 0 {
                        any |= rows_step::<R, W>(e, ju, bg, xy, c, h, [a, a], false, p, l);
                        break;
                    }
                    let b = Step::take(&mut bits, h);
                    any |= match bits.count_ones() {
                        0 => pairs_step2::<R, W>(e, ju, bg, xy, c, h, [a, b], p, l),
                        1 => {
                            let s = [a, b, Step::take(&mut bits, h)];
                            pairs_step3::<R, W>(e, ju, bg, xy, c, h, s, p, l)
                        }
                        _ => {
                            let c3 = Step::take(&mut bits, h);
                            let s = [a, b, c3, Step::take(&mut bits, h)];
                            pairs_step4::<R, W>(e, ju, bg, xy, c, h, s, p, l)
                        }
                    };
                }
            } else {
                // One lane loop per pair, over its even and its odd row side by side (each
                // adding to its own column sums), or over the one row that visits the half.
                stats.lanes += (8 * rows.count_ones()) as u64;
                let mut bits = pairs;
                while bits != 0 {
                    let m = bits.trailing_zeros() as usize / 4;
                    bits &= bits - 1;
                    let g = rows >> (4 * m) & 5;
                    let (even, odd) = (Step::of(m, h, 0), Step::of(m, h, 1));
                    any |= match g {
                        5 => rows_step::<R, W>(e, ju, bg, xy, c, h, [even, odd], true, p, l),
                        1 => rows_step::<R, W>(e, ju, bg, xy, c, h, [even, even], false, p, l),
                        _ => rows_step::<R, W>(e, ju, bg, xy, c, h, [odd, odd], false, p, l),
                    };
                }
            }
        }
        if any > 0 {
            // Per column: even rows + odd rows; then the columns in order.
            let acc = column_sums::<R, X512>(&lanes.0, k0, k1);
            recs.push((e.id, acc));
        }
    }
    (recs, stats)
}

/// `W` values of `v` from `o`.
#[inline(always)]
fn fixed<T: Copy, const W: usize, const N: usize>(v: &[T; N], o: usize) -> &[T; W] {
    v[o..o + W].try_into().unwrap()
}

/// Per-pixel state of the backward kernel, tile-local in the order of [`slot_index`]: T
/// recovered so far, the final T, the colour behind (S), dL/dpixel and n_contrib, each array at
/// a 64-byte boundary (see [`Lines`](super::Lines)).
#[repr(C, align(64))]
struct Pixels<R> {
    tcur: [R; TP],
    tfin: [R; TP],
    behind: [R; TP],
    g: [R; TP],
    last: [u32; TP],
}

/// One lane loop's part of a step: the pixels of [`Pixels`] from `o` (`W` of them), the
/// column sums from `acc` in the layout of the kernel's `lanes`, and the pair `m` (for the
/// rows' y).
#[derive(Clone, Copy)]
struct Step {
    o: usize,
    acc: usize,
    m: usize,
}

impl Step {
    /// The 16-lane step of the lowest pair set in `bits` (bit 4 m: pair m), half `h`, that bit
    /// cleared.
    #[inline(always)]
    fn take(bits: &mut u32, h: usize) -> Step {
        let m = bits.trailing_zeros() as usize / 4;
        *bits &= *bits - 1;
        Step::of(m, h, 0)
    }

    /// Pair `m`, half `h`, from the pixels of row parity `p` on (0: both rows with 16 lanes).
    #[inline(always)]
    fn of(m: usize, h: usize, p: usize) -> Step {
        Step {
            o: 32 * m + 16 * h + 8 * p,
            acc: 16 * h + 8 * p,
            m,
        }
    }
}

/// One pixel's part of the backward of one entry: whether it blended there (`valid`) and
/// whether its clamp is inactive (`live`), the seven gradient terms (mean x, mean y, A, B, C,
/// opacity, colour; A, B and C are subtracted), with the pixel's T and colour-behind updated.
struct Lane<R> {
    valid: u32,
    live: u32,
    d: [R; 7],
}

/// The `W` pixels of one step as the backward of one entry sees them: the row offset `dy`
/// per lane, n_contrib, dL/dpixel, final T, and the T and colour-behind it updates (local
/// copies, so that nothing aliases in the lane loop).
struct Row<R, const W: usize> {
    o: usize,
    dy: [R; W],
    last: [u32; W],
    g: [R; W],
    tfin: [R; W],
    tcur: [R; W],
    behind: [R; W],
}

impl<R: Real, const W: usize> Row<R, W> {
    #[inline(always)]
    fn load(px: &Pixels<R>, e: &Entry<R>, xy: &SlotLanes<R>, s: Step) -> Self {
        let o = s.o;
        let ys: &[R; W] = fixed(&xy.ys[s.m], o % 16);
        let mut dy = *ys;
        for d in &mut dy {
            *d -= e.my;
        }
        Row {
            o,
            dy,
            last: *fixed(&px.last, o),
            g: *fixed(&px.g, o),
            tfin: *fixed(&px.tfin, o),
            tcur: *fixed(&px.tcur, o),
            behind: *fixed(&px.behind, o),
        }
    }

    #[inline(always)]
    fn store(&self, px: &mut Pixels<R>) {
        px.tcur[self.o..self.o + W].copy_from_slice(&self.tcur);
        px.behind[self.o..self.o + W].copy_from_slice(&self.behind);
    }
}

/// The backward of entry `e` (list position `ju`) at lane `k` of `row` (offset `dx`, lane
/// mask `act`), updating its T and colour behind where the entry blended.
#[inline(always)]
fn lane<R: Real, const W: usize>(
    e: &Entry<R>,
    ju: u32,
    bg: R,
    dx: R,
    act: u32,
    row: &mut Row<R, W>,
    k: usize,
) -> Lane<R> {
    let (amax, amin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN));
    let (one, zero, half) = (R::one(), R::zero(), R::c(0.5));
    let dy = row.dy[k];
    let (gp, tc, bh) = (row.g[k], row.tcur[k], row.behind[k]);
    let pw = power_of(e.a, e.b, e.c, dx, dy);
    let gk = exp_k(pw);
    let og = e.o * gk;
    let alpha = sel(mask(og > amax), amax, og);
    let valid = act & mask(ju < row.last[k]) & mask(pw <= zero) & mask(alpha >= amin);
    let inv = one / (one - alpha);
    let tk = tc * inv;
    let d_alpha = gp * (e.col.mul_add(tk, -(bh * inv)) - bg * row.tfin[k] * inv);
    row.behind[k] = sel(valid, add_blend(bh, e.col, alpha, tk), bh);
    row.tcur[k] = sel(valid, tk, tc);
    // Clamp active (o G > 0.99): d alpha / d (o G) = 0.
    let live = valid & mask(og <= amax);
    let d_pw = og * d_alpha;
    Lane {
        valid,
        live,
        d: [
            d_pw * e.a.mul_add(dx, e.b * dy),
            d_pw * e.b.mul_add(dx, e.c * dy),
            half * dx * dx * d_pw,
            dx * dy * d_pw,
            half * dy * dy * d_pw,
            gk * d_alpha,
            gp * alpha * tk,
        ],
    }
}

/// Adds one pixel's terms ([`Lane`]) to the column sums `acc[.][k]` where it counts.
#[inline(always)]
fn add_lane<R: Real, const W: usize>(acc: &mut [[R; W]; 7], k: usize, l: &Lane<R>) {
    for m in [0, 1, 5] {
        acc[m][k] = sel(l.live, acc[m][k] + l.d[m], acc[m][k]);
    }
    for m in [2, 3, 4] {
        acc[m][k] = sel(l.live, acc[m][k] - l.d[m], acc[m][k]);
    }
    acc[6][k] = sel(l.valid, acc[6][k] + l.d[6], acc[6][k]);
}

/// `$name`: the backward of entry `e` (list position `ju`) at the 16-lane steps `s` of half `h`
/// (pixels and column sums of [`Step`]; `s` in ascending pairs, one row state `$row` and lane
/// result `$lane` per step), in one lane loop so that their dependency chains run side by
/// side; returns the lanes (OR-ed) where the entry blended. All add to the same column sums,
/// `s[0]` first: per pixel and per column sum the operations are those of one step at a time
/// in order, so the bits do not depend on the grouping. (Written out per count by a macro: a
/// loop over an array of row states is not vectorised.)
macro_rules! pairs_step {
    ($name:ident, $n:literal, $(($row:ident, $lane:ident)),+) => {
        #[allow(clippy::too_many_arguments)]
        #[inline(always)]
        fn $name<R: Real, const W: usize>(
            e: &Entry<R>,
            ju: u32,
            bg: R,
            xy: &SlotLanes<R>,
            colm: &[[u32; 16]; 2],
            h: usize,
            s: [Step; $n],
            px: &mut Pixels<R>,
            lanes: &mut [[R; 2 * TILE]; 7],
        ) -> u32 {
            let xh: &[R; W] = fixed(&xy.xs[h], 0);
            let act: &[u32; W] = fixed(&colm[h], 0);
            let acc0 = s[0].acc;
            let [$($row),+] = s;
            $(let mut $row = Row::<R, W>::load(px, e, xy, $row);)+
            let mut acc = [[R::zero(); W]; 7];
            for m in 0..7 {
                acc[m] = *fixed(&lanes[m], acc0);
            }
            let mut any = 0u32;
            for (k, &x) in xh.iter().enumerate() {
                let dx = x - e.mx;
                $(let $lane = lane(e, ju, bg, dx, act[k], &mut $row, k);)+
                $(add_lane(&mut acc, k, &$lane);)+
                any |= 0 $(| $lane.valid)+;
            }
            $($row.store(px);)+
            for m in 0..7 {
                lanes[m][acc0..acc0 + W].copy_from_slice(&acc[m]);
            }
            any
        }
    };
}

pairs_step!(pairs_step2, 2, (a, la), (b, lb));
pairs_step!(pairs_step3, 3, (a, la), (b, lb), (c, lc));
pairs_step!(pairs_step4, 4, (a, la), (b, lb), (c, lc), (d, ld));

/// The backward of entry `e` (list position `ju`) at the step `s[0]` of half `h` and, if `two`
/// (8 lanes only), at `s[1]` (the even and the odd row of a pair, each with its own column
/// sums), in one lane loop so that the two rows' dependency chains run side by side; returns
/// the lanes (OR-ed) where the entry blended. With 16 lanes and `two` false: one pair's step.
/// Per pixel and per column sum the operations are those of one row at a time.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn rows_step<R: Real, const W: usize>(
    e: &Entry<R>,
    ju: u32,
    bg: R,
    xy: &SlotLanes<R>,
    colm: &[[u32; 16]; 2],
    h: usize,
    s: [Step; 2],
    two: bool,
    px: &mut Pixels<R>,
    lanes: &mut [[R; 2 * TILE]; 7],
) -> u32 {
    // The columns of both parities' lanes are the same: the first W serve either. The lanes
    // are masked by the entry's columns only: a lane in a row or half the entry does not
    // visit fails the alpha test (outside its chord) or the n_contrib test.
    let xh: &[R; W] = fixed(&xy.xs[h], 0);
    let act: &[u32; W] = fixed(&colm[h], 0);
    let mut a = Row::<R, W>::load(px, e, xy, s[0]);
    let mut acc = [[R::zero(); W]; 7];
    for m in 0..7 {
        acc[m] = *fixed(&lanes[m], s[0].acc);
    }
    let mut any = 0u32;
    if two {
        let mut b = Row::<R, W>::load(px, e, xy, s[1]);
        let mut acc_b = [[R::zero(); W]; 7];
        for m in 0..7 {
            acc_b[m] = *fixed(&lanes[m], s[1].acc);
        }
        for (k, &x) in xh.iter().enumerate() {
            let dx = x - e.mx;
            let la = lane(e, ju, bg, dx, act[k], &mut a, k);
            let lb = lane(e, ju, bg, dx, act[k], &mut b, k);
            add_lane(&mut acc, k, &la);
            add_lane(&mut acc_b, k, &lb);
            any |= la.valid | lb.valid;
        }
        b.store(px);
        for m in 0..7 {
            lanes[m][s[1].acc..s[1].acc + W].copy_from_slice(&acc_b[m]);
        }
    } else {
        for (k, &x) in xh.iter().enumerate() {
            let dx = x - e.mx;
            let la = lane(e, ju, bg, dx, act[k], &mut a, k);
            add_lane(&mut acc, k, &la);
            any |= la.valid;
        }
    }
    a.store(px);
    for m in 0..7 {
        lanes[m][s[0].acc..s[0].acc + W].copy_from_slice(&acc[m]);
    }
    any
}

/// The sequential reduction of the tiles' gradient records into per-splat gradients, in tile
/// order and, within a tile, back-to-front entry order: the same additions in the same order
/// whichever thread runs them and however the tiles finish, so the gradients are bit-identical
/// for any thread count.
struct Reducer<R: Real> {
    out: SplatGrads<R>,
    work: KernelWork,
    /// The first tile not reduced yet.
    next: usize,
}

impl<R: Real> Reducer<R> {
    /// Reduce the finished tiles from `next` on, up to the first unfinished one.
    fn drain(&mut self, slots: &[Mutex<Option<TileGrads<R>>>]) {
        while let Some(slot) = slots.get(self.next) {
            let Some((tile, w)) = lock(slot).take() else {
                return;
            };
            self.work += w;
            let out = &mut self.out;
            for (id, a) in &tile {
                let i = *id as usize;
                out.mean2d[i][0] += a[0];
                out.mean2d[i][1] += a[1];
                out.conic[i][0] += a[2];
                out.conic[i][1] += a[3];
                out.conic[i][2] += a[4];
                out.opacity[i] += a[5];
                out.color[i] += a[6];
            }
            self.next += 1;
        }
    }
}

/// Vector-Jacobian product of [`forward`](fn@super::forward): the gradient of sum(d_image * image)
/// with respect to the splat fields (mean2d in pixels, conic (A, B, C) with B the single
/// off-diagonal parameter, opacity after the sigmoid, colour). Splats that are not drawn get 0.
pub fn backward<R: Real>(
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    backward_with(Simd::active(), splats, saved, d_image)
}

/// [`backward`] with the tile kernels compiled for `simd` (see
/// [`forward_with`](super::forward_with)).
pub fn backward_with<R: Real>(
    simd: Simd,
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    backward_kernel(Kernel::of(simd), splats, saved, d_image)
}

/// [`backward`] calling `probe` as each of its phases ends ([`Phase::BackwardTiles`],
/// [`Phase::Reduce`]), e.g. to time them; also returns the work of the tile kernels. Same
/// gradients as [`backward`].
pub fn backward_probed<R: Real>(
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
    probe: &mut dyn FnMut(Phase),
) -> (SplatGrads<R>, KernelWork) {
    let k = Kernel::of(Simd::active());
    backward_kernel_probed(k, splats, saved, d_image, probe)
}

pub(crate) fn backward_kernel<R: Real>(
    kernel: Kernel,
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
) -> SplatGrads<R> {
    backward_kernel_probed(kernel, splats, saved, d_image, &mut |_| {}).0
}

fn backward_kernel_probed<R: Real>(
    kernel: Kernel,
    splats: &Splats<R>,
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
    probe: &mut dyn FnMut(Phase),
) -> (SplatGrads<R>, KernelWork) {
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
        pack(splats, saved.bins.width, saved.bins.height)
    };
    let n_tiles = saved.bins.n_tiles();
    let reducer = Mutex::new(Reducer {
        out: SplatGrads {
            mean2d: vec![[R::zero(); 2]; n],
            conic: vec![[R::zero(); 3]; n],
            opacity: vec![R::zero(); n],
            color: vec![R::zero(); n],
        },
        work: KernelWork::default(),
        next: 0,
    });
    let slots: Vec<Mutex<Option<TileGrads<R>>>> = (0..n_tiles).map(|_| Mutex::new(None)).collect();
    (0..n_tiles).into_par_iter().for_each(|t| {
        let g = dispatch::backward_tile(kernel, &packed, saved, d_image, t);
        *lock(&slots[t]) = Some(g);
        // Whoever finds the reducer free adds the finished tiles that come next in tile order
        // (the others go on with their tiles), so most of the sequential reduction overlaps the
        // tile kernels instead of following them.
        if let Ok(mut r) = reducer.try_lock() {
            r.drain(&slots);
        }
    });
    probe(Phase::BackwardTiles);
    // The tiles no worker reduced yet (every tile is finished now).
    let mut r = reducer.into_inner().unwrap_or_else(|e| e.into_inner());
    r.drain(&slots);
    debug_assert_eq!(r.next, n_tiles);
    let (out, work) = (r.out, r.work);
    probe(Phase::Reduce);
    (out, work)
}
