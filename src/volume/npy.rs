//! The `.npy` reader (NumPy's array file format, versions 1-3): volumes, dataset arrays and
//! weight images all go through [`read`].
//!
//! Our own header parser rather than `ndarray-npy`'s reader, so that a hostile header cannot make
//! us allocate: the file must be a regular file, the header at most [`MAX_HEADER`] bytes, and the
//! claimed shape times the item size (checked arithmetic) must equal the bytes that follow the
//! header before any buffer is reserved. Numeric dtypes only: `f4`, `f8`, `i1`/`i2`/`i4`/`i8`,
//! `u1`/`u2`/`u4`/`u8`, `b1`, either byte order; C or Fortran order.

use std::io::Read;
use std::path::Path;

use super::{Provenance, Volume};
use crate::error::{Error, Result};

/// Longest `.npy` header accepted, in bytes (numpy itself refuses headers over 10,000 bytes
/// by default; ours are under 128).
pub const MAX_HEADER: usize = 65536;

/// An array read from a `.npy` file: its shape, element type and raw data (file order).
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    /// The shape as stored.
    pub shape: Vec<usize>,
    /// The dtype string as stored, e.g. `<f4`.
    pub descr: String,
    /// True when the data is in Fortran order (first axis fastest).
    pub fortran: bool,
    kind: u8,
    size: usize,
    big_endian: bool,
    raw: Vec<u8>,
}

impl Array {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    /// True when the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// True for `f4` / `f8` arrays.
    pub fn is_float(&self) -> bool {
        self.kind == b'f'
    }
    /// Short numpy name of the element type (`float32`, `int16`, ...).
    pub fn type_name(&self) -> String {
        match self.kind {
            b'f' => format!("float{}", 8 * self.size),
            b'i' => format!("int{}", 8 * self.size),
            b'u' => format!("uint{}", 8 * self.size),
            _ => "bool".into(),
        }
    }

    /// Element `k` of the raw data (file order) as f64.
    fn value(&self, k: usize) -> f64 {
        let s = &self.raw[k * self.size..(k + 1) * self.size];
        let mut w = [0u8; 8];
        if self.big_endian {
            for (d, &c) in w[..self.size].iter_mut().zip(s.iter().rev()) {
                *d = c;
            }
        } else {
            w[..self.size].copy_from_slice(s);
        }
        let bits = u64::from_le_bytes(w);
        match (self.kind, self.size) {
            (b'f', 4) => f32::from_bits(bits as u32) as f64,
            (b'f', _) => f64::from_bits(bits),
            (b'i', n) => {
                let sh = 64 - 8 * n as u32;
                (((bits << sh) as i64) >> sh) as f64
            }
            _ => bits as f64,
        }
    }

    /// The values as f64 in C order (last axis fastest).
    pub fn to_f64_c(&self) -> Vec<f64> {
        self.ordered(false, |v| v)
    }
    /// The values as f32 in C order (last axis fastest; f64 values are rounded).
    pub fn to_f32_c(&self) -> Vec<f32> {
        self.ordered(false, |v| v as f32)
    }
    /// The values as f32 with the first axis fastest (Fortran order): for an array `[x, y, z]`
    /// this is our volume layout `data[i + nx * (j + ny * k)]`.
    pub fn to_f32_first_fastest(&self) -> Vec<f32> {
        self.ordered(true, |v| v as f32)
    }

    /// The values in C order (`first_fastest` false) or Fortran order (true).
    fn ordered<T>(&self, first_fastest: bool, conv: impl Fn(f64) -> T) -> Vec<T> {
        let n = self.len();
        if self.fortran == first_fastest || self.shape.len() < 2 {
            return (0..n).map(|k| conv(self.value(k))).collect();
        }
        // Strides of the file order, visited in the wanted order.
        let nd = self.shape.len();
        let mut stride = vec![1usize; nd];
        if self.fortran {
            for d in 1..nd {
                stride[d] = stride[d - 1] * self.shape[d - 1];
            }
        } else {
            for d in (0..nd - 1).rev() {
                stride[d] = stride[d + 1] * self.shape[d + 1];
            }
        }
        // Axes from fastest to slowest in the wanted order.
        let axes: Vec<usize> = if first_fastest {
            (0..nd).collect()
        } else {
            (0..nd).rev().collect()
        };
        let mut idx = vec![0usize; nd];
        let mut out = Vec::with_capacity(n);
        let mut off = 0usize;
        for _ in 0..n {
            out.push(conv(self.value(off)));
            for &d in &axes {
                idx[d] += 1;
                off += stride[d];
                if idx[d] < self.shape[d] {
                    break;
                }
                off -= stride[d] * self.shape[d];
                idx[d] = 0;
            }
        }
        out
    }
}

