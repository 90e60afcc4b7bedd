//! Point encoders of the neural attenuation fields: frequency (IntraTomo, NeRF) and the
//! multiresolution hash grid (NAF). Each maps a point in metres to a feature vector; the hash
//! grid has parameters and a backward pass.

pub mod frequency;
pub mod hash_grid;

pub use frequency::Frequency;
pub use hash_grid::HashGrid;

use crate::real::Real;

/// An encoder.
#[derive(Clone, Debug, PartialEq)]
pub enum Encoder {
    Frequency(Frequency),
    HashGrid(HashGrid),
}

impl Encoder {
    /// Output width.
    pub fn out_dim(&self) -> usize {
        match self {
            Encoder::Frequency(f) => f.out_dim(),
            Encoder::HashGrid(h) => h.out_dim(),
        }
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        match self {
            Encoder::Frequency(_) => 0,
            Encoder::HashGrid(h) => h.n_params(),
        }
    }

    /// Encode one point.
    #[inline]
    pub fn encode<R: Real>(&self, params: &[R], x: [R; 3], out: &mut [R]) {
        match self {
            Encoder::Frequency(f) => f.encode(x, out),
            Encoder::HashGrid(h) => h.encode(params, x, out),
        }
    }

    /// Accumulate the parameter gradient (see [`HashGrid::backward`]); nothing for encoders
    /// without parameters.
    pub fn backward<R: Real>(
        &self,
        xs: &[[R; 3]],
        g_out: &[R],
        g_stride: usize,
        g_off: usize,
        grad: &mut [R],
    ) {
        if let Encoder::HashGrid(h) = self {
            h.backward(xs, g_out, g_stride, g_off, grad);
        }
    }
}
