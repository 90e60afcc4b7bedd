//! Backward pass of the compositor: the exact vector-Jacobian product of Eqs. (4)-(5) (the
//! formulas are in the stage header, [`super`]). Per tile, back to front over the work list
//! saved by the forward, with T recovered by division; one gradient record per entry, reduced
//! sequentially in tile order so that the gradients are bit-identical for any thread count.

use rayon::prelude::*;

use super::super::lanes::{exp_k, mask, power_of, sel};
use super::super::tiles::TILE;
use super::super::SplatGrads;
use super::dispatch::{self, Kernel};
use super::worklist::{pack, tile_entries, Entry, Packed};
use super::{CompositeSaved, KernelWork, Phase, Splats, ALPHA_MAX, ALPHA_MIN, TP};
use crate::image2d::Image2d;
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
        return (Vec::new(), KernelWork::default());
    }
    let built;
    let entries: &[Entry<R>] = if saved.work.tiles.len() == bins.n_tiles() {
        &saved.work.tiles[t]
    } else {
        built = tile_entries(packed, bins, t);
        &built
    };
    let (amax, amin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN));
    let one = R::one();
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
        let mut any = 0u32;
        stats.entries += 1;
        for l in lanes.iter_mut() {
            *l = [zero; TILE];
        }
        for row in e.y0 as usize..e.y1 as usize {
            if ju >= row_last[row - y0] {
                continue;
            }
            stats.rows += 1;
            let dy = R::c(row as f64) + half - e.my;
            let base = (row - y0) * TILE;
            let r2 = 2 * (row - y0);
            let hv = [e.halves >> r2 & 1 != 0, e.halves >> (r2 + 1) & 1 != 0];
            for v in 0..TILE / W {
                let (c0, h0) = (v * W, v * W / 8);
                if !hv[h0..h0 + W / 8].iter().any(|&h| h) {
                    continue;
                }
                stats.lanes += W as u64;
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
    (recs, stats)
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
        pack(splats, &saved.bins)
    };
    let recs: Vec<TileGrads<R>> = (0..saved.bins.n_tiles())
        .into_par_iter()
        .map(|t| dispatch::backward_tile(kernel, &packed, saved, d_image, t))
        .collect();
    probe(Phase::BackwardTiles);
    let mut work = KernelWork::default();
    let mut out = SplatGrads {
        mean2d: vec![[R::zero(); 2]; n],
        conic: vec![[R::zero(); 3]; n],
        opacity: vec![R::zero(); n],
        color: vec![R::zero(); n],
    };
    // Sequential reduction in tile order (and, within a tile, back-to-front entry order).
    for (tile, w) in &recs {
        work += *w;
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
    probe(Phase::Reduce);
    (out, work)
}
