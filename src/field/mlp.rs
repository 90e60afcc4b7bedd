//! The density MLP of NAF / SAX-NeRF (`src/network/network.py` `DensityNetwork`): `layers`
//! linear layers, LeakyReLU (slope 0.01) after every hidden layer, a chosen output activation;
//! layer `i` in `skips` takes `cat([encoding, h])`. PyTorch's default `nn.Linear` init
//! (weights and biases U(-1/sqrt(fan_in), 1/sqrt(fan_in))).
//!
//! Batched: a block of samples goes through each layer as a matrix product ([`gemm`]: blocked,
//! register-tiled, AVX-512, AVX2 or scalar with the same bits) in which every sum runs in a
//! fixed sequential order whatever the block, the instruction set and the thread count; the
//! LeakyReLU passes and bias-gradient sums between the products run on [`act`] (element-wise,
//! same bits on every path).
//!
//! Parameter layout (flat): for each layer, `W` as `[in][out]` (input-major) then `b[out]`.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::act::{self, Rows};
use super::gemm;
use crate::error::{Error, Result};
use crate::real::Real;
use crate::simd::Simd;

/// Output activation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutAct {
    /// `sigmoid` (upstream `last_activation: sigmoid`).
    Sigmoid,
    /// LeakyReLU 0.01 (upstream `last_activation: relu` builds `nn.LeakyReLU()`).
    LeakyRelu,
    /// softplus (not used upstream; offered for fields that must stay positive).
    Softplus,
}

/// LeakyReLU slope (PyTorch default).
pub const SLOPE: f64 = 0.01;

/// Shape of an MLP.
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    pub in_dim: usize,
    pub hidden: usize,
    /// Number of linear layers (upstream `num_layers`), >= 2.
    pub layers: usize,
    pub skips: Vec<usize>,
    pub out_act: OutAct,
    /// `(in, out, offset of W)` per layer.
    pub shape: Vec<(usize, usize, usize)>,
    pub n_params: usize,
}

impl Mlp {
    /// Check the settings (errors name them) and lay the parameters out.
    pub fn new(
        in_dim: usize,
        hidden: usize,
        layers: usize,
        skips: &[usize],
        out_act: OutAct,
    ) -> Result<Mlp> {
        if layers < 2 {
            return Err(Error::invalid(
                "num_layers",
                format!("must be >= 2 (one hidden and the output layer), got {layers}"),
            ));
        }
        if hidden == 0 {
            return Err(Error::invalid("hidden_dim", "must be > 0"));
        }
        for &s in skips {
            if s == 0 || s >= layers - 1 {
                return Err(Error::invalid(
                    "skips",
                    format!(
                        "skip layer {s} is not a hidden layer: skips must be in 1..={} for \
                         num_layers = {layers} (the last layer is the output layer)",
                        layers - 2
                    ),
                ));
            }
        }
        let mut shape = Vec::with_capacity(layers);
        let mut off = 0;
        for i in 0..layers {
            let inp = if i == 0 {
                in_dim
            } else if skips.contains(&i) {
                hidden + in_dim
            } else {
                hidden
            };
            let out = if i == layers - 1 { 1 } else { hidden };
            shape.push((inp, out, off));
            off += inp * out + out;
        }
        Ok(Mlp {
            in_dim,
            hidden,
            layers,
            skips: skips.to_vec(),
            out_act,
            shape,
            n_params: off,
        })
    }

