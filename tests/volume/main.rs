//! Volume readers, conversions and resampling (`src/volume/`), the built-in phantom and the
//! ultrasound proxy, and hostile volume files.

#[path = "../common/mod.rs"]
mod common;

mod hostile;
mod io;
mod phantom;
