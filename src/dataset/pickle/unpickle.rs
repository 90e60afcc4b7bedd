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

use std::collections::HashMap;
use std::path::Path;

use crate::error::{Error, Result};

/// Numeric data of a numpy array, in C order.
#[derive(Clone, Debug, PartialEq)]
pub enum ArrayData {
    F32(Vec<f32>),
    F64(Vec<f64>),
    Int(Vec<i64>),
    /// u8 values (also `b1`).
    U64(Vec<u64>),
}

/// A numpy array read from a pickle (data converted to C order and native byte order).
#[derive(Clone, Debug, PartialEq)]
pub struct NdArray {
    pub shape: Vec<usize>,
    /// The numpy dtype string, e.g. `<f4`.
    pub dtype: String,
    pub data: ArrayData,
}

impl NdArray {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    /// True when the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The values as f64 (C order).
    pub fn to_f64(&self) -> Vec<f64> {
        match &self.data {
            ArrayData::F32(v) => v.iter().map(|&x| x as f64).collect(),
            ArrayData::F64(v) => v.clone(),
            ArrayData::Int(v) => v.iter().map(|&x| x as f64).collect(),
            ArrayData::U64(v) => v.iter().map(|&x| x as f64).collect(),
        }
    }
    /// The values as f32 (C order; f64 values are rounded).
    pub fn to_f32(&self) -> Vec<f32> {
        match &self.data {
            ArrayData::F32(v) => v.clone(),
            ArrayData::F64(v) => v.iter().map(|&x| x as f32).collect(),
            ArrayData::Int(v) => v.iter().map(|&x| x as f32).collect(),
            ArrayData::U64(v) => v.iter().map(|&x| x as f32).collect(),
        }
    }
}

/// A Python value as far as dataset pickles need.
#[derive(Clone, Debug, PartialEq)]
pub enum Py {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    List(Vec<Py>),
    Tuple(Vec<Py>),
    /// Key/value pairs in insertion order.
    Dict(Vec<(Py, Py)>),
    Array(NdArray),
}

