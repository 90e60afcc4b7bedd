//! The trilinear ray-march's zero-padded samples ([`super::trilinear::sum_padded`]) over vector
//! lanes: one run of a ray's samples per lane; 4 lanes with AVX2 (f64 positions in 256-bit
//! vectors, f32 weights and values in 128-bit ones), 8 with AVX-512 (512-bit and 256-bit),
//! which the AVX-512 path runs with the 16-lane march ([`super::MarchLanes::Sixteen`]; with 8
//! march lanes it keeps the 4 lanes).
//!
//! These are the samples within half a voxel of the box faces on either side (some corner is
//! outside the grid): about 2 % of a CT view's samples, but about a sixth of its time in the
//! per-ray loop (rays leaving through a face at a grazing angle spend dozens of samples there,
//! each with its own floor, weights and eight reads).
//!
//! Each lane computes the per-ray loop's IEEE operations in its order, so the same bits: the
//! position `q0 + i dq` in f64 (`i` counted in f64, exact), the range test, `floor` (the
//! rounding instruction: exact, and -0.0 stays -0.0, as [`crate::math::round::floor`]), the
//! fraction rounded to f32, the weights `1 - f` and `f` (0 for a neighbour outside the grid,
//! whose index is clamped into it), the eight products `((w_x w_y) w_z) value` added in corner
//! order from +0, a sample outside the padded box giving +0, and the sample added to the
//! lane's sum. The eight values are read with gathers (on AMD Zen 4 a gather is slow, but here
//! it replaces eight scalar reads, their index extraction and their inserts).

use super::lanes::{hand_over, start_lanes, RayLanes};
use super::trilinear::Run;

/// The lanes' runs: positions, sample index (f64), samples left, sum, and where it goes.
struct RunLanes<const W: usize> {
    q0: [[f64; W]; 3],
    dq: [[f64; W]; 3],
    fi: [f64; W],
    left: [i32; W],
    acc: [f32; W],
    slot: [usize; W],
}

impl<const W: usize> RunLanes<W> {
    fn new() -> Self {
        RunLanes {
            q0: [[0.0; W]; 3],
            dq: [[0.0; W]; 3],
            fi: [0.0; W],
            left: [0; W],
            acc: [0.0; W],
            slot: [0; W],
        }
    }
}

impl<const W: usize> RayLanes for RunLanes<W> {
    type Ray = Run;

    /// (The run has samples: `first <= last`.) An idle lane needs no parking: its count of
    /// samples left stays below 1, so it neither adds nor ends.
    fn start(&mut self, k: usize, slot: usize, r: Run) {
        for a in 0..3 {
            self.q0[a][k] = r.q0[a];
            self.dq[a][k] = r.dq[a];
        }
        self.fi[k] = r.first as f64;
        self.left[k] = (r.last - r.first + 1) as i32;
        self.acc[k] = r.acc;
        self.slot[k] = slot;
    }

    fn result(&self, k: usize) -> (usize, f32) {
        (self.slot[k], self.acc[k])
    }
}

