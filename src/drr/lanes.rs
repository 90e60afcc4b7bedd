//! Vector lanes of the DRR kernels: one ray per lane, f32 values, i32 voxel indices.
//!
//! The kernel ([`super::siddon_lanes`]) is written once against [`Lanes`] and compiled for
//! AVX-512 (16 lanes) and AVX2 (8 lanes); the scalar path runs the per-ray loop of
//! [`super::siddon`]. Every lane performs the IEEE
//! operations of the per-ray loop in the same order (no fused multiply-add anywhere), so every
//! path gives the same bits (`tests/drr_simd.rs` compares them).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// A vector of `W` f32 lanes, a vector of `W` i32 lanes and a lane mask.
///
/// # Safety
/// The methods use the instruction set of the implementation: call them only from code compiled
/// with that instruction set enabled, on a CPU that has it.
pub(crate) unsafe trait Lanes {
    const W: usize;
    type F: Copy;
    type I: Copy;
    type M: Copy;
    unsafe fn load_f(p: &[f32]) -> Self::F;
    unsafe fn load_i(p: &[i32]) -> Self::I;
    unsafe fn store_f(v: Self::F, p: &mut [f32]);
    unsafe fn store_i(v: Self::I, p: &mut [i32]);
    unsafe fn splat_i(x: i32) -> Self::I;
    /// Mask of the lanes whose bit is set in `bits` (bit k = lane k).
    unsafe fn mask_from_bits(bits: u32) -> Self::M;
    /// Bit k set when lane k is set.
    unsafe fn mask_bits(m: Self::M) -> u32;
    /// `a <= b` (ordered).
    unsafe fn le(a: Self::F, b: Self::F) -> Self::M;
    unsafe fn eq_i(a: Self::I, b: Self::I) -> Self::M;
    unsafe fn and(a: Self::M, b: Self::M) -> Self::M;
    /// `!a & b`.
    unsafe fn andnot(a: Self::M, b: Self::M) -> Self::M;
    /// `m ? a : b`.
    unsafe fn sel_f(m: Self::M, a: Self::F, b: Self::F) -> Self::F;
    /// `m ? a : b`.
    unsafe fn sel_i(m: Self::M, a: Self::I, b: Self::I) -> Self::I;
    unsafe fn add(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn sub(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn mul(a: Self::F, b: Self::F) -> Self::F;
    unsafe fn add_i(a: Self::I, b: Self::I) -> Self::I;
    /// `data[idx]` in the lanes of `m`, 0 elsewhere (no memory read there).
    ///
    /// # Safety
    /// `0 <= idx < data.len()` in every lane of `m`.
    unsafe fn gather(m: Self::M, idx: Self::I, data: &[f32]) -> Self::F;
}

/// AVX-512 F/BW/DQ/VL: 16 lanes.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx512;

#[cfg(target_arch = "x86_64")]
unsafe impl Lanes for Avx512 {
    const W: usize = 16;
    type F = __m512;
    type I = __m512i;
    type M = __mmask16;
    #[inline(always)]
    unsafe fn load_f(p: &[f32]) -> __m512 {
        unsafe {
            debug_assert!(p.len() >= 16);
            _mm512_loadu_ps(p.as_ptr())
        }
    }
    #[inline(always)]
    unsafe fn load_i(p: &[i32]) -> __m512i {
        unsafe {
            debug_assert!(p.len() >= 16);
            _mm512_loadu_si512(p.as_ptr().cast())
        }
    }
    #[inline(always)]
    unsafe fn store_f(v: __m512, p: &mut [f32]) {
        unsafe {
            debug_assert!(p.len() >= 16);
            _mm512_storeu_ps(p.as_mut_ptr(), v)
        }
    }
    #[inline(always)]
    unsafe fn store_i(v: __m512i, p: &mut [i32]) {
        unsafe {
            debug_assert!(p.len() >= 16);
            _mm512_storeu_si512(p.as_mut_ptr().cast(), v)
        }
    }
    #[inline(always)]
    unsafe fn splat_i(x: i32) -> __m512i {
        unsafe { _mm512_set1_epi32(x) }
    }
    #[inline(always)]
    unsafe fn mask_from_bits(bits: u32) -> __mmask16 {
        bits as __mmask16
    }
    #[inline(always)]
    unsafe fn mask_bits(m: __mmask16) -> u32 {
        m as u32
    }
    #[inline(always)]
    unsafe fn le(a: __m512, b: __m512) -> __mmask16 {
        unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, b) }
    }
    #[inline(always)]
    unsafe fn eq_i(a: __m512i, b: __m512i) -> __mmask16 {
        unsafe { _mm512_cmpeq_epi32_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn and(a: __mmask16, b: __mmask16) -> __mmask16 {
        a & b
    }
    #[inline(always)]
    unsafe fn andnot(a: __mmask16, b: __mmask16) -> __mmask16 {
        !a & b
    }
    #[inline(always)]
    unsafe fn sel_f(m: __mmask16, a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_mask_blend_ps(m, b, a) }
    }
    #[inline(always)]
    unsafe fn sel_i(m: __mmask16, a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_mask_blend_epi32(m, b, a) }
    }
    #[inline(always)]
    unsafe fn add(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn add_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_add_epi32(a, b) }
    }
    #[inline(always)]
    unsafe fn gather(m: __mmask16, idx: __m512i, data: &[f32]) -> __m512 {
        unsafe { _mm512_mask_i32gather_ps::<4>(_mm512_setzero_ps(), m, idx, data.as_ptr()) }
    }
}

