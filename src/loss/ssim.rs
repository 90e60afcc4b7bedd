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
//!
//! The kernels here are fused and work in bands of output rows: a row of x, y and the three
//! products (formed a row at a time) is correlated along the row into a ring of the window's
//! rows; each output row correlates those five down the columns and forms S and the three
//! partials, kept in a second ring; each gradient row correlates the partials down the columns
//! and then along the row and adds the three terms. Only S (for the mean) and the gradient are
//! image-sized (the definition writes 24 image-sized buffers). Every pixel sums the same
//! products in the same order as the five whole-image blurs of [`reference`](mod@reference)
//! (the definition, kept as the oracle), so the bits are the same on every SIMD path, band
//! height and thread count.

use rayon::prelude::*;

use super::filters::{
    cast_kernel, col_kernel, gaussian_kernel, row_kernel, RowLayout, BLOCK_AVX2, BLOCK_AVX512,
    BLOCK_SCALAR,
};
use crate::image2d::Image2d;
use crate::par::det_sum_by;
use crate::real::Real;
use crate::simd::Simd;

pub mod reference;

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

/// Per-pixel terms (mu_x, mu_y, A1, A2, B1, B2) from the five window statistics
/// `[mu_x, mu_y, W*(x x), W*(y y), W*(x y)]`.
#[inline(always)]
fn terms<R: Real>(st: [R; 5]) -> (R, R, R, R, R, R) {
    let [mx, my, exx, eyy, exy] = st;
    let sxx = exx - mx * mx;
    let syy = eyy - my * my;
    let sxy = exy - mx * my;
    let two = R::c(2.0);
    let a1 = two * mx * my + R::c(C1);
    let a2 = two * sxy + R::c(C2);
    let b1 = mx * mx + my * my + R::c(C1);
    let b2 = sxx + syy + R::c(C2);
    (mx, my, a1, a2, b1, b2)
}

/// S at a pixel and the three partials dS/dmu_x, dS/de_xx, dS/de_xy times `inv_n`.
#[inline(always)]
fn partials<R: Real>(st: [R; 5], inv_n: R) -> (R, [R; 3]) {
    let (mx, my, a1, a2, b1, b2) = terms(st);
    // S exactly as in `ssim_map` (so the value is bit-identical to `ssim`); the partials with
    // two reciprocals instead of five divisions.
    let sv = (a1 * a2) / (b1 * b2);
    let (ib1, ib2) = (R::one() / b1, R::one() / b2);
    let ib = ib1 * ib2;
    let two = R::c(2.0);
    let d_mu = two * my * (a2 - a1) * ib - two * mx * sv * (ib1 - ib2);
    let d_exx = -sv * ib2;
    let d_exy = two * a1 * ib;
    (sv, [d_mu * inv_n, d_exx * inv_n, d_exy * inv_n])
}

/// Calls the row kernel `$name` (`$name_avx2`, `$name_avx512` its wide builds) with the
/// instruction set `$simd` (from [`Simd::or_narrower`]).
macro_rules! per_simd {
    ($simd:expr, $scalar:ident, $avx2:ident, $avx512:ident ($($arg:expr),* $(,)?)) => {
        match $simd {
            // SAFETY: `or_narrower` returns an instruction set the CPU supports.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { $avx512($($arg),*) },
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { $avx2($($arg),*) },
            _ => $scalar::<_, BLOCK_SCALAR>($($arg),*),
        }
    };
}

/// Row `i` of the row pass, written over `o` (5 w values): x, y, x x, y y and x y correlated
/// along the row with `k`, side by side; `prod` is scratch of 3 w values.
#[inline(always)]
fn stats_row<R: Real, const B: usize>(o: &mut [R], prod: &mut [R], xi: &[R], yi: &[R], k: &[R]) {
    let w = xi.len();
    let (xi, yi) = (&xi[..w], &yi[..w]);
    let (pxx, rest) = prod.split_at_mut(w);
    let (pyy, pxy) = rest.split_at_mut(w);
    let (pyy, pxy) = (&mut pyy[..w], &mut pxy[..w]);
    for j in 0..w {
        pxx[j] = xi[j] * xi[j];
        pyy[j] = yi[j] * yi[j];
        pxy[j] = xi[j] * yi[j];
    }
    for (os, src) in o.chunks_mut(w).zip([xi, yi, &*pxx, &*pyy, &*pxy]) {
        row_kernel::<R, B>(os, src, k);
    }
}

