//! Eqs. (4)-(5): splats to an image (interface; not written yet).

use std::marker::PhantomData;

use super::{SplatGrads, Splats};
use crate::image2d::Image2d;
use crate::real::Real;

/// What [`backward`] needs from [`forward`].
#[derive(Clone, Debug, Default)]
pub struct CompositeSaved<R: Real> {
    _p: PhantomData<R>,
}

/// Composite `splats` into a `width` x `height` image over `background`.
pub fn forward<R: Real>(
    _splats: &Splats<R>,
    width: usize,
    height: usize,
    background: R,
) -> (Image2d<R>, CompositeSaved<R>) {
    (
        Image2d::filled(width, height, background),
        CompositeSaved { _p: PhantomData },
    )
}

/// Vector-Jacobian product of [`forward`].
pub fn backward<R: Real>(
    splats: &Splats<R>,
    _saved: &CompositeSaved<R>,
    _d_image: &Image2d<R>,
) -> SplatGrads<R> {
    let n = splats.mean2d.len();
    SplatGrads {
        mean2d: vec![[R::zero(); 2]; n],
        conic: vec![[R::zero(); 3]; n],
        opacity: vec![R::zero(); n],
        color: vec![R::zero(); n],
    }
}
