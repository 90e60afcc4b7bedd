//! The matrix products of the field MLP: one strided kernel
//! `C[i][j] = init[i][j] + sum_t A(i, t) B[t][j]` (t in order), cache-blocked over rows,
//! register-tiled (a tile of rows x columns held in registers across the whole sum), and
//! compiled three times from the same source: for the baseline target ([`Simd::Scalar`], 4 x 8
//! tiles of SSE2 vectors), with AVX2 ([`Simd::Avx2`], 6 x 16: two 8-lane vectors per row) and
//! with AVX-512 ([`Simd::Avx512`], 8 x 32: two 16-lane vectors per row).
//!
//! Each element of `C` is one chain of IEEE-754 operations: start from its initial value, then
//! for t = 0, 1, ... multiply `A(i, t) B[t][j]` and add (a separate multiply and add, never
//! fused). The chain does not depend on the tile the element falls in, on the row block, on
//! the instruction set or on the thread, so every path, tiling and thread count gives the same
//! bits, and the bits equal those of the plain loops the MLP used before. (On AMD Zen 3 / 4 the two
//! floating-point add pipes and two multiply pipes give separate multiplies and adds the same
//! peak rate as fused multiply-adds, so not fusing costs no throughput there; the peak of
//! `unispine bench field` is measured with the same unfused operations.)
//!
//! The three products of a layer with `W` stored `[in][out]`:
//! - forward `Z = 1 b^T + X W` ([`forward`]);
//! - `dX = dY W^T` ([`grad_input`], from `W^T` laid out `[out][in]`, [`transpose`]);
//! - `dW += X^T dY`, `db += 1^T dY` ([`grad_weight`], rows in order).
//!
//! Generic over [`Real`]: f32 runs the blocked kernels, f64 (the gradient checks) the plain
//! loops with the same operation order.

use std::any::TypeId;

use crate::real::Real;
use crate::simd::Simd;

/// Rows per cache block (the block of `A` stays in L2 while the panels of `B` pass through L1).
const MC: usize = 96;

/// Layout of the left operand: `A(i, t) = a[i * row_stride + t * col_stride]`.
#[derive(Clone, Copy, Debug)]
struct ALayout {
    row_stride: usize,
    col_stride: usize,
}

/// The operands of one product `C = init + A B` (`m x nn`, inner dimension `kk`): `init` is
/// `bias[j]` when given, else the current `C`.
#[derive(Clone, Copy)]
struct Operands<'a> {
    a: &'a [f32],
    al: ALayout,
    b: &'a [f32],
    ldb: usize,
    bias: Option<&'a [f32]>,
    ldc: usize,
    m: usize,
    nn: usize,
    kk: usize,
}

/// Cache-blocked product with `MR x NR` register tiles (tiles with fewer rows at the bottom
/// edge use the same kernel with fewer rows; a column remainder of at least `NH` a half-width
/// tile; narrower remainders go through [`tile_edge`]).
#[inline(always)]
fn kernel_generic<const MR: usize, const NR: usize, const NH: usize>(o: Operands, c: &mut [f32]) {
    let mut i0 = 0;
    while i0 < o.m {
        let i1 = (i0 + MC).min(o.m);
        let mut j0 = 0;
        while j0 < o.nn {
            let jw = match o.nn - j0 {
                w if w >= NR => NR,
                w if w >= NH => NH,
                w => w,
            };
            let mut i = i0;
            while i < i1 {
                let iw = (i1 - i).min(MR);
                if jw == NR {
                    // SAFETY: `kernel` checked that every index of the product is in bounds.
                    unsafe { tile_rows::<MR, NR>(&o, c, i, iw, j0) };
                } else if jw == NH {
                    // SAFETY: as above.
                    unsafe { tile_rows::<MR, NH>(&o, c, i, iw, j0) };
                } else {
                    tile_edge(&o, c, i, iw, j0, jw);
                }
                i += iw;
            }
            j0 += jw;
        }
        i0 = i1;
    }
}

/// Rows `i .. i + iw` (`iw <= MR`) by columns `j0 .. j0 + NR`, accumulators in registers.
///
/// # Safety
/// Every index of rows `i .. i + iw`, columns `j0 .. j0 + NR` and `t < kk` must be in bounds
/// (checked once by [`kernel`]).
#[inline(always)]
unsafe fn tile_rows<const MR: usize, const NR: usize>(
    o: &Operands,
    c: &mut [f32],
    i: usize,
    iw: usize,
    j0: usize,
) {
    // SAFETY: as this function's contract.
    unsafe {
        match iw {
            n if n == MR => tile::<MR, NR>(o, c, i, j0),
            1 => tile::<1, NR>(o, c, i, j0),
            2 => tile::<2, NR>(o, c, i, j0),
            3 => tile::<3, NR>(o, c, i, j0),
            4 => tile::<4, NR>(o, c, i, j0),
            5 => tile::<5, NR>(o, c, i, j0),
            6 => tile::<6, NR>(o, c, i, j0),
            7 => tile::<7, NR>(o, c, i, j0),
            _ => {
                for r in i..i + iw {
                    tile::<1, NR>(o, c, r, j0)
                }
            }
        }
    }
}

