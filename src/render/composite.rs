//! Eqs. (4)-(5): splats to an image by front-to-back alpha compositing over 16x16 tiles, and the
//! exact vector-Jacobian product of that image.
//!
//! Forward, per pixel p with centre (col + 0.5, row + 0.5) (the convention of `mean2d`), over
//! the splats of p's tile in (depth, index) order ([`super::tiles`]):
//! - d = p - mean2d, power = -0.5 (A dx^2 + C dy^2) - B dx dy (conic (A, B, C)); skip if
//!   power > 0 (3DGS);
//! - Eq. (4): alpha = min(0.99, o exp(power)); skip if alpha < 1/255;
//! - exclusive stop (3DGS): if T (1 - alpha) < 1e-4 the pixel is done and this splat is NOT
//!   blended;
//! - Eq. (5): C += c alpha T, T <- T (1 - alpha); the output is C + T_final * background.
//!
//! Saved for the backward pass (as 3DGS): the final T and the number of entries of the tile's
//! work list up to and including the last blended one (`n_contrib`), per pixel; and, per tile,
//! the work list up to the largest `n_contrib` with the per-row chord tests made when the list
//! was gathered ([`WorkLists`]), so that the backward neither re-packs the splats nor redoes the
//! chord tests of the rows it visits.
//!
//! Backward, per pixel back to front from the last blended entry, T recovered by division
//! T_k = T_{k+1} / (1 - alpha_k) (alpha <= 0.99, so no blow-up), S_k = sum_{j>k} c_j alpha_j T_j:
//! - dL/dc_k = g alpha_k T_k;
//! - dL/dalpha_k = g (c_k T_k - S_k / (1 - alpha_k)) - g bg T_final / (1 - alpha_k);
//! - where o G > 0.99 the clamp is active and d alpha / d(o G) = 0 (3DGS passes the gradient
//!   through; gsplat and brush zero it as we do); else dL/do = G dL/dalpha, dL/dpower =
//!   o G dL/dalpha, dL/dmean = dL/dpower (A dx + B dy, B dx + C dy), dL/dA = -dx^2/2 dL/dpower,
//!   dL/dB = -dx dy dL/dpower (B is the single off-diagonal parameter), dL/dC = -dy^2/2 dL/dpower.
//!   The hard cutoffs (power > 0, alpha < 1/255, the T stop, the tile box) are not
//!   differentiated: they are the same in both passes.
//!
//! Work limits that do not change any bit of the result: for each (tile, splat) the pixels
//! evaluated are restricted to the bounding box of the ellipse o G >= (1/255) e^-0.001 widened
//! by one pixel (outside it alpha < 1/255, so those pixels would be skipped anyway); splats with
//! o < (1/255) e^-0.001 are dropped; a tile stops when all its pixels are done (and the
//! forward reads no splat of its list behind that point); the forward skips a row or an
//! 8-column half whose pixels are all done (every lane would fail the `done` test), the backward
//! an 8-column half of a row where no pixel has n_contrib > j (every lane would fail
//! `j < n_contrib`).
//!
//! Summation order of an entry's gradient record (the backward; every path, width and thread
//! count): per tile column, the pixels of the even tile rows are summed top to bottom, those of
//! the odd rows likewise, then even + odd; then the columns left to right. (Rows in pairs let a
//! 16-lane vector hold one 8-column half of two rows, so that an entry meeting one half of the
//! tile does not take whole-row vectors.)
//!
//! Parallelism: rayon over tiles. Each tile is computed by one task in a fixed order; the
//! per-tile gradient records (one per list entry) are reduced sequentially in tile order (by
//! whichever worker finds the reducer free once the next tiles in that order are finished,
//! during the tile loop, and the rest after it), so image and gradients are bit-identical for
//! any thread count. No atomics.
//!
//! The stage in five files, by job:
//! - `worklist`: per-splat pixel boxes, per-row chord tests and the per-tile work lists that
//!   both passes walk ([`WorkLists`]);
//! - `forward`: the Eq. (4)-(5) forward tile kernel and the image assembly;
//! - `backward`: the VJP tile kernel and the sequential gradient reduction;
//! - `colsum`: an entry's gradient record from the backward's per-column sums (the order
//!   above; with AVX-512 the seven sums advance side by side in one vector);
//! - `dispatch`: the kernels compiled per instruction set and lane width
//!   ([`Simd`](crate::simd::Simd)).
//!
//! [`naive_forward`] is the per-pixel reference the tests compare with, bit for bit.

