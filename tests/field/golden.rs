//! Golden files of the neural-field encoders (`golden/field-*`): small deterministic inputs ->
//! the encoding and the gradients of L = sum(d_out * encoding) with respect to every parameter
//! array and to the points, so another implementation can check its encoders forward and
//! backward without running Rust:
//! - `field-frequency`: NeRF positional encoding (no parameters: d_points only);
//! - `field-hash-grid`: torch-ngp's hash grid as NAF uses it (a dense level and two hashed);
//! - `field-tensorf-vm`: SAX-NeRF's TensoRF VM, upstream line factor and corrected lines;
//! - `field-dense-grid`: the dense grid, align-corners and torch-ngp level mappings.
//!
//! (a) Recomputes every case with the f64 path and compares within the file's tolerance.
//! (b) Runs `python3 tools/field_reference.py`: numpy forwards written from the conventions
//!     (PyTorch `grid_sample`, torch-ngp's indexing), differentiated by the complex step.
//!
//! Regenerate: `UNISPINE_REGEN_GOLDEN=1 cargo test --release --test field golden::`.

use crate::common;
use common::golden::*;

use serde_json::{json, Value};
use unispine::audit::field as fc;
use unispine::field::encode::{
    DenseGrid, Encoder, Frequency, GridMap, HashGrid, TensorVm, VmLines,
};
use unispine::simd::Simd;

const TOL: [f64; 2] = [1e-12, 1e-10];

const CHECKED_BY: &str = "tools/field_reference.py (numpy forward written from the \
    conventions in golden/README.md, complex-safe; every gradient by the complex step \
    Im L(x + i h e_j) / h, h = 1e-30, one input at a time, cell and tap choices taken at the \
    real point); central finite differences of the same backward in `unispine gradcheck` \
    (src/audit/field.rs)";

const BOUND: f64 = 0.3;

/// Test points: 6 from the gradient check's generator (kept off cell faces) and one at the
/// clamp of the cube (`+-(bound - 1e-6)`).
fn points() -> Vec<[f64; 3]> {
    let mut p = fc::points(6, 500);
    p.push([BOUND - 1e-6, -(BOUND - 1e-6), 0.1234]);
    p
}

fn flat(p: &[[f64; 3]]) -> Vec<f64> {
    p.concat()
}

/// Every case: (folder, stem, description, encoder, inputs without the encoder arrays).
fn cases() -> Vec<(&'static str, &'static str, String, Encoder)> {
    let vm = |lines| {
        Encoder::TensorVm(TensorVm {
            resolution: 6,
            components: 2,
            out_dim: 4,
            bound: BOUND,
            lines,
        })
    };
    let dense = |resolution, map| {
        Encoder::DenseGrid(DenseGrid {
            resolution,
            features: 2,
            bound: BOUND,
            map,
        })
    };
    vec![
        (
            "field-frequency",
            "bands-3",
            "NeRF positional encoding of the point in metres, [x, sin(2^0 x), cos(2^0 x), ..., \
             sin(2^(B-1) x), cos(2^(B-1) x)], each block 3-wide (3 + 6 B values)"
                .into(),
            Encoder::Frequency(Frequency { bands: 3 }),
        ),
        (
            "field-hash-grid",
            "dense-and-hashed",
            "torch-ngp hash grid (NAF): u = (x + bound) / (2 bound); level l resolution R = \
             base 2^l, pos = u (R - 1) + 1/2, corner floor(pos), trilinear weights (corner bit d \
             set: frac_d, else 1 - frac_d); level size min(T, (R + 1)^3); dense index \
             i + (R + 1)(j + (R + 1) k) when (R + 1)^3 <= T, else (i ^ j*19349663 ^ \
             k*83492791) mod T in u32 arithmetic; table rows are the entries of every level \
             in order (offsets), F features each; output level-major. Here R = 2 (dense), 4, 8 \
             (hashed), T = 64"
                .into(),
            Encoder::HashGrid(HashGrid::new(3, 2, 6, 2, BOUND)),
        ),
        (
            "field-tensorf-vm",
            "upstream-lines",
            vm_description("upstream: the line factor is F.grid_sample(density_plane[i], (0, c_v)) \
                 (SAX-NeRF passes the plane, not the line), i.e. the plane read at pixel x = (N - 1) / 2 \
                 (between two texel columns for even N), y = pixel of c_v; the lines are unused \
                 (d_lines = 0)"),
            vm(VmLines::Upstream),
        ),
        (
            "field-tensorf-vm",
            "corrected-lines",
            vm_description("corrected: the line factor is F.grid_sample(density_line[i], (0, c_v)) on \
                 the (1, C, N, 1) line, i.e. linear interpolation of line i at pixel (c_v + 1) / 2 (N - 1)"),
            vm(VmLines::Corrected),
        ),
        (
            "field-dense-grid",
            "align-corners",
            "dense grid of N^3 vertices, table [z, y, x, F]; pos = (x / bound + 1) / 2 (N - 1) \
             per axis (grid_sample align_corners=True), trilinear over corners floor(pos) + {0, 1}, \
             corners outside the grid read 0"
                .into(),
            dense(5, GridMap::AlignCorners),
        ),
        (
            "field-dense-grid",
            "ngp-level",
            "dense grid of N^3 vertices, table [z, y, x, F]; torch-ngp level mapping pos = \
             (x + bound) / (2 bound) (N - 2) + 1/2 (a hash-grid level of resolution R = N - 1), \
             trilinear over corners floor(pos) + {0, 1}"
                .into(),
            dense(5, GridMap::Ngp),
        ),
    ]
}