/// Each run of `runs` (`(slot, run)`) added to its `acc`, its samples in order, into
/// `out[slot]` (4 lanes).
///
/// # Safety
/// The CPU supports AVX2 (the caller is compiled with it); `data` is the `n`-voxel grid (x
/// fastest) with `n[0] n[1] n[2] < 2^31` and `n[a] >= 1`; every run has from 1 to 2^31 - 1
/// samples, all of index below 2^53 in magnitude; every slot is in `out`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn sum_runs(data: &[f32], n: [usize; 3], runs: &[(usize, Run)], out: &mut [f32]) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's contract (AVX2); every read index is clamped into the grid.
    unsafe {
        debug_assert!(data.len() == n[0] * n[1] * n[2] && data.len() < 1 << 31);
        const W: usize = 4;
        let upper = n.map(|v| _mm256_set1_pd(v as f64));
        let last = n.map(|v| _mm_set1_epi32(v as i32 - 1));
        let (nx, nxy) = (
            _mm_set1_epi32(n[0] as i32),
            _mm_set1_epi32((n[0] * n[1]) as i32),
        );
        let (minus1, one_d) = (_mm256_set1_pd(-1.0), _mm256_set1_pd(1.0));
        let (zero_i, one_i, one_f) = (_mm_setzero_si128(), _mm_set1_epi32(1), _mm_set1_ps(1.0));
        let mut s = RunLanes::<W>::new();
        let runs = &mut runs.iter().copied();
        let mut active = start_lanes(&mut s, W, runs);
        while active != 0 {
            let load_d = |v: &[f64; W]| _mm256_loadu_pd(v.as_ptr());
            let vq0 = [load_d(&s.q0[0]), load_d(&s.q0[1]), load_d(&s.q0[2])];
            let vdq = [load_d(&s.dq[0]), load_d(&s.dq[1]), load_d(&s.dq[2])];
            let mut vfi = load_d(&s.fi);
            let mut vleft = _mm_loadu_si128(s.left.as_ptr().cast());
            let mut vacc = _mm_loadu_ps(s.acc.as_ptr());
            let done = loop {
                // Per axis: in range (-1 < q < n), the neighbours' clamped indices and weights.
                let mut inside = _mm_set1_epi32(-1);
                let mut at = [[zero_i; 2]; 3];
                let mut wt = [[_mm_setzero_ps(); 2]; 3];
                for a in 0..3 {
                    let q = _mm256_add_pd(vq0[a], _mm256_mul_pd(vfi, vdq[a]));
                    let ok = _mm256_and_pd(
                        _mm256_cmp_pd::<_CMP_GT_OQ>(q, minus1),
                        _mm256_cmp_pd::<_CMP_LT_OQ>(q, upper[a]),
                    );
                    // The low 32 bits of each 64-bit lane mask, as a 4 x 32-bit mask.
                    let ok = _mm_castps_si128(_mm_shuffle_ps::<0x88>(
                        _mm256_castps256_ps128(_mm256_castpd_ps(ok)),
                        _mm256_extractf128_ps::<1>(_mm256_castpd_ps(ok)),
                    ));
                    inside = _mm_and_si128(inside, ok);
                    let fl = _mm256_floor_pd(q);
                    let f = _mm256_cvtpd_ps(_mm256_sub_pd(q, fl));
                    // In [-1, n - 1] for a sample in range (anything clamps for the others).
                    let i = _mm256_cvttpd_epi32(fl);
                    let clamp = |v| _mm_max_epi32(_mm_min_epi32(v, last[a]), zero_i);
                    at[a] = [clamp(i), clamp(_mm_add_epi32(i, one_i))];
                    let lower_in = _mm_cmpgt_epi32(i, _mm_set1_epi32(-1));
                    let upper_in = _mm_cmpgt_epi32(last[a], i);
                    wt[a] = [
                        _mm_and_ps(_mm_castsi128_ps(lower_in), _mm_sub_ps(one_f, f)),
                        _mm_and_ps(_mm_castsi128_ps(upper_in), f),
                    ];
                }
                // (Hoisting the row offsets and the products w_x w_y out of the corner loop
                // measured slower: AP view 0.049 -> 0.051 s.)
                let mut sample = _mm_setzero_ps();
                for uz in 0..2 {
                    for uy in 0..2 {
                        let row = _mm_add_epi32(
                            _mm_mullo_epi32(at[1][uy], nx),
                            _mm_mullo_epi32(at[2][uz], nxy),
                        );
                        for ux in 0..2 {
                            let w = _mm_mul_ps(_mm_mul_ps(wt[0][ux], wt[1][uy]), wt[2][uz]);
                            let v =
                                _mm_i32gather_ps::<4>(data.as_ptr(), _mm_add_epi32(at[0][ux], row));
                            sample = _mm_add_ps(sample, _mm_mul_ps(w, v));
                        }
                    }
                }
                // A sample outside the padded box is +0.
                let sample = _mm_and_ps(_mm_castsi128_ps(inside), sample);
                let running = _mm_cmpgt_epi32(vleft, zero_i);
                vacc = _mm_blendv_ps(vacc, _mm_add_ps(vacc, sample), _mm_castsi128_ps(running));
                vfi = _mm256_add_pd(vfi, one_d);
                vleft = _mm_sub_epi32(vleft, one_i);
                let ended = _mm_and_si128(running, _mm_cmpeq_epi32(vleft, zero_i));
                let bits = _mm_movemask_ps(_mm_castsi128_ps(ended)) as u32;
                if bits != 0 {
                    break bits;
                }
            };
            _mm256_storeu_pd(s.fi.as_mut_ptr(), vfi);
            _mm_storeu_si128(s.left.as_mut_ptr().cast(), vleft);
            _mm_storeu_ps(s.acc.as_mut_ptr(), vacc);
            active = hand_over(&mut s, active, done, runs, out);
        }
    }
}

