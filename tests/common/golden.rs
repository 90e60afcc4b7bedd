//! Reading and writing golden files (format: `golden/README.md`), shared by the golden tests.

#![allow(dead_code)]

use std::fmt::Write as _;
use std::path::PathBuf;

use serde_json::{json, Value};
use unispine::image2d::Image2d;

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `{"shape": [...], "data": [flat row-major]}`.
pub fn arr(shape: &[usize], data: Vec<f64>) -> Value {
    assert_eq!(shape.iter().product::<usize>(), data.len());
    json!({ "shape": shape, "data": data })
}

pub fn get_arr(v: &Value, key: &str) -> (Vec<usize>, Vec<f64>) {
    let a = &v[key];
    let shape = a["shape"]
        .as_array()
        .unwrap_or_else(|| panic!("`{key}` has no shape"))
        .iter()
        .map(|x| x.as_u64().unwrap() as usize)
        .collect();
    let data = a["data"]
        .as_array()
        .unwrap_or_else(|| panic!("`{key}` has no data"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    (shape, data)
}

pub fn rows<const N: usize>(v: &Value, key: &str) -> Vec<[f64; N]> {
    let (shape, data) = get_arr(v, key);
    assert_eq!(*shape.last().unwrap(), N, "`{key}` shape {shape:?}");
    data.chunks(N)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect()
}

/// JSON text with every float written with 17 significant digits.
pub fn write_value(out: &mut String, v: &Value, indent: usize) {
    let pad = "  ".repeat(indent);
    match v {
        Value::Null | Value::Bool(_) | Value::String(_) => out.push_str(&v.to_string()),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                write!(out, "{i}").unwrap();
            } else {
                write!(out, "{:.16e}", n.as_f64().unwrap()).unwrap();
            }
        }
        Value::Array(a) => {
            out.push('[');
            for (k, x) in a.iter().enumerate() {
                if k > 0 {
                    out.push_str(", ");
                }
                write_value(out, x, indent + 1);
            }
            out.push(']');
        }
        Value::Object(m) => {
            out.push_str("{\n");
            for (k, (key, x)) in m.iter().enumerate() {
                write!(out, "{pad}  {}: ", Value::String(key.clone())).unwrap();
                write_value(out, x, indent + 1);
                out.push_str(if k + 1 < m.len() { ",\n" } else { "\n" });
            }
            write!(out, "{pad}}}").unwrap();
        }
    }
}

pub fn get_image(v: &Value, key: &str) -> Image2d<f64> {
    let a = &v[key];
    let shape: Vec<usize> = a["shape"]
        .as_array()
        .unwrap_or_else(|| panic!("`{key}` has no shape"))
        .iter()
        .map(|x| x.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(shape.len(), 2, "`{key}` is not an image");
    let data = a["data"]
        .as_array()
        .unwrap_or_else(|| panic!("`{key}` has no data"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    Image2d::from_vec(shape[1], shape[0], data)
}

pub fn image_value(im: &Image2d<f64>) -> Value {
    arr(&[im.height, im.width], im.data.clone())
}
