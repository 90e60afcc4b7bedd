//! The value tree an unpickled file yields: Python values as far as dataset pickles need them
//! ([`Py`]), with numpy arrays decoded to C order and native byte order ([`NdArray`]).

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