/// [`sum_runs`] on 8 lanes with AVX-512 (F, DQ, VL): the same operations per lane, the range
/// tests as lane masks.
///
/// # Safety
/// As [`sum_runs`], with AVX-512 F/DQ/VL.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn sum_runs_8(data: &[f32], n: [usize; 3], runs: &[(usize, Run)], out: &mut [f32]) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's contract (AVX-512); every read index is clamped into the grid.
    unsafe {
        debug_assert!(data.len() == n[0] * n[1] * n[2] && data.len() < 1 << 31);
        const W: usize = 8;
        let upper = n.map(|v| _mm512_set1_pd(v as f64));
        let last = n.map(|v| _mm256_set1_epi32(v as i32 - 1));
        let (nx, nxy) = (
            _mm256_set1_epi32(n[0] as i32),
            _mm256_set1_epi32((n[0] * n[1]) as i32),
        );
        let (minus1, one_d) = (_mm512_set1_pd(-1.0), _mm512_set1_pd(1.0));
        let (zero_i, one_i, one_f) = (
            _mm256_setzero_si256(),
            _mm256_set1_epi32(1),
            _mm256_set1_ps(1.0),
        );
        let mut s = RunLanes::<W>::new();
        let runs = &mut runs.iter().copied();
        let mut active = start_lanes(&mut s, W, runs);
        while active != 0 {
            let load_d = |v: &[f64; W]| _mm512_loadu_pd(v.as_ptr());
            let vq0 = [load_d(&s.q0[0]), load_d(&s.q0[1]), load_d(&s.q0[2])];
            let vdq = [load_d(&s.dq[0]), load_d(&s.dq[1]), load_d(&s.dq[2])];
            let mut vfi = load_d(&s.fi);
            let mut vleft = _mm256_loadu_si256(s.left.as_ptr().cast());
            let mut vacc = _mm256_loadu_ps(s.acc.as_ptr());
            let done = loop {
                let mut inside: __mmask8 = 0xff;
                let mut at = [[zero_i; 2]; 3];
                let mut wt = [[_mm256_setzero_ps(); 2]; 3];
                for a in 0..3 {
                    let q = _mm512_add_pd(vq0[a], _mm512_mul_pd(vfi, vdq[a]));
                    inside &= _mm512_cmp_pd_mask::<_CMP_GT_OQ>(q, minus1)
                        & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(q, upper[a]);
                    // Round toward -inf, no scaling: floor.
                    let fl =
                        _mm512_roundscale_pd::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(q);
                    let f = _mm512_cvtpd_ps(_mm512_sub_pd(q, fl));
                    let i = _mm512_cvttpd_epi32(fl);
                    let clamp = |v| _mm256_max_epi32(_mm256_min_epi32(v, last[a]), zero_i);
                    at[a] = [clamp(i), clamp(_mm256_add_epi32(i, one_i))];
                    let lower_in = _mm256_cmpgt_epi32(i, _mm256_set1_epi32(-1));
                    let upper_in = _mm256_cmpgt_epi32(last[a], i);
                    wt[a] = [
                        _mm256_and_ps(_mm256_castsi256_ps(lower_in), _mm256_sub_ps(one_f, f)),
                        _mm256_and_ps(_mm256_castsi256_ps(upper_in), f),
                    ];
                }
                let mut sample = _mm256_setzero_ps();
                for uz in 0..2 {
                    for uy in 0..2 {
                        let row = _mm256_add_epi32(
                            _mm256_mullo_epi32(at[1][uy], nx),
                            _mm256_mullo_epi32(at[2][uz], nxy),
                        );
                        for ux in 0..2 {
                            let w = _mm256_mul_ps(_mm256_mul_ps(wt[0][ux], wt[1][uy]), wt[2][uz]);
                            let v = _mm256_i32gather_ps::<4>(
                                data.as_ptr(),
                                _mm256_add_epi32(at[0][ux], row),
                            );
                            sample = _mm256_add_ps(sample, _mm256_mul_ps(w, v));
                        }
                    }
                }
                // A sample outside the padded box is +0.
                let sample = _mm256_maskz_mov_ps(inside, sample);
                let running = _mm256_cmpgt_epi32(vleft, zero_i);
                vacc = _mm256_blendv_ps(
                    vacc,
                    _mm256_add_ps(vacc, sample),
                    _mm256_castsi256_ps(running),
                );
                vfi = _mm512_add_pd(vfi, one_d);
                vleft = _mm256_sub_epi32(vleft, one_i);
                let ended = _mm256_and_si256(running, _mm256_cmpeq_epi32(vleft, zero_i));
                let bits = _mm256_movemask_ps(_mm256_castsi256_ps(ended)) as u32;
                if bits != 0 {
                    break bits;
                }
            };
            _mm512_storeu_pd(s.fi.as_mut_ptr(), vfi);
            _mm256_storeu_si256(s.left.as_mut_ptr().cast(), vleft);
            _mm256_storeu_ps(s.acc.as_mut_ptr(), vacc);
            active = hand_over(&mut s, active, done, runs, out);
        }
    }
}

