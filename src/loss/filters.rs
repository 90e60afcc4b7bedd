//! Image filters shared by SSIM (Eq. 8) and the SPWM attention map (Eq. 6): separable Gaussian
//! correlation and the 3x3 Sobel operator, both with **zero padding** and same-size output (as
//! PyTorch `conv2d(.., padding = k // 2)`, which is a cross-correlation), plus their adjoints
//! (the transposed linear maps) used by the backward passes.
//!
//! Every output pixel is one fixed sequential sum over the kernel taps in ascending order, so the
//! result does not depend on how rows are spread over threads (rayon over output rows only).
//! The loops over a row's pixels run with the widest SIMD instruction set of the CPU
//! ([`Simd::active`]): each lane is one pixel doing the same multiplies and adds in the same
//! order (no fused multiply-add), so every path gives the same bits.

use rayon::prelude::*;

use crate::image2d::Image2d;
use crate::real::Real;
use crate::simd::Simd;

/// Normalised 1D Gaussian `exp(-(k - r)^2 / (2 sigma^2)) / sum`, `k = 0..size`, `r = size / 2`.
/// `extra_norm_eps` is added to the normalising sum (the UniSpine-GS blur adds 1e-12; the SSIM
/// window adds nothing).
pub fn gaussian_kernel(size: usize, sigma: f64, extra_norm_eps: f64) -> Vec<f64> {
    let r = (size / 2) as f64;
    let g: Vec<f64> = (0..size)
        .map(|k| {
            let c = k as f64 - r;
            (-(c * c) / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let s: f64 = g.iter().sum::<f64>() + extra_norm_eps;
    g.into_iter().map(|v| v / s).collect()
}

pub(super) fn cast_kernel<R: Real>(k: &[f64]) -> Vec<R> {
    k.iter().map(|&v| R::c(v)).collect()
}

/// Pixels per register block of the filter kernels (`B`), per instruction set: the block's sums
/// stay in registers while every tap is added (the output is written once instead of read and
/// written once per tap), and there are enough of them (eight vectors of f32) for the adds'
/// latency to overlap. The block changes no sum: each pixel adds its taps in the same order.
pub(super) const BLOCK_AVX512: usize = 128;
pub(super) const BLOCK_AVX2: usize = 64;
pub(super) const BLOCK_SCALAR: usize = 16;

/// One output row of [`correlate_rows`] (`xi` the input row), written over `o`.
///
/// Per pixel j: acc = 0 + k[t_lo] x[j + t_lo - r] + k[t_lo + 1] x[..] + ..., the taps that reach
/// inside the row in ascending order (zero padding: the others are skipped, not added as 0).
#[inline(always)]
pub(super) fn row_kernel<R: Real, const B: usize>(o: &mut [R], xi: &[R], k: &[R]) {
    let w = o.len();
    let xi = &xi[..w];
    let r = k.len() / 2;
    // Pixels [lo, hi) have every tap inside the row.
    let lo = r.min(w);
    let hi = w.saturating_sub(k.len() - 1 - r).max(lo);
    let pixel = |j: usize| {
        let t_lo = r.saturating_sub(j);
        let t_hi = k.len().min(w + r - j);
        let mut acc = R::zero();
        for t in t_lo..t_hi {
            acc += k[t] * xi[j + t - r];
        }
        acc
    };
    for j in (0..lo).chain(hi..w) {
        o[j] = pixel(j);
    }
    let mut j = lo;
    while j + B <= hi {
        let mut acc = [R::zero(); B];
        for (t, &kt) in k.iter().enumerate() {
            let src = &xi[j + t - r..][..B];
            for l in 0..B {
                acc[l] += kt * src[l];
            }
        }
        o[j..j + B].copy_from_slice(&acc);
        j += B;
    }
    for (jj, oj) in o.iter_mut().enumerate().take(hi).skip(j) {
        *oj = pixel(jj);
    }
}

/// Where row `a` of an image starts in a buffer: at `(a % held) * stride` (a whole image in
/// rows `stride` apart: `held` is its height; a ring of the last `held` rows: slots `stride`
/// apart).
#[derive(Clone, Copy, Debug)]
pub(super) struct RowLayout {
    pub stride: usize,
    pub held: usize,
}

impl RowLayout {
    #[inline(always)]
    pub(super) fn start(self, a: usize) -> usize {
        (a % self.held) * self.stride
    }
}

/// Output row `i` of [`correlate_cols`], written over `o`, of the image of height `h` whose row
/// `a` is `x[layout.start(a)..][..o.len()]`.
///
/// Per pixel: acc = 0 + k[t_lo] x[..] + k[t_lo + 1] x[..] + ..., the taps that reach inside the
/// image in ascending order (the same taps for every pixel of the row; t_lo < t_hi as i < h).
#[inline(always)]
pub(super) fn col_kernel<R: Real, const B: usize>(
    o: &mut [R],
    x: &[R],
    layout: RowLayout,
    h: usize,
    i: usize,
    k: &[R],
) {
    let w = o.len();
    let r = k.len() / 2;
    let t_lo = r.saturating_sub(i);
    let t_hi = k.len().min(h + r - i);
    // The slot of the first tap's row; the next taps' rows follow it, wrapping once at most
    // (a ring holds at least as many rows as there are taps, an image all of them).
    let first = (i + t_lo - r) % layout.held;
    let start = |t: usize| {
        let slot = first + (t - t_lo);
        let slot = if slot >= layout.held {
            slot - layout.held
        } else {
            slot
        };
        slot * layout.stride
    };
    let mut j = 0;
    while j + B <= w {
        let mut acc = [R::zero(); B];
        for (t, &kt) in k.iter().enumerate().take(t_hi).skip(t_lo) {
            let src = &x[start(t) + j..][..B];
            for l in 0..B {
                acc[l] += kt * src[l];
            }
        }
        o[j..j + B].copy_from_slice(&acc);
        j += B;
    }
    if j < w {
        let tail = &mut o[j..];
        tail.fill(R::zero());
        for (t, &kt) in k.iter().enumerate().take(t_hi).skip(t_lo) {
            let src = &x[start(t) + j..][..tail.len()];
            for (oj, &xj) in tail.iter_mut().zip(src) {
                *oj += kt * xj;
            }
        }
    }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](o: &mut [R], xi: &[R], k: &[R]);
    row_kernel_avx2 => { row_kernel::<R, BLOCK_AVX2>(o, xi, k) }
    row_kernel_avx512 => { row_kernel::<R, BLOCK_AVX512>(o, xi, k) }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](o: &mut [R], x: &[R], layout: RowLayout, h: usize, i: usize, k: &[R]);
    col_kernel_avx2 => { col_kernel::<R, BLOCK_AVX2>(o, x, layout, h, i, k) }
    col_kernel_avx512 => { col_kernel::<R, BLOCK_AVX512>(o, x, layout, h, i, k) }
}

/// One row of a row correlation with `k` (zero padding): `o[j] = sum_t k[t] xi[j + t - r]`,
/// taps ascending, written over `o`; `simd` must come from [`Simd::or_narrower`].
#[inline]
fn correlate_row<R: Real>(simd: Simd, o: &mut [R], xi: &[R], k: &[R]) {
    match simd {
        // SAFETY: the caller passes an instruction set from `or_narrower`, which the CPU supports.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { row_kernel_avx512(o, xi, k) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { row_kernel_avx2(o, xi, k) },
        _ => row_kernel::<R, BLOCK_SCALAR>(o, xi, k),
    }
}

/// 1D correlation of every row with `k` (odd length, centre `k.len() / 2`), zero padding:
/// `out[i][j] = sum_t k[t] x[i][j + t - r]`.
fn correlate_rows<R: Real>(simd: Simd, x: &Image2d<R>, k: &[R]) -> Image2d<R> {
    let (w, h) = (x.width, x.height);
    let mut out = Image2d::filled(w, h, R::zero());
    if w == 0 || h == 0 {
        return out;
    }
    let simd = simd.or_narrower();
    out.data
        .par_chunks_mut(w)
        .zip(x.data.par_chunks(w))
        .for_each(|(o, xi)| correlate_row(simd, o, xi, k));
    out
}

/// 1D correlation of every column with `k`, zero padding:
/// `out[i][j] = sum_t k[t] x[i + t - r][j]`.
fn correlate_cols<R: Real>(simd: Simd, x: &Image2d<R>, k: &[R]) -> Image2d<R> {
    let (w, h) = (x.width, x.height);
    let mut out = Image2d::filled(w, h, R::zero());
    if w == 0 || h == 0 {
        return out;
    }
    let simd = simd.or_narrower();
    let xd = &x.data;
    out.data.par_chunks_mut(w).enumerate().for_each(|(i, o)| {
        let layout = RowLayout { stride: w, held: h };
        match simd {
            // SAFETY: `or_narrower` returns an instruction set the CPU supports.
            #[cfg(target_arch = "x86_64")]
            Simd::Avx512 => unsafe { col_kernel_avx512(o, xd, layout, h, i, k) },
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => unsafe { col_kernel_avx2(o, xd, layout, h, i, k) },
            _ => col_kernel::<R, BLOCK_SCALAR>(o, xd, layout, h, i, k),
        }
    });
    out
}

fn reversed<R: Real>(k: &[R]) -> Vec<R> {
    k.iter().rev().copied().collect()
}

/// Separable correlation: rows with `k_row` first, then columns with `k_col` (zero padding).
/// With zero padding this equals the 2D correlation with the outer product `k_col k_row^T`.
pub fn correlate_sep<R: Real>(x: &Image2d<R>, k_row: &[f64], k_col: &[f64]) -> Image2d<R> {
    correlate_sep_with(Simd::active(), x, k_row, k_col)
}

/// [`correlate_sep`] with the instruction set `simd` (or the widest supported narrower one);
/// every path gives the same bits.
pub fn correlate_sep_with<R: Real>(
    simd: Simd,
    x: &Image2d<R>,
    k_row: &[f64],
    k_col: &[f64],
) -> Image2d<R> {
    let t = correlate_rows(simd, x, &cast_kernel::<R>(k_row));
    correlate_cols(simd, &t, &cast_kernel::<R>(k_col))
}

/// Adjoint of [`correlate_sep`]: `<correlate_sep(x), y> = <x, correlate_sep_adjoint(y)>`
/// (correlation with the reversed kernels, in the reverse order).
pub fn correlate_sep_adjoint<R: Real>(y: &Image2d<R>, k_row: &[f64], k_col: &[f64]) -> Image2d<R> {
    correlate_sep_adjoint_with(Simd::active(), y, k_row, k_col)
}

/// [`correlate_sep_adjoint`] with the instruction set `simd` (same bits on every path).
pub fn correlate_sep_adjoint_with<R: Real>(
    simd: Simd,
    y: &Image2d<R>,
    k_row: &[f64],
    k_col: &[f64],
) -> Image2d<R> {
    let t = correlate_cols(simd, y, &reversed(&cast_kernel::<R>(k_col)));
    correlate_rows(simd, &t, &reversed(&cast_kernel::<R>(k_row)))
}

/// Separable Gaussian blur with the 1D kernel `k` on both axes (zero padding).
pub fn blur<R: Real>(x: &Image2d<R>, k: &[f64]) -> Image2d<R> {
    correlate_sep(x, k, k)
}

/// Adjoint of [`blur`] (equal to `blur` itself for a symmetric kernel).
pub fn blur_adjoint<R: Real>(y: &Image2d<R>, k: &[f64]) -> Image2d<R> {
    correlate_sep_adjoint(y, k, k)
}

/// Sobel x kernel as cross-correlation (UniSpine-GS `sobel_x`); the y kernel is its transpose.
pub const SOBEL_X: [[f64; 3]; 3] = [[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]];

/// Sobel gradients `(gx, gy)`: 2D correlation with [`SOBEL_X`] and its transpose, zero padding 1.
/// Written as the separable products `gx = [1 2 1]^T (x) [-1 0 1]`, `gy = [-1 0 1]^T (x) [1 2 1]`.
pub fn sobel<R: Real>(x: &Image2d<R>) -> (Image2d<R>, Image2d<R>) {
    let (d, s) = ([-1.0, 0.0, 1.0], [1.0, 2.0, 1.0]);
    (correlate_sep(x, &d, &s), correlate_sep(x, &s, &d))
}

/// Adjoint of [`sobel`]: `<sobel(x), (a, b)> = <x, sobel_adjoint(a, b)>`.
pub fn sobel_adjoint<R: Real>(gx_bar: &Image2d<R>, gy_bar: &Image2d<R>) -> Image2d<R> {
    let (d, s) = ([-1.0, 0.0, 1.0], [1.0, 2.0, 1.0]);
    let mut a = correlate_sep_adjoint(gx_bar, &d, &s);
    let b = correlate_sep_adjoint(gy_bar, &s, &d);
    for (u, v) in a.data.iter_mut().zip(&b.data) {
        *u += *v;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(w: usize, h: usize, seed: u64) -> Image2d<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        Image2d::from_vec(
            w,
            h,
            (0..w * h).map(|_| rng.random::<f64>() - 0.3).collect(),
        )
    }

    fn dot(a: &Image2d<f64>, b: &Image2d<f64>) -> f64 {
        a.data.iter().zip(&b.data).map(|(x, y)| x * y).sum()
    }

    /// Direct 2D zero-padded correlation with a dense kernel, the definition.
    fn correlate2d(x: &Image2d<f64>, k: &[Vec<f64>]) -> Image2d<f64> {
        let (kh, kw) = (k.len(), k[0].len());
        let (rh, rw) = (kh as isize / 2, kw as isize / 2);
        let mut out = Image2d::filled(x.width, x.height, 0.0);
        for i in 0..x.height as isize {
            for j in 0..x.width as isize {
                let mut s = 0.0;
                for a in 0..kh as isize {
                    for b in 0..kw as isize {
                        let (p, q) = (i + a - rh, j + b - rw);
                        if p >= 0 && q >= 0 && p < x.height as isize && q < x.width as isize {
                            s += k[a as usize][b as usize] * x.at(p as usize, q as usize);
                        }
                    }
                }
                out.data[i as usize * x.width + j as usize] = s;
            }
        }
        out
    }

    #[test]
    fn separable_equals_dense_2d_correlation() {
        let x = random(9, 6, 1);
        let (kr, kc) = ([0.1, -0.7, 0.3, 0.5, 0.2], [0.4, 1.0, -0.5]);
        let dense: Vec<Vec<f64>> = kc
            .iter()
            .map(|a| kr.iter().map(|b| a * b).collect())
            .collect();
        let want = correlate2d(&x, &dense);
        let got = correlate_sep(&x, &kr, &kc);
        for (g, w) in got.data.iter().zip(&want.data) {
            assert!((g - w).abs() < 1e-14, "{g} vs {w}");
        }
        // Sobel against the literal 3x3 kernels (UniSpine-GS sobel_x, sobel_y = sobel_x^T).
        let sx: Vec<Vec<f64>> = SOBEL_X.iter().map(|r| r.to_vec()).collect();
        let sy: Vec<Vec<f64>> = (0..3)
            .map(|a| (0..3).map(|b| SOBEL_X[b][a]).collect())
            .collect();
        let (gx, gy) = sobel(&x);
        for (got, k) in [(&gx, &sx), (&gy, &sy)] {
            let want = correlate2d(&x, k);
            for (g, w) in got.data.iter().zip(&want.data) {
                assert!((g - w).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn adjoints_pass_the_dot_product_test() {
        // Wide kernel (longer than the image side) to exercise every border case.
        let k = gaussian_kernel(11, 1.5, 0.0);
        let kr = [0.3, -1.0, 0.25, 2.0, 0.5, -0.1, 0.7];
        for (w, h) in [(13, 17), (4, 3), (1, 1)] {
            let x = random(w, h, 2);
            let y = random(w, h, 3);
            let y2 = random(w, h, 4);
            let lhs = dot(&blur(&x, &k), &y);
            let rhs = dot(&x, &blur_adjoint(&y, &k));
            assert!((lhs - rhs).abs() < 1e-13 * (1.0 + lhs.abs()), "{lhs} {rhs}");
            let lhs = dot(&correlate_sep(&x, &kr, &k), &y);
            let rhs = dot(&x, &correlate_sep_adjoint(&y, &kr, &k));
            assert!((lhs - rhs).abs() < 1e-13 * (1.0 + lhs.abs()), "{lhs} {rhs}");
            let (gx, gy) = sobel(&x);
            let lhs = dot(&gx, &y) + dot(&gy, &y2);
            let rhs = dot(&x, &sobel_adjoint(&y, &y2));
            assert!((lhs - rhs).abs() < 1e-13 * (1.0 + lhs.abs()), "{lhs} {rhs}");
        }
    }

    #[test]
    fn gaussian_kernel_values() {
        // Kernel 3, sigma 1.5: exp(-1/4.5) = 0.80073740..., weights [0.3078, 0.3844, 0.3078].
        let k = gaussian_kernel(3, 1.5, 0.0);
        let e = (-1.0f64 / 4.5).exp();
        assert!((k[0] - e / (1.0 + 2.0 * e)).abs() < 1e-16);
        assert!((k[1] - 1.0 / (1.0 + 2.0 * e)).abs() < 1e-16);
        assert_eq!(k[0], k[2]);
        assert!((k[0] - 0.3078).abs() < 1e-4 && (k[1] - 0.3844).abs() < 1e-4);
        let k11 = gaussian_kernel(11, 1.5, 0.0);
        assert!((k11.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn every_simd_path_gives_the_same_bits() {
        // Widths that leave remainders for every lane count, a kernel longer than the image.
        let bits = |im: &Image2d<f32>| im.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let k = gaussian_kernel(11, 1.5, 0.0);
        let kr = [0.3, -1.0, 0.25, 2.0, 0.5, -0.1, 0.7];
        for (w, h) in [(203, 77), (37, 5), (4, 9), (1, 1)] {
            let x: Image2d<f32> = random(w, h, 6).cast();
            let want = (
                correlate_sep_with(Simd::Scalar, &x, &kr, &k),
                correlate_sep_adjoint_with(Simd::Scalar, &x, &kr, &k),
            );
            for p in Simd::ALL {
                let got = (
                    correlate_sep_with(p, &x, &kr, &k),
                    correlate_sep_adjoint_with(p, &x, &kr, &k),
                );
                assert_eq!(bits(&got.0), bits(&want.0), "{p:?} {w}x{h}");
                assert_eq!(bits(&got.1), bits(&want.1), "{p:?} {w}x{h}");
            }
        }
    }

    #[test]
    fn filters_are_thread_count_invariant() {
        let x: Image2d<f32> = random(203, 77, 5).cast();
        let k = gaussian_kernel(11, 1.5, 0.0);
        let mut outs = Vec::new();
        for t in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            outs.push(pool.install(|| {
                let (gx, gy) = sobel(&x);
                (blur(&x, &k), gx, gy, blur_adjoint(&x, &k))
            }));
        }
        let bits = |im: &Image2d<f32>| im.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        for o in &outs[1..] {
            assert_eq!(bits(&o.0), bits(&outs[0].0));
            assert_eq!(bits(&o.1), bits(&outs[0].1));
            assert_eq!(bits(&o.2), bits(&outs[0].2));
            assert_eq!(bits(&o.3), bits(&outs[0].3));
        }
    }
}
