//! Losses, Eqs. (6)-(9): SPWM weights, (weighted) Charbonnier, L1, SSIM and the hybrid loss.

pub mod charbonnier;
pub mod filters;
pub mod spwm;
pub mod ssim;
