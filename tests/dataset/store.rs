//! Dataset folders: round trip of `save` / `load` and the errors of `load` on damaged folders.

use std::path::Path;

use ndarray::{Array3, ShapeBuilder};
use unispine::dataset::{store, Dataset, Manifest, Split};
use unispine::geometry::ConeBeam;
use unispine::image2d::Image2d;
use unispine::volume::{Provenance, Volume};

use crate::common;

fn geometry() -> ConeBeam {
    ConeBeam {
        off_origin: [0.5, -1.0, 2.0],
        off_detector: [0.25, -0.5],
        ..ConeBeam::centred([6, 7], [1.25, 1.5], [4, 5, 3], [1.0, 0.75, 2.0])
    }
}

/// A small dataset with values that are all distinct, so any transposition shows.
fn dataset(n_train: usize, n_test: usize) -> Dataset {
    let geo = geometry();
    let (w, h) = geo.image_size();
    let split = |n: usize, base: f32, a0: f64| Split {
        angles: (0..n)
            .map(|k| a0 + k as f64 * std::f64::consts::PI / n as f64)
            .collect(),
        projections: (0..n)
            .map(|k| {
                Image2d::from_vec(
                    w,
                    h,
                    (0..w * h)
                        .map(|i| base + k as f32 * 100.0 + i as f32 * 0.37)
                        .collect(),
                )
            })
            .collect(),
    };
    let mut vol = Volume::<f32>::zeros(geo.n_voxel, geo.d_voxel);
    vol.offset = geo.off_origin;
    for (i, v) in vol.data.iter_mut().enumerate() {
        *v = i as f32 * 0.01 - 0.2;
    }
    vol.provenance = Provenance {
        source: "test volume".into(),
        file_affine: None,
        steps: vec!["made by hand".into()],
    };
    let mut extra = serde_json::Map::new();
    extra.insert("seed".into(), serde_json::json!(7));
    Dataset {
        geometry: geo,
        train: split(n_train, 1.0, 0.0),
        test: split(n_test, 2.0, 0.031415926535897934),
        manifest: Manifest {
            projection_units: "mm * volume value".into(),
            volume_normalisation: "none".into(),
            provenance: vol.provenance.clone(),
            projector: "siddon".into(),
            noise: "none".into(),
            extra,
            pose_noise: None,
        },
        volume: Some(vol),
    }
}

fn err_of(dir: &Path) -> String {
    store::load(dir).unwrap_err().to_string()
}

#[test]
fn round_trip_is_exact() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(5, 3);
    store::save(&ds, tmp.path()).unwrap();
    let back = store::load(tmp.path()).unwrap();
    assert_eq!(back, ds);
    // Without a volume too, and a stale volume.npy is removed.
    let mut nv = ds.clone();
    nv.volume = None;
    store::save(&nv, tmp.path()).unwrap();
    assert!(!tmp.path().join("volume.npy").exists());
    assert_eq!(store::load(tmp.path()).unwrap(), nv);
}

