//! The density MLP of NAF / SAX-NeRF (`src/network/network.py` `DensityNetwork`): `layers`
//! linear layers, LeakyReLU (slope 0.01) after every hidden layer, a chosen output activation;
//! layer `i` in `skips` takes `cat([encoding, h])`. PyTorch's default `nn.Linear` init
//! (weights and biases U(-1/sqrt(fan_in), 1/sqrt(fan_in))).
//!
//! Batched: a block of samples goes through each layer as a matrix product whose inner loop
//! runs along the output features (contiguous, vectorised by the compiler), so every sum is a
//! fixed sequential order whatever the block and the thread count.
//!
//! Parameter layout (flat): for each layer, `W` as `[in][out]` (input-major) then `b[out]`.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};
use crate::real::Real;

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
    /// and, when `keep`, the cache for [`Mlp::backward`].
    pub fn forward<R: Real>(&self, p: &[R], x: &[R], n: usize, keep: bool) -> (Vec<R>, Cache<R>) {
        let mut cache = Cache {
            inputs: Vec::new(),
            pre: Vec::new(),
            out: Vec::new(),
        };
        let mut h: Vec<R> = Vec::new();
        let slope = R::c(SLOPE);
        for (i, &(inp, out, off)) in self.shape.iter().enumerate() {
            let input: Vec<R> = if i == 0 {
                x.to_vec()
            } else if self.skips.contains(&i) {
                let mut v = Vec::with_capacity(n * inp);
                for r in 0..n {
                    v.extend_from_slice(&x[r * self.in_dim..(r + 1) * self.in_dim]);
                    v.extend_from_slice(&h[r * self.hidden..(r + 1) * self.hidden]);
                }
                v
            } else {
                std::mem::take(&mut h)
            };
            let w = &p[off..off + inp * out];
            let b = &p[off + inp * out..off + inp * out + out];
            let mut z = vec![R::zero(); n * out];
            matmul_bias(&input, w, b, n, inp, out, &mut z);
            let last = i == self.layers - 1;
            let y: Vec<R> = z
                .iter()
                .map(|&v| {
                    if last {
                        out_act(self.out_act, v)
                    } else if v > R::zero() {
                        v
                    } else {
                        v * slope
                    }
                })
                .collect();
            if keep {
                cache.inputs.push(input);
                cache.pre.push(z);
            }
            h = y;
        }
        if keep {
            cache.out = h.clone();
        }
        (h, cache)
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
        mut g_x: Option<&mut [R]>,
    ) {
        let slope = R::c(SLOPE);
        let mut g: Vec<R> = (0..n)
            .map(|r| {
                g_y[r] * out_act_grad(self.out_act, cache.pre[self.layers - 1][r], cache.out[r])
            })
            .collect();
        if let Some(gx) = g_x.as_deref_mut() {
            gx.iter_mut().for_each(|v| *v = R::zero());
        }
        for i in (0..self.layers).rev() {
            let (inp, out, off) = self.shape[i];
            let input = &cache.inputs[i];
            // dW[in][out] += sum_r input[r][in] g[r][out]; db += sum_r g[r].
            {
                let (gw, gb) = grad[off..off + inp * out + out].split_at_mut(inp * out);
                for r in 0..n {
                    let gr = &g[r * out..(r + 1) * out];
                    let xr = &input[r * inp..(r + 1) * inp];
                    for (k, &xv) in xr.iter().enumerate() {
                        let row = &mut gw[k * out..(k + 1) * out];
                        for (a, &gv) in row.iter_mut().zip(gr) {
                            *a += xv * gv;
                        }
                    }
                    for (a, &gv) in gb.iter_mut().zip(gr) {
                        *a += gv;
                    }
                }
            }
            let need_dx = i > 0 || g_x.is_some();
            if !need_dx {
                break;
            }
            // dX[r][in] = sum_out g[r][out] W[in][out].
            let w = &p[off..off + inp * out];
            let mut dx = vec![R::zero(); n * inp];
            for r in 0..n {
                let gr = &g[r * out..(r + 1) * out];
                for k in 0..inp {
                    let wr = &w[k * out..(k + 1) * out];
                    let mut acc = R::zero();
                    for (a, b) in wr.iter().zip(gr) {
                        acc += *a * *b;
                    }
                    dx[r * inp + k] = acc;
                }
            }
            // Route dX: the encoding part of a skip input (or of layer 0) to g_x, the hidden
            // part through the previous layer's LeakyReLU.
            let skip = self.skips.contains(&i);
            if i == 0 {
                if let Some(gx) = g_x.as_deref_mut() {
                    for (a, &b) in gx.iter_mut().zip(&dx) {
                        *a += b;
                    }
                }
                break;
            }
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
            let zprev = &cache.pre[i - 1];
            g = vec![R::zero(); n * hid];
            for r in 0..n {
                for k in 0..hid {
                    let d = dx[r * inp + enc + k];
                    g[r * hid + k] = if zprev[r * hid + k] > R::zero() {
                        d
                    } else {
                        d * slope
                    };
                }
            }
        }
    }
}

/// What [`Mlp::forward`] keeps for the backward pass: each layer's input and pre-activation,
/// and the outputs.
pub struct Cache<R> {
    pub inputs: Vec<Vec<R>>,
    pub pre: Vec<Vec<R>>,
    pub out: Vec<R>,
}

/// `z[r][o] = b[o] + sum_k x[r][k] w[k][o]`, rows in blocks of 4 so that each weight row is
/// read once per block; the sum over `k` runs in order for every element.
fn matmul_bias<R: Real>(x: &[R], w: &[R], b: &[R], n: usize, inp: usize, out: usize, z: &mut [R]) {
    let mut r = 0;
    while r + 4 <= n {
        let (z0, rest) = z[r * out..(r + 4) * out].split_at_mut(out);
        let (z1, rest) = rest.split_at_mut(out);
        let (z2, z3) = rest.split_at_mut(out);
        z0.copy_from_slice(b);
        z1.copy_from_slice(b);
        z2.copy_from_slice(b);
        z3.copy_from_slice(b);
        for k in 0..inp {
            let wr = &w[k * out..(k + 1) * out];
            let (a0, a1, a2, a3) = (
                x[r * inp + k],
                x[(r + 1) * inp + k],
                x[(r + 2) * inp + k],
                x[(r + 3) * inp + k],
            );
            for o in 0..out {
                let wv = wr[o];
                z0[o] += a0 * wv;
                z1[o] += a1 * wv;
                z2[o] += a2 * wv;
                z3[o] += a3 * wv;
            }
        }
        r += 4;
    }
    while r < n {
        let zr = &mut z[r * out..(r + 1) * out];
        zr.copy_from_slice(b);
        for k in 0..inp {
            let a = x[r * inp + k];
            for (zo, &wv) in zr.iter_mut().zip(&w[k * out..(k + 1) * out]) {
                *zo += a * wv;
            }
        }
        r += 1;
    }
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
