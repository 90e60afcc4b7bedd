//! TensoRF's vector-matrix (VM) encoder as SAX-NeRF re-implements it for X-ray
//! (caiyuanhao1998/SAX-NeRF `src/encoder/tensorf_encoder.py`, `TensorfEncoder`):
//! - `c = x / bound` in [-1, 1] (the point in metres divided by the network's bound);
//! - plane `i` (`matMode` (x, y), (x, z), (y, z)) holds `C` components of `N x N` texels,
//!   PyTorch shape `(1, C, N, N)`: its width runs along the first axis of the pair, its height
//!   along the second; line `i` (`vecMode` z, y, x) holds `C x N` values, shape `(1, C, N, 1)`;
//! - every read is `F.grid_sample(align_corners=True)`, bilinear with zero padding:
//!   `pixel = (c + 1) / 2 (size - 1)`, weights `nw = (x1 - ix)(y1 - iy)`,
//!   `ne = (ix - x0)(y1 - iy)`, `sw = (x1 - ix)(iy - y0)`, `se = (ix - x0)(iy - y0)`;
//! - feature `(i, r)` = `P_ir(c_a, c_b) * L_ir(c_v)`, the `3 C` features in plane-major order go
//!   through `basis_mat` (a Linear `3C -> out_dim` without bias, weight `[out][3C]`).
//!
//! The line factor [`VmLines`]: upstream passes `density_plane[i]` to the second `grid_sample`
//! (with the grid `(0, c_v)`), so the "line" is the plane's column at `x = 0` (pixel
//! `(N - 1) / 2`, between two texel columns for even `N`) read at height `c_v`, and the line
//! parameters are never used ([`VmLines::Upstream`], the default). [`VmLines::Corrected`] reads
//! `density_line[i]` as TensoRF intends (linear interpolation along the line). The line
//! parameters exist in both modes (same parameter count as upstream); upstream they keep their
//! initial values.
//!
//! Init as upstream: planes and lines `0.1 N(0, 1)`, `basis_mat` PyTorch's Linear default
//! U(-1/sqrt(3C), 1/sqrt(3C)). Parameter layout: planes `[3][C][N][N]` (row = second axis),
//! then lines `[3][C][N]`, then the basis `[out_dim][3C]`.
//!
//! Backward (hand-written): `dB[a][k] += g_a feat_k`, `g_feat = B^T g`, then per component
//! `dP[4 texels] += w g_feat L`, `dL[taps] += w g_feat P` (upstream mode: the line taps are
//! texels of the same plane). The basis products (forward `feat B^T`, `G B`, `dB += G^T F`) run
//! the field MLP's blocked kernels ([`crate::field::gemm::accumulate`]), whose chains are the
//! per-point loops' (from the initial value, the inner index in order, multiply then add), so
//! every SIMD path gives the point-by-point bits. Each point's taps are computed once; the
//! scatter is parallel over the `3C` (plane, component) pairs and the basis rows, each owning
//! its gradient slice and visiting the points in order: no atomics, bit-identical for any
//! thread count.

use rayon::prelude::*;

use crate::field::gemm;
use crate::real::Real;
use crate::simd::Simd;

/// Axis pairs of the planes (`matMode`).
pub const MAT: [[usize; 2]; 3] = [[0, 1], [0, 2], [1, 2]];
/// Axis of each line (`vecMode`).
pub const VEC: [usize; 3] = [2, 1, 0];

crate::choice! {
/// Where the line factor is read from (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum VmLines {
    /// SAX-NeRF: the plane itself at `(0, c_v)`.
    Upstream = "upstream",
    /// The line vector at `c_v`.
    Corrected = "corrected",
}
}

/// A VM encoder.
#[derive(Clone, Debug, PartialEq)]
pub struct TensorVm {
    /// Texels per plane side and line length (`num_levels` upstream), >= 2.
    pub resolution: usize,
    /// Components per plane (`density_n_comp`, the rank), >= 1.
    pub components: usize,
    /// Output width (`app_dim`).
    pub out_dim: usize,
    pub bound: f64,
    pub lines: VmLines,
}

/// Up to 4 texel taps (flat index within one component's texels, weight); unused taps have
/// weight 0 and index 0.
type Taps<R> = [(usize, R); 4];

