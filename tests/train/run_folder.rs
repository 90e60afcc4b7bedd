//! Run folders tell the truth: the model scored at the last iteration is the model saved (through
//! a densification and an opacity reset), `eval` of it from another folder gives the recorded
//! bits, `render` uses the intensity model the PLY records, and a run stopped (by
//! `--stop-after` or a real SIGTERM) and resumed gives the same bits as the run that never
//! stopped.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;

use crate::common;
use common::tiny;
use unispine::session::{self, Control};
use unispine::train::{Checkpoint, Event, Method, RunDir, TrainConfig};

fn bin() -> Command {
    common::cli::bin()
}

fn ok(out: std::process::Output) -> String {
    assert!(
        out.status.success(),
        "exit {:?}\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// The tiny config with a densification (20) and an opacity reset (15) inside the run and both
/// also due at the last iteration (30), where they must not change the saved model.
fn schedule() -> TrainConfig {
    let mut c = tiny::tiny(Method::Unispine, 30);
    c.densify.until_iter = 40;
    c.densify.opacity_reset_interval = 15;
    c.eval_iterations = vec![15, 20];
    c
}

/// A dataset folder and a config file in `root`.
fn setup(root: &Path, cfg: &TrainConfig) -> PathBuf {
    unispine::dataset::store::save(&tiny::dataset(), &root.join("data")).unwrap();
    let c = root.join("cfg.json");
    std::fs::write(&c, serde_json::to_string(cfg).unwrap()).unwrap();
    c
}

/// `log.csv` without its wall-clock column.
fn log_rows(run: &Path) -> Vec<String> {
    std::fs::read_to_string(run.join("log.csv"))
        .unwrap()
        .lines()
        .map(|l| l.rsplit_once(',').unwrap().0.to_string())
        .collect()
}

#[test]
fn the_scored_model_is_the_saved_model() {
    let root = tempfile::tempdir().unwrap();
    let cfg = schedule();
    setup(root.path(), &cfg);
    // Relative paths, from the temporary folder.
    ok(bin()
        .current_dir(root.path())
        .args([
            "train", "--data", "data", "--out", "run", "--config", "cfg.json",
        ])
        .output()
        .unwrap());
    let run = root.path().join("run");
    let m = json(&run.join("metrics.json"));
    assert_eq!(m["completed"], true);
    // Iteration 20 densified (the count changes there), and its evaluation counts the model it
    // evaluated: the one before the densification.
    let log = log_rows(&run);
    let count = |it: usize| -> u64 { log[it].rsplit(',').next().unwrap().parse().unwrap() };
    assert_ne!(count(19), count(20), "no densification at iteration 20");
    let e20 = m["evals"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["iteration"] == 20)
        .unwrap();
    assert_eq!(e20["n_gaussians"].as_u64().unwrap(), count(19));
    assert_eq!(m["n_gaussians"].as_u64().unwrap(), count(30));

    // `eval` from another folder finds the dataset and gives the recorded bits.
    let out = ok(bin()
        .current_dir("/")
        .args(["eval", "--run"])
        .arg(&run)
        .output()
        .unwrap());
    let e = json(&run.join("eval.json"));
    assert_eq!(e["psnr"].as_f64(), m["test_psnr"].as_f64(), "{out}");
    assert_eq!(e["ssim"].as_f64(), m["test_ssim"].as_f64());
    assert_eq!(e["n_gaussians"], m["n_gaussians"]);

    // The PLY records how to render it; `render` uses that, and a contradicting --color fails.
    let model = run.join("model.ply");
    let head = std::fs::read(&model).unwrap();
    let head = String::from_utf8_lossy(&head[..400]);
    assert!(
        head.contains("comment unispine-render {\"color\":\"rirf-xgaussian\""),
        "{head}"
    );
    let view = ["--dataset", "data", "--view", "test:1"];
    ok(bin()
        .current_dir(root.path())
        .args(["render", "--ply", "run/model.ply", "--out", "r1"])
        .args(view)
        .output()
        .unwrap());
    ok(bin()
        .current_dir(root.path())
        .args([
            "render",
            "--run",
            "run",
            "--out",
            "r2",
            "--precision",
            "f64",
        ])
        .args(view)
        .output()
        .unwrap());
    assert_eq!(
        std::fs::read(root.path().join("r1/image.npy")).unwrap(),
        std::fs::read(root.path().join("r2/image.npy")).unwrap()
    );
    let out = bin()
        .current_dir(root.path())
        .args([
            "render",
            "--ply",
            "run/model.ply",
            "--out",
            "r3",
            "--color",
            "rirf-paper",
        ])
        .args(view)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("contradicts") && err.contains("model.ply"),
        "{err}"
    );

    // Training again into the folder: nothing of the first run is left to be mistaken for the
    // second (here the second run is stopped after 2 iterations, so it writes no model).
    let mut bad = cfg.clone();
    bad.preview_views = 0;
    bad.iterations = 5;
    bad.eval_iterations = vec![];
    bad.checkpoint_every = 0;
    std::fs::write(
        root.path().join("cfg2.json"),
        serde_json::to_string(&bad).unwrap(),
    )
    .unwrap();
    ok(bin()
        .current_dir(root.path())
        .args([
            "train",
            "--data",
            "data",
            "--out",
            "run",
            "--config",
            "cfg2.json",
        ])
        .args(["--stop-after", "2"])
        .output()
        .unwrap());
    for gone in ["model.ply", "eval.json", "previews"] {
        assert!(
            !run.join(gone).exists(),
            "{gone} of the first run is still there"
        );
    }
    assert_eq!(json(&run.join("metrics.json"))["iterations"], 2);

    // A value that cannot work is refused before iteration 1, with its range, and a failure
    // that is not a divergence names no checkpoint.
    let out = bin()
        .current_dir(root.path())
        .args([
            "train",
            "--data",
            "data",
            "--out",
            "run2",
            "--position-lr-init",
            "1e30",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("lr.position_init") && err.contains("(0, 1]"),
        "{err}"
    );
    assert!(!err.contains("checkpoint"), "{err}");
}

fn quiet(_: &Event) {}

fn same_state(a: &Checkpoint, b: &Checkpoint) {
    assert_eq!(a.iteration, b.iteration);
    assert_eq!(a.state.params, b.state.params);
    assert_eq!(a.state.adam, b.state.adam);
    assert_eq!(a.state.stats, b.state.stats);
    assert_eq!(a.rng_word_pos, b.rng_word_pos);
    assert_eq!(a.view_stack, b.view_stack);
    assert_eq!(a.evals, b.evals);
    assert_eq!(a.render, b.render);
}

#[test]
fn a_stopped_and_resumed_run_gives_the_same_bits() {
    let ds = tiny::dataset();
    let mut cfg = schedule();
    cfg.iterations = 40;
    cfg.densify.until_iter = 30;
    cfg.eval_iterations = vec![10, 25];
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let never = AtomicBool::new(false);
    let ctl = |stop_after| Control {
        stop: &never,
        stop_after,
    };
    let straight = session::run(
        &cfg.clone().into(),
        &ds,
        Some(a.path()),
        ctl(None),
        &mut quiet,
    )
    .unwrap();
    // Stopped at 17: between a reset (15) and a densification (20), statistics half-gathered.
    let stopped = session::run(
        &cfg.clone().into(),
        &ds,
        Some(b.path()),
        ctl(Some(17)),
        &mut quiet,
    )
    .unwrap();
    assert!(!stopped.completed);
    assert_eq!(stopped.iterations, 17);
    let resumed = session::resume(b.path(), &ds, ctl(None), &mut quiet).unwrap();
    assert!(resumed.completed);
    assert_eq!(resumed.evals, straight.evals);
    assert_eq!(resumed.test_psnr, straight.test_psnr);
    assert_eq!(resumed.n_gaussians, straight.n_gaussians);
    assert_eq!(
        std::fs::read(a.path().join("model.ply")).unwrap(),
        std::fs::read(b.path().join("model.ply")).unwrap()
    );
    assert_eq!(log_rows(a.path()), log_rows(b.path()));
    assert_eq!(log_rows(a.path()).len(), 41);
    let ck = |p: &Path| RunDir::open(p).unwrap().read_checkpoint().unwrap();
    same_state(&ck(a.path()), &ck(b.path()));
}

#[test]
fn sigterm_writes_a_checkpoint_exits_143_and_resumes_with_the_same_bits() {
    let root = tempfile::tempdir().unwrap();
    let mut cfg = tiny::tiny(Method::Xgaussian, 5000);
    cfg.checkpoint_every = 0;
    setup(root.path(), &cfg);
    let train = || {
        let mut c = bin();
        c.current_dir(root.path())
            .args(["train", "--data", "data", "--config", "cfg.json", "--out"]);
        c
    };
    let mut child = train()
        .arg("sig")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // The first checkpoint (iteration 0) is written once the handler is installed.
    let sig = root.path().join("sig");
    let t = std::time::Instant::now();
    while !sig.join("checkpoint.bin").exists() {
        assert!(t.elapsed().as_secs() < 120, "training did not start");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    std::thread::sleep(std::time::Duration::from_millis(200));
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(143));
    let m = json(&sig.join("metrics.json"));
    assert_eq!(m["completed"], false);
    let k = m["iterations"].as_u64().unwrap() as usize;
    let c = RunDir::open(&sig).unwrap().read_checkpoint().unwrap();
    assert_eq!(c.iteration, k);
    assert!(k < 5000);
    assert_eq!(m["n_gaussians"].as_u64().unwrap() as usize, c.state.len());
    // Resume to k + 7; a fresh run stopped at k + 7 must hold the same state.
    let until = (k + 7).to_string();
    ok(bin()
        .current_dir("/")
        .args(["train", "--resume"])
        .arg(&sig)
        .args(["--stop-after", &until])
        .output()
        .unwrap());
    ok(train()
        .arg("straight")
        .args(["--stop-after", &until])
        .output()
        .unwrap());
    let ck = |p: &str| {
        RunDir::open(&root.path().join(p))
            .unwrap()
            .read_checkpoint()
            .unwrap()
    };
    let (a, b) = (ck("sig"), ck("straight"));
    assert_eq!(a.iteration, k + 7);
    same_state(&a, &b);
    assert_eq!(log_rows(&sig), log_rows(&root.path().join("straight")));
}

/// The progress of `train --resume` counts from the iteration it resumed at: the plain-text
/// progress (stderr is not a terminal here) ends with `train: N/N`, which a count from 0 never
/// reaches (it would end at N - k).
#[test]
fn resumed_progress_counts_from_the_resumed_iteration() {
    let root = tempfile::tempdir().unwrap();
    let mut cfg = tiny::tiny(Method::Xgaussian, 24);
    cfg.checkpoint_every = 0;
    setup(root.path(), &cfg);
    let run = root.path().join("r");
    ok(bin()
        .current_dir(root.path())
        .args([
            "train", "--data", "data", "--config", "cfg.json", "--out", "r",
        ])
        .args(["--stop-after", "9"])
        .output()
        .unwrap());
    let o = bin()
        .args(["train", "--resume"])
        .arg(&run)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{err}");
    assert!(err.contains("train: 24/24 "), "{err}");
    assert!(!err.contains("train: 15/24 "), "{err}");
}

#[test]
fn resume_refuses_another_dataset_an_edited_config_and_a_corrupted_checkpoint() {
    let ds = tiny::dataset();
    let cfg = schedule();
    let d = tempfile::tempdir().unwrap();
    let never = AtomicBool::new(false);
    let ctl = |stop_after| Control {
        stop: &never,
        stop_after,
    };
    let stopped = session::run(
        &cfg.clone().into(),
        &ds,
        Some(d.path()),
        ctl(Some(7)),
        &mut quiet,
    )
    .unwrap();
    assert!(!stopped.completed);
    let ckpt = d.path().join("checkpoint.bin");
    let good = std::fs::read(&ckpt).unwrap();
    let refused = |ds: &unispine::dataset::Dataset, words: &[&str]| {
        let e = session::resume(d.path(), ds, ctl(None), &mut quiet)
            .unwrap_err()
            .to_string();
        for w in words {
            assert!(e.contains(w), "no `{w}` in: {e}");
        }
    };
    // Another dataset: one projection value changed.
    let mut other = tiny::dataset();
    other.train.projections[0].data[5] += 0.25;
    refused(&other, &["checkpoint.bin", "dataset"]);
    // config.json edited: the intensity model reinterprets the features; then a setting that
    // only the fingerprint sees.
    let cfg_path = d.path().join("config.json");
    let original = std::fs::read_to_string(&cfg_path).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&original).unwrap();
    v["color"] = serde_json::json!("sh");
    std::fs::write(&cfg_path, v.to_string()).unwrap();
    refused(&ds, &["color", "sh"]);
    let mut v: serde_json::Value = serde_json::from_str(&original).unwrap();
    v["seed"] = serde_json::json!(cfg.seed + 1);
    std::fs::write(&cfg_path, v.to_string()).unwrap();
    refused(&ds, &["seed"]);
    let mut v: serde_json::Value = serde_json::from_str(&original).unwrap();
    v["background"] = serde_json::json!(0.5);
    std::fs::write(&cfg_path, v.to_string()).unwrap();
    refused(&ds, &["config.json changed"]);
    std::fs::write(&cfg_path, &original).unwrap();
    // A flipped bit in the middle of the parameters.
    let mut bad = good.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 0x01;
    std::fs::write(&ckpt, &bad).unwrap();
    refused(&ds, &["checksum"]);
    // Restored: it resumes and completes.
    std::fs::write(&ckpt, &good).unwrap();
    let m = session::resume(d.path(), &ds, ctl(None), &mut quiet).unwrap();
    assert!(m.completed);
}

/// `eval --run` of a stopped run scores its checkpoint's model, even beside a `model.ply`
/// (only a completed run's `model.ply` is its model).
#[test]
fn a_stopped_run_is_scored_from_its_checkpoint() {
    let root = tempfile::tempdir().unwrap();
    let cfg = schedule();
    setup(root.path(), &cfg);
    let train = |out: &str, extra: &[&str]| {
        ok(bin()
            .current_dir(root.path())
            .args([
                "train", "--data", "data", "--out", out, "--config", "cfg.json",
            ])
            .args(extra)
            .output()
            .unwrap())
    };
    train("full", &[]);
    train("cut", &["--stop-after", "10"]);
    let cut = root.path().join("cut");
    assert_eq!(json(&cut.join("metrics.json"))["completed"], false);
    let at10: u64 = log_rows(&cut)[10]
        .rsplit(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    let full_n = json(&root.path().join("full/metrics.json"))["n_gaussians"]
        .as_u64()
        .unwrap();
    assert_ne!(at10, full_n, "the two models must be told apart");
    std::fs::copy(root.path().join("full/model.ply"), cut.join("model.ply")).unwrap();
    ok(bin()
        .current_dir(root.path())
        .args(["eval", "--run", "cut"])
        .output()
        .unwrap());
    assert_eq!(
        json(&cut.join("eval.json"))["n_gaussians"].as_u64(),
        Some(at10)
    );
}
