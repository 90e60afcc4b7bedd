//! `unispine train --method fdk`: the run folder has the Gaussian trainer's `metrics.json`
//! (read by `unispine report` without special cases), the model as numpy-readable npy, and bad
//! settings are errors naming them.

use std::path::Path;
use std::process::Output;

use unispine::train::Metrics;

use crate::common;

fn unispine(args: &[&str], cwd: &Path) -> Output {
    common::cli::bin()
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run unispine")
}

fn ok(args: &[&str], cwd: &Path) -> String {
    let o = unispine(args, cwd);
    assert!(
        o.status.success(),
        "{args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// `unispine data phantom` into `d/ph`: `size`^3 voxels, a `detector`^2 detector, the given views.
fn phantom(d: &Path, size: u32, detector: u32, train: u32, test: u32) {
    let (size, detector, train, test) = (
        size.to_string(),
        detector.to_string(),
        train.to_string(),
        test.to_string(),
    );
    ok(
        &[
            "data",
            "phantom",
            "--size",
            &size,
            "--detector",
            &detector,
            "--train-views",
            &train,
            "--test-views",
            &test,
            "--out",
            "ph",
        ],
        d,
    );
}

#[test]
fn fdk_run_folder_is_a_report_row() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, 32, 64, 24, 6);
    let out = ok(
        &["train", "--data", "ph", "--method", "fdk", "--out", "fdk"],
        d,
    );
    assert!(out.contains("fdk: test PSNR"), "{out}");
    let m: Metrics =
        serde_json::from_str(&std::fs::read_to_string(d.join("fdk/metrics.json")).unwrap())
            .unwrap();
    assert_eq!(m.method, "fdk");
    assert!(m.completed);
    // FDK of a 32^3 phantom from 24 views, re-projected: a usable reconstruction (the
    // 64^3 phantom from 50 views scores about 32 dB), but not the ground truth.
    let psnr = m.test_psnr.unwrap();
    assert!(psnr > 22.0 && psnr < 60.0, "psnr {psnr}");
    assert!(m.test_ssim.unwrap() > 0.7);
    assert!(m.render_fps.unwrap() > 0.0 && m.train_time_s > 0.0);
    assert_eq!(m.model_bytes, Some(32 * 32 * 32 * 4));
    let vol: ndarray::Array3<f32> = ndarray_npy::read_npy(d.join("fdk/model.npy")).unwrap();
    assert_eq!(vol.dim(), (32, 32, 32));
    assert!(d.join("fdk/log.csv").exists() && d.join("fdk/config.json").exists());
    let table = ok(&["report", "fdk"], d);
    assert!(table.contains("| fdk | fdk | 1 |"), "{table}");
}

