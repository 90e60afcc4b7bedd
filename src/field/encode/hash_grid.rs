//! Multiresolution hash grid, torch-ngp's original variant as NAF uses it
//! (Ruyi-Zha/naf_cbct `src/encoder/hashencoder/hashgrid.py`, `src/hashencoder.cu`):
//! - input `x` in metres mapped to `(x + bound) / (2 bound)` in [0, 1];
//! - level `l` has resolution `R_l = base * 2^l` (per-level scale 2), `scale_l = R_l - 1`,
//!   `pos = x scale_l + 1/2`, corner `floor(pos)`, trilinear weights from `pos - floor(pos)`;
//! - level `l` stores `min(T, (R_l + 1)^3)` entries of `F` features; it is dense
//!   (`i + (R+1) (j + (R+1) k)`) when `(R_l + 1)^3 <= T`, else hashed with
//!   `(i * 1) ^ (j * 19349663) ^ (k * 83492791)` (u32 wrapping) modulo `T`;
//! - features initialised U(-1e-4, 1e-4); output `L * F` values, level-major.
//!
//! Backward: `dT_l[idx_c] += w_c g_l` per corner. The scatter is done level by level (levels in
//! parallel, the samples of a level in order), so the gradient is bit-identical for any
//! thread count and no atomics are needed. Forward over a block and backward both run one level
//! at a time and compute the corners of a chunk of points before touching the table, asking the
//! CPU to fetch their cache lines as they go; both are compiled for each instruction set of
//! [`crate::simd`] (the same operations, so the same bits on every path).

use rayon::prelude::*;

use crate::real::Real;
use crate::simd::Simd;

/// Points whose corners are computed before their table entries are read or written: the
/// loads of a chunk do not wait on one another's corner arithmetic, so their cache misses
/// overlap (same values and the same scatter order as point by point).
const CHUNK: usize = 64;

/// torch-ngp's hash primes.
const PRIMES: [u32; 3] = [1, 19_349_663, 83_492_791];

/// Layout of a hash grid.
#[derive(Clone, Debug, PartialEq)]
pub struct HashGrid {
    pub levels: usize,
    pub features: usize,
    pub log2_table: u32,
    pub base: usize,
    /// Half side of the cube the grid covers, metres.
    pub bound: f64,
    /// First entry of each level, plus the total at the end.
    pub offsets: Vec<usize>,
}

impl HashGrid {
    /// The layout (entries per level) of torch-ngp's `HashEncoder`.
    pub fn new(levels: usize, features: usize, log2_table: u32, base: usize, bound: f64) -> Self {
        let t = 1usize << log2_table;
        let mut offsets = Vec::with_capacity(levels + 1);
        let mut off = 0usize;
        for l in 0..levels {
            let r = base << l;
            let dense = (r + 1).saturating_pow(3);
            offsets.push(off);
            off += dense.min(t);
        }
        offsets.push(off);
        HashGrid {
            levels,
            features,
            log2_table,
            base,
            bound,
            offsets,
        }
    }

    /// Output width `L * F`.
    pub fn out_dim(&self) -> usize {
        self.levels * self.features
    }

    /// Number of parameters (entries x features).
    pub fn n_params(&self) -> usize {
        self.offsets[self.levels] * self.features
    }

