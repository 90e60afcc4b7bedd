//! Reading and writing golden files (format: `golden/README.md`), shared by the golden tests.

#![allow(dead_code)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};
use unispine::image2d::Image2d;
use unispine::render::ColorMode;

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
    let (shape, data) = get_arr(v, key);
    assert_eq!(shape.len(), 2, "`{key}` is not an image");
    Image2d::from_vec(shape[1], shape[0], data)
}

pub fn image_value(im: &Image2d<f64>) -> Value {
    arr(&[im.height, im.width], im.data.clone())
}

/// A case in the golden format with empty outputs (filled when the files are regenerated).
pub fn new_case(
    equation: &str,
    description: &str,
    inputs: Value,
    tol: [f64; 2],
    checked_by: &str,
) -> Value {
    json!({
        "equation": equation,
        "description": description,
        "inputs": inputs,
        "outputs": {},
        "tolerance": { "abs": tol[0], "rel": tol[1] },
        "checked_by": checked_by,
    })
}

/// `golden/<folder>/<stem>.json`.
pub fn case_path(folder: &str, stem: &str) -> PathBuf {
    root()
        .join("golden")
        .join(folder)
        .join(format!("{stem}.json"))
}

/// Whether the golden files are to be rewritten (`UNISPINE_REGEN_GOLDEN=1`).
pub fn regen_requested() -> bool {
    std::env::var("UNISPINE_REGEN_GOLDEN").is_ok_and(|v| v == "1")
}

/// Write a whole case (inputs, outputs, tolerance, provenance) in the golden format.
pub fn write_case(folder: &str, stem: &str, case: &Value) {
    let path = case_path(folder, stem);
    let mut s = String::new();
    write_value(&mut s, case, 0);
    s.push('\n');
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, s).unwrap();
    println!("wrote {}", path.display());
}

/// Read a golden file.
pub fn read_case(folder: &str, stem: &str) -> Value {
    let p = case_path(folder, stem);
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (regenerate with UNISPINE_REGEN_GOLDEN=1)",
            p.display()
        )
    });
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Read a golden file, check it has every field of the format, recompute its outputs from its
/// inputs with `compute` and compare them within the file's own tolerance.
pub fn check_case(folder: &str, stem: &str, compute: impl Fn(&Value) -> Value) {
    let path = case_path(folder, stem);
    let file = read_case(folder, stem);
    for key in [
        "equation",
        "description",
        "inputs",
        "outputs",
        "tolerance",
        "checked_by",
    ] {
        assert!(
            file.get(key).is_some(),
            "{}: missing `{key}`",
            path.display()
        );
    }
    let got = compute(&file["inputs"]);
    let abs = file["tolerance"]["abs"].as_f64().unwrap();
    let rel = file["tolerance"]["rel"].as_f64().unwrap();
    compare(&path, "outputs", &got, &file["outputs"], abs, rel);
}

/// Recursive comparison of computed and golden outputs: same keys and lengths, numbers within
/// abs + rel |golden|, everything else equal. `key` names the innermost field in messages.
pub fn compare(path: &Path, key: &str, got: &Value, want: &Value, abs: f64, rel: f64) {
    match (got, want) {
        (Value::Object(a), Value::Object(b)) => {
            assert_eq!(
                a.keys().collect::<Vec<_>>(),
                b.keys().collect::<Vec<_>>(),
                "{}: keys of `{key}`",
                path.display()
            );
            for (k, x) in a {
                compare(path, k, x, &b[k], abs, rel);
            }
        }
        (Value::Array(a), Value::Array(b)) => {
            assert_eq!(a.len(), b.len(), "{}: `{key}` length", path.display());
            for (x, y) in a.iter().zip(b) {
                compare(path, key, x, y, abs, rel);
            }
        }
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!(
                (x - y).abs() <= abs + rel * y.abs(),
                "{}: `{key}`: got {x:e}, golden {y:e}",
                path.display()
            );
        }
        _ => assert_eq!(got, want, "{}: `{key}`", path.display()),
    }
}

/// Run an independent numpy reference script of `tools/` (it checks the golden files itself and
/// exits non-zero on a mismatch). Without python3 + numpy the check is skipped with a note,
/// except under `CI=true`, where that is an error.
pub fn run_numpy_reference(script: &str) {
    let ci = std::env::var("CI").is_ok_and(|v| v == "true");
    let have = std::process::Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        assert!(
            !ci,
            "CI=true but python3 with numpy is not available for {script}"
        );
        super::skip::skipped(
            script,
            "python3 with numpy is not available (CI=true makes this an error)",
        );
        return;
    }
    let out = std::process::Command::new("python3")
        .arg(script)
        .current_dir(root())
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    println!("{text}");
    assert!(out.status.success(), "{script} failed:\n{text}");
}

/// The inputs of an Eq. (2) intensity case for `n` Gaussians: the colour mode, the means and
/// camera centre (zeros unless the mode is view-dependent SH) and the active feature counts.
pub fn intensity_inputs(v: &Value, n: usize) -> (ColorMode, Vec<[f64; 3]>, [f64; 3], Vec<usize>) {
    let mode: ColorMode = serde_json::from_value(v["color_mode"].clone())
        .unwrap_or_else(|e| panic!("`color_mode`: {e}"));
    let (means, centre) = if mode == ColorMode::Sh {
        let c: Vec<f64> = v["camera_centre"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        (rows::<3>(v, "means"), [c[0], c[1], c[2]])
    } else {
        (vec![[0.0; 3]; n], [0.0; 3])
    };
    let actives: Vec<usize> = v["active_features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap() as usize)
        .collect();
    (mode, means, centre, actives)
}