#[test]
fn bad_method_settings_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = unispine(
        &[
            "train", "--data", "nowhere", "--method", "fbp", "--out", "x",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("unknown method `fbp`") && e.contains("fdk"),
        "{e}"
    );
    phantom(d, 32, 16, 2, 1);
    let o = unispine(
        &[
            "train", "--data", "ph", "--method", "fdk", "--iters", "5", "--out", "x",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--iters"));
    let o = unispine(
        &[
            "train", "--data", "ph", "--method", "fdk", "--rays", "all", "--out", "x",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--rays"));
    // A Gaussian training setting given to a baseline is an error naming it (it used to be
    // ignored).
    for (method, flag, value) in [
        ("naf", "--max-gaussians", "10"),
        ("fdk", "--preview-views", "2"),
        ("nerf", "--compress-schedule", ""),
    ] {
        let mut args = vec![
            "train", "--data", "ph", "--method", method, "--out", "x", flag,
        ];
        if !value.is_empty() {
            args.push(value);
        }
        let o = unispine(&args, d);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains(flag) && e.contains("--seed"), "{e}");
    }
}

/// `--seed` reaches a field run (initialisation, ray batches, samples): the same seed gives the
/// same bits, another seed another model.
#[test]
fn a_field_run_follows_its_seed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, 32, 8, 3, 1);
    let model = |seed: &str, out: &str| {
        ok(
            &[
                "train", "--data", "ph", "--method", "naf", "--iters", "2", "--seed", seed,
                "--out", out,
            ],
            d,
        );
        std::fs::read(d.join(out).join("model.npz")).unwrap()
    };
    let a = model("1", "a");
    assert_eq!(a, model("1", "b"));
    // `--rays all` reaches the run and its label.
    ok(
        &[
            "train", "--data", "ph", "--method", "naf", "--iters", "2", "--seed", "1", "--rays",
            "all", "--out", "all",
        ],
        d,
    );
    let m = std::fs::read_to_string(d.join("all/metrics.json")).unwrap();
    assert!(m.contains("\"naf (reduced, all pixels)\""), "{m}");
    let c = std::fs::read_to_string(d.join("all/config.json")).unwrap();
    assert!(c.contains("\"ray_pixels\": \"all\""), "{c}");
    assert_ne!(a, model("2", "c"));
    assert_ne!(a, model("0", "e"));
    // FDK draws nothing at random: the seed is accepted and changes nothing.
    for (seed, out) in [("0", "f0"), ("5", "f5")] {
        ok(
            &[
                "train", "--data", "ph", "--method", "fdk", "--seed", seed, "--out", out,
            ],
            d,
        );
    }
    assert_eq!(
        std::fs::read(d.join("f0/model.npy")).unwrap(),
        std::fs::read(d.join("f5/model.npy")).unwrap()
    );
}

/// SIGTERM / SIGINT during a field baseline run: it stops at the next iteration boundary,
/// writes the model and a `metrics.json` with `"completed": false` (the log holds every
/// iteration done) and a checkpoint, and exits 143 / 130 like the Gaussian trainer; `--resume`
/// continues it.
#[test]
fn a_signal_stops_a_field_run_with_its_model_and_metrics() {
    use std::io::BufRead;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, 32, 16, 4, 2);
    for (sig, code, name) in [(libc::SIGTERM, 143, "term"), (libc::SIGINT, 130, "int")] {
        let mut child = common::cli::bin()
            .args([
                "train", "--data", "ph", "--method", "naf", "--iters", "1000000",
            ])
            .args(["--out", name])
            .current_dir(d)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // The handler is installed before the `running` line; the reader keeps draining
        // stderr so that the child never blocks on it.
        let (tx, rx) = std::sync::mpsc::channel();
        let err = child.stderr.take().unwrap();
        let reader = std::thread::spawn(move || {
            let mut all = String::new();
            for line in std::io::BufReader::new(err).lines() {
                let line = line.unwrap();
                if line.starts_with("running") {
                    tx.send(()).ok();
                }
                all += &line;
                all.push('\n');
            }
            all
        });
        rx.recv_timeout(std::time::Duration::from_secs(120))
            .expect("the field run did not start");
        std::thread::sleep(std::time::Duration::from_millis(700));
        unsafe {
            libc::kill(child.id() as libc::pid_t, sig);
        }
        let status = child.wait().unwrap();
        let stderr = reader.join().unwrap();
        assert_eq!(status.code(), Some(code), "{stderr}");
        let run = d.join(name);
        let m: Metrics =
            serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap())
                .unwrap();
        assert!(!m.completed);
        assert!(m.iterations < 1_000_000);
        assert_eq!(m.test_psnr, None);
        assert!(run.join("model.npz").is_file() && run.join("config.json").is_file());
        let log = std::fs::read_to_string(run.join("log.csv")).unwrap();
        assert_eq!(log.lines().count(), m.iterations + 1, "{log}");
        assert!(run.join("checkpoint.bin").is_file());
        let more = (m.iterations + 3).to_string();
        ok(
            &[
                "train",
                "--resume",
                name,
                "--data",
                "ph",
                "--stop-after",
                &more,
            ],
            d,
        );
        let log = std::fs::read_to_string(run.join("log.csv")).unwrap();
        assert_eq!(log.lines().count(), m.iterations + 4, "{log}");
    }
}

