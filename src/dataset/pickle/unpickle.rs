//! A small purpose-built unpickler for dataset pickles.
//!
//! It executes nothing: it interprets the opcodes of pickle protocols 0-5 that these
//! files use (dicts, lists, tuples, ints, floats, strings, bytes, memo, frames) and recognises a
//! short list of globals, never calling anything else:
//!
//! - `numpy.core.multiarray._reconstruct` (numpy 1.x) / `numpy._core.multiarray._reconstruct`
//!   (numpy 2.x) + `numpy.ndarray` + `BUILD (version, shape, dtype, is_fortran, bytes)`: the
//!   array layout of protocols 2-4, and of protocol 5 for non-contiguous arrays;
//! - `numpy.core.numeric._frombuffer` / `numpy._core.numeric._frombuffer` with an in-band
//!   `BYTEARRAY8` buffer: numpy's protocol-5 layout for contiguous arrays (out-of-band buffers
//!   cannot be in a file and are refused with a clear error);
//! - `numpy.dtype` (+ `BUILD` with the byte order), `numpy.core.multiarray.scalar` /
//!   `numpy._core.multiarray.scalar` (numpy scalars such as `np.float64`);
//! - `_codecs.encode` (how protocol 2 stores bytes), `builtins.bytearray`,
//!   `collections.OrderedDict`.
//!
//! Numeric dtypes: f4, f8, i1/i2/i4/i8, u1/u2/u4/u8, b1, either byte order, C or
//! Fortran order. Anything else is an error naming the file and the opcode's byte offset.
//!
//! Input limits: the value tree may hold at most [`MAX_VALUES`] values and [`MAX_DEPTH`] levels,
//! counted with every shared reference expanded (so a list shared with itself is refused before
//! anything is built, not only when it is deep); decoded arrays and copies of shared objects may
//! take at most [`MEMORY_FACTOR`] x the file size + [`MEMORY_EXTRA`] bytes. An array referenced
//! twice is valid and yields two equal arrays.
//!
//! In four parts, by job: `value` (the value tree returned: [`Py`], [`NdArray`]), `machine`
//! (the opcode interpreter: byte readers, stack, marks and memo), `globals` (the recognised
//! globals above: what GLOBAL/STACK_GLOBAL, REDUCE and BUILD do with them, numpy's array
//! layouts and dtypes), `tree` (the arena to value-tree conversion under the input limits).

use std::collections::HashMap;
use std::path::Path;

use crate::error::{Error, Result};

mod globals;
mod machine;
mod tree;
mod value;

pub use value::{ArrayData, NdArray, Py};

/// Most values (containers, numbers, strings, arrays) a pickle may expand to. A NAF dataset
/// pickle holds a few dozen; a list shared with itself k times over (`L[k+1] = [L[k], L[k]]`)
/// expands to 2^k, which is how a 380-byte file can ask for gigabytes.
pub const MAX_VALUES: usize = 1_000_000;

/// Deepest nesting accepted (NAF pickles are 3 levels deep).
pub const MAX_DEPTH: usize = 64;

/// Memory budget for what is derived from the file (decoded arrays, copies of shared objects):
/// `MEMORY_FACTOR` x the file size + `MEMORY_EXTRA` bytes. A u1 array decodes to 8 bytes per
/// element and an array referenced twice is held twice, so 16x covers honest files.
pub const MEMORY_FACTOR: usize = 16;
/// See [`MEMORY_FACTOR`].
pub const MEMORY_EXTRA: usize = 64 << 20;

/// An object of the unpickler's arena: a finished value, a container of arena indices (filled
/// in place, so memoised references see it complete), or a recognised global and the numpy
/// objects under construction.
#[derive(Clone, Debug)]
enum Obj {
    Py(Py),
    List(Vec<usize>),
    Tuple(Vec<usize>),
    Dict(Vec<(usize, usize)>),
    Global(String, String),
    Dtype { descr: String, order: u8 },
    ArrayStub,
    Moved,
}

/// The unpickler's state: the input and its read position, the object arena, stack, marks and
/// memo, and the input limits' counters.
struct Machine<'a> {
    b: &'a [u8],
    pos: usize,
    op_pos: usize,
    arena: Vec<Obj>,
    stack: Vec<usize>,
    marks: Vec<usize>,
    memo: HashMap<usize, usize>,
    /// The numpy module path seen (`numpy.core` or `numpy._core`), for the manifest.
    numpy_path: Option<String>,
    protocol: u8,
    /// Bytes of derived memory still allowed (see [`MEMORY_FACTOR`]).
    budget: usize,
    budget_total: usize,
    /// Values counted so far by [`Machine::count`], and visits per arena object.
    values: usize,
    visits: Vec<u32>,
}

type R<T> = std::result::Result<T, String>;

/// What [`parse`] found besides the value: the protocol and numpy's module path.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PickleInfo {
    pub protocol: u8,
    /// `numpy.core` (numpy 1.x) or `numpy._core` (numpy 2.x), when numpy objects occur.
    pub numpy_path: Option<String>,
}

/// Unpickle `bytes` (errors carry the byte offset of the failing opcode).
pub fn parse(bytes: &[u8]) -> std::result::Result<(Py, PickleInfo), String> {
    let mut m = Machine {
        b: bytes,
        pos: 0,
        op_pos: 0,
        arena: Vec::new(),
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        numpy_path: None,
        protocol: 0,
        budget: 0,
        budget_total: 0,
        values: 0,
        visits: Vec::new(),
    };
    m.budget_total = bytes
        .len()
        .saturating_mul(MEMORY_FACTOR)
        .saturating_add(MEMORY_EXTRA);
    m.budget = m.budget_total;
    let root = m.run()?;
    m.visits = vec![0; m.arena.len()];
    m.count(root, 0)?;
    let v = m.tree(root, 0)?;
    Ok((
        v,
        PickleInfo {
            protocol: m.protocol,
            numpy_path: m.numpy_path,
        },
    ))
}

/// Read and unpickle a file; errors name the file.
pub fn read(path: &Path) -> Result<(Py, PickleInfo)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse(&bytes).map_err(|msg| Error::format(path, "pickle", msg))
}
