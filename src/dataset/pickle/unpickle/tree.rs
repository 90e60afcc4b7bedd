//! The arena to value-tree conversion under the input limits of the stage header: every path
//! to every object is counted first ([`MAX_VALUES`] values, [`MAX_DEPTH`] levels), then the tree
//! is built, shared byte strings and arrays copied until their last reference and each copy
//! charged to the memory budget ([`MEMORY_FACTOR`]).

use super::{ArrayData, Machine, Obj, Py, MAX_DEPTH, MAX_VALUES, MEMORY_EXTRA, MEMORY_FACTOR, R};

impl<'a> Machine<'a> {
    /// Count how often each arena object is reached from `i` (a shared object once per path),
    /// failing when the expansion exceeds [`MAX_VALUES`] values or [`MAX_DEPTH`] levels.
    pub(super) fn count(&mut self, i: usize, depth: usize) -> R<()> {
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
    pub(super) fn tree(&mut self, i: usize, depth: usize) -> R<Py> {
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
    pub(super) fn trees(&mut self, v: &[usize], depth: usize) -> R<Vec<Py>> {
        v.iter().map(|&i| self.tree(i, depth + 1)).collect()
    }

    /// Take `n` bytes from the budget of memory derived from the file (decoded arrays, copies).
    pub(super) fn charge(&mut self, n: usize) -> R<()> {
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
