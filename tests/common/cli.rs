//! Running the `unispine` binary from the integration tests, and the input files they share.

#![allow(dead_code)]

use std::ffi::OsStr;
use std::path::Path;
use std::process::Command;

/// Exit status and output of one run of the binary.
#[derive(Debug)]
pub struct Run {
    pub ok: bool,
    pub stdout: String,
    pub stderr: String,
}

/// Run `unispine ARGS`.
pub fn run<S: AsRef<OsStr>>(args: &[S]) -> Run {
    run_threads(args, None)
}

/// Run `unispine ARGS` with `RAYON_NUM_THREADS` set when `threads` is given.
pub fn run_threads<S: AsRef<OsStr>>(args: &[S], threads: Option<usize>) -> Run {
    let mut c = Command::new(env!("CARGO_BIN_EXE_unispine"));
    c.args(args);
    if let Some(t) = threads {
        c.env("RAYON_NUM_THREADS", t.to_string());
    }
    let o = c.output().expect("run unispine");
    Run {
        ok: o.status.success(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

/// Run `unispine ARGS`, assert success, return stdout.
pub fn ok<S: AsRef<OsStr> + std::fmt::Debug>(args: &[S]) -> String {
    let r = run(args);
    assert!(r.ok, "{args:?} failed:\n{}", r.stderr);
    r.stdout
}

/// Run `unispine ARGS`, assert a failure that is not a panic, return stderr.
pub fn fails<S: AsRef<OsStr> + std::fmt::Debug>(args: &[S]) -> String {
    let r = run(args);
    assert!(!r.ok, "{args:?} should fail");
    assert!(
        !r.stderr.contains("panicked"),
        "{args:?} panicked:\n{}",
        r.stderr
    );
    r.stderr
}

/// Write a TIGRE / NAF geometry JSON with the given distances (mm), detector size `[v, u]` and
/// square pitch (mm); `extra` is appended inside the object (e.g. `, "nVoxel": [8, 8, 8]`).
pub fn write_geometry(
    path: &Path,
    [dsd, dso]: [f64; 2],
    [nv, nu]: [usize; 2],
    pitch: f64,
    extra: &str,
) {
    let text = format!(
        r#"{{"DSD": {dsd:?}, "DSO": {dso:?}, "nDetector": [{nv}, {nu}], "dDetector": [{pitch:?}, {pitch:?}]{extra}}}"#
    );
    std::fs::write(path, text).unwrap();
}
