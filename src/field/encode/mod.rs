//! Point encoders of the neural attenuation fields: frequency (IntraTomo, NeRF), the
//! multiresolution hash grid (NAF), TensoRF's vector-matrix decomposition and a dense grid (the
//! test oracle of the two grid encoders). Each maps a point in metres to a feature vector; all
//! but the frequency encoding have parameters and a backward pass. `input_vjp` gives the
//! gradient with respect to the point (an audit quantity: upstream never differentiates the
//! sample positions).

pub mod dense_grid;
pub mod frequency;
pub mod hash_grid;
pub mod tensor_vm;

pub use dense_grid::{DenseGrid, GridMap};
pub use frequency::Frequency;
pub use hash_grid::HashGrid;
pub use tensor_vm::{TensorVm, VmLines};

use crate::real::Real;
use crate::simd::Simd;

/// An encoder.
#[derive(Clone, Debug, PartialEq)]
pub enum Encoder {
    Frequency(Frequency),
    HashGrid(HashGrid),
    TensorVm(TensorVm),
    DenseGrid(DenseGrid),
}

impl Encoder {
    /// Output width.
    pub fn out_dim(&self) -> usize {
        match self {
            Encoder::Frequency(f) => f.out_dim(),
            Encoder::HashGrid(h) => h.out_dim(),
            Encoder::TensorVm(v) => v.out_dim(),
            Encoder::DenseGrid(d) => d.out_dim(),
        }
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        match self {
            Encoder::Frequency(_) => 0,
            Encoder::HashGrid(h) => h.n_params(),
            Encoder::TensorVm(v) => v.n_params(),
            Encoder::DenseGrid(d) => d.n_params(),
        }
    }

    /// Encode one point.
    #[inline]
    pub fn encode<R: Real>(&self, params: &[R], x: [R; 3], out: &mut [R]) {
        match self {
            Encoder::Frequency(f) => f.encode(x, out),
            Encoder::HashGrid(h) => h.encode(params, x, out),
            Encoder::TensorVm(v) => v.encode(params, x, out),
            Encoder::DenseGrid(d) => d.encode(params, x, out),
        }
    }

    /// Encode a block of points (`out`: [`Encoder::out_dim`] values per point), as
    /// [`Encoder::encode`] point by point (the hash grid runs level by level, TensoRF's basis as
    /// one matrix product; same values).
    pub fn encode_block<R: Real>(&self, simd: Simd, params: &[R], xs: &[[R; 3]], out: &mut [R]) {
        match self {
            Encoder::HashGrid(h) => h.encode_block(simd, params, xs, out),
            Encoder::TensorVm(v) => v.encode_block(simd, params, xs, out),
            _ => {
                let e = self.out_dim();
                for (p, o) in xs.iter().zip(out.chunks_mut(e)) {
                    self.encode(params, *p, o);
                }
            }
        }
    }

    /// Accumulate the parameter gradient of `sum_n g_n . encode(x_n)`, with
    /// `g_out[n * g_stride + g_off ..]` the gradient of point `n`'s encoding (see
    /// [`HashGrid::backward`]); nothing for encoders without parameters. Bit-identical for any
    /// thread count.
    #[allow(clippy::too_many_arguments)]
    pub fn backward<R: Real>(
        &self,
        simd: Simd,
        params: &[R],
        xs: &[[R; 3]],
        g_out: &[R],
        g_stride: usize,
        g_off: usize,
        grad: &mut [R],
    ) {
        match self {
            Encoder::Frequency(_) => {}
            Encoder::HashGrid(h) => h.backward(simd, xs, g_out, g_stride, g_off, grad),
            Encoder::TensorVm(v) => v.backward(simd, params, xs, g_out, g_stride, g_off, grad),
            Encoder::DenseGrid(d) => d.backward(xs, g_out, g_stride, g_off, grad),
        }
    }

    /// `d (g . encode(x)) / d x` for one point.
    pub fn input_vjp<R: Real>(&self, params: &[R], x: [R; 3], g: &[R]) -> [R; 3] {
        match self {
            Encoder::Frequency(f) => f.input_vjp(x, g),
            Encoder::HashGrid(h) => hash_input_vjp(h, params, x, g),
            Encoder::TensorVm(v) => v.input_vjp(params, x, g),
            Encoder::DenseGrid(d) => d.input_vjp(params, x, g),
        }
    }
}

/// `d (g . encode(x)) / d x` of the hash grid: per level, the trilinear weights' derivative at
/// the level's position `u (R - 1) + 1/2` (the same arithmetic as [`HashGrid::corners`]).
pub fn hash_input_vjp<R: Real>(h: &HashGrid, table: &[R], x: [R; 3], g: &[R]) -> [R; 3] {
    let nf = h.features;
    let b = R::c(h.bound);
    let mut out = [R::zero(); 3];
    for l in 0..h.levels {
        let (idx, _) = h.corners(x, l);
        let scale = R::c((h.base << l) as f64 - 1.0);
        let mut f = [R::zero(); 3];
        for d in 0..3 {
            let p = (x[d] + b) / (b + b) * scale + R::c(0.5);
            f[d] = p - p.floor();
        }
        let mut vals = [R::zero(); 8];
        for c in 0..8 {
            for ch in 0..nf {
                vals[c] += g[l * nf + ch] * table[(h.offsets[l] + idx[c]) * nf + ch];
            }
        }
        let dp = scale / (b + b);
        let gl = dense_grid::trilinear_grad(&vals, f, [dp; 3]);
        for d in 0..3 {
            out[d] += gl[d];
        }
    }
    out
}
