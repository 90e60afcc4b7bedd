//! Frequency (NeRF positional) encoding as SAX-NeRF / NAF `src/encoder/freqencoder.py` with
//! `multires` bands: `[x, sin(2^0 x), cos(2^0 x), ..., sin(2^(B-1) x), cos(2^(B-1) x)]`, each
//! block 3-wide, `3 + 6 B` values. The input is the raw world coordinate in metres (the
//! `bound` argument is ignored upstream). No parameters, so no backward pass.

use crate::real::Real;

/// `bands` frequencies `2^0 .. 2^(bands-1)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Frequency {
    pub bands: usize,
}

impl Frequency {
    /// Output width.
    pub fn out_dim(&self) -> usize {
        3 + 6 * self.bands
    }

    /// Encode one point into `out` (`out_dim` values).
    pub fn encode<R: Real>(&self, x: [R; 3], out: &mut [R]) {
        out[..3].copy_from_slice(&x);
        for k in 0..self.bands {
            let f = R::c((1u64 << k) as f64);
            let o = 3 + 6 * k;
            for d in 0..3 {
                let (s, c) = (x[d] * f).sin_cos();
                out[o + d] = s;
                out[o + 3 + d] = c;
            }
        }
    }
}

impl Frequency {
    /// `d (g . encode(x)) / d x`: `g_x + sum_k 2^k (g_sin cos(2^k x) - g_cos sin(2^k x))`.
    pub fn input_vjp<R: Real>(&self, x: [R; 3], g: &[R]) -> [R; 3] {
        let mut out = [g[0], g[1], g[2]];
        for k in 0..self.bands {
            let f = R::c((1u64 << k) as f64);
            let o = 3 + 6 * k;
            for d in 0..3 {
                let (s, c) = (x[d] * f).sin_cos();
                out[d] += f * (g[o + d] * c - g[o + 3 + d] * s);
            }
        }
        out
    }
}
