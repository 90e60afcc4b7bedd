//! Digitally reconstructed radiographs: line integrals of a volume along the rays of a
//! [`crate::geometry::Camera`], exact (Siddon) or sampled (trilinear ray-march).

pub mod siddon;
pub mod trilinear;

use crate::error::Result;
use crate::geometry::ConeBeam;
use crate::image2d::Image2d;
use crate::real::Real;
use crate::volume::Volume;

/// Projector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Exact line integrals through the voxel grid (piecewise-constant volume).
    #[default]
    Siddon,
    /// Trilinear ray-march with step `accuracy` x voxel (TIGRE 'interpolated').
    Trilinear,
}

/// Line integrals (mm x volume value) of `vol` for the view at `angle` (radians) of `geo`.
/// The volume is placed by its own `spacing` and `offset`; `geo`'s `nVoxel`/`dVoxel`/`offOrigin`
/// must describe the same grid (checked).
pub fn project<R: Real>(
    _vol: &Volume<R>,
    _geo: &ConeBeam,
    _angle: f64,
    _method: Method,
) -> Result<Image2d<R>> {
    Err(crate::error::Error::invalid(
        "drr",
        "the projectors are not implemented yet",
    ))
}

/// [`project`] for several angles; `progress(done)` is called after each view.
pub fn project_views<R: Real>(
    vol: &Volume<R>,
    geo: &ConeBeam,
    angles: &[f64],
    method: Method,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<Image2d<R>>> {
    let mut out = Vec::with_capacity(angles.len());
    for (k, &a) in angles.iter().enumerate() {
        out.push(project(vol, geo, a, method)?);
        progress(k + 1);
    }
    Ok(out)
}