impl Py {
    /// Value of a string key of a dict.
    pub fn get(&self, key: &str) -> Option<&Py> {
        match self {
            Py::Dict(items) => items
                .iter()
                .find(|(k, _)| matches!(k, Py::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }
    /// A number (int, float, bool, or an array with one element) as f64.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Py::Int(i) => Some(*i as f64),
            Py::Float(f) => Some(*f),
            Py::Bool(b) => Some(*b as u8 as f64),
            Py::Array(a) if a.len() == 1 => Some(a.to_f64()[0]),
            _ => None,
        }
    }
    /// A flat sequence of numbers (list, tuple or 1-D array) as f64.
    pub fn as_f64_vec(&self) -> Option<Vec<f64>> {
        match self {
            Py::List(v) | Py::Tuple(v) => v.iter().map(|x| x.as_f64()).collect(),
            Py::Array(a) if a.shape.len() == 1 => Some(a.to_f64()),
            _ => None,
        }
    }
    /// Short type name for messages.
    pub fn type_name(&self) -> String {
        match self {
            Py::None => "None".into(),
            Py::Bool(_) => "bool".into(),
            Py::Int(_) => "int".into(),
            Py::Float(_) => "float".into(),
            Py::Str(_) => "str".into(),
            Py::Bytes(_) => "bytes".into(),
            Py::List(v) => format!("list of {}", v.len()),
            Py::Tuple(v) => format!("tuple of {}", v.len()),
            Py::Dict(_) => "dict".into(),
            Py::Array(a) => format!("ndarray {} {:?}", a.dtype, a.shape),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The unpickler.

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

const NUMPY_PREFIXES: [&str; 2] = ["numpy.core", "numpy._core"];

impl<'a> Machine<'a> {
    fn err<T>(&self, msg: impl std::fmt::Display) -> R<T> {
        Err(format!("opcode at byte {}: {msg}", self.op_pos))
    }
    fn take(&mut self, n: usize) -> R<&'a [u8]> {
        if self.pos.checked_add(n).is_none_or(|e| e > self.b.len()) {
            return self.err(format!(
                "truncated pickle: wanted {n} bytes at byte {}, the file has {}",
                self.pos,
                self.b.len()
            ));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self) -> R<u8> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> R<u16> {
        let s = self.take(2)?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }
    fn u32(&mut self) -> R<u32> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes(s.try_into().unwrap()))
    }
    fn u64(&mut self) -> R<u64> {
        let s = self.take(8)?;
        Ok(u64::from_le_bytes(s.try_into().unwrap()))
    }
    fn line(&mut self) -> R<&'a str> {
        let rest = &self.b[self.pos..];
        let n = match rest.iter().position(|&c| c == b'\n') {
            Some(n) => n,
            None => return self.err("truncated pickle: unterminated text line"),
        };
        let s =
            std::str::from_utf8(&rest[..n]).map_err(|_| "text line is not UTF-8".to_string())?;
        self.pos += n + 1;
        Ok(s)
    }
    fn len_of(&self, n: u64) -> R<usize> {
        if n > (self.b.len() - self.pos) as u64 {
            return self.err(format!(
                "length {n} runs past the end of the file (truncated pickle?)"
            ));
        }
        Ok(n as usize)
    }
    fn push(&mut self, o: Obj) {
        self.arena.push(o);
        self.stack.push(self.arena.len() - 1);
    }
    fn push_py(&mut self, p: Py) {
        self.push(Obj::Py(p));
    }
    fn pop(&mut self) -> R<usize> {
        match self.stack.pop() {
            Some(i) => Ok(i),
            None => self.err("stack underflow (corrupt pickle)"),
        }
    }
    fn top(&self) -> R<usize> {
        match self.stack.last() {
            Some(&i) => Ok(i),
            None => self.err("stack underflow (corrupt pickle)"),
        }
    }
    fn pop_mark(&mut self) -> R<Vec<usize>> {
        let m = match self.marks.pop() {
            Some(m) => m,
            None => return self.err("no MARK on the stack (corrupt pickle)"),
        };
        if m > self.stack.len() {
            return self.err("MARK above the stack top (corrupt pickle)");
        }
        Ok(self.stack.split_off(m))
    }
    fn memo_put(&mut self, k: usize) -> R<()> {
        let t = self.top()?;
        self.memo.insert(k, t);
        Ok(())
    }
    fn memo_get(&mut self, k: usize) -> R<()> {
        match self.memo.get(&k) {
            Some(&i) => {
                self.stack.push(i);
                Ok(())
            }
            None => self.err(format!("memo key {k} was never stored (corrupt pickle)")),
        }
    }
    fn str_of(&self, i: usize) -> Option<&str> {
        match &self.arena[i] {
            Obj::Py(Py::Str(s)) => Some(s),
            _ => None,
        }
    }
    fn bytes_of(&self, i: usize) -> Option<&[u8]> {
        match &self.arena[i] {
            Obj::Py(Py::Bytes(b)) => Some(b),
            _ => None,
        }
    }
    fn int_of(&self, i: usize) -> Option<i64> {
        match &self.arena[i] {
            Obj::Py(Py::Int(v)) => Some(*v),
            Obj::Py(Py::Bool(v)) => Some(*v as i64),
            _ => None,
        }
    }
    fn tuple_of(&self, i: usize) -> Option<Vec<usize>> {
        match &self.arena[i] {
            Obj::Tuple(v) | Obj::List(v) => Some(v.clone()),
            _ => None,
        }
    }

    fn global(&mut self, module: &str, name: &str) -> R<()> {
        let known = match (module, name) {
            ("numpy", "ndarray") | ("numpy", "dtype") => true,
            ("_codecs", "encode") => true,
            ("builtins" | "__builtin__", "bytearray") => true,
            ("collections", "OrderedDict") => true,
            (m, "_reconstruct" | "scalar")
                if NUMPY_PREFIXES
                    .iter()
                    .any(|p| m == format!("{p}.multiarray")) =>
            {
                true
            }
            (m, "_frombuffer") if NUMPY_PREFIXES.iter().any(|p| m == format!("{p}.numeric")) => {
                true
            }
            _ => false,
        };
        if !known {
            return self.err(format!(
                "unsupported global `{module}.{name}` (a dataset pickle holds only dicts, \
                 lists, numbers, strings and numpy arrays)"
            ));
        }
        if let Some(p) = NUMPY_PREFIXES
            .iter()
            .find(|p| module.starts_with(&format!("{p}.")))
        {
            self.numpy_path = Some(p.to_string());
        }
        self.push(Obj::Global(module.to_string(), name.to_string()));
        Ok(())
    }

    fn dtype_of(&self, i: usize) -> R<(String, u8)> {
        match &self.arena[i] {
            Obj::Dtype { descr, order } => Ok((descr.clone(), *order)),
            _ => self.err("expected a numpy dtype"),
        }
    }

    /// Decode raw array bytes of `dtype` (descr like "f4", byte order '<', '>', '|', '=').
    fn decode(
        &mut self,
        descr: &str,
        order: u8,
        shape: &[usize],
        fortran: bool,
        raw: &[u8],
    ) -> R<NdArray> {
        let (kind, size) = descr.split_at(1.min(descr.len()));
        let size: usize = size.parse().map_err(|_| {
            format!(
                "opcode at byte {}: unsupported dtype `{descr}`",
                self.op_pos
            )
        })?;
        let n = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| {
                format!(
                    "opcode at byte {}: array shape {shape:?} overflows",
                    self.op_pos
                )
            })?;
        if n.checked_mul(size) != Some(raw.len()) {
            return self.err(format!(
                "array data has {} bytes but shape {shape:?} of dtype {descr} needs {}",
                raw.len(),
                n.saturating_mul(size)
            ));
        }
        // Decoded size in memory: 4 bytes per f4 element, 8 for every other dtype.
        self.charge(n.saturating_mul(if (kind, size) == ("f", 4) { 4 } else { 8 }))?;
        let big = order == b'>';
        let chunk = |k: usize| -> [u8; 8] {
            let mut w = [0u8; 8];
            let s = &raw[k * size..(k + 1) * size];
            if big {
                for (d, &c) in w[..size].iter_mut().zip(s.iter().rev()) {
                    *d = c;
                }
            } else {
                w[..size].copy_from_slice(s);
            }
            w
        };
        let data = match (kind, size) {
            ("f", 4) => ArrayData::F32(
                (0..n)
                    .map(|k| f32::from_le_bytes(chunk(k)[..4].try_into().unwrap()))
                    .collect(),
            ),
            ("f", 8) => ArrayData::F64((0..n).map(|k| f64::from_le_bytes(chunk(k))).collect()),
            ("i", 1 | 2 | 4 | 8) => ArrayData::Int(
                (0..n)
                    .map(|k| {
                        let v = u64::from_le_bytes(chunk(k));
                        let sh = 64 - 8 * size as u32;
                        ((v << sh) as i64) >> sh
                    })
                    .collect(),
            ),
            ("u" | "b", 1 | 2 | 4 | 8) => {
                ArrayData::U64((0..n).map(|k| u64::from_le_bytes(chunk(k))).collect())
            }
            _ => return self.err(format!("unsupported dtype `{descr}` (numeric dtypes only)")),
        };
        let mut arr = NdArray {
            shape: shape.to_vec(),
            dtype: format!("{}{descr}", if big { '>' } else { '<' }),
            data,
        };
        if fortran && shape.len() > 1 {
            arr = fortran_to_c(arr);
        }
        Ok(arr)
    }