use super::lanes::mask;
use crate::real::Real;

use super::tiles::{TileBins, TILE};
use super::Splats;

mod backward;
mod colsum;
mod dispatch;
mod forward;
mod naive;
mod worklist;

pub use backward::{backward, backward_probed, backward_with};
pub use forward::{forward, forward_probed, forward_with};
pub use naive::naive_forward;
pub use worklist::{box_pixels, WorkLists};

/// Eq. (4) opacity clamp (3DGS; gsplat since 2026).
pub const ALPHA_MAX: f64 = 0.99;
/// Splats with alpha below this are skipped at a pixel.
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
/// Exclusive transmittance stop.
pub const T_MIN: f64 = 1e-4;

/// Pixels per tile.
const TP: usize = TILE * TILE;

/// `T` at a 64-byte boundary: the kernels' per-pixel arrays, so that a 16-lane f32 vector at a
/// multiple of 16 pixels is one cache line (a vector across two lines costs two accesses, and
/// the stack's alignment beyond 16 bytes would otherwise depend on the caller).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Lines<T>(T);

/// Tile-local index of the pixel in tile row `r`, column `c` in the kernels' per-pixel state:
/// the tile's rows in pairs (2 m, 2 m + 1), each pair's 8-column half `h` as 16 consecutive
/// pixels, the even row's 8 then the odd row's (32 m + 16 h + 8 (r % 2) + c % 8). A lane vector
/// of 16 then holds one half of two rows, so that rows where an entry meets one half only
/// share vectors.
#[inline(always)]
fn slot_index(r: usize, c: usize) -> usize {
    32 * (r / 2) + 16 * (c / 8) + 8 * (r % 2) + c % 8
}

/// Pixel-centre coordinates of a tile in the lane order of [`slot_index`]: per half `h`, the
/// x of its 8 columns twice (`xs[h]`, for either row of a pair); per row pair `m`, the y of the
/// even row 8 times, then of the odd row (`ys[m]`).
struct SlotLanes<R> {
    xs: [[R; 16]; 2],
    ys: [[R; 16]; TILE / 2],
}

impl<R: Real> SlotLanes<R> {
    /// The coordinates of the tile whose top-left pixel is (`x0`, `y0`).
    #[inline(always)]
    fn new(x0: usize, y0: usize) -> Self {
        let half = R::c(0.5);
        let mut l = SlotLanes {
            xs: [[half; 16]; 2],
            ys: [[half; 16]; TILE / 2],
        };
        for k in 0..16 {
            for h in 0..2 {
                l.xs[h][k] = R::c((x0 + 8 * h + k % 8) as f64) + half;
            }
            for m in 0..TILE / 2 {
                l.ys[m][k] = R::c((y0 + 2 * m + k / 8) as f64) + half;
            }
        }
        l
    }

    /// Lane masks of the tile columns `k0..k1` in the order of `xs`.
    #[inline(always)]
    fn columns(&self, k0: usize, k1: usize) -> [[u32; 16]; 2] {
        let mut m = [[0u32; 16]; 2];
        for (h, mh) in m.iter_mut().enumerate() {
            for (k, v) in mh.iter_mut().enumerate() {
                let c = 8 * h + k % 8;
                *v = mask(k0 <= c && c < k1);
            }
        }
        m
    }
}

/// Floating-point operations (adds, multiplies, fused multiply-adds, divisions, compares and
/// min/selects on floats; a fused multiply-add counts as one, as it takes one multiply pipe) per
/// pixel lane of the forward kernel, counted from its source, without the ones that are the same
/// for a whole tile row or entry (hoisted out of the lane loop): dx and Eq. (4)'s exponent 3,
/// `exp_f32` 16, opacity and clamp 2, transmittance 2, three tests 3, Eq. (5)'s colour 2.
pub const FLOPS_PER_BLEND_FORWARD: u64 = 28;
/// The same count for the backward kernel: dx, exponent, exp and alpha 21, three tests 3, T
/// recovery 3, dL/dalpha 6, the colour behind 2, d(power) and the seven gradient lanes 14, their
/// seven column sums 7.
pub const FLOPS_PER_BLEND_BACKWARD: u64 = 56;