    /// PyTorch-default initial parameters, seeded.
    pub fn init<R: Real>(&self, seed: u64) -> Vec<R> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut p = vec![R::zero(); self.n_params];
        for &(inp, out, off) in &self.shape {
            let b = 1.0 / (inp as f64).sqrt();
            for v in &mut p[off..off + inp * out + out] {
                *v = R::c(rng.random_range(-b..b));
            }
        }
        p
    }

    /// Forward over a block of `n` encodings `x` (`n x in_dim`, row-major). Returns the outputs
    /// and, when `keep`, the cache for [`Mlp::backward`] (a fresh workspace; the trainer reuses
    /// one through [`Mlp::forward_ws`]).
    pub fn forward<R: Real>(&self, p: &[R], x: &[R], n: usize, keep: bool) -> (Vec<R>, Cache<R>) {
        let mut cache = Cache::default();
        self.forward_ws(Simd::active(), p, x, n, &mut cache);
        let out = cache.out.clone();
        if !keep {
            cache = Cache::default();
        }
        (out, cache)
    }

    /// Forward into the workspace `ws` (buffers grown once and reused): afterwards
    /// `ws.out[..n]` holds the outputs and `ws` the cache of [`Mlp::backward_ws`]. The matrix
    /// products run on [`gemm`] with the instruction set `simd` (same bits on every path).
    pub fn forward_ws<R: Real>(&self, simd: Simd, p: &[R], x: &[R], n: usize, ws: &mut Cache<R>) {
        let slope = R::c(SLOPE);
        ws.inputs.resize_with(self.layers, Vec::new);
        ws.pre.resize_with(self.layers, Vec::new);
        let ed = self.in_dim;
        let hd = self.hidden;
        for (i, &(inp, out, off)) in self.shape.iter().enumerate() {
            let w = &p[off..off + inp * out];
            let b = &p[off + inp * out..off + inp * out + out];
            if i == 0 {
                fit(&mut ws.inputs[0], n * inp);
                ws.inputs[0].copy_from_slice(&x[..n * inp]);
            }
            fit(&mut ws.pre[i], n * out);
            gemm::forward(simd, &ws.inputs[i], w, b, n, inp, out, &mut ws.pre[i]);
            if i == self.layers - 1 {
                fit(&mut ws.out, n);
                for (y, &z) in ws.out.iter_mut().zip(&ws.pre[i]) {
                    *y = out_act(self.out_act, z);
                }
                break;
            }
            // The next layer's input: [encoding, h] for a skip layer, else h.
            let skip = self.skips.contains(&(i + 1));
            let (enc, next_in) = if skip { (ed, ed + hd) } else { (0, hd) };
            let (pre, inputs) = (&ws.pre[i], &mut ws.inputs[i + 1]);
            fit(inputs, n * next_in);
            if skip {
                for r in 0..n {
                    inputs[r * next_in..r * next_in + enc]
                        .copy_from_slice(&x[r * ed..(r + 1) * ed]);
                }
            }
            let dense = Rows { ld: hd, off: 0 };
            let dst = Rows {
                ld: next_in,
                off: enc,
            };
            act::leaky(simd, pre, dense, pre, n, hd, slope, inputs, dst);
        }
    }

    /// Backward of a block (`cache` from [`Mlp::forward`] with `keep`): `g_y` (n values) is
    /// dL/d(output). Accumulates the parameter
    /// gradient into `grad` and, when `g_x` is given, writes dL/d(encoding) (`n x in_dim`).
    pub fn backward<R: Real>(
        &self,
        p: &[R],
        cache: &Cache<R>,
        g_y: &[R],
        n: usize,
        grad: &mut [R],
        g_x: Option<&mut [R]>,
    ) {
        let mut ws = Cache {
            inputs: cache.inputs.clone(),
            pre: cache.pre.clone(),
            out: cache.out.clone(),
            ..Cache::default()
        };
        self.backward_ws(Simd::active(), p, &mut ws, g_y, n, grad, g_x);
    }

    /// [`Mlp::backward`] on the workspace filled by [`Mlp::forward_ws`] (its scratch buffers
    /// are reused): `dW += X^T dY`, `db += 1^T dY` and `dX = dY W^T` per layer on [`gemm`].
    #[allow(clippy::too_many_arguments)]
    pub fn backward_ws<R: Real>(
        &self,
        simd: Simd,
        p: &[R],
        ws: &mut Cache<R>,
        g_y: &[R],
        n: usize,
        grad: &mut [R],
        mut g_x: Option<&mut [R]>,
    ) {
        let slope = R::c(SLOPE);
        let last = self.layers - 1;
        fit(&mut ws.g, n);
        for (r, g) in ws.g.iter_mut().enumerate() {
            *g = g_y[r] * out_act_grad(self.out_act, ws.pre[last][r], ws.out[r]);
        }
        if let Some(gx) = g_x.as_deref_mut() {
            gx[..n * self.in_dim]
                .iter_mut()
                .for_each(|v| *v = R::zero());
        }
        for i in (0..self.layers).rev() {
            let (inp, out, off) = self.shape[i];
            {
                let (gw, gb) = grad[off..off + inp * out + out].split_at_mut(inp * out);
                gemm::grad_weight(simd, &ws.inputs[i], &ws.g, n, inp, out, gw, gb);
            }
            let need_dx = i > 0 || g_x.is_some();
            if !need_dx {
                break;
            }
            let w = &p[off..off + inp * out];
            fit(&mut ws.wt, inp * out);
            gemm::transpose(w, inp, out, &mut ws.wt);
            fit(&mut ws.dx, n * inp);
            gemm::grad_input(simd, &ws.g, &ws.wt, n, inp, out, &mut ws.dx);
            let dx = &ws.dx;
            // Route dX: the encoding part of a skip input (or of layer 0) to g_x, the hidden
            // part through the previous layer's LeakyReLU.
            if i == 0 {
                if let Some(gx) = g_x.as_deref_mut() {
                    for (a, &b) in gx.iter_mut().zip(&dx[..n * inp]) {
                        *a += b;
                    }
                }
                break;
            }
            let skip = self.skips.contains(&i);
            let (enc, hid) = if skip {
                (self.in_dim, self.hidden)
            } else {
                (0, self.hidden)
            };
            if skip {
                if let Some(gx) = g_x.as_deref_mut() {
                    for r in 0..n {
                        for k in 0..enc {
                            gx[r * self.in_dim + k] += dx[r * inp + k];
                        }
                    }
                }
            }
            let zprev = &ws.pre[i - 1];
            fit(&mut ws.g_next, n * hid);
            let src = Rows { ld: inp, off: enc };
            let dense = Rows { ld: hid, off: 0 };
            act::leaky(simd, dx, src, zprev, n, hid, slope, &mut ws.g_next, dense);
            std::mem::swap(&mut ws.g, &mut ws.g_next);
        }
    }
}

