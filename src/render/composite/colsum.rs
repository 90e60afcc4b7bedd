//! The end of the backward's work on one entry: its gradient record from the per-column partial
//! sums the lane loops left (the summation order of the stage header, [`super`]): per tile
//! column, the sum over the even rows + the sum over the odd rows; then the columns of the
//! entry's box from left to right, each of the seven sums starting from +0.
//!
//! The plain loops add the seven sums one after the other, each a chain of dependent additions
//! as long as the entry's box is wide. The AVX-512 version transposes the seven column vectors
//! (shuffles) so that one vector addition per column advances all seven sums: the same
//! additions in the same order, so the same bits.

use super::super::tiles::TILE;
use crate::real::Real;

/// The seven sums of an entry's gradient record from its per-column partial sums `lanes`
/// (layout of the backward's `lanes`: index 16 h + 8 p + c % 8 for column c of half h = c / 8
/// over the rows of parity p), over the columns `k0..k1`. `X512`: called from the AVX-512
/// kernel (the CPU supports AVX-512), which then uses [`column_sums_avx512`] for f32.
#[inline(always)]
pub(super) fn column_sums<R: Real, const X512: bool>(
    lanes: &[[R; 2 * TILE]; 7],
    k0: usize,
    k1: usize,
) -> [R; 7] {
    #[cfg(target_arch = "x86_64")]
    if X512 && std::any::TypeId::of::<R>() == std::any::TypeId::of::<f32>() {
        // SAFETY: `R` is f32 (the same type, so the same layout), and `X512` is set only in
        // the AVX-512 kernel, which runs only where the CPU supports AVX-512.
        let s = unsafe {
            let l = &*(lanes as *const [[R; 2 * TILE]; 7]).cast::<[[f32; 2 * TILE]; 7]>();
            column_sums_avx512(l, k0, k1)
        };
        let mut out = [R::zero(); 7];
        for (o, x) in out.iter_mut().zip(s) {
            *o = R::c(x as f64);
        }
        return out;
    }
    // Per column: even rows + odd rows; then the columns in order. (Plain loops: the closures
    // of `map` / `from_fn` are not always inlined into the kernel, and then not compiled for
    // its instruction set.)
    let mut acc = [R::zero(); 7];
    for (a, l) in acc.iter_mut().zip(lanes) {
        let mut cols = [R::zero(); TILE];
        for (c, v) in cols.iter_mut().enumerate() {
            let i = 16 * (c / 8) + c % 8;
            *v = l[i] + l[i + 8];
        }
        let mut sum = R::zero();
        for v in &cols[k0..k1] {
            sum += *v;
        }
        *a = sum;
    }
    acc
}