crate::simd::wide_kernels! {
    /// [`sum_runs`] compiled for AVX2 (`sum_runs_avx2`, 4 lanes) or [`sum_runs_8`] for AVX-512
    /// (`sum_runs_avx512`, 8 lanes).
    ///
    /// # Safety
    /// As [`sum_runs`], on a CPU with the instruction set.
    pub(crate) unsafe fn [](data: &[f32], n: [usize; 3], runs: &[(usize, Run)], out: &mut [f32]);
    // SAFETY (both): as this function.
    sum_runs_avx2 => { unsafe { sum_runs(data, n, runs, out) } }
    sum_runs_avx512 => { unsafe { sum_runs_8(data, n, runs, out) } }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::super::grid::Grid;
    use super::super::trilinear::{sum_padded, Run};
    use crate::simd::Simd;
    use rand::{RngExt, SeedableRng};

    /// Runs of random lengths (empty ones too) through random grids (1-voxel axes, values of
    /// both signs, zeros of both signs, tiny ones), from outside the padded box to inside the grid,
    /// against the per-ray sum, bit for bit, on every vector path.
    #[test]
    fn lanes_sum_the_runs_as_the_per_ray_loop() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for case in 0..300 {
            let (n, data) = super::super::grid::random_values::<f32>(&mut rng, 5);
            let grid = Grid::unit(&data, n);
            let runs: Vec<Run> = (0..rng.random_range(0..12))
                .map(|_| {
                    let first = rng.random_range(-40..40i64);
                    Run {
                        q0: n.map(|v| rng.random_range(-2.0..v as f64 + 1.0)),
                        dq: [0; 3].map(|_| rng.random_range(-0.2..0.2)),
                        first,
                        last: first + rng.random_range(-2..30),
                        acc: rng.random_range(-5.0..5.0),
                    }
                })
                .collect();
            let want: Vec<u32> = runs
                .iter()
                .map(|r| sum_padded(&grid, r.q0, r.dq, (r.first, r.last), r.acc).to_bits())
                .collect();
            for simd in [Simd::Avx2, Simd::Avx512] {
                if !simd.supported() {
                    continue;
                }
                // The lanes take the runs that have samples; the empty ones keep their sum.
                let mut got: Vec<f32> = runs.iter().map(|r| r.acc).collect();
                let lane_runs: Vec<(usize, Run)> = runs
                    .iter()
                    .copied()
                    .enumerate()
                    .filter(|(_, r)| r.first <= r.last)
                    .collect();
                // SAFETY: the path is supported; the grid is small; the runs are short and not
                // empty; the slots index `got`.
                unsafe {
                    match simd {
                        Simd::Avx512 => super::sum_runs_avx512(&data, n, &lane_runs, &mut got),
                        _ => super::sum_runs_avx2(&data, n, &lane_runs, &mut got),
                    }
                }
                let got: Vec<u32> = got.iter().map(|v| v.to_bits()).collect();
                assert_eq!(got, want, "case {case} {simd:?}");
            }
        }
    }
}