/// Resize `v` to `len` (allocates only when it grows past its capacity).
fn fit<R: Real>(v: &mut Vec<R>, len: usize) {
    v.resize(len, R::zero());
}

/// What [`Mlp::forward`] keeps for the backward pass (each layer's input and pre-activation,
/// and the outputs) and the backward pass's scratch buffers: the workspace of one block,
/// reused across blocks and iterations.
#[derive(Debug, Default)]
pub struct Cache<R> {
    pub inputs: Vec<Vec<R>>,
    pub pre: Vec<Vec<R>>,
    pub out: Vec<R>,
    /// dL/d(pre-activation) of the current layer, and of the previous one.
    g: Vec<R>,
    g_next: Vec<R>,
    /// `W^T` of the current layer and `dX`.
    wt: Vec<R>,
    dx: Vec<R>,
}

/// Output activation.
#[inline]
pub fn out_act<R: Real>(a: OutAct, v: R) -> R {
    match a {
        OutAct::Sigmoid => R::one() / (R::one() + (-v).exp()),
        OutAct::LeakyRelu => {
            if v > R::zero() {
                v
            } else {
                v * R::c(SLOPE)
            }
        }
        OutAct::Softplus => {
            // log(1 + e^v), stable for large |v|.
            if v > R::c(20.0) {
                v
            } else {
                v.exp().ln_1p()
            }
        }
    }
}

/// Derivative of the output activation at pre-activation `z` (output `y`).
#[inline]
pub fn out_act_grad<R: Real>(a: OutAct, z: R, y: R) -> R {
    match a {
        OutAct::Sigmoid => y * (R::one() - y),
        OutAct::LeakyRelu => {
            if z > R::zero() {
                R::one()
            } else {
                R::c(SLOPE)
            }
        }
        OutAct::Softplus => R::one() / (R::one() + (-z).exp()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Softplus where `e^v` overflows: `v` itself (f32 from 88.7, f64 from 709.8), and the
    /// closed form `v + ln(1 + e^-v)` where it does not; LeakyReLU's slope at 0 is the negative
    /// side's, as PyTorch's `leaky_relu` backward (`x > 0 ? g : g * slope`).
    #[test]
    fn output_activations_at_their_edges() {
        for v in [100.0f32, 1e30] {
            assert_eq!(out_act(OutAct::Softplus, v), v);
        }
        for v in [1000.0f64, 1e300] {
            assert_eq!(out_act(OutAct::Softplus, v), v);
        }
        for v in [-30.0f64, -5.0, 0.0, 3.0, 19.5] {
            let want = v.max(0.0) + (-v.abs()).exp().ln_1p();
            let got = out_act(OutAct::Softplus, v);
            assert!(
                (got - want).abs() <= 1e-15 * want.max(1e-300),
                "{v}: {got} {want}"
            );
        }
        assert_eq!(out_act_grad(OutAct::LeakyRelu, 0.0f64, 0.0), SLOPE);
        assert_eq!(out_act_grad(OutAct::LeakyRelu, 1e-300f64, 1e-300), 1.0);
        assert_eq!(out_act(OutAct::LeakyRelu, -2.0f64), -2.0 * SLOPE);
    }

    /// PyTorch's `nn.Linear` default: every weight and bias of a layer with `fan_in` inputs
    /// drawn from U(-1/sqrt(fan_in), 1/sqrt(fan_in)), so the bound is reached closely.
    #[test]
    fn initial_parameters_fill_each_layer_s_fan_in_bound() {
        let m = Mlp::new(16, 32, 4, &[2], OutAct::Sigmoid).unwrap();
        let p = m.init::<f64>(9);
        let mut fans = Vec::new();
        for &(inp, out, off) in &m.shape {
            let b = (inp as f64).powf(-0.5);
            let layer = &p[off..off + inp * out + out];
            let max = layer.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(
                max < b && max > 0.9 * b,
                "fan-in {inp}: max {max} against {b}"
            );
            fans.push(inp);
        }
        // The skip layer takes the encoding beside the hidden state.
        assert_eq!(fans, [16, 32, 48, 32]);
        assert_eq!(m.shape.last().unwrap().2 + 32 + 1, p.len());
    }
}