#[test]
fn files_have_the_documented_layout() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(5, 3);
    store::save(&ds, tmp.path()).unwrap();
    // train.npy: [N, v, u], row 0 = row 0 of the image.
    let tr: Array3<f32> = ndarray_npy::read_npy(tmp.path().join("train.npy")).unwrap();
    assert_eq!(tr.dim(), (5, 6, 7));
    for k in 0..5 {
        for r in 0..6 {
            for c in 0..7 {
                assert_eq!(tr[[k, r, c]], ds.train.projections[k].at(r, c));
            }
        }
    }
    // volume.npy: [x, y, z].
    let vol = ds.volume.as_ref().unwrap();
    let v: Array3<f32> = ndarray_npy::read_npy(tmp.path().join("volume.npy")).unwrap();
    assert_eq!(v.dim(), (4, 5, 3));
    for i in 0..4 {
        for j in 0..5 {
            for k in 0..3 {
                assert_eq!(v[[i, j, k]], vol.get(i, j, k));
            }
        }
    }
    // dataset.json: TIGRE names, radians, manifest, format version, previews that exist.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("dataset.json")).unwrap())
            .unwrap();
    assert_eq!(json["format_version"], 1);
    assert_eq!(json["geometry"]["DSD"], 1500.0);
    assert_eq!(json["geometry"]["nDetector"], serde_json::json!([6, 7]));
    assert_eq!(
        json["geometry"]["offDetector"],
        serde_json::json!([0.25, -0.5])
    );
    assert_eq!(json["train"]["count"], 5);
    assert_eq!(json["test"]["angles"][0], 0.031415926535897934);
    assert_eq!(json["manifest"]["projector"], "siddon");
    assert_eq!(
        json["volume"]["dVoxel"],
        serde_json::json!([1.0, 0.75, 2.0])
    );
    let previews = json["previews"].as_array().unwrap();
    // 4 of 5 training views, all 3 test views, 3 volume slices.
    assert_eq!(previews.len(), 4 + 3 + 3);
    for p in previews {
        let path = tmp.path().join(p.as_str().unwrap());
        let img = image::open(&path).unwrap().to_luma8();
        // Views are u x v = 7 x 6; volume slices: axial x by y, coronal x by z, sagittal y by z.
        let name = p.as_str().unwrap();
        let want = match name {
            "previews/volume_axial.png" => (4, 5),
            "previews/volume_coronal.png" => (4, 3),
            "previews/volume_sagittal.png" => (5, 3),
            _ => (7, 6),
        };
        assert_eq!((img.width(), img.height()), want, "{name}");
    }
    let img = image::open(tmp.path().join("previews/train_000.png"))
        .unwrap()
        .to_luma8();
    assert_eq!((img.width(), img.height()), (7, 6));
    // min-max scaled: the first pixel is the minimum, the last the maximum.
    assert_eq!(img.get_pixel(0, 0).0[0], 0);
    assert_eq!(img.get_pixel(6, 5).0[0], 255);
}

#[test]
fn save_refuses_bad_datasets() {
    let tmp = tempfile::tempdir().unwrap();
    let mut ds = dataset(3, 2);
    ds.test = Split::default();
    let e = store::save(&ds, tmp.path()).unwrap_err().to_string();
    assert!(
        e.contains("test.angles") && e.contains("zero test views"),
        "{e}"
    );

    let mut ds = dataset(3, 2);
    ds.train.projections[1].data[9] = f32::NAN;
    let e = store::save(&ds, tmp.path()).unwrap_err().to_string();
    assert!(
        e.contains("train projection 1") && e.contains("row 1, column 2"),
        "{e}"
    );

    let mut ds = dataset(3, 2);
    ds.test.projections.pop();
    let e = store::save(&ds, tmp.path()).unwrap_err().to_string();
    assert!(e.contains("test.projections"), "{e}");

    let mut ds = dataset(3, 2);
    ds.volume.as_mut().unwrap().spacing[2] = 3.0;
    let e = store::save(&ds, tmp.path()).unwrap_err().to_string();
    assert!(e.contains("volume") && e.contains("axis 2"), "{e}");
}

fn saved() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    store::save(&dataset(3, 2), tmp.path()).unwrap();
    tmp
}

