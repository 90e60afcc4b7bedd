//! The matrix products of the field MLP: one strided kernel
//! `C[i][j] = init[i][j] + sum_t A(i, t) B[t][j]` (t in order), cache-blocked over rows and
//! over the inner dimension, register-tiled (a tile of rows x columns held in registers across
//! an inner block), and compiled three times: for the baseline target ([`Simd::Scalar`], 4 x 8
//! tiles of SSE2 vectors) and with AVX2 ([`Simd::Avx2`], 6 x 16: two 8-lane vectors per row)
//! from the same generic source, and with AVX-512 ([`Simd::Avx512`]) from intrinsics: 24 x 16,
//! one 16-lane vector per row, so that each `A(i, t)` feeds a single multiply and its broadcast
//! is folded into that multiply's memory operand. On Zen 4 a separate broadcast instruction
//! takes a slot of the floating-point pipes: the earlier 6 x 64 tile (one broadcast for four
//! multiplies) ran at about 75 % of the measured peak in isolation, the 24 x 16 tile at the
//! peak (with the packing below, the reduced NeRF iteration went from 0.56 to 0.48 s,
//! `docs/measurements.md`).
//!
//! The panels of `B` (the tile's columns over the whole inner dimension) are first copied into
//! contiguous rows, once per product (a per-thread buffer reused across calls): rows of `B` a
//! power of two apart (1 KiB at the NeRF width) map to a few sets of the L1 cache and evict each
//! other, so tiles reading them in place fetch the panel from L2 on every pass. The column
//! remainder is copied zero-padded to a narrower tile class (the padding columns are computed
//! and dropped), and products with a single column or a few columns and a column-major `A`
//! (`dW` of the output layer) keep consecutive rows of `C` in the vector lanes instead, so no
//! shape falls back to scalar chains stored to memory at every step.
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
//!
//! Longer than 600 lines: the one kernel in its three compilations (generic scalar / AVX2 and
//! AVX-512 intrinsics) with the packing each tile shape needs, side by side so that the tile
//! shapes stay next to the measurements that chose them.

use std::any::TypeId;
use std::cell::RefCell;

use crate::real::Real;
use crate::simd::Simd;

/// Rows per cache block, a multiple of every path's tile height (the rows of `A` of a block
/// stay in L2 while the panels of `B` pass through L1).
const MC: usize = 96;

/// Inner-dimension block: a `KC x NR` slice of a packed panel of `B` (8 KiB at `NR` = 16)
/// stays in L1 while every tile of a row block runs over it (256 measured no faster).
const KC: usize = 128;

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