/// Output row `i` of the five statistics, written over `st` (5 w values), from the row pass
/// `rows` (5 w values per row, row `a` at `layout.start(a)`; image height `h`).
#[inline(always)]
fn col_stats<R: Real, const B: usize>(
    st: &mut [R],
    rows: &[R],
    layout: RowLayout,
    h: usize,
    i: usize,
    k: &[R],
) {
    let w = st.len() / 5;
    for (s, o) in st.chunks_mut(w).enumerate() {
        col_kernel::<R, B>(o, &rows[s * w..], layout, h, i, k);
    }
}

/// Row `i` of the SSIM map, written over `o`; `st` is scratch of 5 w values.
#[inline(always)]
fn map_row<R: Real, const B: usize>(
    o: &mut [R],
    st: &mut [R],
    rows: &[R],
    layout: RowLayout,
    h: usize,
    i: usize,
    k: &[R],
) {
    let w = o.len();
    col_stats::<R, B>(st, rows, layout, h, i, k);
    let [mx, my, exx, eyy, exy] = split5(st, w);
    for j in 0..w {
        let (_, _, a1, a2, b1, b2) = terms([mx[j], my[j], exx[j], eyy[j], exy[j]]);
        o[j] = (a1 * a2) / (b1 * b2);
    }
}

/// Row `i` of S (`o_s`) and of the three partials times `inv_n` (`o_d`, 3 w values side by
/// side); `st` is scratch of 5 w values.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn partials_row<R: Real, const B: usize>(
    o_s: &mut [R],
    o_d: &mut [R],
    st: &mut [R],
    rows: &[R],
    layout: RowLayout,
    h: usize,
    i: usize,
    k: &[R],
    inv_n: R,
) {
    let w = o_s.len();
    col_stats::<R, B>(st, rows, layout, h, i, k);
    let [mx, my, exx, eyy, exy] = split5(st, w);
    let (o_mu, rest) = o_d.split_at_mut(w);
    let (o_xx, o_xy) = rest.split_at_mut(w);
    let (o_xx, o_xy) = (&mut o_xx[..w], &mut o_xy[..w]);
    for j in 0..w {
        let (s, d) = partials([mx[j], my[j], exx[j], eyy[j], exy[j]], inv_n);
        o_s[j] = s;
        o_mu[j] = d[0];
        o_xx[j] = d[1];
        o_xy[j] = d[2];
    }
}

/// Row `i` of d mean(S) / dx = W^T d_mu + 2 x W^T d_xx + y W^T d_xy, written over `o`: each
/// partial of `parts` (3 w values per row, row `a` at `layout.start(a)`) correlated along the
/// columns, then along the row, with the reversed window `kr` (the adjoint of the blur); `col`
/// (w values) and `g` (3 w) are scratch.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn grad_row<R: Real, const B: usize>(
    o: &mut [R],
    col: &mut [R],
    g: &mut [R],
    parts: &[R],
    layout: RowLayout,
    xi: &[R],
    yi: &[R],
    h: usize,
    i: usize,
    kr: &[R],
) {
    let w = o.len();
    for (s, gs) in g.chunks_mut(w).enumerate() {
        col_kernel::<R, B>(col, &parts[s * w..], layout, h, i, kr);
        row_kernel::<R, B>(gs, col, kr);
    }
    let (g_mu, rest) = g.split_at(w);
    let (g_xx, g_xy) = rest.split_at(w);
    let (g_xx, g_xy, xi, yi) = (&g_xx[..w], &g_xy[..w], &xi[..w], &yi[..w]);
    let two = R::c(2.0);
    for j in 0..w {
        o[j] = g_mu[j] + two * xi[j] * g_xx[j] + yi[j] * g_xy[j];
    }
}