/// One `R x NR` tile: the accumulators start from the initial values, then for each `t` in
/// order `acc[r][j] += A(i + r, t) * B[t][j0 + j]`.
///
/// # Safety
/// As [`tile_rows`].
#[inline(always)]
unsafe fn tile<const R: usize, const NR: usize>(o: &Operands, c: &mut [f32], i: usize, j0: usize) {
    // SAFETY: as this function's contract.
    unsafe {
        let mut acc = [[0.0f32; NR]; R];
        let cp = c.as_mut_ptr();
        for (r, row) in acc.iter_mut().enumerate() {
            let src = match o.bias {
                Some(bv) => bv.as_ptr().add(j0),
                None => cp.add((i + r) * o.ldc + j0) as *const f32,
            };
            for (j, v) in row.iter_mut().enumerate() {
                *v = *src.add(j);
            }
        }
        let ap = o.a.as_ptr();
        let bp = o.b.as_ptr().add(j0);
        let (rs, cs) = (o.al.row_stride, o.al.col_stride);
        for t in 0..o.kk {
            let bt = bp.add(t * o.ldb);
            let mut bv = [0.0f32; NR];
            for (j, v) in bv.iter_mut().enumerate() {
                *v = *bt.add(j);
            }
            for (r, row) in acc.iter_mut().enumerate() {
                let av = *ap.add((i + r) * rs + t * cs);
                for j in 0..NR {
                    row[j] += av * bv[j];
                }
            }
        }
        for (r, row) in acc.iter().enumerate() {
            let dst = cp.add((i + r) * o.ldc + j0);
            for (j, v) in row.iter().enumerate() {
                *dst.add(j) = *v;
            }
        }
    }
}