fn edit_json(dir: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let p = dir.join("dataset.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(&p, serde_json::to_string(&v).unwrap()).unwrap();
}

#[test]
fn load_names_the_missing_file() {
    let tmp = saved();
    std::fs::remove_file(tmp.path().join("test.npy")).unwrap();
    let e = err_of(tmp.path());
    assert!(e.contains("test.npy"), "{e}");
    std::fs::remove_file(tmp.path().join("dataset.json")).unwrap();
    let e = err_of(tmp.path());
    assert!(e.contains("dataset.json"), "{e}");
}

#[test]
fn load_names_shape_mismatches() {
    let tmp = saved();
    let wrong = Array3::<f32>::zeros((2, 7, 6));
    ndarray_npy::write_npy(tmp.path().join("test.npy"), &wrong).unwrap();
    let e = err_of(tmp.path());
    assert!(
        e.contains("test.npy") && e.contains("shape") && e.contains("[2, 6, 7]"),
        "{e}"
    );

    let tmp = saved();
    let wrong = Array3::<f32>::zeros((4, 5, 2).f());
    ndarray_npy::write_npy(tmp.path().join("volume.npy"), &wrong).unwrap();
    let e = err_of(tmp.path());
    assert!(e.contains("volume.npy") && e.contains("nVoxel"), "{e}");

    let tmp = saved();
    edit_json(tmp.path(), |v| v["train"]["count"] = serde_json::json!(4));
    let e = err_of(tmp.path());
    assert!(e.contains("train.angles") && e.contains("count = 4"), "{e}");
}

#[test]
fn load_names_nan_in_a_projection() {
    let tmp = saved();
    let mut a: Array3<f32> = ndarray_npy::read_npy(tmp.path().join("train.npy")).unwrap();
    a[[2, 4, 5]] = f32::NAN;
    ndarray_npy::write_npy(tmp.path().join("train.npy"), &a).unwrap();
    let e = err_of(tmp.path());
    assert!(
        e.contains("train.npy")
            && e.contains("train projection 2")
            && e.contains("row 4, column 5"),
        "{e}"
    );
}

#[test]
fn load_refuses_zero_test_views() {
    let tmp = saved();
    edit_json(tmp.path(), |v| {
        v["test"]["count"] = serde_json::json!(0);
        v["test"]["angles"] = serde_json::json!([]);
    });
    let e = err_of(tmp.path());
    assert!(
        e.contains("test.count") && e.contains("zero test views"),
        "{e}"
    );
}

#[test]
fn load_names_bad_json_fields() {
    let tmp = saved();
    edit_json(tmp.path(), |v| v["format_version"] = serde_json::json!(99));
    let e = err_of(tmp.path());
    assert!(e.contains("format_version") && e.contains("99"), "{e}");

    let tmp = saved();
    edit_json(tmp.path(), |v| {
        v["geometry"].as_object_mut().unwrap().remove("DSO");
    });
    let e = err_of(tmp.path());
    assert!(e.contains("geometry") && e.contains("DSO"), "{e}");

    let tmp = saved();
    edit_json(tmp.path(), |v| {
        v["geometry"]["DSD"] = serde_json::json!(-3.0)
    });
    let e = err_of(tmp.path());
    assert!(e.contains("geometry.DSD"), "{e}");

    let tmp = saved();
    edit_json(tmp.path(), |v| {
        v["volume"]["offOrigin"] = serde_json::json!([0.0, 0.0, 0.0])
    });
    let e = err_of(tmp.path());
    assert!(e.contains("volume") && e.contains("offOrigin"), "{e}");
}

/// Saving over an earlier dataset: stale previews go, a save that fails part-way leaves no
/// `dataset.json` (so `load` refuses the mix of new arrays and an old description), and
/// `data ct` refuses to write over its own input volume.
#[test]
fn saving_over_a_dataset_leaves_no_mix() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    store::save(&dataset(9, 9), d).unwrap();
    let pngs = |d: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d.join("previews"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        v.sort();
        v
    };
    let many = pngs(d);
    store::save(&dataset(2, 1), d).unwrap();
    let few = pngs(d);
    assert!(few.len() < many.len(), "{few:?}");
    assert!(few.iter().all(|p| !p.starts_with("train_008")), "{few:?}");
    // Fail part-way: the previews folder is a file, so writing previews fails after the arrays.
    std::fs::remove_dir_all(d.join("previews")).unwrap();
    std::fs::write(d.join("previews"), b"in the way").unwrap();
    assert!(store::save(&dataset(4, 2), d).is_err());
    assert!(!d.join("dataset.json").exists());
    assert!(err_of(d).contains("dataset.json"));
    // No temporary file is left behind.
    for e in std::fs::read_dir(d).unwrap() {
        let n = e.unwrap().file_name().to_string_lossy().to_string();
        assert!(!n.ends_with(".tmp"), "{n}");
    }
    // The CLI refuses to overwrite its input.
    std::fs::remove_file(d.join("previews")).unwrap();
    store::save(&dataset(2, 1), d).unwrap();
    let out = common::cli::bin()
        .args(["data", "ct", "--volume"])
        .arg(d.join("volume.npy"))
        .arg("--out")
        .arg(d)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--volume") && err.contains("overwritten"),
        "{err}"
    );
    assert_eq!(store::load(d).unwrap(), dataset(2, 1));
}
