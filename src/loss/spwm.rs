//! SPWM, Eqs. (6)-(7) (interface; not written yet).

use crate::image2d::Image2d;
use crate::real::Real;

/// SPWM settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, Default)]
pub struct SpwmConfig {}

/// The iteration-independent part of the SPWM weights of one ground-truth view (computed once
/// per view and cached).
pub fn view_prior<R: Real>(gt: &Image2d<R>, _cfg: &SpwmConfig) -> Image2d<R> {
    Image2d::filled(gt.width, gt.height, R::zero())
}

/// The weights w of Eq. (7) at iteration `iter` from a cached [`view_prior`].
pub fn weights<R: Real>(prior: &Image2d<R>, _iter: usize, _cfg: &SpwmConfig) -> Image2d<R> {
    Image2d::filled(prior.width, prior.height, R::one())
}