    fn reduce(&mut self, callable: usize, args: usize) -> R<Obj> {
        let (module, name) = match &self.arena[callable] {
            Obj::Global(m, n) => (m.clone(), n.clone()),
            _ => return self.err("REDUCE of something that is not a known global"),
        };
        let a = match self.tuple_of(args) {
            Some(a) => a,
            None => return self.err(format!("arguments of `{module}.{name}` are not a tuple")),
        };
        match name.as_str() {
            "_reconstruct" => Ok(Obj::ArrayStub),
            "dtype" => {
                let descr = a
                    .first()
                    .and_then(|&i| self.str_of(i))
                    .ok_or_else(|| {
                        format!(
                            "opcode at byte {}: numpy.dtype without a type string",
                            self.op_pos
                        )
                    })?
                    .to_string();
                Ok(Obj::Dtype { descr, order: b'=' })
            }
            "scalar" => {
                if a.len() != 2 {
                    return self.err("numpy scalar needs (dtype, bytes)");
                }
                let (descr, order) = self.dtype_of(a[0])?;
                let raw = self
                    .bytes_of(a[1])
                    .ok_or_else(|| {
                        format!("opcode at byte {}: numpy scalar without bytes", self.op_pos)
                    })?
                    .to_vec();
                let arr = self.decode(&descr, order, &[], false, &raw)?;
                Ok(Obj::Py(match arr.data {
                    ArrayData::F32(v) => Py::Float(v[0] as f64),
                    ArrayData::F64(v) => Py::Float(v[0]),
                    ArrayData::Int(v) => Py::Int(v[0]),
                    ArrayData::U64(v) => Py::Int(v[0] as i64),
                }))
            }
            "_frombuffer" => {
                if a.len() != 4 {
                    return self.err("numpy _frombuffer needs (buffer, dtype, shape, order)");
                }
                let (descr, order) = self.dtype_of(a[1])?;
                let shape = self.shape_of(a[2])?;
                let fortran = self.str_of(a[3]) == Some("F");
                let raw = match &self.arena[a[0]] {
                    Obj::Py(Py::Bytes(b)) => b.clone(),
                    _ => return self.err("numpy _frombuffer without an in-band buffer"),
                };
                self.charge(raw.len())?;
                Ok(Obj::Py(Py::Array(
                    self.decode(&descr, order, &shape, fortran, &raw)?,
                )))
            }
            "encode" => {
                // _codecs.encode(str, "latin1"): protocol 2's way of storing bytes.
                let s = a.first().and_then(|&i| self.str_of(i)).unwrap_or("");
                let enc = a.get(1).and_then(|&i| self.str_of(i)).unwrap_or("latin1");
                if enc != "latin1" && enc != "latin-1" {
                    return self.err(format!("_codecs.encode with encoding `{enc}`"));
                }
                let n = s.len();
                let s = s.to_string();
                self.charge(n)?;
                let mut out = Vec::with_capacity(n);
                for c in s.chars() {
                    if (c as u32) > 255 {
                        return self.err("_codecs.encode: character outside latin1");
                    }
                    out.push(c as u32 as u8);
                }
                Ok(Obj::Py(Py::Bytes(out)))
            }
            "bytearray" => match a.first() {
                None => Ok(Obj::Py(Py::Bytes(Vec::new()))),
                Some(&i) => match self.bytes_of(i).map(|b| b.to_vec()) {
                    Some(b) => {
                        self.charge(b.len())?;
                        Ok(Obj::Py(Py::Bytes(b)))
                    }
                    None => self.err("bytearray of something that is not bytes"),
                },
            },
            "OrderedDict" => {
                let mut items = Vec::new();
                if let Some(&i) = a.first() {
                    for p in self.tuple_of(i).unwrap_or_default() {
                        match self.tuple_of(p).as_deref() {
                            Some([k, v]) => items.push((*k, *v)),
                            _ => return self.err("OrderedDict items are not pairs"),
                        }
                    }
                }
                Ok(Obj::Dict(items))
            }
            _ => self.err(format!("`{module}.{name}` cannot be called here")),
        }
    }

