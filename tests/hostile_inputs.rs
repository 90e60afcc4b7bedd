//! Hostile input files: each class is built in a temporary folder and given to the binary under
//! a memory limit (`ulimit -v`) and a timeout. Every one must end as a clear error (exit 1)
//! naming the file and the field: no panic (101), no abort (134), no hang, no out-of-memory.

use std::io::Write;
use std::path::Path;
use std::time::Duration;

mod common;

/// Virtual-memory limit of each run, KiB (1.5 GiB: far below what the hostile claims ask for).
const MEM_KIB: u64 = 1_536 * 1024;
/// Wall-time limit of each run.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Run the binary with `args` under the limits; return (exit code, stderr).
fn run(args: &[&str]) -> (i32, String) {
    let r = common::cli::run_limited(args, Path::new("."), &[], MEM_KIB / 1024, TIMEOUT.as_secs());
    (r.code, r.stderr)
}

/// Assert a clean error exit naming `file` and each of `words`.
fn assert_error(args: &[&str], file: &str, words: &[&str]) {
    let (code, err) = run(args);
    assert_eq!(code, 1, "`unispine {}`: exit {code}\n{err}", args.join(" "));
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(file), "message does not name {file}:\n{err}");
    for w in words {
        assert!(err.contains(w), "message does not contain `{w}`:\n{err}");
    }
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

fn data_us(vol: &Path, out: &Path) -> Vec<String> {
    [
        "data",
        "us",
        "--volume",
        &s(vol),
        "--out",
        &s(out),
        "--train-views",
        "1",
        "--test-views",
        "1",
        "--detector",
        "8",
    ]
    .iter()
    .map(|x| x.to_string())
    .collect()
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(|x| x.as_str()).collect()
}

/// A NIfTI-1 header (little endian) for a float32 volume of `dims`, 1 mm voxels.
fn nifti_header(dims: [i16; 3], srow_x0: f32) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    let dim = [3i16, dims[0], dims[1], dims[2], 1, 1, 1, 1];
    for (n, d) in dim.iter().enumerate() {
        h[40 + 2 * n..42 + 2 * n].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&16i16.to_le_bytes()); // float32
    h[72..74].copy_from_slice(&32i16.to_le_bytes());
    for n in 0..4 {
        h[76 + 4 * n..80 + 4 * n].copy_from_slice(&1f32.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    h[123] = 2; // mm
    h[254..256].copy_from_slice(&1i16.to_le_bytes()); // sform_code
    h[280..284].copy_from_slice(&srow_x0.to_le_bytes());
    h[344..348].copy_from_slice(b"n+1\0");
    h
}

fn gzip(b: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(b).unwrap();
    e.finish().unwrap()
}

#[test]
fn pickle_shared_list_bomb_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // Protocol 2: L0 = []; L(k+1) = [Lk, Lk] via the memo; 40 levels = 2^40 values expanded.
    let mut b = vec![0x80, 2, b']', b'q', 0];
    for k in 0..40u8 {
        b.extend_from_slice(&[
            b']',
            b'q',
            k + 1,
            b'(',
            b'h',
            k,
            b'h',
            k,
            b'e',
            b'0',
            b'h',
            k + 1,
        ]);
    }
    b.push(b'.');
    let p = dir.path().join("bomb.pickle");
    std::fs::write(&p, &b).unwrap();
    let out = dir.path().join("out");
    assert_error(
        &["data", "import", "--pickle", &s(&p), "--out", &s(&out)],
        "bomb.pickle",
        &["pickle", "values"],
    );
}

#[test]
fn nifti_gz_with_gigabytes_of_trailing_zeros_reads_only_the_header_needs() {
    let dir = tempfile::tempdir().unwrap();
    // 24^3 volume (valid), then 2 GiB of zeros as 32 gzip members of 64 MiB each.
    let mut raw = nifti_header([24, 24, 24], 1.0);
    raw.extend((0..24 * 24 * 24).flat_map(|i| ((i % 7) as f32).to_le_bytes()));
    let mut file = gzip(&raw);
    let zeros = gzip(&vec![0u8; 64 << 20]);
    for _ in 0..32 {
        file.extend_from_slice(&zeros);
    }
    // Trailing zero padding after the last member, as some writers leave (Python reads it).
    file.extend_from_slice(&[0u8; 512]);
    let p = dir.path().join("zeros.nii.gz");
    std::fs::write(&p, &file).unwrap();
    let v = unispine::volume::load(&p).expect("valid volume followed by trailing data");
    assert_eq!(v.dims, [24, 24, 24]);
    assert_eq!(v.data[8], 1.0);
    // The same header claiming a huge volume: a clear error, bounded by the file's size.
    let mut raw = nifti_header([32000, 32000, 32000], 1.0);
    raw.extend_from_slice(&[0u8; 1024]);
    let p = dir.path().join("huge.nii.gz");
    std::fs::write(&p, gzip(&raw)).unwrap();
    let out = dir.path().join("out");
    assert_error(&strs(&data_us(&p, &out)), "huge.nii.gz", &["`dim`"]);
}