/// The five rows of `st` (5 w values), each exactly `w` long.
#[inline(always)]
fn split5<R: Real>(st: &[R], w: usize) -> [&[R]; 5] {
    [0, 1, 2, 3, 4].map(|s| &st[s * w..(s + 1) * w])
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](o: &mut [R], prod: &mut [R], xi: &[R], yi: &[R], k: &[R]);
    stats_row_avx2 => { stats_row::<R, BLOCK_AVX2>(o, prod, xi, yi, k) }
    stats_row_avx512 => { stats_row::<R, BLOCK_AVX512>(o, prod, xi, yi, k) }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](o: &mut [R], st: &mut [R], rows: &[R], layout: RowLayout, h: usize, i: usize, k: &[R]);
    map_row_avx2 => { map_row::<R, BLOCK_AVX2>(o, st, rows, layout, h, i, k) }
    map_row_avx512 => { map_row::<R, BLOCK_AVX512>(o, st, rows, layout, h, i, k) }
}

crate::simd::wide_kernels! {
    #[allow(clippy::too_many_arguments)]
    unsafe fn [R: Real](o_s: &mut [R], o_d: &mut [R], st: &mut [R], rows: &[R], layout: RowLayout, h: usize, i: usize, k: &[R], inv_n: R);
    partials_row_avx2 => { partials_row::<R, BLOCK_AVX2>(o_s, o_d, st, rows, layout, h, i, k, inv_n) }
    partials_row_avx512 => { partials_row::<R, BLOCK_AVX512>(o_s, o_d, st, rows, layout, h, i, k, inv_n) }
}

crate::simd::wide_kernels! {
    #[allow(clippy::too_many_arguments)]
    unsafe fn [R: Real](o: &mut [R], col: &mut [R], g: &mut [R], parts: &[R], layout: RowLayout, xi: &[R], yi: &[R], h: usize, i: usize, kr: &[R]);
    grad_row_avx2 => { grad_row::<R, BLOCK_AVX2>(o, col, g, parts, layout, xi, yi, h, i, kr) }
    grad_row_avx512 => { grad_row::<R, BLOCK_AVX512>(o, col, g, parts, layout, xi, yi, h, i, kr) }
}

/// One band of output rows and the rings that feed it: the last `K` rows (`K` = the window's
/// length) of the row pass (5 w values each) and of the partials (3 w each), and row scratch.
/// A band computes the rows of the row pass and of the partials that its output rows need, its
/// neighbours' included (up to 2 r and r rows more), so bands are independent; every row is
/// computed the same way in whichever band, so the bits do not depend on the band's height.
struct Band<'a, R: Real> {
    simd: Simd,
    x: &'a Image2d<R>,
    y: &'a Image2d<R>,
    k: &'a [R],
    stats: Vec<R>,
    stats_at: RowLayout,
    /// The next row of the row pass to compute.
    next_stats: usize,
    prod: Vec<R>,
    st: Vec<R>,
}

impl<'a, R: Real> Band<'a, R> {
    fn new(simd: Simd, x: &'a Image2d<R>, y: &'a Image2d<R>, k: &'a [R], first: usize) -> Self {
        let w = x.width;
        Band {
            simd,
            x,
            y,
            k,
            stats: vec![R::zero(); k.len() * 5 * w],
            stats_at: RowLayout {
                stride: 5 * w,
                held: k.len(),
            },
            next_stats: first,
            prod: vec![R::zero(); 3 * w],
            st: vec![R::zero(); 5 * w],
        }
    }

    /// Compute the row pass up to the rows that output row `i` of the statistics needs.
    fn stats_for(&mut self, i: usize) {
        let (w, h) = (self.x.width, self.x.height);
        let end = h.min(i + self.k.len() / 2 + 1);
        while self.next_stats < end {
            let a = self.next_stats;
            let at = self.stats_at.start(a);
            let (o, prod) = (&mut self.stats[at..at + 5 * w], &mut self.prod[..]);
            let (xi, yi) = (&self.x.data[a * w..][..w], &self.y.data[a * w..][..w]);
            let k = self.k;
            per_simd!(
                self.simd,
                stats_row,
                stats_row_avx2,
                stats_row_avx512(o, prod, xi, yi, k)
            );
            self.next_stats += 1;
        }
    }
}

/// The height of a band of output rows: two bands per thread (any height gives the same bits).
fn band_height(h: usize) -> usize {
    h.div_ceil(2 * rayon::current_num_threads()).max(16)
}

/// The SSIM map S (same size as the inputs).
pub fn ssim_map<R: Real>(x: &Image2d<R>, y: &Image2d<R>) -> Image2d<R> {
    ssim_map_with(Simd::active(), x, y)
}