thread_local! {
    /// The packed panels of `B` of the calling thread (grown once, reused by every product).
    static PANEL: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Cache-blocked product with `MR x NR` register tiles (tiles with fewer rows at the bottom
/// edge of a row block use the same kernel with fewer rows), or with the AVX-512 tiles of
/// [`zmm`] when `Z`. The panels of `B` are packed first: full panels of `NR` columns, the
/// column remainder padded with zeros to `NR` (more than `NM` columns left), `NM` (more than
/// `NH`) or `NH` columns, so that it runs the same vector kernel. A product with fewer than
/// `NH` columns whose `A` is column-major (`row_stride` 1: `dW` of the output layer) runs
/// [`narrow`] instead.
#[inline(always)]
fn kernel_generic<
    const MR: usize,
    const NR: usize,
    const NM: usize,
    const NH: usize,
    const L: usize,
    const V: usize,
    const Z: bool,
>(
    o: Operands,
    c: &mut [f32],
) {
    if o.kk == 0 {
        if let Some(bv) = o.bias {
            for i in 0..o.m {
                c[i * o.ldc..i * o.ldc + o.nn].copy_from_slice(&bv[..o.nn]);
            }
        }
        return;
    }
    if o.nn < NH && o.al.row_stride == 1 {
        return narrow::<L, V>(&o, c);
    }
    // Every panel of `B` is copied once into contiguous rows: the full panels (`NR` columns),
    // then the remainder (`jw` columns) padded with zeros to its tile class `pw` (the padding
    // columns are computed and dropped). Rows of `B` a power of two apart (1 KiB at the NeRF
    // width) fall into a few sets of the L1 cache and evict each other, so tiles reading a
    // panel in place fetch it from L2 on every pass. The buffer is taken out of the
    // thread-local cell (and put back) rather than used in a closure, so that the tiles
    // compile with the instruction set of the caller.
    let jr = o.nn / NR * NR;
    let (pw, jw) = match o.nn - jr {
        0 => (0, 0),
        w if w > NM => (NR, w),
        w if w > NH => (NM, w),
        w => (NH, w),
    };
    let mut packed = PANEL.with(|cell| cell.take());
    let len = o.kk * (jr + pw);
    if packed.len() < len {
        packed.resize(len, 0.0);
    }
    let (full, rest) = packed[..len].split_at_mut(o.kk * jr);
    for (p, panel) in full.chunks_exact_mut(o.kk * NR).enumerate() {
        for (t, row) in panel.chunks_exact_mut(NR).enumerate() {
            row.copy_from_slice(&o.b[t * o.ldb + p * NR..][..NR]);
        }
    }
    if pw > 0 {
        for (t, row) in rest.chunks_exact_mut(pw).enumerate() {
            row[..jw].copy_from_slice(&o.b[t * o.ldb + jr..][..jw]);
            row[jw..].fill(0.0);
        }
    }
    let mut i0 = 0;
    while i0 < o.m {
        let i1 = (i0 + MC).min(o.m);
        let mut j0 = 0;
        while j0 < o.nn {
            let (w, used) = if j0 < jr { (NR, NR) } else { (pw, jw) };
            let mut k0 = 0;
            while k0 < o.kk {
                let k1 = (k0 + KC).min(o.kk);
                let s = Span {
                    j0,
                    jw: used,
                    k0,
                    k1,
                };
                // Row `k0` of this panel (full panels first, then the remainder).
                let bp = packed[o.kk * j0 + k0 * w..].as_ptr();
                let mut i = i0;
                while i < i1 {
                    let iw = (i1 - i).min(MR);
                    // SAFETY: `kernel` checked that every index of the product is in bounds;
                    // the packed panel holds `kk x w` values from `bp - k0 w`.
                    unsafe {
                        if Z {
                            // `Z` is set only by `kernel_avx512` (x86-64 with AVX-512 F).
                            #[cfg(target_arch = "x86_64")]
                            zmm::rows(&o, bp, w, c, i, iw, s);
                            #[cfg(not(target_arch = "x86_64"))]
                            unreachable!("AVX-512 tiles on a non-x86-64 target");
                        } else {
                            match w {
                                w if w == NR => tile_rows::<MR, NR>(&o, bp, w, c, i, iw, s),
                                w if w == NM => tile_rows::<MR, NM>(&o, bp, w, c, i, iw, s),
                                _ => tile_rows::<MR, NH>(&o, bp, w, c, i, iw, s),
                            }
                        }
                    };
                    i += iw;
                }
                k0 = k1;
            }
            j0 += used;
        }
        i0 = i1;
    }
    PANEL.with(|cell| cell.replace(packed));
}

/// The columns `j0 .. j0 + jw` and the inner range `k0 .. k1` of a tile.
#[derive(Clone, Copy)]
struct Span {
    j0: usize,
    jw: usize,
    k0: usize,
    k1: usize,
}

/// Rows `i .. i + iw` (`iw <= MR`) of one panel, accumulators in registers.
///
/// # Safety
/// Every index of rows `i .. i + iw`, columns `j0 .. j0 + jw` and `t < kk` must be in bounds
/// (checked once by [`kernel`]); `bp` points at `B[k0][j0]` of a panel with rows `ldp` apart
/// that holds `W` readable columns for every `t` in `k0 .. k1`.
#[inline(always)]
unsafe fn tile_rows<const MR: usize, const W: usize>(
    o: &Operands,
    bp: *const f32,
    ldp: usize,
    c: &mut [f32],
    i: usize,
    iw: usize,
    s: Span,
) {
    // SAFETY: as this function's contract.
    unsafe {
        match iw {
            n if n == MR => tile::<MR, W>(o, bp, ldp, c, i, s),
            1 => tile::<1, W>(o, bp, ldp, c, i, s),
            2 => tile::<2, W>(o, bp, ldp, c, i, s),
            3 => tile::<3, W>(o, bp, ldp, c, i, s),
            4 => tile::<4, W>(o, bp, ldp, c, i, s),
            5 => tile::<5, W>(o, bp, ldp, c, i, s),
            6 => tile::<6, W>(o, bp, ldp, c, i, s),
            7 => tile::<7, W>(o, bp, ldp, c, i, s),
            8 => tile::<8, W>(o, bp, ldp, c, i, s),
            9 => tile::<9, W>(o, bp, ldp, c, i, s),
            10 => tile::<10, W>(o, bp, ldp, c, i, s),
            11 => tile::<11, W>(o, bp, ldp, c, i, s),
            12 => tile::<12, W>(o, bp, ldp, c, i, s),
            13 => tile::<13, W>(o, bp, ldp, c, i, s),
            14 => tile::<14, W>(o, bp, ldp, c, i, s),
            15 => tile::<15, W>(o, bp, ldp, c, i, s),
            _ => {
                for r in i..i + iw {
                    tile::<1, W>(o, bp, ldp, c, r, s)
                }
            }
        }
    }
}

/// One `R x W` tile: the accumulators start from the initial values (the bias or `C` for the
/// first inner block, `C` after), then for each `t` in `k0 .. k1` in order
/// `acc[r][j] += A(i + r, t) * B[t][j0 + j]`; the first `jw` columns are stored.
///
/// # Safety
/// As [`tile_rows`].
#[inline(always)]
unsafe fn tile<const R: usize, const W: usize>(
    o: &Operands,
    bp: *const f32,
    ldp: usize,
    c: &mut [f32],
    i: usize,
    s: Span,
) {
    // SAFETY: as this function's contract.
    unsafe {
        let mut acc = [[0.0f32; W]; R];
        let cp = c.as_mut_ptr();
        for (r, row) in acc.iter_mut().enumerate() {
            let src = match o.bias {
                Some(bv) if s.k0 == 0 => bv.as_ptr().add(s.j0),
                _ => cp.add((i + r) * o.ldc + s.j0) as *const f32,
            };
            if s.jw == W {
                for (j, v) in row.iter_mut().enumerate() {
                    *v = *src.add(j);
                }
            } else {
                // Through a copy: indexing the accumulators by a run-time bound would keep
                // them in memory.
                let mut tmp = [0.0f32; W];
                std::ptr::copy_nonoverlapping(src, tmp.as_mut_ptr(), s.jw);
                *row = tmp;
            }
        }
        let (rs, cs) = (o.al.row_stride, o.al.col_stride);
        let ap = o.a.as_ptr().add(i * rs);
        let mut bp = bp;
        for t in s.k0..s.k1 {
            let mut bv = [0.0f32; W];
            for (j, v) in bv.iter_mut().enumerate() {
                *v = *bp.add(j);
            }
            bp = bp.add(ldp);
            let at = ap.add(t * cs);
            for (r, row) in acc.iter_mut().enumerate() {
                let av = *at.add(r * rs);
                for j in 0..W {
                    row[j] += av * bv[j];
                }
            }
        }
        for (r, row) in acc.iter().enumerate() {
            let dst = cp.add((i + r) * o.ldc + s.j0);
            if s.jw == W {
                for (j, v) in row.iter().enumerate() {
                    *dst.add(j) = *v;
                }
            } else {
                let tmp = *row;
                std::ptr::copy_nonoverlapping(tmp.as_ptr(), dst, s.jw);
            }
        }
    }
}

/// The AVX-512 tiles: `R` rows of one 16-column panel, one 16-lane accumulator per row, so
/// that `A(i + r, t)` is used once per step and its broadcast is folded into the multiply
/// (`vmulps zmm, zmm, m32{1to16}`). On Zen 4 a separate broadcast instruction takes a slot of
/// the floating-point pipes; with it folded, 24 rows run at the measured peak of separate
/// multiplies and adds (wider tiles that reuse one broadcast for several vectors need it in a
/// register). Same operations per element as [`tile`]: start from the initial value, then
/// `acc += A(i + r, t) * B[t][j]` for `t` in order, unfused.
#[cfg(target_arch = "x86_64")]
mod zmm {
    use super::{Operands, Span};
    use std::arch::x86_64::*;

    /// Rows `i .. i + iw` of a 16-column panel, as tiles of 24, 16, 8, 4, 2 and 1 rows.
    ///
    /// # Safety
    /// As [`super::tile_rows`] with `W` = 16; the CPU has AVX-512 F.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn rows(
        o: &Operands,
        bp: *const f32,
        ldp: usize,
        c: &mut [f32],
        i: usize,
        iw: usize,
        s: Span,
    ) {
        let (mut i, end) = (i, i + iw);
        while i < end {
            // SAFETY: as this function's contract; each tile's rows are inside `i .. end`.
            i += unsafe {
                match end - i {
                    24.. => tile::<24>(o, bp, ldp, c, i, s),
                    16.. => tile::<16>(o, bp, ldp, c, i, s),
                    8.. => tile::<8>(o, bp, ldp, c, i, s),
                    4.. => tile::<4>(o, bp, ldp, c, i, s),
                    2.. => tile::<2>(o, bp, ldp, c, i, s),
                    _ => tile::<1>(o, bp, ldp, c, i, s),
                }
            };
        }
    }

    /// One `R x 16` tile (the first `s.jw` columns are read and stored, through masks);
    /// returns `R`.
    ///
    /// # Safety
    /// As [`rows`].
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn tile<const R: usize>(
        o: &Operands,
        bp: *const f32,
        ldp: usize,
        c: &mut [f32],
        i: usize,
        s: Span,
    ) -> usize {
        // SAFETY: as this function's contract; masked lanes are neither read nor written.
        unsafe {
            let mask: __mmask16 = if s.jw >= 16 {
                0xffff
            } else {
                (1u16 << s.jw) - 1
            };
            let cp = c.as_mut_ptr();
            let mut acc = [_mm512_setzero_ps(); R];
            for (r, v) in acc.iter_mut().enumerate() {
                let src = match o.bias {
                    Some(bv) if s.k0 == 0 => bv.as_ptr().add(s.j0),
                    _ => cp.add((i + r) * o.ldc + s.j0) as *const f32,
                };
                *v = _mm512_maskz_loadu_ps(mask, src);
            }
            let (rs, cs) = (o.al.row_stride, o.al.col_stride);
            let mut ap = o.a.as_ptr().add(i * rs + s.k0 * cs);
            let mut bp = bp;
            for _ in s.k0..s.k1 {
                let b = _mm512_loadu_ps(bp);
                bp = bp.add(ldp);
                for (r, v) in acc.iter_mut().enumerate() {
                    let p = _mm512_mul_ps(_mm512_set1_ps(*ap.add(r * rs)), b);
                    *v = _mm512_add_ps(*v, p);
                }
                ap = ap.add(cs);
            }
            for (r, v) in acc.iter().enumerate() {
                _mm512_mask_storeu_ps(cp.add((i + r) * o.ldc + s.j0), mask, *v);
            }
            R
        }
    }
}

/// A product with few columns and a column-major `A` (`A(i, t) = a[i + t * col_stride]`):
/// `L` consecutive rows of one column of `C` are the accumulators (vector lanes), so each
/// element keeps its own chain over `t` in order; rows left over run `V` (one vector) or one at a time.
#[inline(always)]
fn narrow<const L: usize, const V: usize>(o: &Operands, c: &mut [f32]) {
    let mut i = 0;
    while i < o.m {
        let rem = o.m - i;
        let step = if rem >= L {
            narrow_rows::<L>(o, c, i);
            L
        } else if rem >= V {
            narrow_rows::<V>(o, c, i);
            V
        } else {
            narrow_rows::<1>(o, c, i);
            1
        };
        i += step;
    }
}

/// Rows `i .. i + L` of every column of a [`narrow`] product.
#[inline(always)]
fn narrow_rows<const L: usize>(o: &Operands, c: &mut [f32], i: usize) {
    for j in 0..o.nn {
        let mut acc = [0.0f32; L];
        for (r, v) in acc.iter_mut().enumerate() {
            *v = match o.bias {
                Some(bv) => bv[j],
                None => c[(i + r) * o.ldc + j],
            };
        }
        for t in 0..o.kk {
            let bv = o.b[t * o.ldb + j];
            let at = &o.a[i + t * o.al.col_stride..][..L];
            for (v, &av) in acc.iter_mut().zip(at) {
                *v += av * bv;
            }
        }
        for (r, v) in acc.iter().enumerate() {
            c[(i + r) * o.ldc + j] = *v;
        }
    }
}

crate::simd::wide_kernels! {
    unsafe fn [](o: Operands, c: &mut [f32]);
    kernel_avx2 => {
        // 6 x 16: 12 accumulators of 8 lanes, two of B, a broadcast and a product (16
        // registers).
        kernel_generic::<6, 16, 16, 8, 32, 8, false>(o, c)
    }
    kernel_avx512 => {
        // 24 x 16 (the `zmm` tiles): 24 accumulators of 16 lanes, one of B, a product.
        kernel_generic::<24, 16, 16, 16, 64, 16, true>(o, c)
    }
}

fn kernel_scalar(o: Operands, c: &mut [f32]) {
    // 4 x 8: 8 accumulators of 4 SSE2 lanes.
    kernel_generic::<4, 8, 8, 4, 16, 4, false>(o, c)
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

/// `c = init + A b` on `simd` (`A`: `m x kk` with layout `al`, `b`: `kk x nn` with row stride
/// `ldb`, `c`: `m x nn` with row stride `ldc`; `init` is `bias[j]` when given, else the
/// current `c`): the blocked kernels for f32, the same chains as plain loops for f64.
#[allow(clippy::too_many_arguments)]
fn product<R: Real>(
    simd: Simd,
    a: &[R],
    al: ALayout,
    b: &[R],
    ldb: usize,
    bias: Option<&[R]>,
    c: &mut [R],
    ldc: usize,
    (m, nn, kk): (usize, usize, usize),
) {
    if let (Some(a), Some(b)) = (as_f32(a), as_f32(b)) {
        let o = Operands {
            a,
            al,
            b,
            ldb,
            bias: bias.map(|v| as_f32(v).expect("same type as a")),
            ldc,
            m,
            nn,
            kk,
        };
        return kernel(simd, o, as_f32_mut(c).expect("same type as a"));
    }
    for i in 0..m {
        let ci = &mut c[i * ldc..i * ldc + nn];
        if let Some(bv) = bias {
            ci.copy_from_slice(&bv[..nn]);
        }
        for t in 0..kk {
            let av = a[i * al.row_stride + t * al.col_stride];
            for (cv, &bv) in ci.iter_mut().zip(&b[t * ldb..t * ldb + nn]) {
                *cv += av * bv;
            }
        }
    }
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
    let al = ALayout {
        row_stride: inp,
        col_stride: 1,
    };
    product(simd, x, al, w, out, Some(b), z, out, (n, out, inp));
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
    let al = ALayout {
        row_stride: out,
        col_stride: 1,
    };
    product(simd, g, al, wt, inp, None, dx, inp, (n, inp, out));
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
    super::act::sum_rows(simd, g, n, out, gb);
    let al = ALayout {
        row_stride: 1,
        col_stride: inp,
    };
    product(simd, x, al, g, out, None, gw, out, (inp, out, n));
}

/// `c[i][j] += sum_t A(i, t) b[t][j]` (t in order, from the current `c`), with
/// `A(i, t) = a[i * row_stride + t * col_stride]` (`m x kk`), `b`: `kk x nn` with row stride
/// `ldb`, `c`: `m x nn` with row stride `ldc`. The general form of the three products above
/// (the TensoRF basis and its gradients use it on strided gradient rows).
#[allow(clippy::too_many_arguments)]
pub fn accumulate<R: Real>(
    simd: Simd,
    a: &[R],
    row_stride: usize,
    col_stride: usize,
    b: &[R],
    ldb: usize,
    c: &mut [R],
    ldc: usize,
    m: usize,
    nn: usize,
    kk: usize,
) {
    let al = ALayout {
        row_stride,
        col_stride,
    };
    product(simd, a, al, b, ldb, None, c, ldc, (m, nn, kk));
}

/// Floating-point operations of one layer's forward (`2 n inp out`) or of each backward
/// product.
pub fn flops(n: usize, inp: usize, out: usize) -> u64 {
    2 * (n * inp * out) as u64
}