    fn shape_of(&self, i: usize) -> R<Vec<usize>> {
        let t = match self.tuple_of(i) {
            Some(t) => t,
            None => match self.int_of(i) {
                Some(n) if n >= 0 => return Ok(vec![n as usize]),
                _ => return self.err("array shape is not a tuple of ints"),
            },
        };
        t.iter()
            .map(|&k| match self.int_of(k) {
                Some(n) if n >= 0 => Ok(n as usize),
                _ => self.err("array shape is not a tuple of non-negative ints"),
            })
            .collect()
    }

    fn build(&mut self, obj: usize, state: usize) -> R<()> {
        match self.arena[obj].clone() {
            Obj::Dtype { descr, .. } => {
                let st = self.tuple_of(state).unwrap_or_default();
                let order = st
                    .get(1)
                    .and_then(|&i| self.str_of(i))
                    .and_then(|s| s.bytes().next())
                    .unwrap_or(b'=');
                self.arena[obj] = Obj::Dtype { descr, order };
                Ok(())
            }
            Obj::ArrayStub => {
                let st = match self.tuple_of(state) {
                    Some(s) => s,
                    None => return self.err("ndarray state is not a tuple"),
                };
                // (version, shape, dtype, is_fortran, data) or, older, without the version.
                let st = match st.len() {
                    5 => &st[1..],
                    4 => &st[..],
                    n => return self.err(format!("ndarray state has {n} items (expected 4 or 5)")),
                };
                let shape = self.shape_of(st[0])?;
                let (descr, order) = self.dtype_of(st[1])?;
                let fortran = self.int_of(st[2]).unwrap_or(0) != 0;
                let raw =
                    match &self.arena[st[3]] {
                        Obj::Py(Py::Bytes(b)) => b.clone(),
                        Obj::Py(Py::Str(s)) => s.chars().map(|c| c as u32 as u8).collect(),
                        _ => return self.err(
                            "ndarray data is not a byte string (object arrays are not supported)",
                        ),
                    };
                self.charge(raw.len())?;
                let arr = self.decode(&descr, order, &shape, fortran, &raw)?;
                self.arena[obj] = Obj::Py(Py::Array(arr));
                Ok(())
            }
            Obj::Dict(mut items) => {
                // dict.__setstate__-like update (used by some reducers).
                if let Obj::Dict(more) = &self.arena[state] {
                    items.extend(more.iter().copied());
                    self.arena[obj] = Obj::Dict(items);
                    Ok(())
                } else {
                    self.err("BUILD of a dict with a non-dict state")
                }
            }
            _ => self.err("BUILD (object state) of an object that is not a numpy array or dtype"),
        }
    }