/// Bilinear taps of `grid_sample(align_corners=True)` on a `w x h` image at pixel `(ix, iy)`,
/// and the weights' derivatives along `ix` and `iy` (PyTorch's corner order nw, ne, sw, se).
#[inline]
fn bilinear<R: Real>(ix: R, iy: R, w: usize, h: usize) -> (Taps<R>, [R; 4], [R; 4]) {
    let (x0, y0) = (ix.floor(), iy.floor());
    let (x1, y1) = (x0 + R::one(), y0 + R::one());
    let wt = [
        (x1 - ix) * (y1 - iy),
        (ix - x0) * (y1 - iy),
        (x1 - ix) * (iy - y0),
        (ix - x0) * (iy - y0),
    ];
    let dx = [-(y1 - iy), y1 - iy, -(iy - y0), iy - y0];
    let dy = [-(x1 - ix), -(ix - x0), x1 - ix, ix - x0];
    let xi = x0.to_i64().unwrap_or(-2);
    let yi = y0.to_i64().unwrap_or(-2);
    let mut taps = [(0usize, R::zero()); 4];
    let (mut ddx, mut ddy) = ([R::zero(); 4], [R::zero(); 4]);
    for (t, (cx, cy)) in [(xi, yi), (xi + 1, yi), (xi, yi + 1), (xi + 1, yi + 1)]
        .into_iter()
        .enumerate()
    {
        if (0..w as i64).contains(&cx) && (0..h as i64).contains(&cy) {
            taps[t] = ((cy as usize) * w + cx as usize, wt[t]);
            ddx[t] = dx[t];
            ddy[t] = dy[t];
        }
    }
    (taps, ddx, ddy)
}

/// The reads of one point: for each plane `i`, the plane taps and the line taps (indices
/// within a component's plane texels or line values), with the pixel derivatives.
struct Reads<R> {
    plane: [(Taps<R>, [R; 4], [R; 4]); 3],
    line: [(Taps<R>, [R; 4], [R; 4]); 3],
    /// d pixel / d x (the same for every read along a resolution-N axis).
    dpix: R,
}

#[inline]
fn dot<R: Real>(taps: &Taps<R>, v: &[R]) -> R {
    let mut acc = R::zero();
    for &(i, w) in taps {
        acc += w * v[i];
    }
    acc
}

/// One point's taps on one plane and its line, indices narrowed to `u32` (a plane holds at
/// most [`crate::field::MAX_GRID_PARAMS`] values).
#[derive(Clone, Copy, Default)]
struct PlaneTaps<R> {
    plane: [u32; 4],
    plane_w: [R; 4],
    line: [u32; 4],
    line_w: [R; 4],
}

impl<R: Real> PlaneTaps<R> {
    fn new(plane: &Taps<R>, line: &Taps<R>) -> Self {
        PlaneTaps {
            plane: plane.map(|(i, _)| i as u32),
            plane_w: plane.map(|(_, w)| w),
            line: line.map(|(i, _)| i as u32),
            line_w: line.map(|(_, w)| w),
        }
    }
}

impl TensorVm {
    /// Output width.
    pub fn out_dim(&self) -> usize {
        self.out_dim
    }

    fn plane_len(&self) -> usize {
        self.resolution * self.resolution
    }

    /// Offsets of the lines and of the basis in the parameter vector.
    pub fn offsets(&self) -> (usize, usize) {
        let lines = 3 * self.components * self.plane_len();
        (lines, lines + 3 * self.components * self.resolution)
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.offsets().1 + self.out_dim * 3 * self.components
    }

    fn reads<R: Real>(&self, x: [R; 3]) -> Reads<R> {
        let n = self.resolution;
        let b = R::c(self.bound);
        let two = R::c(2.0);
        let s = R::c(n as f64 - 1.0);
        let pix = |v: R| (v / b + R::one()) / two * s;
        let p = [pix(x[0]), pix(x[1]), pix(x[2])];
        let plane = std::array::from_fn(|i| bilinear(p[MAT[i][0]], p[MAT[i][1]], n, n));
        let line = std::array::from_fn(|i| match self.lines {
            // grid (0, c_v) on the (1, C, N, N) plane: column (N - 1) / 2.
            VmLines::Upstream => bilinear(R::one() / two * s, p[VEC[i]], n, n),
            // grid (0, c_v) on the (1, C, N, 1) line: column 0 (width 1).
            VmLines::Corrected => bilinear(R::zero(), p[VEC[i]], 1, n),
        });
        Reads {
            plane,
            line,
            dpix: s / (b + b),
        }
    }