/// One token of the header's Python dict literal.
#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Punct(char),
    Str(String),
    Word(String),
}

fn tokens(h: &str) -> std::result::Result<Vec<Tok>, String> {
    let mut out = Vec::new();
    let mut it = h.chars().peekable();
    while let Some(&c) = it.peek() {
        match c {
            c if c.is_whitespace() => {
                it.next();
            }
            '{' | '}' | '(' | ')' | '[' | ']' | ',' | ':' => {
                it.next();
                out.push(Tok::Punct(c));
            }
            '\'' | '"' => {
                it.next();
                let mut s = String::new();
                loop {
                    match it.next() {
                        Some(d) if d == c => break,
                        Some(d) => s.push(d),
                        None => return Err("unterminated string".into()),
                    }
                }
                out.push(Tok::Str(s));
            }
            c if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '+' => {
                let mut s = String::new();
                while let Some(&d) = it.peek() {
                    if d.is_ascii_alphanumeric() || d == '_' || d == '-' || d == '+' {
                        s.push(d);
                        it.next();
                    } else {
                        break;
                    }
                }
                out.push(Tok::Word(s));
            }
            other => return Err(format!("unexpected character `{other}`")),
        }
    }
    Ok(out)
}

/// The three header keys: (descr, fortran_order, shape).
fn parse_dict(h: &str) -> std::result::Result<(String, bool, Vec<usize>), (&'static str, String)> {
    let t = tokens(h).map_err(|e| ("header", e))?;
    let mut descr = None;
    let mut fortran = None;
    let mut shape = None;
    if t.first() != Some(&Tok::Punct('{')) {
        return Err(("header", "not a Python dict literal".into()));
    }
    let mut i = 1;
    loop {
        match t.get(i) {
            Some(Tok::Punct('}')) => break,
            Some(Tok::Str(key)) if t.get(i + 1) == Some(&Tok::Punct(':')) => {
                i += 2;
                match key.as_str() {
                    "descr" => {
                        match t.get(i) {
                            Some(Tok::Str(s)) => {
                                descr = Some(s.clone());
                                i += 1;
                            }
                            _ => return Err((
                                "descr",
                                "not a simple dtype string (structured dtypes are not supported)"
                                    .into(),
                            )),
                        }
                    }
                    "fortran_order" => match t.get(i) {
                        Some(Tok::Word(w)) if w == "True" || w == "False" => {
                            fortran = Some(w == "True");
                            i += 1;
                        }
                        other => return Err(("fortran_order", format!("{other:?} is not a bool"))),
                    },
                    "shape" => {
                        if t.get(i) != Some(&Tok::Punct('(')) {
                            return Err(("shape", "not a tuple".into()));
                        }
                        i += 1;
                        let mut dims = Vec::new();
                        loop {
                            match t.get(i) {
                                Some(Tok::Punct(')')) => break,
                                Some(Tok::Punct(',')) => {}
                                Some(Tok::Word(w)) => {
                                    let d: usize =
                                        w.trim_end_matches('L').parse().map_err(|_| {
                                            (
                                                "shape",
                                                format!("`{w}` is not a non-negative integer"),
                                            )
                                        })?;
                                    dims.push(d);
                                    if dims.len() > 32 {
                                        return Err(("shape", "more than 32 dimensions".into()));
                                    }
                                }
                                other => {
                                    return Err(("shape", format!("unexpected {other:?}")));
                                }
                            }
                            i += 1;
                        }
                        i += 1;
                        shape = Some(dims);
                    }
                    other => return Err(("header", format!("unknown key `{other}`"))),
                }
                match t.get(i) {
                    Some(Tok::Punct(',')) => i += 1,
                    Some(Tok::Punct('}')) => {}
                    other => return Err(("header", format!("unexpected {other:?}"))),
                }
            }
            other => return Err(("header", format!("unexpected {other:?}"))),
        }
    }
    Ok((
        descr.ok_or(("descr", "missing key".to_string()))?,
        fortran.ok_or(("fortran_order", "missing key".to_string()))?,
        shape.ok_or(("shape", "missing key".to_string()))?,
    ))
}

