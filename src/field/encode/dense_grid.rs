//! Dense feature grid: trilinear interpolation of `n^3` vertices of `F` features. Not an upstream
//! encoder: it is the oracle the other grid encoders are tested against (a collision-free hash
//! level is a dense grid; a full-rank TensoRF VM reproduces the dense grid it was built from).
//!
//! Vertex `(i, j, k)` stores its features at `((i + n (j + n k)) F ..)` (x fastest). The
//! position of a point `x` (metres) in vertex units depends on the [`GridMap`]:
//! - [`GridMap::Ngp`]: torch-ngp's level mapping, `u = (x + b) / (2 b)`,
//!   `pos = u (n - 2) + 1/2` (a hash-grid level of resolution `R` has `n = R + 1` vertices and
//!   `scale = R - 1`); the same floating-point operations as [`super::HashGrid::corners`];
//! - [`GridMap::AlignCorners`]: PyTorch `grid_sample(align_corners=True)` of `c = x / b`,
//!   `pos = (c + 1) / 2 (n - 1)` (TensoRF's planes and lines).
//!
//! Corner `floor(pos) + {0, 1}` per axis with weights `1 - f` / `f`, `f = pos - floor(pos)`, the
//! product taken in axis order; a corner outside the grid reads 0 (PyTorch's zero padding).
//! Backward: `dT[corner] += w g`, sequential over the points (bit-identical for any thread count).

use crate::real::Real;

/// How a point maps to vertex coordinates (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GridMap {
    Ngp,
    AlignCorners,
}

/// A dense grid of `resolution^3` vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseGrid {
    /// Vertices per axis (`n >= 2`).
    pub resolution: usize,
    pub features: usize,
    /// Half side of the cube, metres.
    pub bound: f64,
    pub map: GridMap,
}

/// Marks a corner outside the grid.
pub const OUTSIDE: usize = usize::MAX;

impl DenseGrid {
    /// Output width `F`.
    pub fn out_dim(&self) -> usize {
        self.features
    }

    /// Number of parameters `n^3 F`.
    pub fn n_params(&self) -> usize {
        self.resolution.pow(3) * self.features
    }

    /// Position of `x` in vertex units along one axis, and `d pos / d x`.
    #[inline]
    pub fn pos<R: Real>(&self, x: R) -> (R, R) {
        let b = R::c(self.bound);
        let n = self.resolution as f64;
        match self.map {
            GridMap::Ngp => {
                let scale = R::c(n - 2.0);
                let u = (x + b) / (b + b);
                (u * scale + R::c(0.5), scale / (b + b))
            }
            GridMap::AlignCorners => {
                let s = R::c(n - 1.0);
                let c = x / b;
                ((c + R::one()) / R::c(2.0) * s, s / (b + b))
            }
        }
    }

    /// The 8 corner vertices (flat index, [`OUTSIDE`] if off the grid), their weights, the
    /// fractions `f` per axis and `d pos / d x` per axis.
    #[inline]
    pub fn corners<R: Real>(&self, x: [R; 3]) -> ([usize; 8], [R; 8], [R; 3], [R; 3]) {
        let n = self.resolution as i64;
        let mut g = [0i64; 3];
        let mut f = [R::zero(); 3];
        let mut dp = [R::zero(); 3];
        for d in 0..3 {
            let (p, s) = self.pos(x[d]);
            let pf = p.floor();
            g[d] = pf.to_i64().unwrap_or(-2);
            f[d] = p - pf;
            dp[d] = s;
        }
        let mut idx = [0usize; 8];
        let mut w = [R::one(); 8];
        for c in 0..8 {
            let mut inside = true;
            let mut flat = 0i64;
            for d in (0..3).rev() {
                let hi = c & (1 << d) != 0;
                let p = g[d] + hi as i64;
                inside &= (0..n).contains(&p);
                flat = flat * n + p;
            }
            for (d, &fd) in f.iter().enumerate() {
                if c & (1 << d) == 0 {
                    w[c] *= R::one() - fd;
                } else {
                    w[c] *= fd;
                }
            }
            idx[c] = if inside { flat as usize } else { OUTSIDE };
        }
        (idx, w, f, dp)
    }

    /// Encode one point (`F` values).
    pub fn encode<R: Real>(&self, table: &[R], x: [R; 3], out: &mut [R]) {
        let nf = self.features;
        let (idx, w, _, _) = self.corners(x);
        for ch in 0..nf {
            let mut acc = R::zero();
            for c in 0..8 {
                if idx[c] != OUTSIDE {
                    acc += w[c] * table[idx[c] * nf + ch];
                }
            }
            out[ch] = acc;
        }
    }

    /// Accumulate the table gradient of `sum g . encode(x)` (layout as
    /// [`super::HashGrid::backward`]).
    pub fn backward<R: Real>(
        &self,
        xs: &[[R; 3]],
        g_out: &[R],
        g_stride: usize,
        g_off: usize,
        grad: &mut [R],
    ) {
        let nf = self.features;
        for (n, &x) in xs.iter().enumerate() {
            let (idx, w, _, _) = self.corners(x);
            let g = &g_out[n * g_stride + g_off..][..nf];
            for c in 0..8 {
                if idx[c] != OUTSIDE {
                    for ch in 0..nf {
                        grad[idx[c] * nf + ch] += w[c] * g[ch];
                    }
                }
            }
        }
    }

    /// `d (g . encode(x)) / d x` (the point's gradient; not needed for training).
    pub fn input_vjp<R: Real>(&self, table: &[R], x: [R; 3], g: &[R]) -> [R; 3] {
        let nf = self.features;
        let (idx, _, f, dp) = self.corners(x);
        let mut vals = [R::zero(); 8];
        for c in 0..8 {
            if idx[c] != OUTSIDE {
                for ch in 0..nf {
                    vals[c] += g[ch] * table[idx[c] * nf + ch];
                }
            }
        }
        trilinear_grad(&vals, f, dp)
    }
}

/// Gradient with respect to the point of `sum_c w_c(f) v_c` (corner `c` bit `d` set: weight
/// `f_d`, else `1 - f_d`), with `dp[d] = d f_d / d x_d`.
pub fn trilinear_grad<R: Real>(v: &[R; 8], f: [R; 3], dp: [R; 3]) -> [R; 3] {
    let mut out = [R::zero(); 3];
    for (d, o) in out.iter_mut().enumerate() {
        let mut acc = R::zero();
        for (c, &vc) in v.iter().enumerate() {
            let mut w = if c & (1 << d) == 0 {
                -R::one()
            } else {
                R::one()
            };
            for (e, &fe) in f.iter().enumerate() {
                if e != d {
                    w *= if c & (1 << e) == 0 { R::one() - fe } else { fe };
                }
            }
            acc += w * vc;
        }
        *o = acc * dp[d];
    }
    out
}