#[test]
fn nifti_symlink_to_a_device_and_truncated_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    #[cfg(unix)]
    {
        let p = dir.path().join("random.nii");
        std::os::unix::fs::symlink("/dev/urandom", &p).unwrap();
        assert_error(&strs(&data_us(&p, &out)), "random.nii", &["regular file"]);
    }
    let mut raw = nifti_header([64, 64, 64], 1.0);
    raw.extend_from_slice(&[0u8; 100]);
    let p = dir.path().join("cut.nii");
    std::fs::write(&p, &raw).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "cut.nii", &["truncated"]);
    // Negative and zero dims.
    let raw = nifti_header([-5, 4, 4], 1.0);
    let p = dir.path().join("neg.nii");
    std::fs::write(&p, &raw).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "neg.nii", &["dim[1]"]);
}

#[test]
fn non_finite_affine_is_dropped_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let mut raw = nifti_header([4, 4, 4], f32::NAN);
    raw.extend((0..64).flat_map(|i| (i as f32).to_le_bytes()));
    let p = dir.path().join("nan_affine.nii");
    std::fs::write(&p, &raw).unwrap();
    let v = unispine::volume::load(&p).unwrap();
    assert_eq!(v.provenance.file_affine, None);
    assert!(v.provenance.steps.iter().any(|s| s.contains("dropped")));
    let p = dir.path().join("inf.mha");
    let mut b = b"NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nOffset = 1e400 0 0\nElementDataFile = LOCAL\n".to_vec();
    b.extend_from_slice(&[1u8; 8]);
    std::fs::write(&p, &b).unwrap();
    let v = unispine::volume::load(&p).unwrap();
    assert_eq!(v.provenance.file_affine, None);
}

#[test]
fn npy_claiming_huge_shapes_is_refused_as_volume_and_dataset_array() {
    let dir = tempfile::tempdir().unwrap();
    let mut h =
        "{'descr': '<f4', 'fortran_order': False, 'shape': (4000, 4000, 4000), }".to_string();
    while !(10 + h.len() + 1).is_multiple_of(64) {
        h.push(' ');
    }
    h.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(h.len() as u16).to_le_bytes());
    b.extend_from_slice(h.as_bytes());
    b.extend_from_slice(&[0u8; 4096]);
    let p = dir.path().join("huge.npy");
    std::fs::write(&p, &b).unwrap();
    let out = dir.path().join("out");
    assert_error(&strs(&data_us(&p, &out)), "huge.npy", &["`data`", "4000"]);
    // Wrong dtype string and a non-UTF-8 header.
    let mut b2 = b.clone();
    let at = b2.windows(3).position(|w| w == b"<f4").unwrap();
    b2[at..at + 3].copy_from_slice(b"<c8");
    let p = dir.path().join("complex.npy");
    std::fs::write(&p, &b2).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "complex.npy", &["`descr`"]);
    let mut b3 = b.clone();
    b3[12] = 0xff;
    let p = dir.path().join("binary.npy");
    std::fs::write(&p, &b3).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "binary.npy", &["`header`"]);
}

#[test]
fn ply_claiming_huge_vertex_counts_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let geo = dir.path().join("geometry.json");
    std::fs::write(
        &geo,
        r#"{"DSD": 1500.0, "DSO": 1000.0, "nDetector": [8, 8], "dDetector": [4.0, 4.0],
            "nVoxel": [8, 8, 8], "dVoxel": [2.0, 2.0, 2.0]}"#,
    )
    .unwrap();
    let props = [
        "x", "y", "z", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        "opacity", "f_dc_0",
    ];
    for (name, count, fmt) in [
        ("e9.ply", "1000000000", "binary_little_endian"),
        ("e12.ply", "1000000000000", "binary_little_endian"),
        ("e18.ply", "1000000000000000000", "binary_little_endian"),
        ("ascii.ply", "1000000000000", "ascii"),
    ] {
        let mut h = format!("ply\nformat {fmt} 1.0\nelement vertex {count}\n");
        for p in props {
            h += &format!("property float {p}\n");
        }
        h += "end_header\n";
        let mut b = h.into_bytes();
        b.extend_from_slice(&[0u8; 480]);
        let p = dir.path().join(name);
        std::fs::write(&p, &b).unwrap();
        let out = dir.path().join("out");
        assert_error(
            &[
                "render",
                "--ply",
                &s(&p),
                "--geometry",
                &s(&geo),
                "--angle-deg",
                "0",
                "--out",
                &s(&out),
            ],
            name,
            &["element vertex"],
        );
    }
}

#[test]
fn metaimage_data_file_outside_the_folder_or_a_device_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (name, target, word) in [
        ("up.mhd", "../../etc/passwd", "plain file name"),
        ("abs.mhd", "/dev/zero", "plain file name"),
    ] {
        let p = dir.path().join(name);
        std::fs::write(
            &p,
            format!(
                "NDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\nElementDataFile = {target}\n"
            ),
        )
        .unwrap();
        assert_error(&strs(&data_us(&p, &out)), name, &["ElementDataFile", word]);
    }
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.raw")).unwrap();
        let p = dir.path().join("dev.mhd");
        std::fs::write(
            &p,
            "NDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\nElementDataFile = zero.raw\n",
        )
        .unwrap();
        assert_error(&strs(&data_us(&p, &out)), "zero.raw", &["regular file"]);
    }
    // A header over 1 MiB is reported as such.
    let p = dir.path().join("long.mha");
    let mut b = b"NDims = 3\n".to_vec();
    while b.len() < (1 << 20) + 100 {
        b.extend_from_slice(b"# comment line padding the header out\n");
    }
    b.extend_from_slice(b"ElementDataFile = LOCAL\n");
    std::fs::write(&p, &b).unwrap();
    assert_error(&strs(&data_us(&p, &out)), "long.mha", &["1048576"]);
}

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