    fn setitems(&mut self, dict: usize, kv: &[usize]) -> R<()> {
        if !kv.len().is_multiple_of(2) {
            return self.err("odd number of items for SETITEMS");
        }
        match &mut self.arena[dict] {
            Obj::Dict(items) => {
                for p in kv.chunks(2) {
                    items.push((p[0], p[1]));
                }
                Ok(())
            }
            _ => self.err("SETITEM(S) on something that is not a dict"),
        }
    }

    fn appends(&mut self, list: usize, vals: &[usize]) -> R<()> {
        match &mut self.arena[list] {
            Obj::List(items) => {
                items.extend_from_slice(vals);
                Ok(())
            }
            _ => self.err("APPEND(S) on something that is not a list"),
        }
    }

    fn run(&mut self) -> R<usize> {
        loop {
            self.op_pos = self.pos;
            let op = self.u8()?;
            match op {
                0x80 => {
                    let p = self.u8()?;
                    if p > 5 {
                        return self.err(format!("pickle protocol {p} is newer than 5"));
                    }
                    self.protocol = p;
                }
                0x95 => {
                    self.u64()?; // FRAME: a length hint only
                }
                b'.' => return self.pop(),
                b'(' => self.marks.push(self.stack.len()),
                b'0' => {
                    self.pop()?;
                }
                b'1' => {
                    self.pop_mark()?;
                }
                b'2' => {
                    let t = self.top()?;
                    self.stack.push(t);
                }
                b'N' => self.push_py(Py::None),
                0x88 => self.push_py(Py::Bool(true)),
                0x89 => self.push_py(Py::Bool(false)),
                b'J' => {
                    let v = self.u32()? as i32 as i64;
                    self.push_py(Py::Int(v))
                }
                b'K' => {
                    let v = self.u8()? as i64;
                    self.push_py(Py::Int(v))
                }
                b'M' => {
                    let v = self.u16()? as i64;
                    self.push_py(Py::Int(v))
                }
                0x8a | 0x8b => {
                    let n = if op == 0x8a {
                        self.u8()? as u64
                    } else {
                        self.u32()? as u64
                    };
                    let n = self.len_of(n)?;
                    let s = self.take(n)?;
                    if n > 8 {
                        return self.err(format!("integer of {n} bytes is too large"));
                    }
                    let mut w = [0u8; 8];
                    w[..n].copy_from_slice(s);
                    let neg = n > 0 && s[n - 1] & 0x80 != 0;
                    if neg {
                        for x in w[n..].iter_mut() {
                            *x = 0xff;
                        }
                    }
                    self.push_py(Py::Int(i64::from_le_bytes(w)))
                }
                b'I' => {
                    let l = self.line()?;
                    let v = match l {
                        "01" => Py::Bool(true),
                        "00" => Py::Bool(false),
                        _ => Py::Int(l.parse().map_err(|_| format!("bad INT `{l}`"))?),
                    };
                    self.push_py(v)
                }
                b'L' => {
                    let l = self.line()?.trim_end_matches('L');
                    let v: i64 = l.parse().map_err(|_| format!("bad LONG `{l}`"))?;
                    self.push_py(Py::Int(v))
                }
                b'F' => {
                    let l = self.line()?;
                    let v: f64 = l.parse().map_err(|_| format!("bad FLOAT `{l}`"))?;
                    self.push_py(Py::Float(v))
                }
                b'G' => {
                    let s = self.take(8)?;
                    self.push_py(Py::Float(f64::from_be_bytes(s.try_into().unwrap())))
                }
                b'X' | 0x8c | 0x8d => {
                    let n = match op {
                        b'X' => self.u32()? as u64,
                        0x8c => self.u8()? as u64,
                        _ => self.u64()?,
                    };
                    let n = self.len_of(n)?;
                    let s = self.take(n)?;
                    let s = match std::str::from_utf8(s) {
                        Ok(s) => s.to_string(),
                        Err(_) => return self.err("string is not UTF-8"),
                    };
                    self.push_py(Py::Str(s))
                }
                b'V' => {
                    let l = self.line()?.to_string();
                    self.push_py(Py::Str(l))
                }
                b'B' | b'C' | 0x8e | 0x96 | b'T' | b'U' => {
                    let n = match op {
                        b'B' | b'T' => self.u32()? as u64,
                        b'C' | b'U' => self.u8()? as u64,
                        _ => self.u64()?,
                    };
                    let n = self.len_of(n)?;
                    let s = self.take(n)?.to_vec();
                    self.push_py(Py::Bytes(s))
                }
                0x97 | 0x98 => {
                    return self.err(
                        "out-of-band buffer (protocol 5 NEXT_BUFFER): the pickle was written \
                         with a buffer_callback and its array data is not in the file",
                    )
                }
                b'}' => self.push(Obj::Dict(Vec::new())),
                b']' => self.push(Obj::List(Vec::new())),
                b')' => self.push(Obj::Tuple(Vec::new())),
                b'd' => {
                    let kv = self.pop_mark()?;
                    self.push(Obj::Dict(Vec::new()));
                    let d = self.top()?;
                    self.setitems(d, &kv)?;
                }
                b'l' => {
                    let v = self.pop_mark()?;
                    self.push(Obj::List(v))
                }
                b't' => {
                    let v = self.pop_mark()?;
                    self.push(Obj::Tuple(v))
                }
                0x85..=0x87 => {
                    let n = (op - 0x84) as usize;
                    if self.stack.len() < n {
                        return self.err("stack underflow (corrupt pickle)");
                    }
                    let v = self.stack.split_off(self.stack.len() - n);
                    self.push(Obj::Tuple(v))
                }
                b's' => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    let d = self.top()?;
                    self.setitems(d, &[k, v])?;
                }
                b'u' => {
                    let kv = self.pop_mark()?;
                    let d = self.top()?;
                    self.setitems(d, &kv)?;
                }
                b'a' => {
                    let v = self.pop()?;
                    let l = self.top()?;
                    self.appends(l, &[v])?;
                }
                b'e' => {
                    let v = self.pop_mark()?;
                    let l = self.top()?;
                    self.appends(l, &v)?;
                }
                0x94 => {
                    let k = self.memo.len();
                    self.memo_put(k)?
                }
                b'q' => {
                    let k = self.u8()? as usize;
                    self.memo_put(k)?
                }
                b'r' => {
                    let k = self.u32()? as usize;
                    self.memo_put(k)?
                }
                b'p' => {
                    let l = self.line()?;
                    let k = l.parse().map_err(|_| format!("bad PUT `{l}`"))?;
                    self.memo_put(k)?
                }
                b'h' => {
                    let k = self.u8()? as usize;
                    self.memo_get(k)?
                }
                b'j' => {
                    let k = self.u32()? as usize;
                    self.memo_get(k)?
                }
                b'g' => {
                    let l = self.line()?;
                    let k = l.parse().map_err(|_| format!("bad GET `{l}`"))?;
                    self.memo_get(k)?
                }
                b'c' => {
                    let m = self.line()?.to_string();
                    let n = self.line()?.to_string();
                    self.global(&m, &n)?
                }
                0x93 => {
                    let n = self.pop()?;
                    let m = self.pop()?;
                    let (m, n) = match (self.str_of(m), self.str_of(n)) {
                        (Some(m), Some(n)) => (m.to_string(), n.to_string()),
                        _ => return self.err("STACK_GLOBAL needs two strings"),
                    };
                    self.global(&m, &n)?
                }
                b'R' | 0x81 => {
                    let args = self.pop()?;
                    let f = self.pop()?;
                    let o = self.reduce(f, args)?;
                    self.push(o)
                }
                b'b' => {
                    let st = self.pop()?;
                    let o = self.top()?;
                    self.build(o, st)?
                }
                b'P' | b'Q' => return self.err("persistent ids are not supported"),
                _ => {
                    return self.err(format!(
                        "unsupported pickle opcode 0x{op:02x} (not used by dataset pickles)"
                    ))
                }
            }
        }
    }

    /// Count how often each arena object is reached from `i` (a shared object once per path),
    /// failing when the expansion exceeds [`MAX_VALUES`] values or [`MAX_DEPTH`] levels.
    fn count(&mut self, i: usize, depth: usize) -> R<()> {
        if depth > MAX_DEPTH {
            return Err(format!(
                "nesting deeper than {MAX_DEPTH} levels (a cycle, or not a dataset pickle)"
            ));
        }
        self.values += 1;
        if self.values > MAX_VALUES {
            return Err(format!(
                "the pickle expands to more than {MAX_VALUES} values (objects shared many \
                 times over: a pickle bomb, or not a dataset pickle)"
            ));
        }
        self.visits[i] = self.visits[i].saturating_add(1);
        let children: Vec<usize> = match &self.arena[i] {
            Obj::List(v) | Obj::Tuple(v) => v.clone(),
            Obj::Dict(kv) => kv.iter().flat_map(|&(k, v)| [k, v]).collect(),
            _ => return Ok(()),
        };
        for c in children {
            self.count(c, depth + 1)?;
        }
        Ok(())
    }

    /// Convert an arena object into a value tree. An array, byte or text string reached more
    /// than once is copied (each copy charged to the memory budget) until its last reference,
    /// which takes it; call [`Machine::count`] on the root first.
    fn tree(&mut self, i: usize, depth: usize) -> R<Py> {
        if depth > MAX_DEPTH {
            return Err(format!("nesting deeper than {MAX_DEPTH} levels"));
        }
        self.visits[i] = self.visits[i].saturating_sub(1);
        let last = self.visits[i] == 0;
        let out = match &self.arena[i] {
            Obj::Py(p) => {
                let big = payload(p);
                if big > 0 && last {
                    match std::mem::replace(&mut self.arena[i], Obj::Moved) {
                        Obj::Py(p) => return Ok(p),
                        _ => unreachable!("matched Obj::Py above"),
                    }
                }
                let p = p.clone();
                self.charge(big)?;
                return Ok(p);
            }
            Obj::List(v) => {
                let v = v.clone();
                Py::List(self.trees(&v, depth)?)
            }
            Obj::Tuple(v) => {
                let v = v.clone();
                Py::Tuple(self.trees(&v, depth)?)
            }
            Obj::Dict(kv) => {
                let kv = kv.clone();
                let mut items = Vec::with_capacity(kv.len());
                for (k, v) in kv {
                    items.push((self.tree(k, depth + 1)?, self.tree(v, depth + 1)?));
                }
                Py::Dict(items)
            }
            Obj::Global(m, n) => return Err(format!("a bare reference to `{m}.{n}`")),
            Obj::Dtype { descr, .. } => return Err(format!("a bare numpy dtype `{descr}`")),
            Obj::ArrayStub => return Err("a numpy array without its data (BUILD missing)".into()),
            Obj::Moved => return Err("an object reached more often than counted".into()),
        };
        Ok(out)
    }
    fn trees(&mut self, v: &[usize], depth: usize) -> R<Vec<Py>> {
        v.iter().map(|&i| self.tree(i, depth + 1)).collect()
    }

    /// Take `n` bytes from the budget of memory derived from the file (decoded arrays, copies).
    fn charge(&mut self, n: usize) -> R<()> {
        if n > self.budget {
            return self.err(format!(
                "the pickle's objects would take more than {} bytes of memory ({MEMORY_FACTOR} \
                 x the file size + {} MiB): shared objects copied many times over, or not a \
                 dataset pickle",
                self.budget_total,
                MEMORY_EXTRA >> 20
            ));
        }
        self.budget -= n;
        Ok(())
    }
}