    /// The 8 corner entries (level-relative) and trilinear weights of point `x` at level `l`.
    #[inline(always)]
    pub fn corners<R: Real>(&self, x: [R; 3], l: usize) -> ([usize; 8], [R; 8]) {
        let bound = R::c(self.bound);
        let r = (self.base << l) as u64;
        let scale = R::c(r as f64 - 1.0);
        let size = (self.offsets[l + 1] - self.offsets[l]) as u64;
        let half = R::c(0.5);
        let mut g = [0u32; 3];
        let mut f = [R::zero(); 3];
        for d in 0..3 {
            let u = (x[d] + bound) / (bound + bound);
            let p = u * scale + half;
            let pf = p.floor();
            g[d] = pf.to_u32().unwrap_or(0);
            f[d] = p - pf;
        }
        let dense = (r + 1).pow(3) <= size;
        // Per axis, the two corner coordinates' index terms and weights (`1 - f`, `f`); each
        // corner's weight is `((1 x w_x) x w_y) x w_z` and its index combines one term per
        // axis, as torch-ngp (integer terms: exact in any order).
        let mut wd = [[R::zero(); 2]; 3];
        let mut term = [[0u64; 2]; 3];
        let stride = [1, r + 1, (r + 1) * (r + 1)];
        for d in 0..3 {
            wd[d] = [R::one() - f[d], f[d]];
            for (s, t) in term[d].iter_mut().enumerate() {
                let p = g[d] + s as u32;
                *t = if dense {
                    p as u64 * stride[d]
                } else {
                    p.wrapping_mul(PRIMES[d]) as u64
                };
            }
        }
        let mut idx = [0usize; 8];
        let mut w = [R::one(); 8];
        for c in 0..8 {
            let (sx, sy, sz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            w[c] = R::one() * wd[0][sx] * wd[1][sy] * wd[2][sz];
            // torch-ngp takes the index modulo the level size. A dense index is already below
            // it (corners lie in 0..=R, so the index is below (R + 1)^3 <= size), and a hashed
            // level has size T, a power of two: the modulo is a mask (same result, no division).
            let i = if dense {
                let i = term[0][sx] + term[1][sy] + term[2][sz];
                if i < size {
                    i
                } else {
                    i % size
                }
            } else {
                let h = (term[0][sx] as u32 ^ term[1][sy] as u32 ^ term[2][sz] as u32) as u64;
                if size.is_power_of_two() {
                    h & (size - 1)
                } else {
                    h % size
                }
            };
            idx[c] = i as usize;
        }
        (idx, w)
    }

    /// Encode one point (`out`: `L * F` values).
    pub fn encode<R: Real>(&self, table: &[R], x: [R; 3], out: &mut [R]) {
        let nf = self.features;
        for l in 0..self.levels {
            let (idx, w) = self.corners(x, l);
            let base = self.offsets[l];
            for ch in 0..nf {
                let mut acc = R::zero();
                for c in 0..8 {
                    acc += w[c] * table[(base + idx[c]) * nf + ch];
                }
                out[l * nf + ch] = acc;
            }
        }
    }

    /// Encode a block of points (`out`: `L * F` values per point), level after level: the
    /// samples of a block touch one level's table at a time, which then stays in cache (the
    /// values are those of [`HashGrid::encode`], bit for bit), compiled for the instruction set
    /// `simd` (or the widest supported narrower one; the same operations, so the same bits).
    pub fn encode_block<R: Real>(&self, simd: Simd, table: &[R], xs: &[[R; 3]], out: &mut [R]) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `or_narrower` returns a path the CPU supports.
        match simd.or_narrower() {
            Simd::Avx512 => return unsafe { encode_block_avx512(self, table, xs, out) },
            Simd::Avx2 => return unsafe { encode_block_avx2(self, table, xs, out) },
            Simd::Scalar => {}
        }
        let _ = simd;
        self.encode_block_body(table, xs, out)
    }

    /// The body of [`HashGrid::encode_block`], compiled into each instruction set's copy.
    #[inline(always)]
    fn encode_block_body<R: Real>(&self, table: &[R], xs: &[[R; 3]], out: &mut [R]) {
        let nf = self.features;
        let ed = self.levels * nf;
        let mut cw = [([0usize; 8], [R::zero(); 8]); CHUNK];
        for l in 0..self.levels {
            let lt = &table[self.offsets[l] * nf..self.offsets[l + 1] * nf];
            for (xc, oc) in xs.chunks(CHUNK).zip(out.chunks_mut(CHUNK * ed)) {
                for (v, &x) in cw.iter_mut().zip(xc) {
                    *v = self.corners(x, l);
                    prefetch_corners(lt, &v.0, nf);
                }
                for ((idx, w), o) in cw.iter().zip(oc.chunks_exact_mut(ed)) {
                    for ch in 0..nf {
                        let mut acc = R::zero();
                        for c in 0..8 {
                            acc += w[c] * lt[idx[c] * nf + ch];
                        }
                        o[l * nf + ch] = acc;
                    }
                }
            }
        }
    }

