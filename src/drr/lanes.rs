//! Vector lanes of the DRR kernels: f32 values, i32 voxel indices.
//!
//! The kernels ([`super::siddon_lanes`]: one ray per lane, AVX-512 16 lanes and AVX2 8;
//! [`super::trilinear_lanes`]: one ray per lane, 8 lanes on AVX2, 8 or 16 on AVX-512, with
//! the further operations of [`SampleLanes`]) are written once against [`Lanes`]; the scalar
//! path runs the per-ray loops of [`super::siddon`] and [`super::trilinear`]
//! ([`super::padded_lanes`], the trilinear march's zero-padded samples on 4 or 8 lanes of f64
//! positions, is written in AVX2 and AVX-512 directly). Every lane performs
//! the IEEE operations of the per-ray loop in the same order (no fused multiply-add anywhere),
//! so every path gives the same bits (`tests/drr/simd.rs` compares them).
//!
//! Longer than 600 lines because the trait and its three implementations (AVX2, AVX2 with
//! AVX-512VL's conversions, AVX-512) are read side by side: an operation's semantics must match
//! across them lane for lane.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Lanes of the widest path (the size of the kernels' per-lane state arrays).
pub(crate) const MAXW: usize = 16;

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
    /// The three per-axis vectors of a lane state.
    #[inline(always)]
    unsafe fn load3_f(p: &[[f32; MAXW]; 3]) -> [Self::F; 3] {
        unsafe {
            [
                Self::load_f(&p[0]),
                Self::load_f(&p[1]),
                Self::load_f(&p[2]),
            ]
        }
    }
    /// The three per-axis vectors of a lane state.
    #[inline(always)]
    unsafe fn load3_i(p: &[[i32; MAXW]; 3]) -> [Self::I; 3] {
        unsafe {
            [
                Self::load_i(&p[0]),
                Self::load_i(&p[1]),
                Self::load_i(&p[2]),
            ]
        }
    }
}

/// The per-lane state of a kernel that runs one ray per lane ([`super::siddon_lanes`],
/// [`super::trilinear_lanes`]): a lane starts on a ray, and hands its sum over when the ray is
/// done.
pub(crate) trait RayLanes {
    /// A ray as the kernel starts it.
    type Ray;
    /// Start lane `k` on `ray`, whose sum goes to `out[slot]`.
    fn start(&mut self, k: usize, slot: usize, ray: Self::Ray);
    /// Lane `k`'s slot and sum.
    fn result(&self, k: usize) -> (usize, f32);
    /// Lane `k` has no ray left to take (it stays idle until the kernel returns).
    fn park(&mut self, _k: usize) {}
}

/// Start the first `w` lanes of `s` on the first rays of `rays`; returns the lanes started (bit
/// k for lane k).
#[inline(always)]
pub(crate) fn start_lanes<S: RayLanes>(
    s: &mut S,
    w: usize,
    rays: &mut impl Iterator<Item = (usize, S::Ray)>,
) -> u32 {
    let mut active = 0u32;
    for k in 0..w {
        let Some((slot, ray)) = rays.next() else {
            break;
        };
        s.start(k, slot, ray);
        active |= 1 << k;
    }
    active
}

/// The lanes `done` (bits) write their sums to `out` and take the next rays of `rays`; returns
/// the lanes of `active` still running or restarted.
#[inline(always)]
pub(crate) fn hand_over<S: RayLanes>(
    s: &mut S,
    mut active: u32,
    done: u32,
    rays: &mut impl Iterator<Item = (usize, S::Ray)>,
    out: &mut [f32],
) -> u32 {
    let mut bits = done;
    while bits != 0 {
        let k = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let (slot, sum) = s.result(k);
        out[slot] = sum;
        active &= !(1 << k);
        if let Some((slot, ray)) = rays.next() {
            s.start(k, slot, ray);
            active |= 1 << k;
        } else {
            s.park(k);
        }
    }
    active
}