/// [`ssim_map`] with the instruction set `simd` (or the widest supported narrower one); every
/// path gives the same bits.
pub fn ssim_map_with<R: Real>(simd: Simd, x: &Image2d<R>, y: &Image2d<R>) -> Image2d<R> {
    map_banded(simd, x, y, band_height(x.height))
}

fn map_banded<R: Real>(simd: Simd, x: &Image2d<R>, y: &Image2d<R>, band: usize) -> Image2d<R> {
    check_same(x, y);
    let simd = simd.or_narrower();
    let (w, h) = (x.width, x.height);
    let k = cast_kernel::<R>(&window());
    let r = k.len() / 2;
    let mut out = Image2d::filled(w, h, R::zero());
    out.data
        .par_chunks_mut(band * w)
        .enumerate()
        .for_each(|(b, rows)| {
            let b0 = b * band;
            let mut bd = Band::new(simd, x, y, &k, b0.saturating_sub(r));
            for (q, o) in rows.chunks_mut(w).enumerate() {
                let i = b0 + q;
                bd.stats_for(i);
                let (st, stats, at) = (&mut bd.st[..], &bd.stats[..], bd.stats_at);
                per_simd!(
                    simd,
                    map_row,
                    map_row_avx2,
                    map_row_avx512(o, st, stats, at, h, i, &k)
                );
            }
        });
    out
}

/// Mean SSIM of `a` against `b` (11x11 Gaussian window, sigma 1.5, zero padding).
pub fn ssim<R: Real>(a: &Image2d<R>, b: &Image2d<R>) -> f64 {
    let m = ssim_map(a, b);
    det_sum_by(m.data.len(), |p| m.data[p].f64()) / m.data.len() as f64
}

/// Mean SSIM of `x` against `y` and its gradient with respect to `x`.
pub fn ssim_forward_backward<R: Real>(x: &Image2d<R>, y: &Image2d<R>) -> (f64, Image2d<R>) {
    ssim_forward_backward_with(Simd::active(), x, y)
}

/// [`ssim_forward_backward`] with the instruction set `simd` (or the widest supported narrower
/// one); every path gives the same bits.
pub fn ssim_forward_backward_with<R: Real>(
    simd: Simd,
    x: &Image2d<R>,
    y: &Image2d<R>,
) -> (f64, Image2d<R>) {
    forward_backward_banded(simd, x, y, band_height(x.height))
}

