//! `unispine drr`: outputs on a small .npy volume (checked against a closed form and against the
//! library), and the errors for bad input.

use std::path::Path;

use common::cli::{run, Run};
use ndarray::{Array3, Ix3};

use crate::common;

/// A 16 x 12 x 10 volume (1 mm voxels, `[x, y, z]`) of value `val` everywhere.
fn write_volume(path: &Path, val: f32, nan_at: Option<[usize; 3]>) {
    let mut a = Array3::<f32>::from_elem((16, 12, 10), val);
    if let Some([i, j, k]) = nan_at {
        a[[i, j, k]] = f32::NAN;
    }
    ndarray_npy::write_npy(path, &a).unwrap();
}

/// Cone-beam geometry without nVoxel / dVoxel / offOrigin (taken from the volume).
fn write_geometry(path: &Path, extra: &str) {
    common::cli::write_geometry(path, [300.0, 200.0], [9, 11], 3.0, extra);
}

/// `unispine drr --volume VOL --geometry GEO --out OUT EXTRA...`, with `--angles-deg 0` unless
/// EXTRA gives the angles.
fn drr(vol: &Path, geo: &Path, out: &Path, extra: &[&str]) -> Run {
    let mut args = vec![
        "drr",
        "--volume",
        vol.to_str().unwrap(),
        "--geometry",
        geo.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    if !extra.contains(&"--angles-deg") {
        args.extend_from_slice(&["--angles-deg", "0"]);
    }
    run(&args)
}

#[test]
fn drr_writes_projections_pngs_and_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("vol.npy");
    let geo = dir.path().join("geo.json");
    write_volume(&vol, 0.5, None);
    write_geometry(&geo, "");
    for method in ["siddon", "trilinear"] {
        let out = dir.path().join(method);
        let Run {
            ok, stderr: err, ..
        } = drr(
            &vol,
            &geo,
            &out,
            &["--angles-deg", "0,90,-45", "--method", method],
        );
        assert!(ok, "{method}: {err}");
        let p: ndarray::ArrayD<f32> = ndarray_npy::read_npy(out.join("projections.npy")).unwrap();
        let p = p.into_dimensionality::<Ix3>().unwrap();
        assert_eq!(p.dim(), (3, 9, 11));
        // Odd detector: the centre pixel's ray runs through the origin along -x at 0 deg
        // (chord 16 mm) and along -y at 90 deg (chord 12 mm); value 0.5.
        let tol = if method == "siddon" { 1e-5 } else { 1e-3 * 8.0 };
        assert!(
            (p[[0, 4, 5]] - 8.0).abs() <= tol,
            "{method}: {}",
            p[[0, 4, 5]]
        );
        assert!(
            (p[[1, 4, 5]] - 6.0).abs() <= tol * 0.75,
            "{method}: {}",
            p[[1, 4, 5]]
        );
        // Same numbers as the library on the same file.
        let v = unispine::volume::load(&vol).unwrap();
        let g: unispine::geometry::ConeBeam = serde_json::from_value(
            serde_json::from_str::<serde_json::Value>(
                &std::fs::read_to_string(out.join("drr.json")).unwrap(),
            )
            .unwrap()["geometry"]
                .clone(),
        )
        .unwrap();
        assert_eq!(g.n_voxel, [16, 12, 10]);
        let m = if method == "siddon" {
            unispine::drr::Method::Siddon
        } else {
            unispine::drr::Method::Trilinear
        };
        let lib = unispine::drr::project(&v, &g, (-45f64).to_radians(), m).unwrap();
        let row: Vec<f32> = p.slice(ndarray::s![2, .., ..]).iter().copied().collect();
        assert_eq!(row, lib.data);
        for k in 0..3 {
            assert!(out.join(format!("view_{k:03}.png")).exists());
        }
    }
}

#[test]
fn drr_f64_and_hu_conversion() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("vol.npy");
    let geo = dir.path().join("geo.json");
    // 0 HU is water: naf-mu gives 0.206 / cm.
    write_volume(&vol, 0.0, None);
    write_geometry(&geo, r#", "nVoxel": [16, 12, 10], "dVoxel": [1, 1, 1]"#);
    let out = dir.path().join("o");
    let Run {
        ok, stderr: err, ..
    } = drr(&vol, &geo, &out, &["--precision", "f64", "--hu", "naf-mu"]);
    assert!(ok, "{err}");
    let p: ndarray::ArrayD<f32> = ndarray_npy::read_npy(out.join("projections.npy")).unwrap();
    assert!(
        (p[[0, 4, 5]] - 16.0 * 0.206).abs() < 1e-5,
        "{}",
        p[[0, 4, 5]]
    );
}

fn expect_error(args_extra: &[&str], vol_nan: bool, geo_extra: &str, needle: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("vol.npy");
    let geo = dir.path().join("geo.json");
    write_volume(&vol, 1.0, vol_nan.then_some([3, 4, 5]));
    write_geometry(&geo, geo_extra);
    let Run {
        ok, stderr: err, ..
    } = drr(&vol, &geo, &dir.path().join("o"), args_extra);
    assert!(!ok, "expected a failure for {args_extra:?} {geo_extra}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needle {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

#[test]
fn drr_bad_inputs_give_clear_errors() {
    // Missing volume file: the path is named.
    let dir = tempfile::tempdir().unwrap();
    let geo = dir.path().join("geo.json");
    write_geometry(&geo, "");
    let missing = dir.path().join("nope.nii.gz");
    let Run {
        ok, stderr: err, ..
    } = drr(&missing, &geo, &dir.path().join("o"), &[]);
    assert!(!ok && err.contains("nope.nii.gz"), "{err}");
    // NaN voxel: the voxel is named.
    expect_error(&[], true, "", &["(3, 4, 5)"]);
    // A geometry that misses the volume.
    expect_error(&[], false, r#", "offDetector": [900.0, 0.0]"#, &["no ray"]);
    // Source inside the volume.
    expect_error(&[], false, r#", "DSO": 4.0"#, &["inside the volume"]);
    // Grid mismatch: the field is named.
    expect_error(&[], false, r#", "nVoxel": [16, 12, 11]"#, &["nVoxel"]);
    // Bad angle list.
    expect_error(
        &["--angles-deg", "0,x"],
        false,
        "",
        &["--angles-deg", "`x`"],
    );
    // Bad geometry field.
    expect_error(&[], false, r#", "DSD": -1.0"#, &["DSD"]);
}

#[test]
fn drr_missing_geometry_file_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("vol.npy");
    write_volume(&vol, 1.0, None);
    let missing = dir.path().join("missing.json");
    let Run {
        ok, stderr: err, ..
    } = drr(&vol, &missing, &dir.path().join("o"), &[]);
    assert!(!ok && err.contains("missing.json"), "{err}");
}

#[test]
fn drr_help_explains_each_flag() {
    let Run {
        ok, stdout: out, ..
    } = run(&["drr", "--help"]);
    assert!(ok);
    for flag in [
        "--volume",
        "--geometry",
        "--angles-deg",
        "--method",
        "--precision",
        "--hu",
        "--out",
    ] {
        assert!(out.contains(flag), "{flag} missing from --help:\n{out}");
    }
    assert!(out.contains("siddon") && out.contains("trilinear") && out.contains("naf-mu"));
}