/// The compositor's phases in the order they run, reported to the probe of [`forward_probed`]
/// (`Bin` to `Assemble`) and [`backward_probed`] (`BackwardTiles`, `Reduce`) as each ends (the
/// per-phase times of `unispine bench render`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Phase {
    /// Tile binning and the (tile, depth, index) sort ([`super::tiles::bin`]), and, side by
    /// side with them, the per-splat packed records with their pixel boxes.
    BinPack,
    /// The forward tile kernels (parallel over tiles), including the gather of each tile's
    /// work list.
    ForwardTiles,
    /// Tiles to image, final transmittance and `n_contrib`.
    Assemble,
    /// The backward tile kernels (parallel over tiles).
    BackwardTiles,
    /// Per-tile gradient records to per-splat gradients: the part left after the backward tile
    /// kernels (most of the reduction runs during them, on the tiles already finished).
    Reduce,
}

/// Work counters of one pass of the tile kernels (the useful lanes are the blends).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KernelWork {
    /// Work-list entries visited.
    pub entries: u64,
    /// (entry, tile row) pairs visited.
    pub rows: u64,
    /// Pixel lanes evaluated (lane vectors x their width), including masked-out lanes.
    pub lanes: u64,
}

impl std::ops::AddAssign for KernelWork {
    fn add_assign(&mut self, o: KernelWork) {
        self.entries += o.entries;
        self.rows += o.rows;
        self.lanes += o.lanes;
    }
}

/// What [`backward`](fn@backward) needs from [`forward`](fn@forward).
#[derive(Clone, Debug, Default)]
pub struct CompositeSaved<R: Real> {
    /// The tile lists (depth-sorted Gaussian indices).
    pub bins: TileBins,
    /// Background value of the forward pass.
    pub background: R,
    /// Final transmittance per pixel (row-major).
    pub final_t: Vec<R>,
    /// Per pixel: 1 + position of the last blended entry in its tile's work list (0 = none).
    pub n_contrib: Vec<u32>,
    /// Number of (pixel, splat) blends performed (throughput statistics).
    pub blends: u64,
    /// Work of the forward tile kernels (statistics).
    pub forward_work: KernelWork,
    /// The tile work lists built by [`forward`](fn@forward), reused by [`backward`](fn@backward)
    /// (which rebuilds them when this is empty, e.g. for a `Default` value).
    pub work: WorkLists<R>,
}

/// Error if a drawn splat (radius > 0) has a non-finite field, naming the splat and the field.
/// [`forward`](fn@forward) skips such splats; callers that want an error call this first.
pub fn validate<R: Real>(splats: &Splats<R>) -> crate::error::Result<()> {
    for i in 0..splats.radius.len() {
        if splats.radius[i] == 0 {
            continue;
        }
        let fields: [(&str, &[R]); 5] = [
            ("mean2d", &splats.mean2d[i]),
            ("conic", &splats.conic[i]),
            ("opacity", std::slice::from_ref(&splats.opacity[i])),
            ("color", std::slice::from_ref(&splats.color[i])),
            ("depth", std::slice::from_ref(&splats.depth[i])),
        ];
        for (name, v) in fields {
            if let Some(x) = v.iter().find(|x| !x.is_finite()) {
                return Err(crate::error::Error::NonFinite {
                    what: format!("splat {i} `{name}`"),
                    index: i,
                    value: x.f64(),
                });
            }
        }
    }
    Ok(())
}
// What the unit tests use besides the public API.
#[cfg(test)]
use {
    super::SplatGrads, crate::image2d::Image2d, crate::simd::Simd, backward::backward_kernel,
    dispatch::Kernel, forward::forward_kernel,
};

#[cfg(test)]
mod tests;