    /// Accumulate the table gradient of `sum g . encode(x)` over the points `xs`, with
    /// `g_out[n * g_stride + g_off ..]` the gradient of point `n`'s encoding; the levels in
    /// parallel, each compiled for the instruction set `simd` as [`HashGrid::encode_block`].
    pub fn backward<R: Real>(
        &self,
        simd: Simd,
        xs: &[[R; 3]],
        g_out: &[R],
        g_stride: usize,
        g_off: usize,
        grad: &mut [R],
    ) {
        let nf = self.features;
        let mut slices: Vec<&mut [R]> = Vec::with_capacity(self.levels);
        let mut rest = grad;
        for l in 0..self.levels {
            let len = (self.offsets[l + 1] - self.offsets[l]) * nf;
            let (a, b) = rest.split_at_mut(len);
            slices.push(a);
            rest = b;
        }
        let simd = simd.or_narrower();
        slices.into_par_iter().enumerate().for_each(|(l, gl)| {
            let g = (g_out, g_stride, g_off);
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `or_narrower` returned a path the CPU supports.
            match simd {
                Simd::Avx512 => return unsafe { scatter_level_avx512(self, l, xs, g, gl) },
                Simd::Avx2 => return unsafe { scatter_level_avx2(self, l, xs, g, gl) },
                Simd::Scalar => {}
            }
            let _ = simd;
            self.scatter_level(l, xs, g, gl)
        });
    }

    /// Level `l`'s share of [`HashGrid::backward`] into its gradient slice `gl`, the points in
    /// order; `g` is (`g_out`, `g_stride`, `g_off`).
    #[inline(always)]
    fn scatter_level<R: Real>(
        &self,
        l: usize,
        xs: &[[R; 3]],
        (g_out, g_stride, g_off): (&[R], usize, usize),
        gl: &mut [R],
    ) {
        let nf = self.features;
        let mut cw = [([0usize; 8], [R::zero(); 8]); CHUNK];
        for (k, xc) in xs.chunks(CHUNK).enumerate() {
            for (v, &x) in cw.iter_mut().zip(xc) {
                *v = self.corners(x, l);
                prefetch_corners(gl, &v.0, nf);
            }
            for (j, (idx, w)) in cw.iter().take(xc.len()).enumerate() {
                let n = k * CHUNK + j;
                let g = &g_out[n * g_stride + g_off + l * nf..][..nf];
                for c in 0..8 {
                    for ch in 0..nf {
                        gl[idx[c] * nf + ch] += w[c] * g[ch];
                    }
                }
            }
        }
    }
}

