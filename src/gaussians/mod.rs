//! Radiative Gaussians (Eq. 1): the model, its intensity response (Eq. 2), the initialisers
//! (ACUI, random, unit cube, FDK) and PLY interop.

pub mod fdk_init;
pub mod init;
pub mod model;
pub mod ply;
pub mod rirf;

pub use model::Gaussians;
