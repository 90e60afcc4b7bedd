//! Hostile-input runs: each case is given to the binary under a memory limit (`ulimit -v`) and a
//! timeout, and must end as a clear error (exit 1) naming the file and the field: no panic
//! (101), no abort (134), no hang, no out-of-memory.

use std::io::Write;
use std::path::Path;
use std::time::Duration;

/// Virtual-memory limit of each run, KiB (1.5 GiB: far below what the hostile claims ask for).
pub const MEM_KIB: u64 = 1_536 * 1024;
/// Wall-time limit of each run.
pub const TIMEOUT: Duration = Duration::from_secs(60);

/// Run the binary with `args` under the limits; return (exit code, stderr).
pub fn run(args: &[&str]) -> (i32, String) {
    let r = super::cli::run_limited(args, Path::new("."), &[], MEM_KIB / 1024, TIMEOUT.as_secs());
    (r.code, r.stderr)
}

/// Assert a clean error exit naming `file` and each of `words`.
pub fn assert_error(args: &[&str], file: &str, words: &[&str]) {
    let (code, err) = run(args);
    assert_eq!(code, 1, "`unispine {}`: exit {code}\n{err}", args.join(" "));
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(file), "message does not name {file}:\n{err}");
    for w in words {
        assert!(err.contains(w), "message does not contain `{w}`:\n{err}");
    }
}

pub fn s(p: &Path) -> String {
    p.display().to_string()
}

pub fn data_us(vol: &Path, out: &Path) -> Vec<String> {
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

pub fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(|x| x.as_str()).collect()
}

/// A NIfTI-1 header (little endian) for a float32 volume of `dims`, 1 mm voxels.
pub fn nifti_header(dims: [i16; 3], srow_x0: f32) -> Vec<u8> {
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

pub fn gzip(b: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(b).unwrap();
    e.finish().unwrap()
}