/// AVX2: 8 lanes; masks are all-ones / all-zeros lanes.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
unsafe impl Lanes for Avx2 {
    const W: usize = 8;
    type F = __m256;
    type I = __m256i;
    type M = __m256i;
    #[inline(always)]
    unsafe fn load_f(p: &[f32]) -> __m256 {
        unsafe {
            debug_assert!(p.len() >= 8);
            _mm256_loadu_ps(p.as_ptr())
        }
    }
    #[inline(always)]
    unsafe fn load_i(p: &[i32]) -> __m256i {
        unsafe {
            debug_assert!(p.len() >= 8);
            _mm256_loadu_si256(p.as_ptr().cast())
        }
    }
    #[inline(always)]
    unsafe fn store_f(v: __m256, p: &mut [f32]) {
        unsafe {
            debug_assert!(p.len() >= 8);
            _mm256_storeu_ps(p.as_mut_ptr(), v)
        }
    }
    #[inline(always)]
    unsafe fn store_i(v: __m256i, p: &mut [i32]) {
        unsafe {
            debug_assert!(p.len() >= 8);
            _mm256_storeu_si256(p.as_mut_ptr().cast(), v)
        }
    }
    #[inline(always)]
    unsafe fn splat_i(x: i32) -> __m256i {
        unsafe { _mm256_set1_epi32(x) }
    }
    #[inline(always)]
    unsafe fn mask_from_bits(bits: u32) -> __m256i {
        unsafe {
            let b = _mm256_set1_epi32(bits as i32);
            let sel = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            _mm256_cmpeq_epi32(_mm256_and_si256(b, sel), sel)
        }
    }
    #[inline(always)]
    unsafe fn mask_bits(m: __m256i) -> u32 {
        unsafe { _mm256_movemask_ps(_mm256_castsi256_ps(m)) as u32 }
    }
    #[inline(always)]
    unsafe fn le(a: __m256, b: __m256) -> __m256i {
        unsafe { _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(a, b)) }
    }
    #[inline(always)]
    unsafe fn eq_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_cmpeq_epi32(a, b) }
    }
    #[inline(always)]
    unsafe fn and(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_and_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn andnot(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_andnot_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn sel_f(m: __m256i, a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_blendv_ps(b, a, _mm256_castsi256_ps(m)) }
    }
    #[inline(always)]
    unsafe fn sel_i(m: __m256i, a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_blendv_epi8(b, a, m) }
    }
    #[inline(always)]
    unsafe fn add(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn add_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_add_epi32(a, b) }
    }
    #[inline(always)]
    unsafe fn gather(m: __m256i, idx: __m256i, data: &[f32]) -> __m256 {
        unsafe {
            _mm256_mask_i32gather_ps::<4>(
                _mm256_setzero_ps(),
                data.as_ptr(),
                idx,
                _mm256_castsi256_ps(m),
            )
        }
    }
}