/// Bytes held by a value's payload (0 for small scalars and containers).
fn payload(p: &Py) -> usize {
    match p {
        Py::Str(s) => s.len(),
        Py::Bytes(b) => b.len(),
        Py::Array(a) => array_bytes(&a.data),
        _ => 0,
    }
}

/// Bytes held by array data in memory.
fn array_bytes(d: &ArrayData) -> usize {
    match d {
        ArrayData::F32(v) => 4 * v.len(),
        ArrayData::F64(v) => 8 * v.len(),
        ArrayData::Int(v) => 8 * v.len(),
        ArrayData::U64(v) => 8 * v.len(),
    }
}

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

fn fortran_to_c(a: NdArray) -> NdArray {
    let shape = a.shape.clone();
    let n = a.len();
    // Fortran strides: first axis fastest.
    let mut fstride = vec![1usize; shape.len()];
    for d in 1..shape.len() {
        fstride[d] = fstride[d - 1] * shape[d - 1];
    }
    let mut perm = Vec::with_capacity(n);
    let mut idx = vec![0usize; shape.len()];
    for _ in 0..n {
        perm.push(idx.iter().zip(&fstride).map(|(i, s)| i * s).sum::<usize>());
        // Increment the C-order multi-index (last axis fastest).
        for d in (0..shape.len()).rev() {
            idx[d] += 1;
            if idx[d] < shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    fn pick<T: Copy>(v: &[T], perm: &[usize]) -> Vec<T> {
        perm.iter().map(|&p| v[p]).collect()
    }
    let data = match &a.data {
        ArrayData::F32(v) => ArrayData::F32(pick(v, &perm)),
        ArrayData::F64(v) => ArrayData::F64(pick(v, &perm)),
        ArrayData::Int(v) => ArrayData::Int(pick(v, &perm)),
        ArrayData::U64(v) => ArrayData::U64(pick(v, &perm)),
    };
    NdArray { data, ..a }
}

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