fn vm_description(lines: &str) -> String {
    format!(
        "TensoRF VM as SAX-NeRF src/encoder/tensorf_encoder.py: c = x / bound; plane i on axes \
         (x, y), (x, z), (y, z) with shape [C, N, N] (row = second axis, column = first), line i \
         on axis z, y, x with shape [C, N]; every read is F.grid_sample(align_corners=True, \
         bilinear, zero padding): pixel = (c + 1) / 2 (size - 1); feature i C + r = P_ir * L_ir; \
         encoding = basis @ features, basis [out, 3C] (Linear without bias). Line factor: {lines}"
    )
}

fn params_value(e: &Encoder, p: &[f64]) -> Value {
    match e {
        Encoder::Frequency(_) => json!({}),
        Encoder::HashGrid(h) => {
            json!({ "table": arr(&[h.offsets[h.levels], h.features], p.to_vec()) })
        }
        Encoder::DenseGrid(d) => {
            let n = d.resolution;
            json!({ "table": arr(&[n, n, n, d.features], p.to_vec()) })
        }
        Encoder::TensorVm(v) => {
            let (l, b) = v.offsets();
            let (n, c) = (v.resolution, v.components);
            json!({
                "planes": arr(&[3, c, n, n], p[..l].to_vec()),
                "lines": arr(&[3, c, n], p[l..b].to_vec()),
                "basis": arr(&[v.out_dim, 3 * c], p[b..].to_vec()),
            })
        }
    }
}

fn settings(e: &Encoder) -> Value {
    match e {
        Encoder::Frequency(f) => json!({ "kind": "frequency", "bands": f.bands }),
        Encoder::HashGrid(h) => json!({
            "kind": "hash-grid", "levels": h.levels, "features": h.features,
            "log2_table_size": h.log2_table, "base_resolution": h.base, "bound": h.bound,
            "offsets": h.offsets,
        }),
        Encoder::DenseGrid(d) => json!({
            "kind": "dense-grid", "resolution": d.resolution, "features": d.features,
            "bound": d.bound, "map": match d.map { GridMap::Ngp => "ngp", GridMap::AlignCorners => "align-corners" },
        }),
        Encoder::TensorVm(v) => json!({
            "kind": "tensorf-vm", "resolution": v.resolution, "components": v.components,
            "out_dim": v.out_dim, "bound": v.bound,
            "lines": match v.lines { VmLines::Upstream => "upstream", VmLines::Corrected => "corrected" },
        }),
    }
}

