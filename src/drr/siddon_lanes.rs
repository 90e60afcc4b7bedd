//! Siddon's walk ([`super::siddon`]) over vector lanes, one ray per lane (f32 volumes).
//!
//! Each lane runs the per-ray loop of [`super::siddon::integrate`] step for step: pick the axis
//! of the nearest boundary crossing with the same comparisons (`tm[0] <= tm[1]`, ...), add
//! `(tn - t) x v` to the lane's sum, advance that axis. The set-up is the per-ray f64 code
//! ([`super::siddon::start`]). So a lane's sum is the scalar sum, bit for bit. A lane whose ray
//! has left the box hands its sum to the image and takes the next ray of the band (rays in tile
//! order, so the lanes walk neighbouring rays through the same cache lines).

use super::lanes::{hand_over, start_lanes, Lanes, RayLanes, MAXW};
use super::siddon::Walk;

/// The per-lane state, as arrays the vectors are loaded from and stored to when a lane changes
/// ray.
struct State {
    tm: [[f32; MAXW]; 3],
    dt: [[f32; MAXW]; 3],
    left: [[i32; MAXW]; 3],
    step: [[i32; MAXW]; 3],
    idx: [i32; MAXW],
    t: [f32; MAXW],
    acc: [f32; MAXW],
    slot: [usize; MAXW],
}

impl State {
    fn new() -> Self {
        State {
            tm: [[0.0; MAXW]; 3],
            dt: [[0.0; MAXW]; 3],
            left: [[1; MAXW]; 3],
            step: [[0; MAXW]; 3],
            idx: [0; MAXW],
            t: [0.0; MAXW],
            acc: [0.0; MAXW],
            slot: [0; MAXW],
        }
    }
}

impl RayLanes for State {
    type Ray = Walk<f32>;

    fn start(&mut self, k: usize, slot: usize, w: Walk<f32>) {
        for a in 0..3 {
            self.tm[a][k] = w.tm[a];
            self.dt[a][k] = w.dt[a];
            // Counts are at most the voxels per axis (< 2^31, checked by the caller); an axis the
            // ray is parallel to is never picked (its `tm` is +inf and another axis's is finite).
            self.left[a][k] = w.left[a].min(i32::MAX as i64) as i32;
            self.step[a][k] = w.step[a] as i32;
        }
        self.idx[k] = w.idx as i32;
        self.t[k] = 0.0;
        self.acc[k] = 0.0;
        self.slot[k] = slot;
    }

    fn result(&self, k: usize) -> (usize, f32) {
        (self.slot[k], self.acc[k])
    }
}

/// Walk every ray of `rays` (`(slot, walk)`), writing each sum to `out[slot]`.
///
/// # Safety
/// The CPU supports `L`'s instruction set (the caller is compiled with it); `data` has fewer
/// than 2^31 values; every walk is one of [`super::siddon::start`] on a grid whose values are
/// `data` (so every index it visits is in bounds); every slot is in `out`.
#[inline(always)]
pub(crate) unsafe fn run<L: Lanes>(
    data: &[f32],
    rays: &mut impl Iterator<Item = (usize, Walk<f32>)>,
    out: &mut [f32],
) {
    // SAFETY: the caller's contract.
    unsafe {
        let w = L::W;
        debug_assert!(w <= MAXW && data.len() < (1usize << 31));
        let mut s = State::new();
        let mut active = start_lanes(&mut s, w, rays);
        let zero = L::splat_i(0);
        let minus1 = L::splat_i(-1);
        while active != 0 {
            let [mut tm0, mut tm1, mut tm2] = L::load3_f(&s.tm);
            let [dt0, dt1, dt2] = L::load3_f(&s.dt);
            let [mut l0, mut l1, mut l2] = L::load3_i(&s.left);
            let [st0, st1, st2] = L::load3_i(&s.step);
            let mut idx = L::load_i(&s.idx);
            let mut t = L::load_f(&s.t);
            let mut acc = L::load_f(&s.acc);
            let mut act = L::mask_from_bits(active);
            let done = loop {
                // The axis of the nearest crossing, as the scalar loop picks it: 0 if tm0 <= tm1
                // and tm0 <= tm2, else 1 if tm1 <= tm2, else 2.
                let m01 = L::le(tm0, tm1);
                let s0 = L::and(m01, L::le(tm0, tm2));
                let s1 = L::andnot(m01, L::le(tm1, tm2));
                let tn = L::sel_f(s0, tm0, L::sel_f(s1, tm1, tm2));
                // SAFETY: the lanes of `act` walk inside the grid (the caller's contract).
                let v = L::gather(act, idx, data);
                acc = L::sel_f(act, L::add(acc, L::mul(L::sub(tn, t), v)), acc);
                t = tn;
                let l = L::add_i(L::sel_i(s0, l0, L::sel_i(s1, l1, l2)), minus1);
                l0 = L::sel_i(s0, l, l0);
                l1 = L::sel_i(s1, l, l1);
                l2 = L::sel_i(s0, l2, L::sel_i(s1, l2, l));
                let fin = L::and(act, L::eq_i(l, zero));
                act = L::andnot(fin, act);
                tm0 = L::sel_f(s0, L::add(tm0, dt0), tm0);
                tm1 = L::sel_f(s1, L::add(tm1, dt1), tm1);
                tm2 = L::sel_f(s0, tm2, L::sel_f(s1, tm2, L::add(tm2, dt2)));
                idx = L::add_i(idx, L::sel_i(s0, st0, L::sel_i(s1, st1, st2)));
                let fb = L::mask_bits(fin);
                if fb != 0 {
                    break fb;
                }
            };
            L::store_f(tm0, &mut s.tm[0]);
            L::store_f(tm1, &mut s.tm[1]);
            L::store_f(tm2, &mut s.tm[2]);
            L::store_i(l0, &mut s.left[0]);
            L::store_i(l1, &mut s.left[1]);
            L::store_i(l2, &mut s.left[2]);
            L::store_i(idx, &mut s.idx);
            L::store_f(t, &mut s.t);
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
        rays: &mut dyn Iterator<Item = (usize, Walk<f32>)>,
        out: &mut [f32],
    );
    // SAFETY (both): as this function.
    run_avx2 => { unsafe { run::<super::lanes::Avx2>(data, &mut super::lanes::DynIter(rays), out) } }
    run_avx512 => { unsafe { run::<super::lanes::Avx512>(data, &mut super::lanes::DynIter(rays), out) } }
}