/// The further operations of the trilinear kernel ([`super::trilinear_lanes`]): 16 lanes
/// ([`Avx512`]) or 8 ([`Avx2`], which the AVX-512 path also runs, from code compiled with
/// AVX-512 enabled, where 512-bit operations run as two halves).
///
/// # Safety
/// As [`Lanes`].
pub(crate) unsafe trait SampleLanes: Lanes {
    unsafe fn splat_f(x: f32) -> Self::F;
    /// `a - b` (wrapping).
    unsafe fn sub_i(a: Self::I, b: Self::I) -> Self::I;
    /// `a & b`.
    unsafe fn and_i(a: Self::I, b: Self::I) -> Self::I;
    /// The unsigned 32-bit integer in each lane, rounded to the nearest f32 (ties to even), as
    /// `u32 as f32` rounds it.
    unsafe fn u32_to_f(a: Self::I) -> Self::F;
    /// `lo + dlo` as unsigned 32-bit lanes (wrapping), and -1 in the lanes where that addition
    /// carried (0 elsewhere).
    unsafe fn add_carry(lo: Self::I, dlo: Self::I) -> (Self::I, Self::I);
    /// Lane k gets the pair `data[idx[k] + off]`, `data[idx[k] + off + 1]`: the first values in
    /// one vector, the second ones in the other.
    ///
    /// # Safety
    /// `0 <= idx[k]` and `idx[k] + off + 1 < data.len()` for every lane `k < W`.
    unsafe fn load_pairs(data: &[f32], idx: Self::I, off: usize) -> (Self::F, Self::F);
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

#[cfg(target_arch = "x86_64")]
unsafe impl SampleLanes for Avx512 {
    #[inline(always)]
    unsafe fn splat_f(x: f32) -> __m512 {
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn sub_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_sub_epi32(a, b) }
    }
    #[inline(always)]
    unsafe fn and_i(a: __m512i, b: __m512i) -> __m512i {
        unsafe { _mm512_and_si512(a, b) }
    }
    #[inline(always)]
    unsafe fn u32_to_f(a: __m512i) -> __m512 {
        // Round to nearest even, the default mode.
        unsafe { _mm512_cvtepu32_ps(a) }
    }
    #[inline(always)]
    unsafe fn add_carry(lo: __m512i, dlo: __m512i) -> (__m512i, __m512i) {
        unsafe {
            let sum = _mm512_add_epi32(lo, dlo);
            (sum, _mm512_movm_epi32(_mm512_cmplt_epu32_mask(sum, dlo)))
        }
    }
    #[inline(always)]
    unsafe fn load_pairs(data: &[f32], idx: __m512i, off: usize) -> (__m512, __m512) {
        // As on AVX2, per 128-bit quarter: the pairs of lanes 4j, 4j + 1 in `a`, of lanes
        // 4j + 2, 4j + 3 in `b`.
        unsafe {
            let mut at = [0i32; 16];
            Self::store_i(idx, &mut at);
            let idx = &at;
            macro_rules! q {
                ($k:expr) => {
                    pair(data, idx, off, $k)
                };
            }
            let a = _mm512_castsi512_ps(_mm512_set_epi64(
                q!(13),
                q!(12),
                q!(9),
                q!(8),
                q!(5),
                q!(4),
                q!(1),
                q!(0),
            ));
            let b = _mm512_castsi512_ps(_mm512_set_epi64(
                q!(15),
                q!(14),
                q!(11),
                q!(10),
                q!(7),
                q!(6),
                q!(3),
                q!(2),
            ));
            (
                _mm512_shuffle_ps::<0x88>(a, b),
                _mm512_shuffle_ps::<0xdd>(a, b),
            )
        }
    }
}

/// AVX2: 8 lanes; masks are all-ones / all-zeros lanes. With `VL` (only from code compiled with
/// AVX-512 F and VL, on a CPU that has them) the unsigned conversion is AVX-512's one
/// instruction; every other operation is AVX2's.
#[cfg(target_arch = "x86_64")]
pub(crate) struct Avx2<const VL: bool = false>;

