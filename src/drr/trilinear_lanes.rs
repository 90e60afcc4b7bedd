//! The trilinear ray-march's inner loop ([`super::trilinear`]) over vector lanes: consecutive
//! samples of one ray in consecutive lanes (f32 volumes; blocks of 8 samples on both vector
//! paths, see `march_avx512`).
//!
//! Lane `k` of a block takes sample `k` of the block: its 32.32 fixed-point position is the
//! scalar loop's `p0 + j dp`, held as two 32-bit halves and stepped by `W dp` with the carry
//! (exact integer arithmetic, so the same position). The voxel index, the fraction (`u32 ->
//! f32`, one rounding to nearest, times 2^-32) and the seven lerps are the scalar loop's IEEE
//! operations. The samples are then added to the ray's sum one at a time in sample order, as the
//! scalar loop adds them. So the sum is the scalar sum, bit for bit, and only the per-sample work
//! runs in the lanes.
//!
//! The eight corners are four x pairs `(x, x + 1)`, each read with one 64-bit scalar load and
//! split into two vectors ([`SampleLanes::load_pairs`]): on AMD Zen 4 gathering them (eight
//! gathers per block) was no faster than the per-ray loop, even on a volume that fits in cache.

use super::lanes::SampleLanes;

/// Lanes of the widest path.
const MAXW: usize = 16;

/// The sum, in order, of the trilinear samples at the fixed-point positions `p + k dp`
/// (`0 <= k < count`; voxel units x 2^32, voxel centres at integers) of the `n`-voxel grid
/// `data` (x fastest).
///
/// # Safety
/// The CPU supports `L`'s instruction set (the caller is compiled with it); `data` has
/// `n[0] n[1] n[2] < 2^31` values, `n[a] >= 2`; every position satisfies
/// `0 <= p[a] + k dp[a] < (n[a] - 1) 2^32` on each axis (so all 8 neighbours are in the grid).
#[inline(always)]
pub(crate) unsafe fn march<L: SampleLanes>(
    data: &[f32],
    n: [usize; 3],
    p: [i64; 3],
    dp: [i64; 3],
    count: usize,
) -> f32 {
    // SAFETY: the caller's contract.
    unsafe {
        let w = L::W;
        debug_assert!(w <= MAXW && data.len() == n[0] * n[1] * n[2] && data.len() < 1 << 31);
        let (nx, nxy) = (n[0], n[0] * n[1]);
        // The 64-bit positions of the first block's lanes and the step of a block, as halves.
        let mut lo = [[0i32; MAXW]; 3];
        let mut hi = [[0i32; MAXW]; 3];
        for a in 0..3 {
            for k in 0..w {
                let q = p[a].wrapping_add((k as i64).wrapping_mul(dp[a]));
                lo[a][k] = q as u32 as i32;
                hi[a][k] = (q >> 32) as i32;
            }
        }
        // (Local macros rather than closures: a closure is not guaranteed to be inlined, and
        // one that is not runs without the caller's target features.)
        macro_rules! halves {
            ($a:expr) => {{
                let s = (w as i64).wrapping_mul(dp[$a]);
                (L::splat_i(s as u32 as i32), L::splat_i((s >> 32) as i32))
            }};
        }
        let (dlx, dhx) = halves!(0);
        let (dly, dhy) = halves!(1);
        let (dlz, dhz) = halves!(2);
        let (mut lx, mut hx) = (L::load_i(&lo[0]), L::load_i(&hi[0]));
        let (mut ly, mut hy) = (L::load_i(&lo[1]), L::load_i(&hi[1]));
        let (mut lz, mut hz) = (L::load_i(&lo[2]), L::load_i(&hi[2]));
        // The lower corner's row offsets: (y, z), (y + 1, z), (y, z + 1), (y + 1, z + 1); each row
        // gives the x pair (x, x + 1), one 64-bit load.
        let rows = [0, nx, nxy, nxy + nx];
        let mut idx = [0i32; MAXW];
        let (vnx, vnxy) = (L::splat_i(nx as i32), L::splat_i(nxy as i32));
        let inv = L::splat_f((1.0 / super::trilinear::FIX) as f32);
        let mut buf = [0.0f32; MAXW];
        let mut acc = 0.0f32;
        let mut left = count;
        while left > 0 {
            let fx = L::mul(L::u32_to_f(lx), inv);
            let fy = L::mul(L::u32_to_f(ly), inv);
            let fz = L::mul(L::u32_to_f(lz), inv);
            let b = L::add_i(L::add_i(hx, L::mul_i(vnx, hy)), L::mul_i(vnxy, hz));
            L::store_i(b, &mut idx);
            let valid = left.min(w);
            // Lanes past the last sample read the first voxel's pairs (in the grid, not summed).
            idx[valid..w].fill(0);
            // SAFETY: the position of sample k < valid is one of the caller's, so its index is at
            // most len - 1 - (nxy + nx + 1) and every pair of its rows is in `data`; 0 is too.
            let (c000, c100) = L::load_pairs(data, &idx, rows[0]);
            let (c010, c110) = L::load_pairs(data, &idx, rows[1]);
            let (c001, c101) = L::load_pairs(data, &idx, rows[2]);
            let (c011, c111) = L::load_pairs(data, &idx, rows[3]);
            macro_rules! lerp {
                ($a:expr, $b:expr, $f:expr) => {
                    L::add($a, L::mul($f, L::sub($b, $a)))
                };
            }
            let c00 = lerp!(c000, c100, fx);
            let c10 = lerp!(c010, c110, fx);
            let c01 = lerp!(c001, c101, fx);
            let c11 = lerp!(c011, c111, fx);
            let c0 = lerp!(c00, c10, fy);
            let c1 = lerp!(c01, c11, fy);
            L::store_f(lerp!(c0, c1, fz), &mut buf);
            // (A full block's loop has a constant length, so it unrolls.)
            if valid == w {
                for v in &buf[..w] {
                    acc += v;
                }
            } else {
                for v in &buf[..valid] {
                    acc += v;
                }
            }
            left -= valid;
            (lx, hx) = L::add_64(lx, hx, dlx, dhx);
            (ly, hy) = L::add_64(ly, hy, dly, dhy);
            (lz, hz) = L::add_64(lz, hz, dlz, dhz);
        }
        acc
    }
}

crate::simd::wide_kernels! {
    /// [`march`] compiled for AVX2 (`march_avx2`) or AVX-512 (`march_avx512`).
    ///
    /// # Safety
    /// As [`march`], on a CPU with the instruction set.
    pub(crate) unsafe fn [](
        data: &[f32],
        n: [usize; 3],
        p: [i64; 3],
        dp: [i64; 3],
        count: usize,
    ) -> f32;
    // SAFETY (both): as this function.
    march_avx2 => { unsafe { march::<super::lanes::Avx2>(data, n, p, dp, count) } }
    // Blocks of 8 samples here too: with the paths timed in turns, blocks of 16 measured slower
    // on the AP view of the CT (1.13-1.15x the per-ray loop against 1.32-1.36x) and a little
    // faster on the lateral one (1.30-1.31x against 1.22-1.30x), so AVX-512 brings its encoding
    // and 32 registers, not the width (the 16-lane operations are in the history of
    // `drr/lanes.rs`).
    march_avx512 => { unsafe { march::<super::lanes::Avx2>(data, n, p, dp, count) } }
}
