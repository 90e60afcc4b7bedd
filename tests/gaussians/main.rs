//! Gaussian models (`src/gaussians/`): the FDK initialiser, and hostile PLY files.

#[path = "../common/mod.rs"]
mod common;

mod hostile;
mod init_rules;