/// Read a `.npy` file. Errors name the file and the header field (`magic`, `version`, `header`,
/// `descr`, `fortran_order`, `shape`, `data`).
pub fn read(path: &Path) -> Result<Array> {
    let (file, len) = super::open_regular(path)?;
    let fmt = |field: &str, msg: String| Error::format(path, field, msg);
    let mut rd = std::io::BufReader::new(file);
    let mut pre = [0u8; 8];
    rd.read_exact(&mut pre)
        .map_err(|_| fmt("header", format!("{len} bytes: too short for an .npy file")))?;
    if &pre[..6] != b"\x93NUMPY" {
        return Err(fmt(
            "header",
            "not an .npy file (no \\x93NUMPY magic)".into(),
        ));
    }
    let (hlen, prefix) = match pre[6] {
        1 => {
            let mut b = [0u8; 2];
            rd.read_exact(&mut b)
                .map_err(|_| fmt("header", "truncated".into()))?;
            (u16::from_le_bytes(b) as usize, 10)
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            rd.read_exact(&mut b)
                .map_err(|_| fmt("header", "truncated".into()))?;
            (u32::from_le_bytes(b) as usize, 12)
        }
        v => {
            return Err(fmt(
                "version",
                format!("format version {v} is not 1, 2 or 3"),
            ))
        }
    };
    if hlen > MAX_HEADER {
        return Err(fmt(
            "header",
            format!("header length {hlen} exceeds the {MAX_HEADER}-byte limit"),
        ));
    }
    if (prefix + hlen) as u64 > len {
        return Err(fmt(
            "header",
            format!("header length {hlen} runs past the end of the {len}-byte file"),
        ));
    }
    let mut hb = vec![0u8; hlen];
    rd.read_exact(&mut hb)
        .map_err(|e| fmt("header", format!("truncated: {e}")))?;
    let h =
        std::str::from_utf8(&hb).map_err(|_| fmt("header", "not text (invalid UTF-8)".into()))?;
    let (descr, fortran, shape) = parse_dict(h).map_err(|(f, m)| fmt(f, m))?;
    let (order, rest) = match descr.chars().next() {
        Some(c @ ('<' | '>' | '|' | '=')) => (c, &descr[1..]),
        _ => ('=', descr.as_str()),
    };
    let (kind, size) = match rest {
        "f4" => (b'f', 4),
        "f8" => (b'f', 8),
        "i1" => (b'i', 1),
        "i2" => (b'i', 2),
        "i4" => (b'i', 4),
        "i8" => (b'i', 8),
        "u1" => (b'u', 1),
        "u2" => (b'u', 2),
        "u4" => (b'u', 4),
        "u8" => (b'u', 8),
        "b1" => (b'b', 1),
        _ => {
            return Err(fmt(
                "descr",
                format!(
                    "unsupported dtype `{descr}`: numeric dtypes only (f4, f8, i1-i8, u1-u8, b1)"
                ),
            ))
        }
    };
    let big_endian = order == '>' || (order == '=' && cfg!(target_endian = "big"));
    let need = shape
        .iter()
        .try_fold(size, |a: usize, &d| a.checked_mul(d))
        .ok_or_else(|| {
            fmt(
                "shape",
                format!("{shape:?} of {descr} overflows the address space"),
            )
        })?;
    let have = len - (prefix + hlen) as u64;
    if need as u64 != have {
        return Err(fmt(
            if (need as u64) > have { "data" } else { "shape" },
            format!(
                "shape {shape:?} of {descr} needs {need} data bytes, the file holds {have} after its \
                 header{}",
                if (need as u64) > have {
                    " (truncated, or a false shape)"
                } else {
                    ""
                }
            ),
        ));
    }
    let mut raw = Vec::new();
    raw.try_reserve_exact(need)
        .map_err(|_| fmt("data", format!("cannot hold {need} bytes in memory")))?;
    rd.take(have)
        .read_to_end(&mut raw)
        .map_err(|e| Error::io(path, e))?;
    if raw.len() != need {
        return Err(fmt(
            "data",
            format!("file shrank while read: {} of {need} bytes", raw.len()),
        ));
    }
    Ok(Array {
        shape,
        descr,
        fortran,
        kind,
        size,
        big_endian,
        raw,
    })
}

