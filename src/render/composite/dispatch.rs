//! The tile kernels compiled for each instruction set ([`Simd`]) and chosen at run time: the
//! baseline target with 8 lanes, AVX2 with 8 or 16 lanes, AVX-512 with 16 lanes. All perform the
//! same IEEE operations per pixel and give the same bits: Rust never fuses a multiply and an add
//! by itself, and the fused multiply-adds the lane maths asks for (`mul_add`) are correctly
//! rounded on every path (the FMA instruction, or the C library's `fmaf` on the baseline target).

use super::backward::TileGrads;
use super::forward::TileOut;
use super::worklist::Packed;
use super::{CompositeSaved, TileBins};
use crate::image2d::Image2d;
use crate::real::Real;
use crate::simd::Simd;

/// Which compiled tile kernel runs: the instruction set and the lane width (8 or 16 pixels).
/// Every combination gives the same bits; [`Kernel::of`] picks the natural width of a set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Kernel {
    pub simd: Simd,
    pub wide: bool,
}

impl Kernel {
    /// The kernel of `simd` (or of the widest supported narrower set): 16 lanes with AVX-512,
    /// 8 otherwise.
    pub fn of(simd: Simd) -> Kernel {
        let simd = simd.or_narrower();
        Kernel {
            simd,
            wide: simd == Simd::Avx512,
        }
    }
}

pub(super) fn forward_tile<R: Real>(
    k: Kernel,
    s: &[Option<Packed<R>>],
    bins: &TileBins,
    t: usize,
) -> TileOut<R> {
    #[cfg(target_arch = "x86_64")]
    match k.simd {
        // SAFETY: the CPU supports the instruction set (checked by `supported`).
        Simd::Avx512 if Simd::Avx512.supported() => {
            return unsafe { forward_tile_avx512::<R, 16>(s, bins, t) };
        }
        Simd::Avx2 if k.wide && Simd::Avx2.supported() => {
            return unsafe { forward_tile_avx2::<R, 16>(s, bins, t) };
        }
        Simd::Avx2 if Simd::Avx2.supported() => {
            return unsafe { forward_tile_avx2::<R, 8>(s, bins, t) };
        }
        _ => {}
    }
    let _ = k;
    super::forward::forward_tile::<R, 8>(s, bins, t)
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real, const W: usize](
        s: &[Option<Packed<R>>],
        bins: &TileBins,
        t: usize,
    ) -> TileOut<R>;
    forward_tile_avx2 => { super::forward::forward_tile::<R, W>(s, bins, t) }
    forward_tile_avx512 => { super::forward::forward_tile::<R, W>(s, bins, t) }
}

pub(super) fn backward_tile<R: Real>(
    k: Kernel,
    s: &[Option<Packed<R>>],
    saved: &CompositeSaved<R>,
    d_image: &Image2d<R>,
    t: usize,
) -> TileGrads<R> {
    #[cfg(target_arch = "x86_64")]
    match k.simd {
        // SAFETY: the CPU supports the instruction set (checked by `supported`).
        Simd::Avx512 if Simd::Avx512.supported() => {
            return unsafe { backward_tile_avx512::<R, 16>(s, saved, d_image, t) };
        }
        Simd::Avx2 if k.wide && Simd::Avx2.supported() => {
            return unsafe { backward_tile_avx2::<R, 16>(s, saved, d_image, t) };
        }
        Simd::Avx2 if Simd::Avx2.supported() => {
            return unsafe { backward_tile_avx2::<R, 8>(s, saved, d_image, t) };
        }
        _ => {}
    }
    let _ = k;
    super::backward::backward_tile::<R, 8, false>(s, saved, d_image, t)
}

crate::simd::wide_kernels! {
    unsafe fn [R: Real, const W: usize](
        s: &[Option<Packed<R>>],
        saved: &CompositeSaved<R>,
        d_image: &Image2d<R>,
        t: usize,
    ) -> TileGrads<R>;
    backward_tile_avx2 => { super::backward::backward_tile::<R, W, false>(s, saved, d_image, t) }
    backward_tile_avx512 => { super::backward::backward_tile::<R, W, true>(s, saved, d_image, t) }
}
