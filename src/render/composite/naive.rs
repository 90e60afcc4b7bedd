//! The naive per-pixel reference of the compositor (Eqs. 4-5): no tile lists, no pixel boxes, no
//! early tile exit, one pixel at a time. The tests compare [`super::forward`](fn@super::forward)
//! with it bit for bit, and `unispine bench render` uses it as its per-blend baseline.

use super::{ALPHA_MAX, ALPHA_MIN, T_MIN};
use crate::image2d::Image2d;
use crate::real::Real;
use crate::render::lanes::{add_blend, exp_k, power_of};
use crate::render::tiles::{self, TILE};
use crate::render::Splats;
use crate::simd::Simd;

/// Naive reference of [`super::forward`](fn@super::forward) (no tile lists, no pixel boxes, no
/// early tile exit): for every pixel, every drawn splat whose tile rectangle holds the pixel's
/// tile, in (depth, index) order. Same arithmetic per pixel, so it agrees with
/// [`super::forward`](fn@super::forward) bit for bit; used by the tests and as the per-blend
/// baseline of `unispine bench render`. Single-threaded, O(pixels x splats). Compiled, like the
/// tile kernels, for the widest instruction set of the CPU ([`Simd::active`]; its fused
/// multiply-adds are then instructions rather than library calls), with the same bits on every
/// path.
pub fn naive_forward<R: Real>(
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> Image2d<R> {
    #[cfg(target_arch = "x86_64")]
    match Simd::active() {
        // SAFETY: `Simd::active` is supported by the CPU.
        Simd::Avx512 => return unsafe { naive_avx512(splats, width, height, background) },
        Simd::Avx2 => return unsafe { naive_avx2(splats, width, height, background) },
        Simd::Scalar => {}
    }
    naive_body(splats, width, height, background)
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](splats: &Splats<R>, width: usize, height: usize, background: R)
        -> Image2d<R>;
    naive_avx2 => { naive_body(splats, width, height, background) }
    naive_avx512 => { naive_body(splats, width, height, background) }
}

#[inline(always)]
fn naive_body<R: Real>(
    splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> Image2d<R> {
    let n = splats.radius.len();
    let (tx, ty) = (width.div_ceil(TILE), height.div_ceil(TILE));
    let mut order: Vec<(u64, u32, [usize; 4])> = (0..n)
        .filter(|&i| tiles::drawn(splats, i))
        .filter_map(|i| {
            let [u, v] = splats.mean2d[i].map(|x| x.f64());
            tiles::tile_rect(u, v, splats.radius[i], tx, ty).map(|r| {
                (
                    tiles::sort_key(splats.depth[i].f64(), i as u32),
                    i as u32,
                    r,
                )
            })
        })
        .collect();
    order.sort_unstable();
    let (amax, amin, tmin) = (R::c(ALPHA_MAX), R::c(ALPHA_MIN), R::c(T_MIN));
    let half = R::c(0.5);
    let mut img = Image2d::filled(width, height, R::zero());
    for row in 0..height {
        for col in 0..width {
            let (ptx, pty) = (col / TILE, row / TILE);
            let (mut c, mut t) = (R::zero(), R::one());
            for &(_, i, r) in &order {
                if !(r[0] <= ptx && ptx < r[1] && r[2] <= pty && pty < r[3]) {
                    continue;
                }
                let i = i as usize;
                let dx = R::c(col as f64) + half - splats.mean2d[i][0];
                let dy = R::c(row as f64) + half - splats.mean2d[i][1];
                let [a, b, cc] = splats.conic[i];
                let pw = power_of(a, b, cc, dx, dy);
                if pw > R::zero() {
                    continue;
                }
                let og = splats.opacity[i] * exp_k(pw);
                let alpha = if og > amax { amax } else { og };
                if alpha < amin {
                    continue;
                }
                let next = t * (R::one() - alpha);
                if next < tmin {
                    break;
                }
                c = add_blend(c, splats.color[i], alpha, t);
                t = next;
            }
            img.data[row * width + col] = c + t * background;
        }
    }
    img
}
