//! SSIM, the structural term of the hybrid loss, Eq. (8), and of the evaluation.
//!
//! As the 3DGS / X-Gaussian / UniSpine-GS `ssim` (`utils/loss_utils.py`): an 11x11 Gaussian
//! window (sigma 1.5, normalised 1D kernel, outer product), applied by correlation with **zero
//! padding 5** (so the borders count, with the window partly outside the image), C1 = 0.01^2,
//! C2 = 0.03^2 (data range 1), and the mean of the SSIM map over all pixels:
//!
//! ```text
//! mu_x = W*x, mu_y = W*y, s_xx = W*(x x) - mu_x^2, s_yy = W*(y y) - mu_y^2, s_xy = W*(x y) - mu_x mu_y
//! S = (2 mu_x mu_y + C1)(2 s_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(s_xx + s_yy + C2)),  SSIM = mean(S)
//! ```
//!
//! Backward (d SSIM / d x, exact): with A1 = 2 mu_x mu_y + C1, A2 = 2 s_xy + C2,
//! B1 = mu_x^2 + mu_y^2 + C1, B2 = s_xx + s_yy + C2 and the independent maps mu_x, e_xx = W*(x x),
//! e_xy = W*(x y):
//! dS/dmu_x = 2 mu_y (A2 - A1)/(B1 B2) - 2 mu_x S (1/B1 - 1/B2), dS/de_xx = -S/B2,
//! dS/de_xy = 2 A1/(B1 B2); then
//! d mean(S)/dx = (W^T(dS/dmu_x) + 2 x W^T(dS/de_xx) + y W^T(dS/de_xy)) / N.
//!
//! The maps are computed in the precision `R` (as upstream computes them in f32); the mean is a
//! deterministic f64 reduction ([`crate::par`]).

use rayon::prelude::*;

use super::filters::{blur, blur_adjoint, gaussian_kernel};
use crate::image2d::Image2d;
use crate::par::{det_sum_by, CHUNK};
use crate::real::Real;

/// Window side (11) and Gaussian sigma (1.5).
pub const WINDOW: usize = 11;
pub const SIGMA: f64 = 1.5;
/// Stabilisers for data range 1.
pub const C1: f64 = 0.01 * 0.01;
pub const C2: f64 = 0.03 * 0.03;

/// The normalised 1D window (11 taps, sigma 1.5).
pub fn window() -> Vec<f64> {
    gaussian_kernel(WINDOW, SIGMA, 0.0)
}

fn check_same<R: Real>(a: &Image2d<R>, b: &Image2d<R>) {
    assert!(
        a.width == b.width && a.height == b.height && !a.data.is_empty(),
        "SSIM of images of different or empty size: {}x{} vs {}x{}",
        a.width,
        a.height,
        b.width,
        b.height
    );
}

fn zip_map<R: Real, F: Fn(R, R) -> R + Sync>(a: &Image2d<R>, b: &Image2d<R>, f: F) -> Image2d<R> {
    let data = a
        .data
        .par_iter()
        .zip(&b.data)
        .map(|(&x, &y)| f(x, y))
        .collect();
    Image2d::from_vec(a.width, a.height, data)
}

/// The five window statistics of (x, y).
struct Stats<R: Real> {
    mu_x: Image2d<R>,
    mu_y: Image2d<R>,
    e_xx: Image2d<R>,
    e_yy: Image2d<R>,
    e_xy: Image2d<R>,
}

fn stats<R: Real>(x: &Image2d<R>, y: &Image2d<R>, k: &[f64]) -> Stats<R> {
    Stats {
        mu_x: blur(x, k),
        mu_y: blur(y, k),
        e_xx: blur(&zip_map(x, x, |a, b| a * b), k),
        e_yy: blur(&zip_map(y, y, |a, b| a * b), k),
        e_xy: blur(&zip_map(x, y, |a, b| a * b), k),
    }
}