    /// Plane and line factors of every feature (`3C` each, plane-major).
    fn factors<R: Real>(&self, params: &[R], rd: &Reads<R>, pf: &mut [R], lf: &mut [R]) {
        let (c, pl) = (self.components, self.plane_len());
        let (loff, _) = self.offsets();
        for i in 0..3 {
            for r in 0..c {
                let k = i * c + r;
                pf[k] = dot(&rd.plane[i].0, &params[k * pl..(k + 1) * pl]);
                lf[k] = match self.lines {
                    VmLines::Upstream => dot(&rd.line[i].0, &params[k * pl..(k + 1) * pl]),
                    VmLines::Corrected => {
                        let n = self.resolution;
                        dot(&rd.line[i].0, &params[loff + k * n..loff + (k + 1) * n])
                    }
                };
            }
        }
    }

    /// Encode one point (`out_dim` values).
    pub fn encode<R: Real>(&self, params: &[R], x: [R; 3], out: &mut [R]) {
        let k3 = 3 * self.components;
        let rd = self.reads(x);
        let (mut pf, mut lf) = (vec![R::zero(); k3], vec![R::zero(); k3]);
        self.factors(params, &rd, &mut pf, &mut lf);
        let basis = &params[self.offsets().1..];
        for (a, o) in out[..self.out_dim].iter_mut().enumerate() {
            let row = &basis[a * k3..(a + 1) * k3];
            let mut acc = R::zero();
            for k in 0..k3 {
                acc += row[k] * (pf[k] * lf[k]);
            }
            *o = acc;
        }
    }

    /// Encode a block of points (`out_dim` values each), as [`TensorVm::encode`] point by
    /// point: the features of every point first, then one product with the basis (the same
    /// chain per output: from zero, `k` in order).
    pub fn encode_block<R: Real>(&self, simd: Simd, params: &[R], xs: &[[R; 3]], out: &mut [R]) {
        let (k3, od) = (3 * self.components, self.out_dim);
        let mut feat = vec![R::zero(); xs.len() * k3];
        let mut lf = vec![R::zero(); k3];
        for (&x, f) in xs.iter().zip(feat.chunks_exact_mut(k3)) {
            self.factors(params, &self.reads(x), f, &mut lf);
            f.iter_mut().zip(&lf).for_each(|(a, &b)| *a *= b);
        }
        let mut bt = vec![R::zero(); k3 * od];
        gemm::transpose(&params[self.offsets().1..], od, k3, &mut bt);
        let out = &mut out[..xs.len() * od];
        out.iter_mut().for_each(|v| *v = R::zero());
        gemm::accumulate(simd, &feat, k3, 1, &bt, od, out, od, xs.len(), od, k3);
    }

    /// `g_feat = B^T g` of one point.
    fn feature_grad<R: Real>(&self, basis: &[R], g: &[R], gf: &mut [R]) {
        let k3 = 3 * self.components;
        gf.iter_mut().for_each(|v| *v = R::zero());
        for (a, &ga) in g[..self.out_dim].iter().enumerate() {
            for (v, &bk) in gf.iter_mut().zip(&basis[a * k3..(a + 1) * k3]) {
                *v += bk * ga;
            }
        }
    }

