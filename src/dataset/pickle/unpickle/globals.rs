//! The short list of globals the unpickler recognises (see the stage header) and what the
//! opcodes do with them: GLOBAL / STACK_GLOBAL refuse any other global, REDUCE calls one of them
//! (numpy's `_reconstruct`, `_frombuffer`, `dtype` and `scalar`, `_codecs.encode`, `bytearray`,
//! `OrderedDict`), BUILD sets a dtype's byte order or an array's state; numpy array bytes are
//! decoded to C order and native byte order.

use super::{ArrayData, Machine, NdArray, Obj, Py, R};

const NUMPY_PREFIXES: [&str; 2] = ["numpy.core", "numpy._core"];

impl<'a> Machine<'a> {
    pub(super) fn global(&mut self, module: &str, name: &str) -> R<()> {
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

    pub(super) fn dtype_of(&self, i: usize) -> R<(String, u8)> {
        match &self.arena[i] {
            Obj::Dtype { descr, order } => Ok((descr.clone(), *order)),
            _ => self.err("expected a numpy dtype"),
        }
    }

    /// Decode raw array bytes of `dtype` (descr like "f4", byte order '<', '>', '|', '=').
    pub(super) fn decode(
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

    pub(super) fn reduce(&mut self, callable: usize, args: usize) -> R<Obj> {
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

    pub(super) fn shape_of(&self, i: usize) -> R<Vec<usize>> {
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

    pub(super) fn build(&mut self, obj: usize, state: usize) -> R<()> {
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
}

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
