//! The trilinear ray-march's inner loop ([`super::trilinear::march_scalar`]) over vector lanes,
//! one ray per lane (f32 volumes; 8 lanes on AVX2, 8 or 16 on AVX-512, see
//! [`super::MarchLanes`]).
//!
//! Each lane runs the per-ray loop step for step: its 32.32 fixed-point position is the scalar
//! loop's `p + k dp`, held as the three low (fractional) 32-bit halves and the index of the lower
//! corner, `hi_x + nx hi_y + nx ny hi_z`: a step adds `dp`'s low halves with their carries, and
//! moves the index by `dp`'s high halves (times the strides) plus the stride of every axis whose
//! low half carried (exact integer arithmetic, so the same position and corner as the scalar
//! loop's, with no multiplication in the loop); the fraction (`u32 -> f32`, one rounding to
//! nearest, times 2^-32), the seven lerps and the addition to the lane's sum are the scalar
//! loop's IEEE operations in its order. So a lane's sum is the scalar sum, bit for bit. A lane
//! whose ray has run its samples hands its sum over and takes the next ray.
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
/// ray: the position's fractional (low) halves per axis and their steps, the index of the
/// lower corner and its step, the samples left, the sum and where it goes.
struct State {
    lo: [[i32; MAXW]; 3],
    dlo: [[i32; MAXW]; 3],
    idx: [i32; MAXW],
    didx: [i32; MAXW],
    left: [i32; MAXW],
    acc: [f32; MAXW],
    slot: [usize; MAXW],
    /// Index strides of the axes: 1, nx, nx ny.
    strides: [i64; 3],
}

impl State {
    fn new(strides: [i64; 3]) -> Self {
        State {
            lo: [[0; MAXW]; 3],
            dlo: [[0; MAXW]; 3],
            idx: [0; MAXW],
            didx: [0; MAXW],
            left: [0; MAXW],
            acc: [0.0; MAXW],
            slot: [0; MAXW],
            strides,
        }
    }
}

impl RayLanes for State {
    type Ray = March;

    /// (The march's count is in [1, 2^31); its first index is in the grid, below 2^31.)
    fn start(&mut self, k: usize, slot: usize, m: March) {
        let (mut idx, mut didx) = (0i64, 0i64);
        for a in 0..3 {
            self.lo[a][k] = m.p[a] as u32 as i32;
            self.dlo[a][k] = m.dp[a] as u32 as i32;
            idx += (m.p[a] >> 32) * self.strides[a];
            didx = didx.wrapping_add((m.dp[a] >> 32).wrapping_mul(self.strides[a]));
        }
        self.idx[k] = idx as i32;
        // Taken modulo 2^32: the lanes' index arithmetic wraps, and every index it reaches is
        // a true one, below 2^31.
        self.didx[k] = didx as i32;
        self.left[k] = m.count as i32;
        self.acc[k] = 0.0;
        self.slot[k] = slot;
    }

    fn result(&self, k: usize) -> (usize, f32) {
        (self.slot[k], self.acc[k])
    }

    /// An idle lane stays on the first voxel: index 0 and zero steps (no carry either).
    fn park(&mut self, k: usize) {
        for a in 0..3 {
            self.lo[a][k] = 0;
            self.dlo[a][k] = 0;
        }
        self.idx[k] = 0;
        self.didx[k] = 0;
    }
}