/// Parameters from the file's inputs (in the library's flat layout, which is the files').
fn read_params(e: &Encoder, inputs: &Value) -> Vec<f64> {
    let names: &[&str] = match e {
        Encoder::Frequency(_) => &[],
        Encoder::HashGrid(_) | Encoder::DenseGrid(_) => &["table"],
        Encoder::TensorVm(_) => &["planes", "lines", "basis"],
    };
    names
        .iter()
        .flat_map(|k| get_arr(&inputs["params"], k).1)
        .collect()
}

fn compute(e: &Encoder, inputs: &Value) -> Value {
    let p = read_params(e, inputs);
    let pts = rows::<3>(inputs, "points");
    let od = e.out_dim();
    let (_, g) = get_arr(inputs, "d_out");
    let mut enc = vec![0.0; pts.len() * od];
    for (x, o) in pts.iter().zip(enc.chunks_mut(od)) {
        e.encode(&p, *x, o);
    }
    let mut gp = vec![0.0; e.n_params()];
    e.backward(Simd::active(), &p, &pts, &g, od, 0, &mut gp);
    let gx: Vec<f64> = pts
        .iter()
        .enumerate()
        .flat_map(|(n, x)| e.input_vjp(&p, *x, &g[n * od..(n + 1) * od]))
        .collect();
    let mut out = json!({ "encoding": arr(&[pts.len(), od], enc) });
    if let Value::Object(m) = params_value(e, &gp) {
        for (k, v) in m {
            out[format!("d_{k}")] = v;
        }
    }
    out["d_points"] = arr(&[pts.len(), 3], gx);
    out
}

fn full_case(folder: &str, stem: &str, desc: &str, e: &Encoder, k: u64) -> (Value, Value) {
    let pts = points();
    let p = fc::uniform(e.n_params(), -0.5, 0.5, 600 + k);
    let g = fc::uniform(pts.len() * e.out_dim(), -1.0, 1.0, 700 + k);
    let inputs = json!({
        "encoder": settings(e),
        "params": params_value(e, &p),
        "points": arr(&[pts.len(), 3], flat(&pts)),
        "d_out": arr(&[pts.len(), e.out_dim()], g),
    });
    let case = new_case(
        "neural-field encoder (Table 1 baselines)",
        &format!(
            "{desc}. Outputs: encoding [points, out] and the gradients of L = sum(d_out * \
             encoding) with respect to every parameter array (d_<name>, same shape) and to the \
             points (d_points; upstream never differentiates the points, an audit quantity). \
             Case {folder}/{stem}."
        ),
        inputs.clone(),
        TOL,
        CHECKED_BY,
    );
    (case, inputs)
}

#[test]
fn field_golden_files_match_the_rust_encoders() {
    let mut checked = 0;
    for (k, (folder, stem, desc, e)) in cases().into_iter().enumerate() {
        if regen_requested() {
            let (mut c, inputs) = full_case(folder, stem, &desc, &e, k as u64);
            c["outputs"] = compute(&e, &inputs);
            write_case(folder, stem, &c);
        }
        check_case(folder, stem, |inputs| compute(&e, inputs));
        checked += 1;
    }
    assert_eq!(checked, 6);
}

#[test]
fn field_golden_cases_exercise_each_behaviour() {
    // Upstream VM: zero line gradient; corrected: not.
    let up = read_case("field-tensorf-vm", "upstream-lines");
    assert!(get_arr(&up["outputs"], "d_lines")
        .1
        .iter()
        .all(|v| *v == 0.0));
    let co = read_case("field-tensorf-vm", "corrected-lines");
    assert!(get_arr(&co["outputs"], "d_lines")
        .1
        .iter()
        .any(|v| *v != 0.0));
    // Hash grid: some table rows of the hashed levels receive gradient.
    let h = read_case("field-hash-grid", "dense-and-hashed");
    let (_, d) = get_arr(&h["outputs"], "d_table");
    assert!(d[27 * 2..].iter().filter(|v| **v != 0.0).count() > 20);
    assert!(d[..27 * 2].iter().any(|v| *v != 0.0));
}

#[test]
fn numpy_reference_agrees() {
    run_numpy_reference("tools/field_reference.py");
}
