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

/// The `unispine` binary built for these tests, as a command to add arguments to (the one
/// place that names it).
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_unispine"))
}

/// Stdout and stderr of a finished run, one after the other (for assertion messages).
pub fn text(o: &std::process::Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Run `unispine ARGS`.
pub fn run<S: AsRef<OsStr>>(args: &[S]) -> Run {
    run_threads(args, None)
}

/// Run `unispine ARGS` with `RAYON_NUM_THREADS` set when `threads` is given.
pub fn run_threads<S: AsRef<OsStr>>(args: &[S], threads: Option<usize>) -> Run {
    let mut c = bin();
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

/// Exit code, stdout and stderr of a run under limits.
#[derive(Debug)]
pub struct Limited {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

/// Run `unispine ARGS` in `cwd` under a virtual-memory limit of `mem_mib` MiB (`ulimit -v`) and a
/// wall-time limit of `secs` seconds (the test fails if it is exceeded), with extra environment
/// variables `env` (`PATH` among them, for stub commands).
pub fn run_limited<S: AsRef<OsStr>>(
    args: &[S],
    cwd: &Path,
    env: &[(&str, &str)],
    mem_mib: u64,
    secs: u64,
) -> Limited {
    use std::io::Read;
    let mut script = format!("ulimit -v {}; exec \"$0\"", mem_mib * 1024);
    for k in 1..=args.len() {
        script += &format!(" \"${{{k}}}\"");
    }
    let mut c = Command::new("sh");
    c.arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_unispine"))
        .args(args)
        .current_dir(cwd)
        .env("RAYON_NUM_THREADS", "2")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    for (k, v) in env {
        c.env(k, v);
    }
    let mut child = c.spawn().expect("spawn sh");
    let (mut out, mut err) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let t_out = std::thread::spawn(move || {
        let mut s = String::new();
        out.read_to_string(&mut s).ok();
        s
    });
    let t_err = std::thread::spawn(move || {
        let mut s = String::new();
        err.read_to_string(&mut s).ok();
        s
    });
    let t0 = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed().as_secs() > secs {
            child.kill().ok();
            panic!("`unispine` did not finish within {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    Limited {
        code: status.code().unwrap_or(-1),
        stdout: t_out.join().unwrap(),
        stderr: t_err.join().unwrap(),
    }
}

/// A listing of every file below `dir` with its size and FNV-1a checksum, sorted (symlinks
/// listed with their target, not followed): compare it before and after a command to show that
/// the command changed nothing there.
pub fn tree_listing(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<String>) {
        let Ok(rd) = std::fs::read_dir(d) else {
            return;
        };
        for e in rd.flatten() {
            let p = e.path();
            let rel = p.strip_prefix(root).unwrap().display().to_string();
            let m = std::fs::symlink_metadata(&p).unwrap();
            if m.file_type().is_symlink() {
                out.push(format!(
                    "{rel} -> {}",
                    std::fs::read_link(&p).unwrap().display()
                ));
            } else if m.is_dir() {
                out.push(format!("{rel}/"));
                walk(root, &p, out);
            } else {
                let b = std::fs::read(&p).unwrap();
                let h = b.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &x| {
                    (h ^ x as u64).wrapping_mul(0x0000_0100_0000_01b3)
                });
                out.push(format!("{rel} {} {h:016x}", b.len()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}