/// A field run stopped after 12 of 30 iterations and resumed (on another thread count) ends
/// with the bits and the log of the run that never stopped; its `--threads` is followed; a
/// damaged checkpoint or a setting given to `--resume` is an error naming it.
#[test]
fn a_resumed_field_run_has_the_bits_of_one_that_never_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, 32, 16, 4, 2);
    for m in ["intratomo", "tensorf"] {
        let (full, part) = (format!("full-{m}"), format!("part-{m}"));
        let base = ["train", "--data", "ph", "--method", m, "--iters", "30"];
        ok(&[&base[..], &["--out", &full]].concat(), d);
        let args = [&base[..], &["--stop-after", "12", "--out", &part]].concat();
        let out = ok(&args, d);
        assert!(out.contains("stopped at iteration 12"), "{out}");
        let p = d.join(&part);
        assert!(p.join("checkpoint.bin").is_file());
        // A setting of the run: clap refuses --iters (a usage error, exit 1), the check --vm-lines.
        let o = unispine(&["train", "--resume", &part, "--iters", "40"], d);
        assert_eq!(o.status.code(), Some(1), "{m}");
        let o = unispine(&["train", "--resume", &part, "--vm-lines", "corrected"], d);
        assert_eq!(o.status.code(), Some(1), "{m}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("own config.json"));
        ok(
            &["train", "--resume", &part, "--data", "ph", "--threads", "1"],
            d,
        );
        let f = d.join(&full);
        assert_eq!(
            std::fs::read(f.join("model.npz")).unwrap(),
            std::fs::read(p.join("model.npz")).unwrap(),
            "{m}: resumed model differs"
        );
        let cols = |run: &Path| -> Vec<String> {
            let log = std::fs::read_to_string(run.join("log.csv")).unwrap();
            // Every column but the wall-clock seconds.
            log.lines()
                .map(|l| l.rsplit_once(',').unwrap().0.to_string())
                .collect()
        };
        assert_eq!(cols(&f), cols(&p), "{m}");
        let mt: Metrics =
            serde_json::from_str(&std::fs::read_to_string(p.join("metrics.json")).unwrap())
                .unwrap();
        assert!(mt.completed && mt.iterations == 30 && mt.threads == 1);
        assert!(
            !p.join("checkpoint.bin").exists(),
            "a completed run keeps no checkpoint"
        );
    }
    // A truncated checkpoint.
    let args = ["train", "--data", "ph", "--method", "naf", "--iters", "30"];
    ok(
        &[&args[..], &["--stop-after", "5", "--out", "cut"]].concat(),
        d,
    );
    let ck = d.join("cut/checkpoint.bin");
    let b = std::fs::read(&ck).unwrap();
    std::fs::write(&ck, &b[..b.len() - 10]).unwrap();
    let o = unispine(&["train", "--resume", "cut", "--data", "ph"], d);
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("checkpoint.bin") && e.contains("truncated"),
        "{e}"
    );
}

#[test]
fn tensorf_trains_and_saves_a_numpy_readable_model() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, 32, 8, 2, 1);
    for (lines, out) in [(None, "tf"), (Some("corrected"), "tfc")] {
        let mut args = vec![
            "train", "--data", "ph", "--method", "tensorf", "--iters", "2", "--out", out,
        ];
        if let Some(l) = lines {
            args.extend(["--vm-lines", l]);
        }
        let text = ok(&args, d);
        assert!(text.contains("tensorf (reduced): test PSNR"), "{text}");
        let m: Metrics = serde_json::from_str(
            &std::fs::read_to_string(d.join(out).join("metrics.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(m.method, "tensorf (reduced)");
        assert_eq!(m.iterations, 2);
        assert!(m.test_psnr.is_some() && m.render_fps.unwrap() > 0.0);
        // 3 x 8 x 256^2 + 3 x 8 x 256 + 32 x 24 VM values, then the 4 x 64 MLP (skip 2).
        let mlp = (32 * 64 + 64) + (64 * 64 + 64) + (96 * 64 + 64) + (64 + 1);
        assert_eq!(m.model_bytes, Some(4 * (1_579_776 + mlp)));
        let cfg: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.join(out).join("config.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(cfg["encoder"]["lines"], lines.unwrap_or("upstream"));
        let mut npz = ndarray_npy::NpzReader::new(
            std::fs::File::open(d.join(out).join("model.npz")).unwrap(),
        )
        .unwrap();
        let meta: ndarray::Array1<i64> = npz.by_name("vm_meta").unwrap();
        assert_eq!(meta.to_vec(), vec![256, 8, 32, lines.is_some() as i64]);
        let planes: ndarray::Array4<f32> = npz.by_name("vm_planes").unwrap();
        assert_eq!(planes.dim(), (3, 8, 256, 256));
        let basis: ndarray::Array2<f32> = npz.by_name("vm_basis").unwrap();
        assert_eq!(basis.dim(), (32, 24));
    }
    // --vm-lines belongs to the TensoRF presets only.
    for method in ["naf", "unispine"] {
        let o = unispine(
            &[
                "train",
                "--data",
                "ph",
                "--method",
                method,
                "--vm-lines",
                "corrected",
                "--out",
                "x",
            ],
            d,
        );
        assert_eq!(o.status.code(), Some(1), "{method}");
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("--vm-lines"),
            "{method}"
        );
    }
}

/// An FDK run is one pass: `--resume` on its folder is an error saying so (exit 1), and the
/// folder is left as it was.
#[test]
fn an_fdk_run_is_not_resumed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    phantom(d, 32, 8, 4, 1);
    ok(
        &["train", "--data", "ph", "--method", "fdk", "--out", "f"],
        d,
    );
    let before = std::fs::read(d.join("f/metrics.json")).unwrap();
    let o = unispine(&["train", "--resume", "f"], d);
    assert_eq!(o.status.code(), Some(1));
    let e = common::cli::text(&o);
    assert!(e.contains("FDK") && e.contains("nothing to resume"), "{e}");
    assert_eq!(std::fs::read(d.join("f/metrics.json")).unwrap(), before);
}
