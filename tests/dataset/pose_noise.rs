//! `unispine data ... --pose-noise-deg S --pose-noise-mm T`: noise 0 is today's dataset bit for
//! bit; with noise the projections stay those of the exact cameras and only the recorded
//! training cameras change; bad values are errors naming the flag and value, exit 1, nothing
//! written.

use std::path::Path;
use std::process::Output;

use crate::common;

fn data(dir: &Path, out: &str, extra: &[&str]) -> Output {
    common::cli::bin()
        .args([
            "data",
            "phantom",
            "--size",
            "32",
            "--detector",
            "16",
            "--train-views",
            "10",
            "--test-views",
            "2",
            "--out",
        ])
        .arg(dir.join(out))
        .args(extra)
        .output()
        .expect("run unispine")
}

use common::cli::text;

fn read(dir: &Path, ds: &str, f: &str) -> Vec<u8> {
    std::fs::read(dir.join(ds).join(f)).unwrap()
}

#[test]
fn zero_pose_noise_is_todays_dataset_and_noise_changes_only_the_recorded_cameras() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let o = data(d, "plain", &[]);
    assert!(o.status.success(), "{}", text(&o));
    let o = data(
        d,
        "zero",
        &["--pose-noise-deg", "0", "--pose-noise-mm", "0"],
    );
    assert!(o.status.success(), "{}", text(&o));
    for f in ["dataset.json", "train.npy", "test.npy", "volume.npy"] {
        assert!(read(d, "plain", f) == read(d, "zero", f), "{f} differs");
    }
    let o = data(
        d,
        "noisy",
        &[
            "--pose-noise-deg",
            "0.2",
            "--pose-noise-mm",
            "0.5",
            "--pose-seed",
            "3",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    // Projections of the exact cameras: the same arrays.
    for f in ["train.npy", "test.npy", "volume.npy"] {
        assert!(read(d, "plain", f) == read(d, "noisy", f), "{f} differs");
    }
    let j: serde_json::Value = serde_json::from_slice(&read(d, "noisy", "dataset.json")).unwrap();
    let p = &j["manifest"]["pose_noise"];
    assert_eq!(p["rotation_sd_deg"], 0.2);
    assert_eq!(p["translation_sd_mm"], 0.5);
    assert_eq!(p["seed"], 3);
    assert_eq!(p["views"].as_array().unwrap().len(), 10);
    let plain: serde_json::Value =
        serde_json::from_slice(&read(d, "plain", "dataset.json")).unwrap();
    assert!(plain["manifest"].get("pose_noise").is_none());

    // The loaded dataset's training cameras are the recorded (perturbed) ones, test exact.
    let a = unispine::dataset::store::load(&d.join("plain")).unwrap();
    let b = unispine::dataset::store::load(&d.join("noisy")).unwrap();
    for k in 0..10 {
        let (ca, cb) = (a.train_camera(k), b.train_camera(k));
        let v = &b.manifest.pose_noise.as_ref().unwrap().views[k];
        assert_eq!(cb, v.apply(&ca));
        let moved: f64 = (0..3).map(|i| (ca.centre[i] - cb.centre[i]).powi(2)).sum();
        assert!(moved > 0.0, "view {k} not perturbed");
    }
    assert_eq!(a.test_camera(1), b.test_camera(1));
}

#[test]
fn bad_pose_noise_is_an_error_naming_the_flag_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    for (args, needle) in [
        (vec!["--pose-noise-deg", "-1"], "--pose-noise-deg"),
        (vec!["--pose-noise-deg", "NaN"], "--pose-noise-deg"),
        (vec!["--pose-noise-mm", "inf"], "--pose-noise-mm"),
        // A 128 mm phantom 100 mm from the source: translations of N(0, 30^2) mm move some of
        // the 10 recorded sources into the box.
        (
            vec!["--dso", "100", "--dsd", "300", "--pose-noise-mm", "30"],
            "inside the volume",
        ),
    ] {
        let o = data(d, "bad", &args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", text(&o));
        let t = text(&o);
        assert!(
            t.contains(needle) && t.contains(args[args.len() - 1]),
            "{t}"
        );
        assert!(!d.join("bad").exists(), "{args:?} wrote something");
    }
}
