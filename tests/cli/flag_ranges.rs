//! The front end's numeric flags and settings are range checked: values that would allocate
//! without bound or never end are refused with their allowed range, exit 1.

use crate::common::hostile::*;

#[test]
fn geometry_accuracy_and_threads_are_range_checked() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("v.npy");
    ndarray_npy::write_npy(&vol, &ndarray::Array3::<f32>::ones((8, 8, 8))).unwrap();
    let out = dir.path().join("out");
    for acc in ["1e-12", "1e12"] {
        let geo = dir.path().join(format!("geo{acc}.json"));
        std::fs::write(
            &geo,
            format!(
                r#"{{"DSD": 1500.0, "DSO": 1000.0, "nDetector": [8, 8], "dDetector": [4.0, 4.0],
                    "nVoxel": [8, 8, 8], "dVoxel": [1.0, 1.0, 1.0], "accuracy": {acc}}}"#
            ),
        )
        .unwrap();
        assert_error(
            &[
                "drr",
                "--volume",
                &s(&vol),
                "--geometry",
                &s(&geo),
                "--angles-deg",
                "0",
                "--method",
                "trilinear",
                "--out",
                &s(&out),
            ],
            "accuracy",
            &["[0.01, 1]"],
        );
    }
    let (code, err) = run(&[
        "train",
        "--data",
        &s(dir.path()),
        "--out",
        &s(&out),
        "--threads",
        "3000",
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("--threads") && err.contains("allowed range"),
        "{err}"
    );
}

/// Numeric flags that would allocate without bound or never end: view counts and the
/// projection bytes of `data`, `drr` angle counts at a large detector, `bench` cases (render,
/// train and loss), the
/// iterations of a field baseline, `reproduce --jobs`. Each is refused with its allowed range.
#[test]
fn unbounded_numeric_flags_are_range_checked() {
    let dir = tempfile::tempdir().unwrap();
    let out = s(&dir.path().join("out"));
    let phantom = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = ["data", "phantom", "--size", "32", "--out", &out]
            .iter()
            .map(|x| x.to_string())
            .collect();
        v.extend(extra.iter().map(|x| x.to_string()));
        v
    };
    for (extra, flag, range) in [
        (
            &["--train-views", "100000000000"][..],
            "--train-views",
            "[1, 100000]",
        ),
        (
            &["--test-views", "4000000000", "--detector", "64"][..],
            "--test-views",
            "[1, 100000]",
        ),
        (
            &["--train-views", "5000", "--detector", "8192"][..],
            "--detector",
            "8 GiB",
        ),
    ] {
        assert_error(&strs(&phantom(extra)), flag, &[range]);
    }
    for (args, flag, range) in [
        (
            &["bench", "render", "--sizes", "100000", "--gaussians", "10"][..],
            "--sizes",
            "[1, 4096]",
        ),
        (
            &[
                "bench",
                "render",
                "--sizes",
                "64",
                "--gaussians",
                "10000000000",
            ][..],
            "--gaussians",
            "[1, 2000000]",
        ),
        (
            &["bench", "render", "--sizes", "64", "--reps", "0"][..],
            "--reps",
            "[1, 1000]",
        ),
        (
            &["bench", "train", "--sizes", "100000"][..],
            "--sizes",
            "[8, 2048]",
        ),
        (
            &["bench", "train", "--sizes", "64", "--iters", "0"][..],
            "--iters",
            "[1, 100000]",
        ),
        (
            &["bench", "train", "--sizes", "64", "--warmup", "1000000000"][..],
            "--warmup",
            "[0, 20000]",
        ),
        (
            &["bench", "train", "--sizes", "64", "--views", "0"][..],
            "--views",
            "[1, 100]",
        ),
        (
            &["bench", "loss", "--sizes", "64,100000"][..],
            "--sizes",
            "[8, 4096]",
        ),
        (
            &["bench", "loss", "--sizes", "64", "--reps", "0"][..],
            "--reps",
            "[1, 1000]",
        ),
        (
            &["reproduce", "quick", "--jobs", "100000"][..],
            "--jobs",
            "allowed range",
        ),
    ] {
        let mut a = args.to_vec();
        if args[0] == "reproduce" {
            a.extend(["--out", out.as_str()]);
        }
        a.extend(
            ["--baselines", "false"]
                .iter()
                .filter(|_| args[0] == "bench"),
        );
        assert_error(&a, flag, &[range]);
    }
    // drr: 9 views of 16384 x 16384 f32 pixels (9.7 GB).
    let vol = dir.path().join("v.npy");
    ndarray_npy::write_npy(&vol, &ndarray::Array3::<f32>::ones((8, 8, 8))).unwrap();
    let geo = dir.path().join("big.json");
    std::fs::write(
        &geo,
        r#"{"DSD": 1500.0, "DSO": 1000.0, "nDetector": [16384, 16384], "dDetector": [0.01, 0.01]}"#,
    )
    .unwrap();
    assert_error(
        &[
            "drr",
            "--volume",
            &s(&vol),
            "--geometry",
            &s(&geo),
            "--angles-deg",
            "0,1,2,3,4,5,6,7,8",
            "--out",
            &out,
        ],
        "angles",
        &["8 GiB"],
    );
    // A field baseline's --iters.
    let data = s(&dir.path().join("ph"));
    let (code, err) = run(&[
        "data",
        "phantom",
        "--size",
        "32",
        "--detector",
        "8",
        "--train-views",
        "2",
        "--test-views",
        "1",
        "--out",
        &data,
    ]);
    assert_eq!(code, 0, "{err}");
    assert_error(
        &[
            "train",
            "--data",
            &data,
            "--method",
            "naf",
            "--iters",
            "1000000000000",
            "--out",
            &out,
        ],
        "--iters",
        &["[1, 20000000]"],
    );
}