/// The 8 lanes of [`Avx2`] with AVX-512's unsigned conversion.
#[cfg(target_arch = "x86_64")]
pub(crate) type Avx2Vl = Avx2<true>;

#[cfg(target_arch = "x86_64")]
unsafe impl<const VL: bool> Lanes for Avx2<VL> {
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

#[cfg(target_arch = "x86_64")]
unsafe impl<const VL: bool> SampleLanes for Avx2<VL> {
    #[inline(always)]
    unsafe fn splat_f(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn sub_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_sub_epi32(a, b) }
    }
    #[inline(always)]
    unsafe fn and_i(a: __m256i, b: __m256i) -> __m256i {
        unsafe { _mm256_and_si256(a, b) }
    }
    #[inline(always)]
    unsafe fn u32_to_f(a: __m256i) -> __m256 {
        // AVX2 converts signed lanes only: the high and low 16 bits convert exactly, the high
        // part's scaling by 2^16 is exact, and their sum is the one rounding of the value.
        // AVX-512 F converts unsigned lanes (round to nearest even, the default mode), here on
        // the low half of a 16-lane vector whose upper half is not used.
        unsafe {
            if VL {
                return _mm512_castps512_ps256(_mm512_cvtepu32_ps(_mm512_castsi256_si512(a)));
            }
            let hi = _mm256_cvtepi32_ps(_mm256_srli_epi32::<16>(a));
            let lo = _mm256_cvtepi32_ps(_mm256_and_si256(a, _mm256_set1_epi32(0xffff)));
            _mm256_add_ps(_mm256_mul_ps(hi, _mm256_set1_ps(65536.0)), lo)
        }
    }
    #[inline(always)]
    unsafe fn add_carry(lo: __m256i, dlo: __m256i) -> (__m256i, __m256i) {
        unsafe {
            let sum = _mm256_add_epi32(lo, dlo);
            // The sum carried when it is below `dlo` as unsigned values: a signed comparison
            // with the sign bits flipped.
            let flip = _mm256_set1_epi32(i32::MIN);
            let carry =
                _mm256_cmpgt_epi32(_mm256_xor_si256(dlo, flip), _mm256_xor_si256(sum, flip));
            (sum, carry)
        }
    }
    #[inline(always)]
    unsafe fn load_pairs(data: &[f32], idx: __m256i, off: usize) -> (__m256, __m256) {
        // One 64-bit scalar load per lane (the compiler takes the indices out of the vector).
        unsafe {
            let mut at = [0i32; 8];
            Self::store_i(idx, &mut at);
            let idx = &at;
            macro_rules! q {
                ($k:expr) => {
                    pair(data, idx, off, $k)
                };
            }
            // The pairs of lanes 0, 1, 4, 5 and of lanes 2, 3, 6, 7 (64-bit quarters, lowest
            // first): within each 128-bit half, the even floats of `a` then of `b` are four
            // lanes' first values in lane order, and the odd ones their second values.
            let a = _mm256_castsi256_ps(_mm256_set_epi64x(q!(5), q!(4), q!(1), q!(0)));
            let b = _mm256_castsi256_ps(_mm256_set_epi64x(q!(7), q!(6), q!(3), q!(2)));
            (
                _mm256_shuffle_ps::<0x88>(a, b),
                _mm256_shuffle_ps::<0xdd>(a, b),
            )
        }
    }
}

/// The 64 bits of `data[idx[k] + off]` and `data[idx[k] + off + 1]` (the first in the low half).
///
/// # Safety
/// `idx[k] + off + 1 < data.len()`.
#[inline(always)]
unsafe fn pair(data: &[f32], idx: &[i32], off: usize, k: usize) -> i64 {
    unsafe {
        debug_assert!(idx[k] as usize + off + 1 < data.len());
        data.as_ptr()
            .add(idx[k] as usize + off)
            .cast::<i64>()
            .read_unaligned()
    }
}

/// A `dyn Iterator` as a sized one (the ray source is called once per ray, not per step).
pub(super) struct DynIter<'a, T>(pub(super) &'a mut dyn Iterator<Item = T>);