    /// Accumulate the parameter gradient of `sum g . encode(x)` over the points `xs`, with
    /// `g_out[n * g_stride + g_off ..]` the gradient of point `n`'s encoding.
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
        let (c, n, pl, od) = (
            self.components,
            self.resolution,
            self.plane_len(),
            self.out_dim,
        );
        let k3 = 3 * c;
        let (loff, boff) = self.offsets();
        let basis = &params[boff..];
        // Per point (independent): factors, the feature gradient and each plane's taps.
        const CH: usize = 256;
        let np = xs.len();
        let (mut pf, mut lf, mut gf) = (
            vec![R::zero(); np * k3],
            vec![R::zero(); np * k3],
            vec![R::zero(); np * k3],
        );
        let mut taps: [Vec<PlaneTaps<R>>; 3] =
            std::array::from_fn(|_| vec![PlaneTaps::default(); np]);
        let [t0, t1, t2] = &mut taps;
        xs.par_chunks(CH)
            .zip(pf.par_chunks_mut(CH * k3))
            .zip(lf.par_chunks_mut(CH * k3))
            .zip(gf.par_chunks_mut(CH * k3))
            .zip(t0.par_chunks_mut(CH))
            .zip(t1.par_chunks_mut(CH))
            .zip(t2.par_chunks_mut(CH))
            .enumerate()
            .for_each(|(ci, ((((((chunk, pf), lf), gf), t0), t1), t2))| {
                for (j, &x) in chunk.iter().enumerate() {
                    let rd = self.reads(x);
                    let s = j * k3..(j + 1) * k3;
                    self.factors(params, &rd, &mut pf[s.clone()], &mut lf[s]);
                    for (i, t) in [&mut t0[j], &mut t1[j], &mut t2[j]].into_iter().enumerate() {
                        *t = PlaneTaps::new(&rd.plane[i].0, &rd.line[i].0);
                    }
                }
                // g_feat = G B (from zero, rows of the basis in order).
                let (m, g) = (chunk.len(), &g_out[ci * CH * g_stride + g_off..]);
                gemm::accumulate(simd, g, g_stride, 1, basis, k3, gf, k3, m, k3, od);
            });
        let (gp, rest) = grad.split_at_mut(loff);
        let (gl, gb) = rest.split_at_mut(boff - loff);
        // Basis rows: dB[a][k] += sum_p g_a feat_k, points in order.
        // As the product dB += G^T F (G's rows strided in `g_out`), in two halves of the rows.
        let feat: Vec<R> = pf.iter().zip(&lf).map(|(&a, &b)| a * b).collect();
        let half = od.div_ceil(2).max(1);
        gb[..od * k3]
            .par_chunks_mut(half * k3)
            .enumerate()
            .for_each(|(h, rows)| {
                let m = rows.len() / k3;
                let a = &g_out[g_off + h * half..];
                gemm::accumulate(simd, a, 1, g_stride, &feat, k3, rows, k3, m, k3, xs.len());
            });
        // Plane / line components: the taps computed once per point above.
        gp.par_chunks_mut(pl)
            .zip(gl.par_chunks_mut(n))
            .enumerate()
            .for_each(|(k, (dp, dl))| {
                for (p, t) in taps[k / c].iter().enumerate() {
                    let g = gf[p * k3 + k];
                    let gl = g * lf[p * k3 + k];
                    for q in 0..4 {
                        dp[t.plane[q] as usize] += t.plane_w[q] * gl;
                    }
                    let dst: &mut [R] = match self.lines {
                        VmLines::Upstream => dp,
                        VmLines::Corrected => dl,
                    };
                    let gp = g * pf[p * k3 + k];
                    for q in 0..4 {
                        dst[t.line[q] as usize] += t.line_w[q] * gp;
                    }
                }
            });
    }

    /// `d (g . encode(x)) / d x` (the point's gradient; upstream detaches the coordinates, so
    /// training never needs it).
    pub fn input_vjp<R: Real>(&self, params: &[R], x: [R; 3], g: &[R]) -> [R; 3] {
        let (c, n, pl) = (self.components, self.resolution, self.plane_len());
        let k3 = 3 * c;
        let (loff, boff) = self.offsets();
        let rd = self.reads(x);
        let (mut pf, mut lf, mut gf) = (
            vec![R::zero(); k3],
            vec![R::zero(); k3],
            vec![R::zero(); k3],
        );
        self.factors(params, &rd, &mut pf, &mut lf);
        self.feature_grad(&params[boff..], g, &mut gf);
        let mut out = [R::zero(); 3];
        let deriv = |t: &(Taps<R>, [R; 4], [R; 4]), v: &[R]| {
            let (mut a, mut b) = (R::zero(), R::zero());
            for q in 0..4 {
                a += t.1[q] * v[t.0[q].0];
                b += t.2[q] * v[t.0[q].0];
            }
            (a, b)
        };
        for i in 0..3 {
            for r in 0..c {
                let k = i * c + r;
                let plane = &params[k * pl..(k + 1) * pl];
                let (dpx, dpy) = deriv(&rd.plane[i], plane);
                out[MAT[i][0]] += gf[k] * dpx * lf[k];
                out[MAT[i][1]] += gf[k] * dpy * lf[k];
                // The line's pixel x is a constant; only its y follows the point.
                let (_, dly) = match self.lines {
                    VmLines::Upstream => deriv(&rd.line[i], plane),
                    VmLines::Corrected => deriv(&rd.line[i], &params[loff + k * n..][..n]),
                };
                out[VEC[i]] += gf[k] * pf[k] * dly;
            }
        }
        out.map(|v| v * rd.dpix)
    }

    /// Initial parameters: planes and lines `0.1 N(0, 1)` (Box-Muller on `uniform`), the basis
    /// U(-1/sqrt(3C), 1/sqrt(3C)).
    pub fn init<R: Real>(&self, uniform: &mut dyn FnMut() -> f64) -> Vec<R> {
        let (_, boff) = self.offsets();
        let mut p = Vec::with_capacity(self.n_params());
        while p.len() < boff {
            let (u1, u2) = (1.0 - uniform(), uniform());
            let r = (-2.0 * u1.ln()).sqrt();
            let a = std::f64::consts::TAU * u2;
            p.push(R::c(0.1 * r * a.cos()));
            if p.len() < boff {
                p.push(R::c(0.1 * r * a.sin()));
            }
        }
        let bnd = 1.0 / ((3 * self.components) as f64).sqrt();
        while p.len() < self.n_params() {
            p.push(R::c((2.0 * uniform() - 1.0) * bnd));
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vm(lines: VmLines) -> TensorVm {
        TensorVm {
            resolution: 9,
            components: 3,
            out_dim: 13,
            bound: 0.3,
            lines,
        }
    }

    /// 300 points (a partial chunk of the backward's 256), some outside the bound.
    fn points() -> Vec<[f32; 3]> {
        (0..300)
            .map(|i| {
                let t = i as f32 / 300.0;
                [0.7 * t - 0.35, (9.0 * t).sin() * 0.3, 0.25 - 0.6 * t * t]
            })
            .collect()
    }

    fn params(v: &TensorVm) -> Vec<f32> {
        (0..v.n_params())
            .map(|i| ((i * 7919 % 1000) as f32 - 500.0) * 1e-3)
            .collect()
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn block_encode_is_point_encode_bit_for_bit_on_every_path() {
        for lines in [VmLines::Upstream, VmLines::Corrected] {
            let v = vm(lines);
            let (p, xs) = (params(&v), points());
            let mut want = vec![0.0f32; xs.len() * v.out_dim];
            for (x, o) in xs.iter().zip(want.chunks_mut(v.out_dim)) {
                v.encode(&p, *x, o);
            }
            for simd in Simd::supported_paths() {
                let mut got = vec![f32::NAN; xs.len() * v.out_dim];
                v.encode_block(simd, &p, &xs, &mut got);
                assert_eq!(bits(&got), bits(&want), "{lines:?} {simd:?}");
            }
        }
    }

    /// The backward point by point in the documented order (features, `B^T g` from zero, then
    /// the basis rows, planes and lines with the points in order), against the blocked one on
    /// every path, starting from a non-zero gradient (the products accumulate).
    #[test]
    fn backward_is_the_point_by_point_order_on_every_path() {
        for lines in [VmLines::Upstream, VmLines::Corrected] {
            let v = vm(lines);
            let (p, xs) = (params(&v), points());
            let (k3, od, pl, n) = (3 * v.components, v.out_dim, v.plane_len(), v.resolution);
            let (loff, boff) = v.offsets();
            // Gradient rows strided 17 with offset 2 (as inside a wider input).
            let (stride, off) = (17, 2);
            let g: Vec<f32> = (0..xs.len() * stride)
                .map(|i| ((i * 31 % 97) as f32 - 48.0) * 1e-2)
                .collect();
            let start: Vec<f32> = (0..v.n_params()).map(|i| (i % 5) as f32 * 0.25).collect();
            let mut want = start.clone();
            for (q, &x) in xs.iter().enumerate() {
                let rd = v.reads(x);
                let (mut pf, mut lf, mut gf) = (vec![0.0; k3], vec![0.0; k3], vec![0.0; k3]);
                v.factors(&p, &rd, &mut pf, &mut lf);
                let gq = &g[q * stride + off..][..od];
                v.feature_grad(&p[boff..], gq, &mut gf);
                for a in 0..od {
                    for k in 0..k3 {
                        want[boff + a * k3 + k] += gq[a] * (pf[k] * lf[k]);
                    }
                }
                for k in 0..k3 {
                    let i = k / v.components;
                    for &(t, w) in &rd.plane[i].0 {
                        want[k * pl + t] += w * (gf[k] * lf[k]);
                    }
                    let base = match lines {
                        VmLines::Upstream => k * pl,
                        VmLines::Corrected => loff + k * n,
                    };
                    for &(t, w) in &rd.line[i].0 {
                        want[base + t] += w * (gf[k] * pf[k]);
                    }
                }
            }
            for simd in Simd::supported_paths() {
                let mut got = start.clone();
                v.backward(simd, &p, &xs, &g, stride, off, &mut got);
                assert_eq!(bits(&got), bits(&want), "{lines:?} {simd:?}");
            }
        }
    }
}