/// Read a `.npy` array `[x, y, z]` (float32, float64, uint8 or int16; C or Fortran order) as a
/// volume with 1 mm voxels.
pub fn read_volume(path: &Path) -> Result<Volume<f32>> {
    let a = read(path)?;
    if !matches!(
        a.type_name().as_str(),
        "float32" | "float64" | "uint8" | "int16"
    ) {
        return Err(Error::format(
            path,
            "descr",
            format!(
                "unsupported dtype `{}`: .npy volumes must be float32, float64, uint8 or int16",
                a.descr
            ),
        ));
    }
    if a.shape.len() != 3 {
        return Err(Error::format(
            path,
            "shape",
            format!("{:?} is not a 3-D array [x, y, z]", a.shape),
        ));
    }
    let dims = [a.shape[0], a.shape[1], a.shape[2]];
    if dims.contains(&0) {
        return Err(Error::format(
            path,
            "shape",
            format!("empty array of shape {dims:?}"),
        ));
    }
    let data = a.to_f32_first_fastest();
    Ok(Volume {
        data,
        dims,
        spacing: [1.0; 3],
        offset: [0.0; 3],
        provenance: Provenance {
            source: path.display().to_string(),
            file_affine: None,
            steps: vec![format!(
                "read .npy {} array [x, y, z] = {dims:?}; voxel size 1 mm assumed \
                 (.npy carries none); centred (offset 0)",
                a.type_name()
            )],
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, header: &str, data: &[u8]) -> std::path::PathBuf {
        let mut h = header.to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(' ');
        }
        h.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(h.len() as u16).to_le_bytes());
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(data);
        let p = dir.join(name);
        std::fs::write(&p, b).unwrap();
        p
    }

    #[test]
    fn c_and_fortran_orders_give_the_same_values() {
        let dir = tempfile::tempdir().unwrap();
        // Array [[0, 1, 2], [3, 4, 5]] (shape (2, 3)) as i2 in C order and in Fortran order.
        let c: Vec<u8> = [0i16, 1, 2, 3, 4, 5]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let f: Vec<u8> = [0i16, 3, 1, 4, 2, 5]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let pc = write(
            dir.path(),
            "c.npy",
            "{'descr': '<i2', 'fortran_order': False, 'shape': (2, 3), }",
            &c,
        );
        let pf = write(
            dir.path(),
            "f.npy",
            "{'descr': '<i2', 'fortran_order': True, 'shape': (2, 3), }",
            &f,
        );
        for p in [pc, pf] {
            let a = read(&p).unwrap();
            assert_eq!(a.to_f64_c(), vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
            assert_eq!(a.to_f32_first_fastest(), vec![0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
        }
    }

    #[test]
    fn big_endian_and_claimed_sizes_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let data: Vec<u8> = [1.5f64, -2.0]
            .iter()
            .flat_map(|v| v.to_be_bytes())
            .collect();
        let p = write(
            dir.path(),
            "be.npy",
            "{'descr': '>f8', 'fortran_order': False, 'shape': (2,), }",
            &data,
        );
        assert_eq!(read(&p).unwrap().to_f64_c(), vec![1.5, -2.0]);
        let p = write(
            dir.path(),
            "huge.npy",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (4000, 4000, 4000), }",
            &[0u8; 16],
        );
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("huge.npy") && e.contains("`data`"), "{e}");
        let p = write(
            dir.path(),
            "ovf.npy",
            "{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296), }",
            &[],
        );
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("overflows"), "{e}");
    }
}
