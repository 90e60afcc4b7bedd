//! Radiative Gaussians (Eq. 1): the model, its intensity response (Eq. 2), ACUI initialisation
//! and PLY interop.

pub mod init;
pub mod model;
pub mod ply;
pub mod rirf;

pub use model::Gaussians;
