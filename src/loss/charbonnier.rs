//! The per-pixel data terms of Eq. (8): L1, the Charbonnier penalty and the SPWM-weighted
//! Charbonnier of Eq. (9).
//!
//! ```text
//! e(p) = render(p) - gt(p),   rho(e) = sqrt(e^2 + eps^2)          (eps = 1e-3, charb_eps)
//! L1            = mean_p |e(p)|
//! L_charb       = mean_p rho(e(p))
//! L_w-charb     = sum_p w(p) rho(e(p)) / (sum_p w(p) + delta)      Eq. (9), delta = 1e-6
//! ```
//!
//! As UniSpine-GS `weighted_charbonnier_loss`: eps enters squared inside the square root, and
//! the weights are a constant of the loss (detached), so d L_w-charb / d render(p) =
//! w(p) e(p) / rho(e(p)) / (sum w + delta). The L1 subgradient is sign(e), 0 at e = 0 (PyTorch's
//! `abs` backward). Sums are deterministic f64 reductions ([`crate::par`]); the per-pixel
//! gradient is computed in f64 and rounded once to `R`.

use rayon::prelude::*;

use crate::image2d::Image2d;
use crate::par::{det_sum2_by, det_sum_by, CHUNK};
use crate::real::Real;
use crate::simd::Simd;

fn check_same<R: Real>(a: &Image2d<R>, b: &Image2d<R>, what: &str) {
    assert!(
        a.width == b.width && a.height == b.height && !a.data.is_empty(),
        "{what}: images of different or empty size: {}x{} vs {}x{}",
        a.width,
        a.height,
        b.width,
        b.height
    );
}

fn grad_image<R: Real, F: Fn(usize) -> f64 + Sync>(like: &Image2d<R>, f: F) -> Image2d<R> {
    let mut out = Image2d::filled(like.width, like.height, R::zero());
    out.data
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, o)| {
            for (k, v) in o.iter_mut().enumerate() {
                *v = R::c(f(c * CHUNK + k));
            }
        });
    out
}

/// Charbonnier penalty rho(e) = sqrt(e^2 + eps^2).
#[inline(always)]
pub fn rho(e: f64, eps: f64) -> f64 {
    (e * e + eps * eps).sqrt()
}

/// Mean absolute error and its (sub)gradient with respect to `render`.
pub fn l1<R: Real>(render: &Image2d<R>, gt: &Image2d<R>) -> (f64, Image2d<R>) {
    check_same(render, gt, "L1");
    let n = render.data.len();
    let e = |p: usize| render.data[p].f64() - gt.data[p].f64();
    let value = det_sum_by(n, |p| e(p).abs()) / n as f64;
    let inv_n = 1.0 / n as f64;
    let grad = grad_image(render, |p| {
        let d = e(p);
        if d > 0.0 {
            inv_n
        } else if d < 0.0 {
            -inv_n
        } else {
            0.0
        }
    });
    (value, grad)
}

/// Mean Charbonnier penalty and its gradient with respect to `render`.
pub fn charbonnier<R: Real>(render: &Image2d<R>, gt: &Image2d<R>, eps: f64) -> (f64, Image2d<R>) {
    check_same(render, gt, "Charbonnier");
    let n = render.data.len();
    let e = |p: usize| render.data[p].f64() - gt.data[p].f64();
    let value = det_sum_by(n, |p| rho(e(p), eps)) / n as f64;
    let inv_n = 1.0 / n as f64;
    let grad = grad_image(render, |p| {
        let d = e(p);
        d / rho(d, eps) * inv_n
    });
    (value, grad)
}

/// Eq. (9): weighted Charbonnier `sum w rho / (sum w + delta)` and its gradient with respect to
/// `render`. `weights = None` means w = 1 everywhere (what the UniSpine-GS code computes before
/// the SPWM warm-up starts, where the weight map is the full tensor 1 + 0 G A).
pub fn weighted_charbonnier<R: Real>(
    render: &Image2d<R>,
    gt: &Image2d<R>,
    weights: Option<&Image2d<R>>,
    eps: f64,
    delta: f64,
) -> (f64, Image2d<R>) {
    check_same(render, gt, "weighted Charbonnier");
    if let Some(w) = weights {
        check_same(render, w, "weighted Charbonnier weights");
    }
    let n = render.data.len();
    let e = |p: usize| render.data[p].f64() - gt.data[p].f64();
    let w = |p: usize| weights.map_or(1.0, |w| w.data[p].f64());
    let (num, den) = det_sum2_by(n, |p| {
        let wp = w(p);
        (wp * rho(e(p), eps), wp)
    });
    let den = den + delta;
    let simd = Simd::active().or_narrower();
    let mut grad = Image2d::filled(render.width, render.height, R::zero());
    grad.data
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, o)| {
            let span = c * CHUNK..c * CHUNK + o.len();
            let (r, g) = (&render.data[span.clone()], &gt.data[span.clone()]);
            let w = weights.map(|w| &w.data[span]);
            match simd {
                // SAFETY: `or_narrower` returns an instruction set the CPU supports.
                #[cfg(target_arch = "x86_64")]
                Simd::Avx512 => unsafe { weighted_grad_avx512(o, r, g, w, eps, den) },
                #[cfg(target_arch = "x86_64")]
                Simd::Avx2 => unsafe { weighted_grad_avx2(o, r, g, w, eps, den) },
                _ => weighted_grad(o, r, g, w, eps, den),
            }
        });
    (num / den, grad)
}

/// The weighted Charbonnier gradient `w e / rho(e) / den` (w = 1 without weights) of a run of
/// pixels, in f64 rounded once to `R`, written over `o`.
#[inline(always)]
fn weighted_grad<R: Real>(o: &mut [R], r: &[R], g: &[R], w: Option<&[R]>, eps: f64, den: f64) {
    let n = o.len();
    let (r, g) = (&r[..n], &g[..n]);
    match w {
        Some(w) => {
            let w = &w[..n];
            for p in 0..n {
                let d = r[p].f64() - g[p].f64();
                o[p] = R::c(w[p].f64() * d / rho(d, eps) / den);
            }
        }
        None => {
            for p in 0..n {
                let d = r[p].f64() - g[p].f64();
                o[p] = R::c(1.0 * d / rho(d, eps) / den);
            }
        }
    }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](o: &mut [R], r: &[R], g: &[R], w: Option<&[R]>, eps: f64, den: f64);
    weighted_grad_avx2 => { weighted_grad(o, r, g, w, eps, den) }
    weighted_grad_avx512 => { weighted_grad(o, r, g, w, eps, den) }
}
