//! SSIM written as its definition: five whole-image blurs (three of them of product images),
//! the per-pixel terms, then three whole-image adjoint blurs. The fused kernels of
//! [`super`] must give the same bits (every pixel sums the same products in the same order);
//! this is their oracle in the tests and their baseline in `unispine bench loss`.

use rayon::prelude::*;

use super::{check_same, terms, window};
use crate::image2d::Image2d;
use crate::loss::filters::{blur, blur_adjoint};
use crate::par::{det_sum_by, CHUNK};
use crate::real::Real;

fn zip_map<R: Real, F: Fn(R, R) -> R + Sync>(a: &Image2d<R>, b: &Image2d<R>, f: F) -> Image2d<R> {
    let data = a
        .data
        .par_iter()
        .zip(&b.data)
        .map(|(&x, &y)| f(x, y))
        .collect();
    Image2d::from_vec(a.width, a.height, data)
}

/// The five window statistics of (x, y): mu_x, mu_y, W*(x x), W*(y y), W*(x y).
fn stats<R: Real>(x: &Image2d<R>, y: &Image2d<R>, k: &[f64]) -> [Image2d<R>; 5] {
    [
        blur(x, k),
        blur(y, k),
        blur(&zip_map(x, x, |a, b| a * b), k),
        blur(&zip_map(y, y, |a, b| a * b), k),
        blur(&zip_map(x, y, |a, b| a * b), k),
    ]
}

fn at<R: Real>(s: &[Image2d<R>; 5], p: usize) -> [R; 5] {
    [0, 1, 2, 3, 4].map(|k| s[k].data[p])
}

/// The SSIM map S.
pub fn ssim_map<R: Real>(x: &Image2d<R>, y: &Image2d<R>) -> Image2d<R> {
    check_same(x, y);
    let s = stats(x, y, &window());
    let data = (0..x.data.len())
        .into_par_iter()
        .map(|p| {
            let (_, _, a1, a2, b1, b2) = terms(at(&s, p));
            (a1 * a2) / (b1 * b2)
        })
        .collect();
    Image2d::from_vec(x.width, x.height, data)
}

/// Mean SSIM of `x` against `y` and its gradient with respect to `x`.
pub fn ssim_forward_backward<R: Real>(x: &Image2d<R>, y: &Image2d<R>) -> (f64, Image2d<R>) {
    check_same(x, y);
    let k = window();
    let s = stats(x, y, &k);
    let n = x.data.len();
    let inv_n = R::c(1.0 / n as f64);
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
                let (sv, d) = super::partials(at(&s, c * CHUNK + q), inv_n);
                o_s[q] = sv;
                o_mu[q] = d[0];
                o_xx[q] = d[1];
                o_xy[q] = d[2];
            }
        });
    let value = det_sum_by(n, |p| sv_img[p].f64()) / n as f64;
    let img = |v: Vec<R>| Image2d::from_vec(x.width, x.height, v);
    let g_mu = blur_adjoint(&img(d_mu_img), &k);
    let g_xx = blur_adjoint(&img(d_xx_img), &k);
    let g_xy = blur_adjoint(&img(d_xy_img), &k);
    let two = R::c(2.0);
    let data = (0..n)
        .into_par_iter()
        .map(|p| g_mu.data[p] + two * x.data[p] * g_xx.data[p] + y.data[p] * g_xy.data[p])
        .collect();
    (value, Image2d::from_vec(x.width, x.height, data))
}