/// [`column_sums`] for f32 with AVX-512: per sum m, the 16 column values (even + odd rows) in
/// one vector v_m; the eight vectors v_0..v_6, 0 transposed by two rounds of in-lane shuffles
/// into, per column c, the values of sums 0-3 and of sums 4-7 (two 4-lane vectors); then per
/// column from `k0` to `k1` one addition to each of two 4-lane accumulators that start at +0.
/// Per sum these are the additions of the plain loops in their order.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn column_sums_avx512(l: &[[f32; 2 * TILE]; 7], k0: usize, k1: usize) -> [f32; 7] {
    use std::arch::x86_64::*;
    // SAFETY: the CPU supports AVX-512 (this function's contract); every load and store is
    // inside the arrays it names (16 lanes from 0 or 16 of a 32-lane row, 4 from 4 b of 16).
    unsafe {
        const { assert!(TILE == 16) };
        let mut v = [_mm512_setzero_ps(); 8];
        for (vm, lm) in v.iter_mut().zip(l) {
            let lo = _mm512_loadu_ps(lm.as_ptr());
            let hi = _mm512_loadu_ps(lm.as_ptr().add(16));
            // Lanes 0-7: columns 0-7 of the even rows (lo) and 8-15 (hi); 8-15: the odd rows.
            let even = _mm512_shuffle_f32x4::<0b01_00_01_00>(lo, hi);
            let odd = _mm512_shuffle_f32x4::<0b11_10_11_10>(lo, hi);
            *vm = _mm512_add_ps(even, odd);
        }
        // q[g][j][4 b + i]: sum 4 g + i at column 4 b + j (within each 128-bit block b of the
        // vectors, a 4 x 4 transpose).
        let mut q = [[[0.0f32; 16]; 4]; 2];
        for (g, qg) in q.iter_mut().enumerate() {
            let [a, b, c, d] = [v[4 * g], v[4 * g + 1], v[4 * g + 2], v[4 * g + 3]];
            let (t0, t1) = (_mm512_unpacklo_ps(a, b), _mm512_unpackhi_ps(a, b));
            let (t2, t3) = (_mm512_unpacklo_ps(c, d), _mm512_unpackhi_ps(c, d));
            _mm512_storeu_ps(qg[0].as_mut_ptr(), _mm512_shuffle_ps::<0x44>(t0, t2));
            _mm512_storeu_ps(qg[1].as_mut_ptr(), _mm512_shuffle_ps::<0xEE>(t0, t2));
            _mm512_storeu_ps(qg[2].as_mut_ptr(), _mm512_shuffle_ps::<0x44>(t1, t3));
            _mm512_storeu_ps(qg[3].as_mut_ptr(), _mm512_shuffle_ps::<0xEE>(t1, t3));
        }
        let mut s03 = _mm_setzero_ps();
        let mut s47 = _mm_setzero_ps();
        // (`k1` is at most TILE; the bound keeps the loads inside `q` whatever the caller.)
        for c in k0..k1.min(TILE) {
            let (j, o) = (c % 4, 4 * (c / 4));
            s03 = _mm_add_ps(s03, _mm_loadu_ps(q[0][j].as_ptr().add(o)));
            s47 = _mm_add_ps(s47, _mm_loadu_ps(q[1][j].as_ptr().add(o)));
        }
        let mut out = [0.0f32; 8];
        _mm_storeu_ps(out.as_mut_ptr(), s03);
        _mm_storeu_ps(out.as_mut_ptr().add(4), s47);
        [out[0], out[1], out[2], out[3], out[4], out[5], out[6]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX-512 sums against the plain loops, bit for bit, on random partial sums of mixed
    /// magnitudes and signs (so that the order of the additions shows in the bits) and every
    /// column range.
    #[test]
    fn avx512_column_sums_match_the_plain_loops() {
        if !crate::simd::Simd::Avx512.supported() {
            return;
        }
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let u = (s >> 40) as f32 / 16_777_216.0 - 0.5;
            u * 10f32.powi((s % 9) as i32 - 4)
        };
        let mut differs = 0;
        for rep in 0..400 {
            let mut l = [[0.0f32; 2 * TILE]; 7];
            for x in l.iter_mut().flatten() {
                *x = r();
            }
            if rep % 7 == 0 {
                l[3][5] = -0.0;
                l[3][13] = -0.0;
            }
            for k0 in 0..TILE {
                for k1 in k0..=TILE {
                    let want = column_sums::<f32, false>(&l, k0, k1);
                    let got = column_sums::<f32, true>(&l, k0, k1);
                    assert_eq!(want.map(f32::to_bits), got.map(f32::to_bits), "{k0}..{k1}");
                    // A reordered sum would differ somewhere: check that order matters here.
                    let mut rev = [0.0f32; 7];
                    for (m, v) in rev.iter_mut().enumerate() {
                        for c in (k0..k1).rev() {
                            let i = 16 * (c / 8) + c % 8;
                            *v += l[m][i] + l[m][i + 8];
                        }
                    }
                    differs += (rev != want) as u32;
                }
            }
        }
        assert!(differs > 1000, "{differs}");
    }
}