/// Per-pixel terms (A1, A2, B1, B2) at pixel `p`.
#[inline(always)]
fn terms<R: Real>(s: &Stats<R>, p: usize) -> (R, R, R, R, R, R) {
    let (mx, my) = (s.mu_x.data[p], s.mu_y.data[p]);
    let sxx = s.e_xx.data[p] - mx * mx;
    let syy = s.e_yy.data[p] - my * my;
    let sxy = s.e_xy.data[p] - mx * my;
    let two = R::c(2.0);
    let a1 = two * mx * my + R::c(C1);
    let a2 = two * sxy + R::c(C2);
    let b1 = mx * mx + my * my + R::c(C1);
    let b2 = sxx + syy + R::c(C2);
    (mx, my, a1, a2, b1, b2)
}

/// The SSIM map S (same size as the inputs).
pub fn ssim_map<R: Real>(x: &Image2d<R>, y: &Image2d<R>) -> Image2d<R> {
    check_same(x, y);
    let s = stats(x, y, &window());
    let data = (0..x.data.len())
        .into_par_iter()
        .map(|p| {
            let (_, _, a1, a2, b1, b2) = terms(&s, p);
            (a1 * a2) / (b1 * b2)
        })
        .collect();
    Image2d::from_vec(x.width, x.height, data)
}

/// Mean SSIM of `a` against `b` (11x11 Gaussian window, sigma 1.5, zero padding).
pub fn ssim<R: Real>(a: &Image2d<R>, b: &Image2d<R>) -> f64 {
    let m = ssim_map(a, b);
    det_sum_by(m.data.len(), |p| m.data[p].f64()) / m.data.len() as f64
}

/// Mean SSIM of `x` against `y` and its gradient with respect to `x`.
pub fn ssim_forward_backward<R: Real>(x: &Image2d<R>, y: &Image2d<R>) -> (f64, Image2d<R>) {
    check_same(x, y);
    let k = window();
    let s = stats(x, y, &k);
    let n = x.data.len();
    let inv_n = R::c(1.0 / n as f64);
    // Per pixel: S and the three partials (already divided by N), written straight into their
    // images.
    let zero = R::zero();
    let (mut sv_img, mut d_mu_img, mut d_xx_img, mut d_xy_img) =
        (vec![zero; n], vec![zero; n], vec![zero; n], vec![zero; n]);
    sv_img
        .par_chunks_mut(CHUNK)
        .zip(d_mu_img.par_chunks_mut(CHUNK))
        .zip(d_xx_img.par_chunks_mut(CHUNK))
        .zip(d_xy_img.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (((o_s, o_mu), o_xx), o_xy))| {
            for q in 0..o_s.len() {
                let p = c * CHUNK + q;
                let (mx, my, a1, a2, b1, b2) = terms(&s, p);
                // S exactly as in `ssim_map` (so the value is bit-identical to `ssim`); the
                // partials with two reciprocals instead of five divisions.
                let sv = (a1 * a2) / (b1 * b2);
                let (ib1, ib2) = (R::one() / b1, R::one() / b2);
                let ib = ib1 * ib2;
                let two = R::c(2.0);
                let d_mu = two * my * (a2 - a1) * ib - two * mx * sv * (ib1 - ib2);
                let d_exx = -sv * ib2;
                let d_exy = two * a1 * ib;
                o_s[q] = sv;
                o_mu[q] = d_mu * inv_n;
                o_xx[q] = d_exx * inv_n;
                o_xy[q] = d_exy * inv_n;
            }
        });
    let value = det_sum_by(n, |p| sv_img[p].f64()) / n as f64;
    let img = |v: Vec<R>| Image2d::from_vec(x.width, x.height, v);
    let (d_mu_img, d_xx_img, d_xy_img) = (img(d_mu_img), img(d_xx_img), img(d_xy_img));
    let g_mu = blur_adjoint(&d_mu_img, &k);
    let g_xx = blur_adjoint(&d_xx_img, &k);
    let g_xy = blur_adjoint(&d_xy_img, &k);
    let two = R::c(2.0);
    let data = (0..n)
        .into_par_iter()
        .map(|p| g_mu.data[p] + two * x.data[p] * g_xx.data[p] + y.data[p] * g_xy.data[p])
        .collect();
    (value, Image2d::from_vec(x.width, x.height, data))
}