fn forward_backward_banded<R: Real>(
    simd: Simd,
    x: &Image2d<R>,
    y: &Image2d<R>,
    band: usize,
) -> (f64, Image2d<R>) {
    check_same(x, y);
    let simd = simd.or_narrower();
    let (w, h) = (x.width, x.height);
    let n = x.data.len();
    let k = cast_kernel::<R>(&window());
    let kr: Vec<R> = k.iter().rev().copied().collect();
    let r = k.len() / 2;
    let inv_n = R::c(1.0 / n as f64);
    let zero = R::zero();
    let parts_at = RowLayout {
        stride: 3 * w,
        held: k.len(),
    };
    // Per band: S of its rows (for the value) and the gradient of its rows.
    let mut sv = vec![zero; n];
    let mut grad = Image2d::filled(w, h, zero);
    sv.par_chunks_mut(band * w)
        .zip(grad.data.par_chunks_mut(band * w))
        .enumerate()
        .for_each(|(b, (sv_rows, grad_rows))| {
            let b0 = b * band;
            let b1 = b0 + sv_rows.len() / w;
            let first_part = b0.saturating_sub(r);
            let mut bd = Band::new(simd, x, y, &k, first_part.saturating_sub(r));
            let mut parts = vec![zero; k.len() * 3 * w];
            let (mut s_spare, mut col, mut g) = (vec![zero; w], vec![zero; w], vec![zero; 3 * w]);
            let mut next_part = first_part;
            for i in b0..b1 {
                // The partials of rows up to i + r (the rows outside the band are a
                // neighbour's too: their S is not kept), then the gradient of row i.
                while next_part < h.min(i + r + 1) {
                    let a = next_part;
                    bd.stats_for(a);
                    let o_s = if (b0..b1).contains(&a) {
                        &mut sv_rows[(a - b0) * w..][..w]
                    } else {
                        &mut s_spare[..]
                    };
                    let at = parts_at.start(a);
                    let o_d = &mut parts[at..at + 3 * w];
                    let (st, stats, stats_at) = (&mut bd.st[..], &bd.stats[..], bd.stats_at);
                    per_simd!(
                        simd,
                        partials_row,
                        partials_row_avx2,
                        partials_row_avx512(o_s, o_d, st, stats, stats_at, h, a, &k, inv_n)
                    );
                    next_part += 1;
                }
                let o = &mut grad_rows[(i - b0) * w..][..w];
                let (xi, yi) = (&x.data[i * w..][..w], &y.data[i * w..][..w]);
                per_simd!(
                    simd,
                    grad_row,
                    grad_row_avx2,
                    grad_row_avx512(o, &mut col, &mut g, &parts, parts_at, xi, yi, h, i, &kr)
                );
            }
        });
    let value = det_sum_by(n, |p| sv[p].f64()) / n as f64;
    (value, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn pair(w: usize, h: usize, seed: u64) -> (Image2d<f64>, Image2d<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut img = || {
            let v = (0..w * h).map(|_| rng.random::<f64>()).collect();
            Image2d::from_vec(w, h, v)
        };
        (img(), img())
    }

    fn bits<R: Real>(im: &Image2d<R>) -> Vec<u64> {
        im.data.iter().map(|v| v.f64().to_bits()).collect()
    }

    /// The fused kernels against the five whole-image blurs of [`reference`], bit for bit, on
    /// every instruction set, in f32 and f64, on sides shorter and longer than the window and
    /// widths that leave remainders for every lane count.
    #[test]
    fn fused_kernels_give_the_bits_of_the_definition() {
        fn check<R: Real>(x: &Image2d<R>, y: &Image2d<R>) {
            let (v0, g0) = reference::ssim_forward_backward(x, y);
            let m0 = reference::ssim_map(x, y);
            for p in Simd::ALL {
                let (v, g) = ssim_forward_backward_with(p, x, y);
                let what = format!("{p:?} {}x{}", x.width, x.height);
                assert_eq!(v.to_bits(), v0.to_bits(), "value {what}");
                assert_eq!(bits(&g), bits(&g0), "gradient {what}");
                assert_eq!(bits(&ssim_map_with(p, x, y)), bits(&m0), "map {what}");
            }
        }
        for (w, h) in [(37, 29), (203, 13), (5, 17), (16, 3), (1, 1), (1, 12)] {
            let (x, y) = pair(w, h, (w * h) as u64);
            check(&x, &y);
            check::<f32>(&x.cast(), &y.cast());
        }
    }

    /// Bands of any height (one row, fewer rows than the window's radius, uneven, the whole
    /// image) give the bits of the definition: a band computes its neighbours' rows itself.
    #[test]
    fn any_band_height_gives_the_same_bits() {
        let (x, y) = pair(23, 31, 4);
        let (x, y): (Image2d<f32>, Image2d<f32>) = (x.cast(), y.cast());
        let (v0, g0) = reference::ssim_forward_backward(&x, &y);
        let m0 = reference::ssim_map(&x, &y);
        for band in [1, 2, 3, 5, 7, 11, 12, 30, 31, 40] {
            let (v, g) = forward_backward_banded(Simd::active(), &x, &y, band);
            assert_eq!(v.to_bits(), v0.to_bits(), "band {band}");
            assert_eq!(bits(&g), bits(&g0), "band {band}");
            assert_eq!(bits(&map_banded(Simd::active(), &x, &y, band)), bits(&m0));
        }
    }

    #[test]
    #[should_panic(expected = "SSIM of images of different or empty size: 5x4 vs 4x5")]
    fn images_of_different_sizes_are_refused() {
        let (x, _) = pair(5, 4, 1);
        let (y, _) = pair(4, 5, 2);
        ssim_forward_backward(&x, &y);
    }

    #[test]
    fn fused_kernels_are_thread_count_invariant() {
        let (x, y) = pair(131, 70, 9);
        let (x, y): (Image2d<f32>, Image2d<f32>) = (x.cast(), y.cast());
        let run = |t: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            pool.install(|| ssim_forward_backward(&x, &y))
        };
        let (v1, g1) = run(1);
        for t in [2, 3] {
            let (v, g) = run(t);
            assert_eq!(v.to_bits(), v1.to_bits());
            assert_eq!(bits(&g), bits(&g1));
        }
    }
}
