//! The losses (`src/loss/`, Eqs. 6-9 and SSIM): finite differences and golden files.

#[path = "../common/mod.rs"]
mod common;

mod data_terms;
mod golden;
mod gradcheck;
mod settings;
mod window;