/// Asks the CPU to bring the cache lines of the corner entries `idx` of a level's table `lt`
/// (`nf` values each) into the cache: a hint, it changes no value. Corners come in x pairs
/// whose entries are a few apart (the x term of the index is x itself: neighbours on a dense
/// level, the low bits on a hashed one), so every other one is enough.
#[inline(always)]
fn prefetch_corners<R>(lt: &[R], idx: &[usize; 8], nf: usize) {
    #[cfg(target_arch = "x86_64")]
    for c in (0..8).step_by(2) {
        // SAFETY: a prefetch reads nothing and never faults, whatever the address.
        #[allow(unused_unsafe)]
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            _mm_prefetch::<_MM_HINT_T0>(lt.as_ptr().wrapping_add(idx[c] * nf).cast());
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (lt, idx, nf);
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](h: &HashGrid, table: &[R], xs: &[[R; 3]], out: &mut [R]);
    encode_block_avx2 => { h.encode_block_body(table, xs, out) }
    encode_block_avx512 => { h.encode_block_body(table, xs, out) }
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real](
        h: &HashGrid,
        l: usize,
        xs: &[[R; 3]],
        g: (&[R], usize, usize),
        gl: &mut [R],
    );
    scatter_level_avx2 => { h.scatter_level(l, xs, g, gl) }
    scatter_level_avx512 => { h.scatter_level(l, xs, g, gl) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn naf_full_layout() {
        // 16 levels, T = 2^19, base 16: levels 0-2 dense (4913, 35937, 274625 entries),
        // levels 3-15 hashed; 7,131,219 entries in total (14.26 M parameters with F = 2).
        let g = HashGrid::new(16, 2, 19, 16, 0.3);
        assert_eq!(g.offsets[1], 4913);
        assert_eq!(g.offsets[2] - g.offsets[1], 35937);
        assert_eq!(g.offsets[3] - g.offsets[2], 274_625);
        assert_eq!(g.offsets[4] - g.offsets[3], 1 << 19);
        assert_eq!(g.offsets[16], 7_131_219);
        assert_eq!(g.n_params(), 14_262_438);
    }

    /// 4 levels (dense and hashed) and 150 points (two full chunks and a partial one), a
    /// table without structure.
    fn scene() -> (HashGrid, Vec<f32>, Vec<[f32; 3]>) {
        let g = HashGrid::new(4, 2, 10, 4, 0.5);
        let table: Vec<f32> = (0..g.n_params())
            .map(|i| ((i * 7919 % 1000) as f32 - 500.0) * 1e-3)
            .collect();
        let xs: Vec<[f32; 3]> = (0..150)
            .map(|i| {
                let t = i as f32 / 150.0;
                [t - 0.5, 0.4 - 0.8 * t * t, (7.0 * t).sin() * 0.45]
            })
            .collect();
        (g, table, xs)
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn block_encode_is_point_encode_bit_for_bit_on_every_path() {
        let (g, table, xs) = scene();
        let ed = g.out_dim();
        let mut one = vec![f32::NAN; ed];
        for simd in Simd::supported_paths() {
            let mut block = vec![f32::NAN; xs.len() * ed];
            g.encode_block(simd, &table, &xs, &mut block);
            for (n, &x) in xs.iter().enumerate() {
                g.encode(&table, x, &mut one);
                let got = bits(&block[n * ed..(n + 1) * ed]);
                assert_eq!(got, bits(&one), "{simd:?}, point {n}");
            }
        }
    }

    /// The scatter on every path against the sum written point by point, corner by corner, in
    /// the points' order (the order the level-parallel scatter keeps), from a non-zero start.
    #[test]
    fn scatter_is_the_point_by_point_sum_on_every_path() {
        let (g, _, xs) = scene();
        let ed = g.out_dim();
        let (stride, off) = (ed + 3, 2);
        let g_out: Vec<f32> = (0..xs.len() * stride)
            .map(|i| ((i * 104_729 % 997) as f32 - 498.0) * 1e-2)
            .collect();
        let start: Vec<f32> = (0..g.n_params()).map(|i| (i % 13) as f32 * 0.25).collect();
        let mut want = start.clone();
        for (n, &x) in xs.iter().enumerate() {
            for l in 0..g.levels {
                let (idx, w) = g.corners(x, l);
                for c in 0..8 {
                    for ch in 0..2 {
                        let e = (g.offsets[l] + idx[c]) * 2 + ch;
                        want[e] += w[c] * g_out[n * stride + off + l * 2 + ch];
                    }
                }
            }
        }
        for simd in Simd::supported_paths() {
            let mut got = start.clone();
            g.backward(simd, &xs, &g_out, stride, off, &mut got);
            assert_eq!(bits(&got), bits(&want), "{simd:?}");
        }
    }

    #[test]
    fn corners_dense_and_hashed() {
        let g = HashGrid::new(4, 2, 12, 4, 0.5);
        // Level 0: R = 4, scale 3, dense (125 <= 4096). x = -0.5 maps to u = 0: pos 0.5.
        let (idx, w) = g.corners([-0.5f64, -0.5, -0.5], 0);
        assert_eq!(idx[0], 0);
        assert_eq!(idx[7], 1 + 5 + 25);
        assert!(w.iter().all(|&v| (v - 0.125).abs() < 1e-15));
        // Level 3: R = 32, 33^3 > 4096: hashed. x = +0.5 -> u = 1 -> pos 31.5, corner 31.
        let (idx, _) = g.corners([0.5f64, 0.5, 0.5], 3);
        let h = 31u32 ^ 31u32.wrapping_mul(19_349_663) ^ 31u32.wrapping_mul(83_492_791);
        assert_eq!(idx[0], (h as usize) % 4096);
    }

    /// A point beyond the bound has corners past the dense level's last entry; torch-ngp takes
    /// the index `x + (R + 1) (y + (R + 1) z)` modulo the level size, which is what wraps them
    /// (the corner at exactly the size wraps to 0).
    #[test]
    fn corners_beyond_the_bound_wrap_on_a_dense_level() {
        let g = HashGrid::new(4, 2, 12, 4, 0.5);
        // Level 0: R = 4, 125 entries. z = 5/3 - 1/2 maps to u = 5/3, pos 5.5: corners 5 and 6.
        let x = [-0.5f64, -0.5, 5.0 / 3.0 - 0.5];
        let (idx, w) = g.corners(x, 0);
        for (c, (&i, &wc)) in idx.iter().zip(&w).enumerate() {
            let (cx, cy, cz) = (c & 1, (c >> 1) & 1, 5 + (c >> 2));
            assert_eq!(i, (cx + 5 * (cy + 5 * cz)) % 125, "corner {c}");
            assert!((wc - 0.125).abs() < 1e-12, "corner {c}: {wc}");
        }
        assert_eq!((idx[0], idx[4]), (0, 25));
    }
}