impl<T> Iterator for DynIter<'_, T> {
    type Item = T;
    fn next(&mut self) -> Option<T> {
        self.0.next()
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::simd::Simd;

    /// `u32_to_f`, `add_carry`, `and_i`, `sub_i` and `load_pairs` of `L` against their scalar
    /// definitions on values where rounding and carries matter.
    #[inline(always)]
    unsafe fn check<L: SampleLanes>() {
        unsafe {
            let w = L::W;
            let edge: [u32; 16] = [
                0,
                1,
                (1 << 24) + 1,
                (1 << 24) + 3,
                (1 << 25) + 2,
                0x7fff_ffff,
                0x8000_0000,
                0x8000_0001,
                0xffff_fffe,
                0xffff_ffff,
                0xffff_ff7f,
                0xffff_ff80,
                0xffff_ff81,
                0x0123_4567,
                0x89ab_cdef,
                0xfedc_ba98,
            ];
            for start in (0..16).step_by(w) {
                let a: Vec<i32> = edge[start..start + w].iter().map(|&u| u as i32).collect();
                let mut got = [0.0f32; 16];
                L::store_f(L::u32_to_f(L::load_i(&a)), &mut got);
                for k in 0..w {
                    assert_eq!(
                        got[k].to_bits(),
                        (a[k] as u32 as f32).to_bits(),
                        "u32 {:#x}",
                        a[k]
                    );
                }
                // 32-bit unsigned sums with and without carries; and, difference.
                let b: Vec<i32> = (0..w)
                    .map(|k| edge[(start + 3 * k + 5) % 16] as i32)
                    .collect();
                let (sum, carry) = L::add_carry(L::load_i(&a), L::load_i(&b));
                let (mut s, mut c) = ([0i32; 16], [0i32; 16]);
                L::store_i(sum, &mut s);
                L::store_i(carry, &mut c);
                let (mut and, mut diff) = ([0i32; 16], [0i32; 16]);
                L::store_i(L::and_i(L::load_i(&a), L::load_i(&b)), &mut and);
                L::store_i(L::sub_i(L::load_i(&a), L::load_i(&b)), &mut diff);
                for k in 0..w {
                    let (want, carried) = (a[k] as u32).overflowing_add(b[k] as u32);
                    let (x, y) = (a[k], b[k]);
                    assert_eq!(
                        (s[k] as u32, c[k]),
                        (want, -(carried as i32)),
                        "{x:#x} + {y:#x}"
                    );
                    assert_eq!(
                        (and[k], diff[k]),
                        (x & y, x.wrapping_sub(y)),
                        "{x:#x}, {y:#x}"
                    );
                }
            }
            let data: Vec<f32> = (0..64).map(|i| i as f32 * 0.5 - 3.0).collect();
            let idx: Vec<i32> = (0..16).map(|k| (k * 7) % 50).collect();
            let (a, b) = L::load_pairs(&data, L::load_i(&idx), 3);
            let (mut fa, mut fb) = ([0.0f32; 16], [0.0f32; 16]);
            L::store_f(a, &mut fa);
            L::store_f(b, &mut fb);
            for k in 0..w {
                let i = idx[k] as usize + 3;
                assert_eq!((fa[k], fb[k]), (data[i], data[i + 1]), "lane {k}");
            }
        }
    }

    crate::simd::wide_kernels! {
        // The AVX2 operations, also as the AVX-512 path compiles them.
        unsafe fn []();
        check_avx2 => { unsafe { check::<Avx2>() } }
        check_avx512 => { unsafe { check::<Avx2>(); check::<Avx2Vl>(); check::<Avx512>() } }
    }

    #[test]
    fn conversions_carries_and_pairs_match_their_scalar_definitions() {
        // SAFETY: each path runs only where the CPU supports it.
        unsafe {
            if Simd::Avx512.supported() {
                check_avx512();
            }
            if Simd::Avx2.supported() {
                check_avx2();
            }
        }
    }
}
