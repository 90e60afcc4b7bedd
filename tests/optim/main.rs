//! Adam (`src/optim/`) against a hand computation.

#[path = "../common/mod.rs"]
mod common;

mod adam;
