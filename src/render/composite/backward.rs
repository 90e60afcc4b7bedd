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
use super::dispatch::{self, Kernel};
use super::worklist::{pack, tile_entries, Entry, Packed};
use super::{CompositeSaved, KernelWork, Phase, Splats, ALPHA_MAX, ALPHA_MIN, TP};
use crate::image2d::Image2d;
use crate::par::lock;
use crate::real::Real;
use crate::simd::Simd;

/// Gradient record of one work-list entry: (mean x, mean y, A, B, C, opacity, colour).
pub(super) type Rec<R> = (u32, [R; 7]);

/// Output of the backward kernel of one tile: its gradient records and its work.
pub(super) type TileGrads<R> = (Vec<Rec<R>>, KernelWork);

/// The backward kernel of tile `t`, `W` pixels per lane vector (see
/// [`forward_tile`](super::forward::forward_tile); both widths give the same bits: per column, the
/// rows are summed in the same order).
#[inline(always)]
pub(super) fn backward_tile<R: Real, const W: usize>(
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
    let mut max_last = 0u32;
    // Largest n_contrib per tile row: rows with nothing left to visit are skipped.
    let mut row_last = [0u32; TILE];
    for row in y0..y1 {
        for col in x0..x1 {
            let p = (row - y0) * TILE + col - x0;
            let q = row * width + col;
            px.tcur[p] = saved.final_t[q];
            px.tfin[p] = saved.final_t[q];
            px.g[p] = d_image.data[q];
            px.last[p] = saved.n_contrib[q];
            row_last[row - y0] = row_last[row - y0].max(px.last[p]);
        }
        max_last = max_last.max(row_last[row - y0]);
    }
    if max_last == 0 {
        return (Vec::new(), KernelWork::default());
    }
    let built;
    let entries: &[Entry<R>] = if saved.work.tiles.len() == bins.n_tiles() {
        &saved.work.tiles[t]
    } else {
        built = tile_entries(packed, bins, t);
        &built
    };
    let zero = R::zero();
    let half = R::c(0.5);
    let bg = saved.background;
    let xs: [R; TILE] = std::array::from_fn(|k| R::c((x0 + k) as f64) + half);
    let mut recs = Vec::with_capacity(max_last as usize);
    let mut stats = KernelWork::default();
    // Per-column partial sums (each column sums its own rows in order), reduced over the
    // columns in order at the end of the entry.
    let mut lanes = [[zero; TILE]; 7];
    for j in (0..max_last as usize).rev() {
        let e = &entries[j];
        let ju = j as u32;
        let (k0, k1) = (e.x0 as usize - x0, e.x1 as usize - x0);
        let colm: [u32; TILE] = std::array::from_fn(|k| mask(k0 <= k && k < k1));
        stats.entries += 1;
        for l in lanes.iter_mut() {
            *l = [zero; TILE];
        }
        // The lane vectors this entry visits, per column block `v` (rows ascending): rows with
        // a pixel where the entry may still blend (`j < n_contrib`) and a half the chord meets
        // (bit 2 r of `live` and of the halves word), gathered from the set bits without a
        // branch per row.
        let live = (0..TILE).fold(0u32, |b, r| b | ((ju < row_last[r]) as u32) << (2 * r));
        let (r0, r1) = (e.y0 as usize - y0, e.y1 as usize - y0);
        let in_box = ((1u64 << (2 * r1)) - (1u64 << (2 * r0))) as u32 & 0x5555_5555;
        stats.rows += (live & in_box).count_ones() as u64;
        let mut steps = [[0u8; TILE]; 2];
        let mut n_steps = [0usize; 2];
        for v in 0..TILE / W {
            let h = e.halves >> (v * W / 8);
            let meets = if W == 16 {
                (h | h >> 1) & 0x5555_5555
            } else {
                h & 0x5555_5555
            };
            let mut bits = meets & live;
            while bits != 0 {
                steps[v][n_steps[v]] = (bits.trailing_zeros() / 2) as u8;
                n_steps[v] += 1;
                bits &= bits - 1;
            }
        }
        // Two rows per step (independent dependency chains side by side); per column the rows
        // still add in ascending order, so the bits are those of one row at a time.
        let mut any = 0u32;
        for v in 0..TILE / W {
            let rows = &steps[v][..n_steps[v]];
            stats.lanes += (W * rows.len()) as u64;
            for pr in rows.chunks(2) {
                let (r, two) = ([pr[0] as usize, pr[pr.len() - 1] as usize], pr.len() == 2);
                any |= rows_step::<R, W>(
                    e,
                    ju,
                    bg,
                    &colm,
                    &xs,
                    y0,
                    v * W,
                    r,
                    two,
                    &mut px,
                    &mut lanes,
                );
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
    (recs, stats)
}

/// Per 2-bit `halves` value of a tile row ([`Entry::halves`]), the lanes of its columns that a
/// chord-tested half may hold.
const HALF_MASKS: [[u32; TILE]; 4] = {
    let mut m = [[0u32; TILE]; 4];
    let mut b = 0;
    while b < 4 {
        let mut k = 0;
        while k < TILE {
            if (b >> (k / 8)) & 1 != 0 {
                m[b][k] = u32::MAX;
            }
            k += 1;
        }
        b += 1;
    }
    m
};

/// `W` values of `v` from `o`.
#[inline(always)]
fn fixed<T: Copy, const W: usize, const N: usize>(v: &[T; N], o: usize) -> &[T; W] {
    v[o..o + W].try_into().unwrap()
}

/// Per-pixel state of the backward kernel, tile-local: T recovered so far, the final T, the
/// colour behind (S), dL/dpixel and n_contrib.
struct Pixels<R> {
    tcur: [R; TP],
    tfin: [R; TP],
    behind: [R; TP],
    g: [R; TP],
    last: [u32; TP],
}

/// One pixel's part of the backward of one entry: whether it blended there (`valid`) and
/// whether its clamp is inactive (`live`), the seven gradient terms (mean x, mean y, A, B, C,
/// opacity, colour; A, B and C are subtracted), with the pixel's T and colour-behind updated.
struct Lane<R> {
    valid: u32,
    live: u32,
    d: [R; 7],
}

/// One tile row's `W` pixels from column `c0` as the backward of one entry sees them: the
/// row offset `dy`, the lanes (the entry's columns within the halves its chord meets),
/// n_contrib, dL/dpixel, final T, and the T and colour-behind it updates (local copies, so
/// that nothing aliases in the lane loop).
struct Row<R, const W: usize> {
    o: usize,
    dy: R,
    act: [u32; W],
    last: [u32; W],
    g: [R; W],
    tfin: [R; W],
    tcur: [R; W],
    behind: [R; W],
}

impl<R: Real, const W: usize> Row<R, W> {
    #[inline(always)]
    fn load(
        px: &Pixels<R>,
        e: &Entry<R>,
        colm: &[u32; TILE],
        y0: usize,
        r: usize,
        c0: usize,
    ) -> Self {
        let o = r * TILE + c0;
        let cm: &[u32; W] = fixed(colm, c0);
        let hm: &[u32; W] = fixed(&HALF_MASKS[(e.halves >> (2 * r) & 3) as usize], c0);
        let mut act = [0u32; W];
        for k in 0..W {
            act[k] = cm[k] & hm[k];
        }
        Row {
            o,
            dy: R::c((y0 + r) as f64) + R::c(0.5) - e.my,
            act,
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

/// The backward of entry `e` (list position `ju`) at pixel `k` of `row` (offset `dx`),
/// updating its T and colour behind where the entry blended.
#[inline(always)]
fn lane<R: Real, const W: usize>(
    e: &Entry<R>,
    ju: u32,
    bg: R,
    dx: R,
    row: &mut Row<R, W>,
    k: usize,
) -> Lane<R> {
    let (amax, amin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN));
    let (one, zero, half) = (R::one(), R::zero(), R::c(0.5));
    let dy = row.dy;
    let (gp, tc, bh) = (row.g[k], row.tcur[k], row.behind[k]);
    let pw = power_of(e.a, e.b, e.c, dx, dy);
    let gk = exp_k(pw);
    let og = e.o * gk;
    let alpha = sel(mask(og > amax), amax, og);
    let valid = row.act[k] & mask(ju < row.last[k]) & mask(pw <= zero) & mask(alpha >= amin);
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

/// The backward of entry `e` (list position `ju`) at the `W` pixels from column `c0` of tile
/// rows `rows[0]` and, if `two`, `rows[1]` (> `rows[0]`), in one lane loop so that the two
/// rows' dependency chains run side by side; returns the lanes (OR-ed) where the entry blended.
/// Per pixel and per column sum, the operations are those of one row at a time in ascending
/// order, so the bits do not depend on the pairing.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn rows_step<R: Real, const W: usize>(
    e: &Entry<R>,
    ju: u32,
    bg: R,
    colm: &[u32; TILE],
    xs: &[R; TILE],
    y0: usize,
    c0: usize,
    rows: [usize; 2],
    two: bool,
    px: &mut Pixels<R>,
    lanes: &mut [[R; TILE]; 7],
) -> u32 {
    let xh: &[R; W] = fixed(xs, c0);
    let mut a = Row::<R, W>::load(px, e, colm, y0, rows[0], c0);
    let mut acc = [[R::zero(); W]; 7];
    for m in 0..7 {
        acc[m] = *fixed(&lanes[m], c0);
    }
    let mut any = 0u32;
    if two {
        let mut b = Row::<R, W>::load(px, e, colm, y0, rows[1], c0);
        for (k, &x) in xh.iter().enumerate() {
            let dx = x - e.mx;
            let la = lane(e, ju, bg, dx, &mut a, k);
            let lb = lane(e, ju, bg, dx, &mut b, k);
            add_lane(&mut acc, k, &la);
            add_lane(&mut acc, k, &lb);
            any |= la.valid | lb.valid;
        }
        b.store(px);
    } else {
        for (k, &x) in xh.iter().enumerate() {
            let dx = x - e.mx;
            let la = lane(e, ju, bg, dx, &mut a, k);
            add_lane(&mut acc, k, &la);
            any |= la.valid;
        }
    }
    a.store(px);
    for m in 0..7 {
        lanes[m][c0..c0 + W].copy_from_slice(&acc[m]);
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
