//! The field's model file read back with an npz reader and evaluated by an f64 MLP written
//! from the file format alone (the `src/field/model.rs` header: `z = x @ w{i} + b{i}`,
//! LeakyReLU 0.01 between layers, `cat([encoding, h])` into each skip layer, the output
//! activation of `mlp_meta[3]`), on the frequency encoding of the point written out by hand.

use ndarray::{Array1, Array2};
use unispine::field::{model, EncoderConfig, Field};

fn leaky(x: f64) -> f64 {
    if x > 0.0 {
        x
    } else {
        0.01 * x
    }
}

/// `field` saved as a model file in a temporary folder (kept while the first value lives), and
/// a reader of that file.
fn saved(field: &Field<f32>) -> (tempfile::TempDir, ndarray_npy::NpzReader<std::fs::File>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.npz");
    model::save(&path, field).unwrap();
    let npz = ndarray_npy::NpzReader::new(std::fs::File::open(&path).unwrap()).unwrap();
    (dir, npz)
}

#[test]
fn a_saved_field_evaluates_to_its_density_from_the_file_alone() {
    let bands = 3;
    let cfg = crate::small_cfg(EncoderConfig::Frequency { bands });
    let mut field = Field::<f32>::new(&cfg).unwrap();
    // Every parameter distinct and non-zero, so that a weight stored in another's place shows.
    for (i, p) in field.params.iter_mut().enumerate() {
        *p = (((i * 7919) % 1013) as f32 / 1013.0 - 0.5) * 0.9;
    }
    let (_dir, mut npz) = saved(&field);
    let meta: Array1<i64> = npz.by_name("mlp_meta").unwrap();
    let skips: Array1<i64> = npz.by_name("skips").unwrap();
    let fb: Array1<i64> = npz.by_name("freq_bands").unwrap();
    let (layers, hidden, ed) = (meta[0] as usize, meta[1] as usize, meta[2] as usize);
    assert_eq!((layers, hidden, fb[0] as usize), (4, 8, bands));
    assert_eq!(ed, 3 + 6 * bands);
    assert_eq!(skips.to_vec(), vec![2]);
    let mut w = Vec::new();
    let mut b = Vec::new();
    for i in 0..layers {
        let wi: Array2<f32> = npz.by_name(&format!("w{i}")).unwrap();
        let bi: Array1<f32> = npz.by_name(&format!("b{i}")).unwrap();
        assert_eq!(wi.ncols(), bi.len(), "layer {i}");
        w.push(wi);
        b.push(bi);
    }
    // Every parameter is in the file once.
    let stored: usize =
        w.iter().map(|a| a.len()).sum::<usize>() + b.iter().map(|a| a.len()).sum::<usize>();
    assert_eq!(stored, field.params.len());

    let pts: Vec<[f32; 3]> = vec![[0.01, -0.02, 0.03], [-0.05, 0.04, 0.0], [0.08, 0.07, -0.06]];
    let got = field.density(&pts);
    for (p, &g) in pts.iter().zip(&got) {
        let x: Vec<f64> = p.iter().map(|&v| v as f64).collect();
        let mut enc = x.clone();
        for k in 0..bands {
            let f = 2f64.powi(k as i32);
            enc.extend(x.iter().map(|&v| (f * v).sin()));
            enc.extend(x.iter().map(|&v| (f * v).cos()));
        }
        let mut h = enc.clone();
        for i in 0..layers {
            let input: Vec<f64> = if i > 0 && skips.iter().any(|&s| s as usize == i) {
                enc.iter().chain(&h).copied().collect()
            } else {
                h.clone()
            };
            assert_eq!(input.len(), w[i].nrows(), "layer {i}'s input width");
            let z: Vec<f64> = (0..w[i].ncols())
                .map(|o| {
                    b[i][o] as f64
                        + input
                            .iter()
                            .enumerate()
                            .map(|(r, &v)| v * w[i][[r, o]] as f64)
                            .sum::<f64>()
                })
                .collect();
            h = if i + 1 < layers {
                z.into_iter().map(leaky).collect()
            } else {
                z
            };
        }
        assert_eq!(h.len(), 1);
        let want = match meta[3] {
            0 => 1.0 / (1.0 + (-h[0]).exp()),
            1 => leaky(h[0]),
            2 => h[0].exp().ln_1p(),
            a => panic!("output activation {a}"),
        };
        assert!(
            (g as f64 - want).abs() <= 1e-5 * want.abs().max(1e-3),
            "density at {p:?}: field {g}, from the file {want}"
        );
    }
}

/// A TensoRF VM field's file: the planes, lines and basis under their names with the shapes
/// the header gives, every encoder parameter stored once, in place.
#[test]
fn a_saved_tensor_vm_field_keeps_planes_lines_and_basis_in_place() {
    let (n, c, out) = (4, 2, 5);
    let cfg = crate::small_cfg(EncoderConfig::TensorVm {
        resolution: n,
        components: c,
        out_dim: out,
        lines: unispine::field::encode::VmLines::Corrected,
    });
    let mut field = Field::<f32>::new(&cfg).unwrap();
    for (i, p) in field.params.iter_mut().enumerate() {
        *p = i as f32;
    }
    let (_dir, mut npz) = saved(&field);
    let meta: Array1<i64> = npz.by_name("vm_meta").unwrap();
    assert_eq!(meta.to_vec(), vec![n as i64, c as i64, out as i64, 1]);
    let planes: ndarray::Array4<f32> = npz.by_name("vm_planes").unwrap();
    let lines: ndarray::Array3<f32> = npz.by_name("vm_lines").unwrap();
    let basis: Array2<f32> = npz.by_name("vm_basis").unwrap();
    assert_eq!(planes.shape(), [3, c, n, n]);
    assert_eq!(lines.shape(), [3, c, n]);
    assert_eq!(basis.shape(), [out, 3 * c]);
    // The parameters in order: planes, lines, basis (row-major), values 0, 1, 2, ...
    let stored: Vec<f32> = planes
        .iter()
        .chain(lines.iter())
        .chain(basis.iter())
        .copied()
        .collect();
    let want: Vec<f32> = (0..stored.len()).map(|i| i as f32).collect();
    assert_eq!(stored, want);
}