/// A tile narrower than the register tile (`jw` columns): the same chain per element.
#[inline(always)]
fn tile_edge(o: &Operands, c: &mut [f32], i: usize, iw: usize, j0: usize, jw: usize) {
    for r in i..i + iw {
        let cr = &mut c[r * o.ldc + j0..][..jw];
        if let Some(bv) = o.bias {
            cr.copy_from_slice(&bv[j0..j0 + jw]);
        }
        for t in 0..o.kk {
            let av = o.a[r * o.al.row_stride + t * o.al.col_stride];
            for (cv, &bv) in cr.iter_mut().zip(&o.b[t * o.ldb + j0..][..jw]) {
                *cv += av * bv;
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn kernel_avx2(o: Operands, c: &mut [f32]) {
    // 6 x 16: 12 accumulators of 8 lanes, two of B, a broadcast and a product (16 registers).
    kernel_generic::<6, 16, 8>(o, c)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl")]
unsafe fn kernel_avx512(o: Operands, c: &mut [f32]) {
    // 8 x 32: 16 accumulators of 16 lanes out of 32 registers.
    kernel_generic::<8, 32, 16>(o, c)
}

fn kernel_scalar(o: Operands, c: &mut [f32]) {
    // 4 x 8: 8 accumulators of 4 SSE2 lanes.
    kernel_generic::<4, 8, 4>(o, c)
}

/// Check the bounds of the product once, then run the kernel of `simd` (or the widest
/// supported narrower path).
fn kernel(simd: Simd, o: Operands, c: &mut [f32]) {
    if o.m == 0 || o.nn == 0 {
        return;
    }
    if o.kk > 0 {
        let last_a = (o.m - 1) * o.al.row_stride + (o.kk - 1) * o.al.col_stride;
        assert!(last_a < o.a.len(), "gemm: A too short");
        assert!((o.kk - 1) * o.ldb + o.nn <= o.b.len(), "gemm: B too short");
    }
    assert!((o.m - 1) * o.ldc + o.nn <= c.len(), "gemm: C too short");
    if let Some(bv) = o.bias {
        assert!(o.nn <= bv.len(), "gemm: bias too short");
    }
    assert!(
        o.nn <= o.ldc && o.nn <= o.ldb.max(o.nn),
        "gemm: row strides"
    );
    #[cfg(target_arch = "x86_64")]
    match simd.or_narrower() {
        // SAFETY: `or_narrower` only returns paths the CPU supports.
        Simd::Avx512 => return unsafe { kernel_avx512(o, c) },
        Simd::Avx2 => return unsafe { kernel_avx2(o, c) },
        Simd::Scalar => {}
    }
    let _ = simd;
    kernel_scalar(o, c)
}

/// `slice` as f32 when `R` is f32.
fn as_f32<R: Real>(s: &[R]) -> Option<&[f32]> {
    (TypeId::of::<R>() == TypeId::of::<f32>())
        // SAFETY: R is f32 (same type, so same size and alignment).
        .then(|| unsafe { std::slice::from_raw_parts(s.as_ptr() as *const f32, s.len()) })
}

/// `slice` as mutable f32 when `R` is f32.
fn as_f32_mut<R: Real>(s: &mut [R]) -> Option<&mut [f32]> {
    (TypeId::of::<R>() == TypeId::of::<f32>())
        // SAFETY: R is f32 (same type, so same size and alignment).
        .then(|| unsafe { std::slice::from_raw_parts_mut(s.as_mut_ptr() as *mut f32, s.len()) })
}

/// Forward of a layer: `z[r][o] = b[o] + sum_k x[r][k] w[k][o]` (`x`: `n x inp`, `w`:
/// `inp x out`, `z`: `n x out`), with the instruction set `simd`.
#[allow(clippy::too_many_arguments)]
pub fn forward<R: Real>(
    simd: Simd,
    x: &[R],
    w: &[R],
    b: &[R],
    n: usize,
    inp: usize,
    out: usize,
    z: &mut [R],
) {
    if let (Some(x), Some(w), Some(b)) = (as_f32(x), as_f32(w), as_f32(b)) {
        let z = as_f32_mut(z).expect("same type as x");
        let o = Operands {
            a: x,
            al: ALayout {
                row_stride: inp,
                col_stride: 1,
            },
            b: w,
            ldb: out,
            bias: Some(b),
            ldc: out,
            m: n,
            nn: out,
            kk: inp,
        };
        return kernel(simd, o, z);
    }
    for r in 0..n {
        let zr = &mut z[r * out..(r + 1) * out];
        zr.copy_from_slice(b);
        for k in 0..inp {
            let a = x[r * inp + k];
            for (zo, &wv) in zr.iter_mut().zip(&w[k * out..(k + 1) * out]) {
                *zo += a * wv;
            }
        }
    }
}

/// `wt[o][k] = w[k][o]` (`w`: `inp x out`).
pub fn transpose<R: Real>(w: &[R], inp: usize, out: usize, wt: &mut [R]) {
    for k in 0..inp {
        for o in 0..out {
            wt[o * inp + k] = w[k * out + o];
        }
    }
}

/// `dx[r][k] = sum_o g[r][o] w[k][o]` (o in order, from zero), given `wt` = `W^T`
/// (`out x inp`, [`transpose`]).
#[allow(clippy::too_many_arguments)]
pub fn grad_input<R: Real>(
    simd: Simd,
    g: &[R],
    wt: &[R],
    n: usize,
    inp: usize,
    out: usize,
    dx: &mut [R],
) {
    dx[..n * inp].iter_mut().for_each(|v| *v = R::zero());
    if let (Some(g), Some(wt)) = (as_f32(g), as_f32(wt)) {
        let dx = as_f32_mut(dx).expect("same type as g");
        let o = Operands {
            a: g,
            al: ALayout {
                row_stride: out,
                col_stride: 1,
            },
            b: wt,
            ldb: inp,
            bias: None,
            ldc: inp,
            m: n,
            nn: inp,
            kk: out,
        };
        return kernel(simd, o, dx);
    }
    for r in 0..n {
        let dr = &mut dx[r * inp..(r + 1) * inp];
        for o in 0..out {
            let gv = g[r * out + o];
            for (d, &wv) in dr.iter_mut().zip(&wt[o * inp..(o + 1) * inp]) {
                *d += gv * wv;
            }
        }
    }
}

/// `gw[k][o] += sum_r x[r][k] g[r][o]` and `gb[o] += sum_r g[r][o]`, rows in order.
#[allow(clippy::too_many_arguments)]
pub fn grad_weight<R: Real>(
    simd: Simd,
    x: &[R],
    g: &[R],
    n: usize,
    inp: usize,
    out: usize,
    gw: &mut [R],
    gb: &mut [R],
) {
    for r in 0..n {
        for (a, &gv) in gb.iter_mut().zip(&g[r * out..(r + 1) * out]) {
            *a += gv;
        }
    }
    if let (Some(x), Some(g)) = (as_f32(x), as_f32(g)) {
        let gw = as_f32_mut(gw).expect("same type as x");
        let o = Operands {
            a: x,
            al: ALayout {
                row_stride: 1,
                col_stride: inp,
            },
            b: g,
            ldb: out,
            bias: None,
            ldc: out,
            m: inp,
            nn: out,
            kk: n,
        };
        return kernel(simd, o, gw);
    }
    for r in 0..n {
        let gr = &g[r * out..(r + 1) * out];
        for k in 0..inp {
            let xv = x[r * inp + k];
            for (a, &gv) in gw[k * out..(k + 1) * out].iter_mut().zip(gr) {
                *a += xv * gv;
            }
        }
    }
}

/// Floating-point operations of one layer's forward (`2 n inp out`) or of each backward
/// product.
pub fn flops(n: usize, inp: usize, out: usize) -> u64 {
    2 * (n * inp * out) as u64
}
