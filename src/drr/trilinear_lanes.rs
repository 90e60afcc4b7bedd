//! The trilinear ray-march's inner loop ([`super::trilinear::march_scalar`]) over vector lanes,
//! one ray per lane (f32 volumes; 8 lanes on both vector paths, see `run_avx512`).
//!
//! Each lane runs the per-ray loop step for step: its 32.32 fixed-point position is the scalar
//! loop's `p + k dp`, held as two 32-bit halves and stepped by `dp` with the carry (exact integer
//! arithmetic, so the same position); the voxel index, the fraction (`u32 -> f32`, one rounding
//! to nearest, times 2^-32), the seven lerps and the addition to the lane's sum are the scalar
//! loop's IEEE operations in its order. So a lane's sum is the scalar sum, bit for bit. A lane
//! whose ray has run its samples hands its sum over and takes the next ray (rays in tile order,
//! so the lanes march neighbouring rays through the same cache lines).
//!
//! The eight corners are four x pairs `(x, x + 1)`, each read with one 64-bit scalar load and
//! split into two vectors ([`SampleLanes::load_pairs`]): on AMD Zen 4 gathers are slower (eight
//! gathers of single values per block in the first lane version were no faster than the per-ray
//! loop, even on a volume that fits in cache; two AVX-512 gathers of pairs per row in this one
//! were slower than it).
//!
//! An earlier version put 8 consecutive samples of one ray in the lanes and added them to the
//! ray's sum one at a time: the horizontal, serial sum and the extraction of the lanes bounded
//! it at about 1.3x the per-ray loop.

use super::lanes::{hand_over, start_lanes, RayLanes, SampleLanes, MAXW};
use super::trilinear::March;

/// The per-lane state, as arrays the vectors are loaded from and stored to when a lane changes
/// ray: the position's low and high halves per axis, the step's, the samples left, the sum and
/// where it goes.
struct State {
    lo: [[i32; MAXW]; 3],
    hi: [[i32; MAXW]; 3],
    dlo: [[i32; MAXW]; 3],
    dhi: [[i32; MAXW]; 3],
    left: [i32; MAXW],
    acc: [f32; MAXW],
    slot: [usize; MAXW],
}

impl State {
    fn new() -> Self {
        State {
            lo: [[0; MAXW]; 3],
            hi: [[0; MAXW]; 3],
            dlo: [[0; MAXW]; 3],
            dhi: [[0; MAXW]; 3],
            left: [0; MAXW],
            acc: [0.0; MAXW],
            slot: [0; MAXW],
        }
    }
}

impl RayLanes for State {
    type Ray = March;

    /// (The march's count is in [1, 2^31).)
    fn start(&mut self, k: usize, slot: usize, m: March) {
        for a in 0..3 {
            self.lo[a][k] = m.p[a] as u32 as i32;
            self.hi[a][k] = (m.p[a] >> 32) as i32;
            self.dlo[a][k] = m.dp[a] as u32 as i32;
            self.dhi[a][k] = (m.dp[a] >> 32) as i32;
        }
        self.left[k] = m.count as i32;
        self.acc[k] = 0.0;
        self.slot[k] = slot;
    }

    fn result(&self, k: usize) -> (usize, f32) {
        (self.slot[k], self.acc[k])
    }
}

