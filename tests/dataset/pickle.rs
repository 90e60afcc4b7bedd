//! Import of NAF-layout dataset pickles: every value of fixtures written by numpy 1.x and 2.x
//! in protocols 2, 4 and 5 (tests/fixtures/make_pickle_fixtures.py), and the errors on bad pickles.

use std::path::{Path, PathBuf};

use unispine::dataset::pickle::{import, ImportOptions};
use unispine::dataset::store;
use unispine::geometry::Mode;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn expected() -> serde_json::Value {
    let text = std::fs::read_to_string(fixture("naf_expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn values(v: &serde_json::Value) -> Vec<f64> {
    v["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn shape(v: &serde_json::Value) -> Vec<usize> {
    v["shape"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap() as usize)
        .collect()
}

fn nums(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

const GOOD: [(&str, u64, &str); 8] = [
    ("naf_p2_np1.pickle", 2, "numpy.core"),
    ("naf_p4_np1.pickle", 4, "numpy.core"),
    ("naf_p5_np1.pickle", 5, "numpy.core"),
    ("naf_p2_np2.pickle", 2, "numpy._core"),
    ("naf_p4_np2.pickle", 4, "numpy._core"),
    ("naf_p5_np2.pickle", 5, "numpy._core"),
    // Protocol 5, Fortran-order image: `_frombuffer(buf, dtype, shape, 'F')`.
    ("naf_p5_fortran_np2.pickle", 5, "numpy._core"),
    // The image array referenced twice (a memo reference).
    ("naf_shared_np2.pickle", 4, "numpy._core"),
];

/// The protocol-5 Fortran fixture really stores its image through `_frombuffer` with order
/// 'F' (so `every_fixture_gives_every_value` fails if that order were read as C order).
#[test]
fn protocol5_fortran_fixture_uses_frombuffer_with_order_f() {
    let b = std::fs::read(fixture("naf_p5_fortran_np2.pickle")).unwrap();
    let has = |pat: &[u8]| b.windows(pat.len()).any(|w| w == pat);
    assert!(has(b"_frombuffer"));
    // SHORT_BINUNICODE of length 1: "F".
    assert!(has(&[0x8c, 1, b'F']), "no 'F' order argument");
    // The image is not symmetric under a C/Fortran mix-up: read in C order, voxel (1, 0, 0)
    // would hold the value of voxel (0, 0, 1).
    let e = expected();
    let img = values(&e["image"]);
    assert_ne!(img[12], img[1]);
}

#[test]
fn every_fixture_gives_every_value() {
    let e = expected();
    for (name, protocol, numpy) in GOOD {
        for scale in [1.0f64, 1000.0] {
            let ds = import(
                &fixture(name),
                &ImportOptions {
                    projection_scale: scale,
                },
            )
            .unwrap_or_else(|err| panic!("{name}: {err}"));
            let g = &ds.geometry;
            assert_eq!(g.dsd, e["DSD"].as_f64().unwrap(), "{name}");
            assert_eq!(g.dso, e["DSO"].as_f64().unwrap(), "{name}");
            assert_eq!(g.n_detector, [3, 4], "{name}");
            assert_eq!(g.d_detector.to_vec(), nums(&e["dDetector"]), "{name}");
            assert_eq!(g.n_voxel, [2, 3, 4], "{name}");
            assert_eq!(g.d_voxel.to_vec(), values(&e["dVoxel"]), "{name}");
            assert_eq!(g.off_origin.to_vec(), nums(&e["offOrigin"]), "{name}");
            assert_eq!(g.off_detector.to_vec(), nums(&e["offDetector"]), "{name}");
            assert_eq!(g.accuracy, 0.5);
            assert_eq!(g.mode, Mode::Cone);
            for (split, key) in [(&ds.train, "train"), (&ds.test, "val")] {
                assert_eq!(split.angles, values(&e[key]["angles"]), "{name} {key}");
                let p = &e[key]["projections"];
                assert_eq!(shape(p), vec![3, 3, 4]);
                let vals = values(p);
                for k in 0..3 {
                    let img = &split.projections[k];
                    assert_eq!((img.height, img.width), (3, 4));
                    for r in 0..3 {
                        for c in 0..4 {
                            let want = vals[(k * 3 + r) * 4 + c] as f32 * scale as f32;
                            assert_eq!(img.at(r, c), want, "{name} {key} view {k} ({r},{c})");
                        }
                    }
                }
            }
            let vol = ds.volume.as_ref().expect("image");
            assert_eq!(vol.dims, [2, 3, 4]);
            assert_eq!(vol.spacing, g.d_voxel);
            assert_eq!(vol.offset, g.off_origin);
            let img = values(&e["image"]);
            for i in 0..2 {
                for j in 0..3 {
                    for k in 0..4 {
                        assert_eq!(
                            vol.get(i, j, k),
                            img[(i * 3 + j) * 4 + k] as f32,
                            "{name} voxel ({i},{j},{k})"
                        );
                    }
                }
            }
            let x = &ds.manifest.extra;
            assert_eq!(x["pickle.protocol"], protocol, "{name}");
            assert_eq!(x["pickle.numpy_module"], numpy, "{name}");
            assert_eq!(x["pickle.numTrain"], 3);
            assert_eq!(x["pickle.totalAngle"], 180.0);
            assert_eq!(x["pickle.randomAngle"], false);
            assert_eq!(x["pickle.filter"], serde_json::Value::Null);
            assert_eq!(x["projection_scale"], scale);
            assert!(ds.manifest.volume_normalisation.contains("0.206"));
            assert!(ds.manifest.volume_normalisation.contains("[0, 1]"));
            assert_eq!(ds.manifest.noise, "none");
        }
    }
}

#[test]
fn imported_dataset_round_trips_through_the_store() {
    let ds = import(&fixture("naf_p5_np2.pickle"), &ImportOptions::default()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    store::save(&ds, tmp.path()).unwrap();
    assert_eq!(store::load(tmp.path()).unwrap(), ds);
}

fn err(name: &str) -> String {
    import(&fixture(name), &ImportOptions::default())
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_pickles_name_the_file_and_the_key() {
    let cases = [
        ("bad_missing_dso.pickle", vec!["`DSO`", "missing key"]),
        ("bad_shape.pickle", vec!["`train.projections`", "[3, 3, 3]"]),
        (
            "bad_nan.pickle",
            vec!["`val.projections`", "view 1 at row 2, column 3"],
        ),
        (
            "bad_zero_views.pickle",
            vec!["`val.angles`", "zero val views"],
        ),
        (
            "bad_global.pickle",
            vec!["unsupported global `fractions.Fraction`"],
        ),
        ("bad_dtype.pickle", vec!["unsupported dtype `c8`"]),
    ];
    for (name, needles) in cases {
        let e = err(name);
        assert!(e.contains(name), "{name}: {e}");
        for n in needles {
            assert!(e.contains(n), "{name}: `{n}` not in: {e}");
        }
    }
}

#[test]
fn truncated_and_missing_files_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(fixture("naf_p4_np2.pickle")).unwrap();
    for cut in [5, bytes.len() / 2, bytes.len() - 1] {
        let p = tmp.path().join("cut.pickle");
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let e = import(&p, &ImportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cut.pickle") && e.contains("truncated"),
            "{cut}: {e}"
        );
    }
    let p = tmp.path().join("absent.pickle");
    let e = import(&p, &ImportOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("absent.pickle"), "{e}");
    // Not a pickle at all.
    let p = tmp.path().join("text.pickle");
    std::fs::write(&p, b"hello world").unwrap();
    let e = import(&p, &ImportOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("text.pickle") && e.contains("opcode"), "{e}");
}

#[test]
fn image_is_optional_and_may_be_coarser_than_nvoxel() {
    let ds = import(&fixture("naf_noimage.pickle"), &ImportOptions::default()).unwrap();
    assert!(ds.volume.is_none());
    assert_eq!(ds.train.angles.len(), 3);

    // image[:1, :, ::2] of the [2, 3, 4] volume: shape [1, 3, 2], same physical box.
    let ds = import(
        &fixture("naf_small_image.pickle"),
        &ImportOptions::default(),
    )
    .unwrap();
    let v = ds.volume.as_ref().unwrap();
    assert_eq!(v.dims, [1, 3, 2]);
    assert_eq!(v.spacing, [2.0, 0.5, 4.0]);
    assert_eq!(ds.geometry.n_voxel, [2, 3, 4]);
    let img = values(&expected()["image"]);
    for j in 0..3 {
        for k in 0..2 {
            assert_eq!(v.get(0, j, k), img[j * 4 + 2 * k] as f32);
        }
    }
    assert!(
        v.provenance.steps.iter().any(|s| s.contains("not nVoxel")),
        "{:?}",
        v.provenance.steps
    );
    let tmp = tempfile::tempdir().unwrap();
    store::save(&ds, tmp.path()).unwrap();
    assert_eq!(store::load(tmp.path()).unwrap(), ds);
}
