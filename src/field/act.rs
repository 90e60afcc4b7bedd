//! The element-wise passes of the MLP between its matrix products, compiled like [`super::gemm`]
//! for each instruction set (the same IEEE-754 operation per element on every path, so the
//! same bits): LeakyReLU forward and its backward over row-strided blocks, and the column sums
//! of `db`.

use std::any::TypeId;

use crate::real::Real;
use crate::simd::Simd;

/// A block of `n` rows of `w` values: row `r` starts at `off + r * ld`.
#[derive(Clone, Copy, Debug)]
pub struct Rows {
    pub ld: usize,
    pub off: usize,
}

/// `out(r, k) = d(r, k)` when `z[r * w + k] > 0`, else `d(r, k) * slope`, for `r < n`,
/// `k < w` (`z` is `n x w` dense). The LeakyReLU forward with `d = z`, and its backward with
/// `d` = dL/d(output).
#[allow(clippy::too_many_arguments)]
pub fn leaky<R: Real>(
    simd: Simd,
    d: &[R],
    dl: Rows,
    z: &[R],
    n: usize,
    w: usize,
    slope: R,
    out: &mut [R],
    ol: Rows,
) {
    if n == 0 || w == 0 {
        return;
    }
    assert!(
        dl.off + (n - 1) * dl.ld + w <= d.len(),
        "leaky: d too short"
    );
    assert!(
        ol.off + (n - 1) * ol.ld + w <= out.len(),
        "leaky: out too short"
    );
    assert!(n * w <= z.len(), "leaky: z too short");
    if TypeId::of::<R>() == TypeId::of::<f32>() {
        // SAFETY: R is f32 (same type, so same size and alignment); the bounds are checked.
        unsafe {
            let d = std::slice::from_raw_parts(d.as_ptr() as *const f32, d.len());
            let z = std::slice::from_raw_parts(z.as_ptr() as *const f32, z.len());
            let out = std::slice::from_raw_parts_mut(out.as_mut_ptr() as *mut f32, out.len());
            let slope = slope.f64() as f32;
            #[cfg(target_arch = "x86_64")]
            match simd.or_narrower() {
                Simd::Avx512 => return leaky_avx512(d, dl, z, n, w, slope, out, ol),
                Simd::Avx2 => return leaky_avx2(d, dl, z, n, w, slope, out, ol),
                Simd::Scalar => {}
            }
            let _ = simd;
            return leaky_body(d, dl, z, n, w, slope, out, ol);
        }
    }
    leaky_body(d, dl, z, n, w, slope, out, ol)
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn leaky_body<R: Real>(
    d: &[R],
    dl: Rows,
    z: &[R],
    n: usize,
    w: usize,
    slope: R,
    out: &mut [R],
    ol: Rows,
) {
    for r in 0..n {
        let dr = &d[dl.off + r * dl.ld..][..w];
        let zr = &z[r * w..][..w];
        let or = &mut out[ol.off + r * ol.ld..][..w];
        for ((o, &dv), &zv) in or.iter_mut().zip(dr).zip(zr) {
            *o = if zv > R::zero() { dv } else { dv * slope };
        }
    }
}

crate::simd::wide_kernels! {
    #[allow(clippy::too_many_arguments)]
    unsafe fn [](
        d: &[f32],
        dl: Rows,
        z: &[f32],
        n: usize,
        w: usize,
        slope: f32,
        out: &mut [f32],
        ol: Rows,
    );
    leaky_avx2 => { leaky_body(d, dl, z, n, w, slope, out, ol) }
    leaky_avx512 => { leaky_body(d, dl, z, n, w, slope, out, ol) }
}

/// `acc[o] += sum_r g[r * w + o]`, rows in order (each column one chain).
pub fn sum_rows<R: Real>(simd: Simd, g: &[R], n: usize, w: usize, acc: &mut [R]) {
    assert!(n * w <= g.len() && w <= acc.len(), "sum_rows: too short");
    if TypeId::of::<R>() == TypeId::of::<f32>() {
        // SAFETY: R is f32 (same type, so same size and alignment).
        unsafe {
            let g = std::slice::from_raw_parts(g.as_ptr() as *const f32, g.len());
            let acc = std::slice::from_raw_parts_mut(acc.as_mut_ptr() as *mut f32, acc.len());
            #[cfg(target_arch = "x86_64")]
            match simd.or_narrower() {
                Simd::Avx512 => return sum_rows_avx512(g, n, w, acc),
                Simd::Avx2 => return sum_rows_avx2(g, n, w, acc),
                Simd::Scalar => {}
            }
            let _ = simd;
            return sum_rows_body(g, n, w, acc);
        }
    }
    sum_rows_body(g, n, w, acc)
}

#[inline(always)]
fn sum_rows_body<R: Real>(g: &[R], n: usize, w: usize, acc: &mut [R]) {
    let acc = &mut acc[..w];
    for r in 0..n {
        for (a, &gv) in acc.iter_mut().zip(&g[r * w..][..w]) {
            *a += gv;
        }
    }
}

crate::simd::wide_kernels! {
    unsafe fn [](g: &[f32], n: usize, w: usize, acc: &mut [f32]);
    sum_rows_avx2 => { sum_rows_body(g, n, w, acc) }
    sum_rows_avx512 => { sum_rows_body(g, n, w, acc) }
}