/// March every ray of `rays` (`(slot, march)`, counts >= 1), writing each inner sum to
/// `out[slot]`.
///
/// # Safety
/// The CPU supports `L`'s instruction set (the caller is compiled with it); `data` is the
/// `n`-voxel grid (x fastest), `n[0] n[1] n[2] < 2^31`, `n[a] >= 2`; every march is one of
/// [`super::trilinear::plan`] on that grid (so its positions satisfy `0 <= p[a] + k dp[a] <
/// (n[a] - 1) 2^32`, all 8 neighbours in the grid) with `1 <= count < 2^31`; every slot is in
/// `out`.
#[inline(always)]
pub(crate) unsafe fn run<L: SampleLanes>(
    data: &[f32],
    n: [usize; 3],
    rays: &mut impl Iterator<Item = (usize, March)>,
    out: &mut [f32],
) {
    // SAFETY: the caller's contract.
    unsafe {
        let w = L::W;
        debug_assert!(w <= MAXW && data.len() == n[0] * n[1] * n[2] && data.len() < 1 << 31);
        let (nx, nxy) = (n[0], n[0] * n[1]);
        // The lower corner's row offsets: (y, z), (y + 1, z), (y, z + 1), (y + 1, z + 1); each row
        // gives the x pair (x, x + 1), one 64-bit load.
        let rows = [0, nx, nxy, nxy + nx];
        let (vnx, vnxy) = (L::splat_i(nx as i32), L::splat_i(nxy as i32));
        let inv = L::splat_f((1.0 / super::trilinear::FIX) as f32);
        let (zero, minus1) = (L::splat_i(0), L::splat_i(-1));
        let mut s = State::new();
        let mut active = start_lanes(&mut s, w, rays);
        while active != 0 {
            let [mut lx, mut ly, mut lz] = L::load3_i(&s.lo);
            let [mut hx, mut hy, mut hz] = L::load3_i(&s.hi);
            let [dlx, dly, dlz] = L::load3_i(&s.dlo);
            let [dhx, dhy, dhz] = L::load3_i(&s.dhi);
            let mut left = L::load_i(&s.left);
            let mut acc = L::load_f(&s.acc);
            let mut act = L::mask_from_bits(active);
            let done = loop {
                let fx = L::mul(L::u32_to_f(lx), inv);
                let fy = L::mul(L::u32_to_f(ly), inv);
                let fz = L::mul(L::u32_to_f(lz), inv);
                let b = L::add_i(L::add_i(hx, L::mul_i(vnx, hy)), L::mul_i(vnxy, hz));
                // Idle lanes read the first voxel's pairs (in the grid, not summed).
                let idx = L::sel_i(act, b, zero);
                // SAFETY: an active lane's position is one of its march's, so its index is at
                // most len - 1 - (nxy + nx + 1) and every pair of its rows is in `data`; 0 is too.
                let (c000, c100) = L::load_pairs(data, idx, rows[0]);
                let (c010, c110) = L::load_pairs(data, idx, rows[1]);
                let (c001, c101) = L::load_pairs(data, idx, rows[2]);
                let (c011, c111) = L::load_pairs(data, idx, rows[3]);
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
                acc = L::sel_f(act, L::add(acc, lerp!(c0, c1, fz)), acc);
                left = L::add_i(left, minus1);
                let fin = L::and(act, L::eq_i(left, zero));
                act = L::andnot(fin, act);
                (lx, hx) = L::add_64(lx, hx, dlx, dhx);
                (ly, hy) = L::add_64(ly, hy, dly, dhy);
                (lz, hz) = L::add_64(lz, hz, dlz, dhz);
                let fb = L::mask_bits(fin);
                if fb != 0 {
                    break fb;
                }
            };
            L::store_i(lx, &mut s.lo[0]);
            L::store_i(ly, &mut s.lo[1]);
            L::store_i(lz, &mut s.lo[2]);
            L::store_i(hx, &mut s.hi[0]);
            L::store_i(hy, &mut s.hi[1]);
            L::store_i(hz, &mut s.hi[2]);
            L::store_i(left, &mut s.left);
            L::store_f(acc, &mut s.acc);
            active = hand_over(&mut s, active, done, rays, out);
        }
    }
}

crate::simd::wide_kernels! {
    /// [`run`] compiled for AVX2 (`run_avx2`) or AVX-512 (`run_avx512`).
    ///
    /// # Safety
    /// As [`run`], on a CPU with the instruction set.
    pub(crate) unsafe fn [](
        data: &[f32],
        n: [usize; 3],
        rays: &mut dyn Iterator<Item = (usize, March)>,
        out: &mut [f32],
    );
    // SAFETY (both): as this function.
    run_avx2 => { unsafe { run::<super::lanes::Avx2>(data, n, &mut super::DynIter(rays), out) } }
    // 8 lanes here too: 16 (the corner pairs loaded per lane as on AVX2) measured slower on the
    // CT (AP 1.34x the per-ray loop against 1.43x, lateral 1.49x against 1.81x), and AVX-512
    // gathers of the pairs slower still (AP 0.87x); the path brings its encoding and 32
    // registers, not the width.
    run_avx512 => { unsafe { run::<super::lanes::Avx2>(data, n, &mut super::DynIter(rays), out) } }
}