/// March every ray of `rays` (`(slot, march)`, counts >= 1), writing each inner sum to
/// `out[slot]`.
///
/// # Safety
/// The CPU supports `L`'s instruction set (the caller is compiled with it); `data` is the
/// `n`-voxel grid (x fastest), `n[0] n[1] n[2] < 2^31`, `n[a] >= 2`; every march is one of
/// [`super::trilinear::plan_runs`] on that grid (so its positions satisfy `0 <= p[a] + k dp[a] <
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
        let mut s = State::new([1, nx as i64, nxy as i64]);
        let mut active = start_lanes(&mut s, w, rays);
        while active != 0 {
            // Run the samples that every active lane still has (at least one), with no test
            // per sample; idle lanes are parked on voxel 0 (`park`, or never started) and their
            // sums are not read.
            let run = (0..w)
                .filter(|&k| active >> k & 1 != 0)
                .map(|k| s.left[k])
                .min()
                .unwrap_or(1);
            let [mut lx, mut ly, mut lz] = L::load3_i(&s.lo);
            let [dlx, dly, dlz] = L::load3_i(&s.dlo);
            let mut b = L::load_i(&s.idx);
            let db = L::load_i(&s.didx);
            let mut acc = L::load_f(&s.acc);
            for _ in 0..run {
                let fx = L::mul(L::u32_to_f(lx), inv);
                let fy = L::mul(L::u32_to_f(ly), inv);
                let fz = L::mul(L::u32_to_f(lz), inv);
                // SAFETY: an active lane's index is its position's lower corner (see the step
                // below), at most len - 1 - (nxy + nx + 1), so every pair of its rows is in
                // `data`; an idle lane's is 0.
                let (c000, c100) = L::load_pairs(data, b, rows[0]);
                let (c010, c110) = L::load_pairs(data, b, rows[1]);
                let (c001, c101) = L::load_pairs(data, b, rows[2]);
                let (c011, c111) = L::load_pairs(data, b, rows[3]);
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
                acc = L::add(acc, lerp!(c0, c1, fz));
                // The next position: each axis's high half moves by the step's high half plus
                // the low halves' carry, so the lower corner's index moves by `didx` plus the
                // carried axes' strides (the carry masks are -1).
                let (nlx, cx) = L::add_carry(lx, dlx);
                let (nly, cy) = L::add_carry(ly, dly);
                let (nlz, cz) = L::add_carry(lz, dlz);
                (lx, ly, lz) = (nlx, nly, nlz);
                let carried = L::add_i(L::and_i(cy, vnx), L::and_i(cz, vnxy));
                b = L::add_i(L::sub_i(L::add_i(b, db), cx), carried);
            }
            L::store_i(lx, &mut s.lo[0]);
            L::store_i(ly, &mut s.lo[1]);
            L::store_i(lz, &mut s.lo[2]);
            L::store_i(b, &mut s.idx);
            L::store_f(acc, &mut s.acc);
            let mut done = 0;
            for k in 0..w {
                if active >> k & 1 != 0 {
                    s.left[k] -= run;
                    if s.left[k] == 0 {
                        done |= 1 << k;
                    }
                }
            }
            active = hand_over(&mut s, active, done, rays, out);
        }
    }
}

crate::simd::wide_kernels! {
    /// [`run`] compiled for AVX2 (`run_avx2`) or AVX-512 (`run_avx512`), 8 lanes each.
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
    run_avx2 => { unsafe { run::<super::lanes::Avx2>(data, n, &mut super::lanes::DynIter(rays), out) } }
    // AVX2's 8 lanes with AVX-512's encoding, 32 registers and unsigned conversion: where
    // 512-bit operations run as two halves (AMD Zen 4), 16 lanes measured slower (AP view 1.34x
    // the per-ray loop against 1.43x, lateral 1.49x against 1.81x, an earlier version of this
    // kernel), and AVX-512 gathers of the pairs slower still (AP 0.87x).
    run_avx512 => {
        unsafe { run::<super::lanes::Avx2Vl>(data, n, &mut super::lanes::DynIter(rays), out) }
    }
}

/// [`run`] on 16 lanes, compiled for AVX-512 ([`super::MarchLanes::Sixteen`]). On AMD Zen 5,
/// whose 512-bit units are full width, gathers of the pairs (two 8-pair gathers and two
/// permutes per row) were slower than the 64-bit loads (lateral view 0.056 against 0.050 s).
///
/// # Safety
/// As [`run`], on a CPU with AVX-512 F/BW/DQ/VL.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,fma")]
pub(crate) unsafe fn run_avx512_16(
    data: &[f32],
    n: [usize; 3],
    rays: &mut dyn Iterator<Item = (usize, March)>,
    out: &mut [f32],
) {
    // SAFETY: as this function.
    unsafe { run::<super::lanes::Avx512>(data, n, &mut super::lanes::DynIter(rays), out) }
}
