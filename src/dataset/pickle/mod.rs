//! Import of NAF / SAX-NeRF / X-Gaussian / UniSpine-GS dataset pickles: a general unpickler
//! that executes nothing ([`unpickle`]) and the NAF dict layout on top of it ([`naf`]).

pub mod naf;
pub mod unpickle;

pub use naf::{from_naf, import, ImportOptions};
pub use unpickle::{parse, read, ArrayData, NdArray, PickleInfo, Py};
