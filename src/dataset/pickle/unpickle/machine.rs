//! The opcode interpreter of pickle protocols 0-5: byte readers, the object arena, stack, marks
//! and memo, and the opcode loop ([`Machine::run`]). What the recognised globals do is in
//! `globals`; the conversion of the arena into a value tree is in `tree`.

use super::{Machine, Obj, Py, R};

impl<'a> Machine<'a> {
    pub(super) fn err<T>(&self, msg: impl std::fmt::Display) -> R<T> {
        Err(format!("opcode at byte {}: {msg}", self.op_pos))
    }
    pub(super) fn take(&mut self, n: usize) -> R<&'a [u8]> {
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
    pub(super) fn u8(&mut self) -> R<u8> {
        Ok(self.take(1)?[0])
    }
    pub(super) fn u16(&mut self) -> R<u16> {
        let s = self.take(2)?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }
    pub(super) fn u32(&mut self) -> R<u32> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes(s.try_into().unwrap()))
    }
    pub(super) fn u64(&mut self) -> R<u64> {
        let s = self.take(8)?;
        Ok(u64::from_le_bytes(s.try_into().unwrap()))
    }
    pub(super) fn line(&mut self) -> R<&'a str> {
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
    pub(super) fn len_of(&self, n: u64) -> R<usize> {
        if n > (self.b.len() - self.pos) as u64 {
            return self.err(format!(
                "length {n} runs past the end of the file (truncated pickle?)"
            ));
        }
        Ok(n as usize)
    }
    pub(super) fn push(&mut self, o: Obj) {
        self.arena.push(o);
        self.stack.push(self.arena.len() - 1);
    }
    pub(super) fn push_py(&mut self, p: Py) {
        self.push(Obj::Py(p));
    }
    pub(super) fn pop(&mut self) -> R<usize> {
        match self.stack.pop() {
            Some(i) => Ok(i),
            None => self.err("stack underflow (corrupt pickle)"),
        }
    }
    pub(super) fn top(&self) -> R<usize> {
        match self.stack.last() {
            Some(&i) => Ok(i),
            None => self.err("stack underflow (corrupt pickle)"),
        }
    }
    pub(super) fn pop_mark(&mut self) -> R<Vec<usize>> {
        let m = match self.marks.pop() {
            Some(m) => m,
            None => return self.err("no MARK on the stack (corrupt pickle)"),
        };
        if m > self.stack.len() {
            return self.err("MARK above the stack top (corrupt pickle)");
        }
        Ok(self.stack.split_off(m))
    }
    pub(super) fn memo_put(&mut self, k: usize) -> R<()> {
        let t = self.top()?;
        self.memo.insert(k, t);
        Ok(())
    }
    pub(super) fn memo_get(&mut self, k: usize) -> R<()> {
        match self.memo.get(&k) {
            Some(&i) => {
                self.stack.push(i);
                Ok(())
            }
            None => self.err(format!("memo key {k} was never stored (corrupt pickle)")),
        }
    }
    pub(super) fn str_of(&self, i: usize) -> Option<&str> {
        match &self.arena[i] {
            Obj::Py(Py::Str(s)) => Some(s),
            _ => None,
        }
    }
    pub(super) fn bytes_of(&self, i: usize) -> Option<&[u8]> {
        match &self.arena[i] {
            Obj::Py(Py::Bytes(b)) => Some(b),
            _ => None,
        }
    }
    pub(super) fn int_of(&self, i: usize) -> Option<i64> {
        match &self.arena[i] {
            Obj::Py(Py::Int(v)) => Some(*v),
            Obj::Py(Py::Bool(v)) => Some(*v as i64),
            _ => None,
        }
    }
    pub(super) fn tuple_of(&self, i: usize) -> Option<Vec<usize>> {
        match &self.arena[i] {
            Obj::Tuple(v) | Obj::List(v) => Some(v.clone()),
            _ => None,
        }
    }

    pub(super) fn setitems(&mut self, dict: usize, kv: &[usize]) -> R<()> {
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

    pub(super) fn appends(&mut self, list: usize, vals: &[usize]) -> R<()> {
        match &mut self.arena[list] {
            Obj::List(items) => {
                items.extend_from_slice(vals);
                Ok(())
            }
            _ => self.err("APPEND(S) on something that is not a list"),
        }
    }

    pub(super) fn run(&mut self) -> R<usize> {
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
}
