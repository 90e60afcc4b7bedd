//! `unispine reproduce`: running a tiny plan, resuming it, bit-identical results for any
//! `--jobs`, failing cells recorded while the others go on, collecting partial results, and
//! plan errors naming the line.

use std::path::Path;
use std::process::Output;

use crate::common;

fn reproduce(args: &[&str], cwd: &Path) -> Output {
    common::cli::bin()
        .arg("reproduce")
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run unispine")
}

use common::cli::text;

/// A plan small enough for the test suite: a 32^3 phantom, 32 x 32 detector, 10 training
/// views, 30 iterations.
fn tiny_plan(iters: usize, extra: &str) -> String {
    format!(
        "name = \"tiny\"\niters = {iters}\ncompress_schedule = true\nseeds = [0, 1]\n\
         methods = [\"xgaussian\", \"unispine\"{extra_m}]\n[train]\npreview_views = 0\n\
         [[datasets]]\nname = \"ph\"\n\
         data = [\"phantom\", \"--size\", \"32\", \"--detector\", \"32\", \"--train-views\", \
         \"10\", \"--test-views\", \"4\"]\n{extra}",
        extra_m = if extra.is_empty() { "" } else { ", \"broken\"" },
    )
}

/// Columns that must be bit-identical between runs: (cell, psnr, ssim, n_gaussians).
fn deterministic_columns(csv: &str) -> Vec<String> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
    let (d, m, s, p, q, g) = (
        col("dataset"),
        col("method"),
        col("seed"),
        col("psnr"),
        col("ssim"),
        col("n_gaussians"),
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            format!("{}/{}/{} {} {} {}", f[d], f[m], f[s], f[p], f[q], f[g])
        })
        .collect()
}

/// Every row of `OUT/results.csv` against its run folder, read here: the figures of
/// `metrics.json`, the record of `cell.json`, and the row's identity from its folder's name
/// (`runs/DATASET/METHOD/seedN`). A gather that read the wrong key, the wrong file or another
/// cell's folder shows here.
fn rows_match_their_run_folders(out: &Path) {
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut n = 0;
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), header.len(), "{line}");
        let col = |name: &str| f[header.iter().position(|h| *h == name).unwrap()];
        let run = out.join(col("run_dir"));
        let parts: Vec<String> = Path::new(col("run_dir"))
            .iter()
            .map(|s| s.to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            parts[1..],
            [
                col("dataset").to_string(),
                col("method").to_string(),
                format!("seed{}", col("seed"))
            ],
            "{line}"
        );
        let json = |name: &str| -> serde_json::Value {
            serde_json::from_str(&std::fs::read_to_string(run.join(name)).unwrap()).unwrap()
        };
        let (m, c) = (json("metrics.json"), json("cell.json"));
        let num = |s: &str| s.parse::<f64>().unwrap();
        assert_eq!(col("status"), c["status"].as_str().unwrap(), "{line}");
        assert_eq!(col("completed"), m["completed"].to_string(), "{line}");
        for (column, key) in [
            ("psnr", "test_psnr"),
            ("ssim", "test_ssim"),
            ("train_time_s", "train_time_s"),
            ("fps", "render_fps"),
        ] {
            assert_eq!(
                num(col(column)),
                m[key].as_f64().unwrap(),
                "{column}: {line}"
            );
        }
        assert_eq!(num(col("n_gaussians")), m["n_gaussians"].as_f64().unwrap());
        assert_eq!(
            num(col("peak_memory_mib")),
            m["peak_memory_bytes"].as_f64().unwrap() / 1048576.0
        );
        assert_eq!(num(col("wall_s")), c["wall_s"].as_f64().unwrap(), "{line}");
        assert_eq!(
            col("dataset_checksum"),
            c["dataset_checksum"].as_str().unwrap()
        );
        assert_eq!(num(col("threads")), c["threads"].as_f64().unwrap());
        for k in ["cpu_model", "simd", "version", "git_commit"] {
            assert_eq!(col(k), c["machine"][k].as_str().unwrap(), "{k}: {line}");
        }
        assert_eq!(num(col("cores")), c["machine"]["cores"].as_f64().unwrap());
        n += 1;
    }
    assert!(n > 0, "no row in {csv}");
}

#[test]
fn a_plan_runs_resumes_and_does_not_depend_on_jobs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("plan.toml"), tiny_plan(30, "")).unwrap();

    let o = reproduce(&["plan.toml", "--out", "a", "--jobs", "1"], dir);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("[cell 4/4]") && t.contains("left"), "{t}");
    let csv_a = std::fs::read_to_string(dir.join("a/results.csv")).unwrap();
    let cols_a = deterministic_columns(&csv_a);
    assert_eq!(cols_a.len(), 4);
    for c in &cols_a {
        assert!(!c.contains("  "), "a cell without a result: {c}\n{csv_a}");
    }
    assert!(csv_a.contains(",done,true,"), "{csv_a}");
    rows_match_their_run_folders(&dir.join("a"));
    for f in ["tables.md", "results.json"] {
        assert!(dir.join("a").join(f).is_file(), "{f}");
    }
    let md = std::fs::read_to_string(dir.join("a/tables.md")).unwrap();
    assert!(md.contains("| xgaussian | 2 of 2 |"), "{md}");
    assert!(md.contains("SPWM improves on X-Gaussian"), "{md}");
    // Magnitude, pooled and per dataset: `ph` stands in for no paper dataset, so the sign alone.
    assert!(md.contains("## Verdicts on magnitude"), "{md}");
    assert!(
        md.contains("| pooled | 2 |") && md.contains("| ph | 2 |"),
        "{md}"
    );
    assert!(
        t.contains("magnitude: [ph] SPWM improves on X-Gaussian"),
        "{t}"
    );
    // The verdict of the plan's claim, as the harness prints it.
    assert!(
        t.lines()
            .any(|l| l.starts_with("verdict: ") && l.contains("SPWM improves on X-Gaussian")),
        "{t}"
    );

    // Run again: every cell is kept, nothing retrains.
    let ply = dir.join("a/runs/ph/unispine/seed1/model.ply");
    let before = std::fs::metadata(&ply).unwrap().modified().unwrap();
    let o = reproduce(&["plan.toml", "--out", "a"], dir);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        text(&o).matches("finished earlier, kept").count(),
        4,
        "{}",
        text(&o)
    );
    assert_eq!(std::fs::metadata(&ply).unwrap().modified().unwrap(), before);

    // A stopped cell is run again, the others kept.
    let rec = dir.join("a/runs/ph/xgaussian/seed0/cell.json");
    let r = std::fs::read_to_string(&rec).unwrap();
    std::fs::write(&rec, r.replace("\"done\"", "\"stopped\"")).unwrap();
    let o = reproduce(&["plan.toml", "--out", "a"], dir);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        text(&o).matches("finished earlier, kept").count(),
        3,
        "{}",
        text(&o)
    );
    let csv_a2 = std::fs::read_to_string(dir.join("a/results.csv")).unwrap();
    assert_eq!(
        deterministic_columns(&csv_a2),
        cols_a,
        "a rerun cell changed its result"
    );

    // The same plan with two cells at once (one thread each): bit-identical results.
    let o = reproduce(&["plan.toml", "--out", "b", "--jobs", "2"], dir);
    assert!(o.status.success(), "{}", text(&o));
    let csv_b = std::fs::read_to_string(dir.join("b/results.csv")).unwrap();
    assert_eq!(deterministic_columns(&csv_b), cols_a);
    assert!(
        csv_b.contains(",1,"),
        "threads column of --jobs 2 runs: {csv_b}"
    );
    for cell in ["xgaussian/seed0", "unispine/seed1"] {
        let pa = std::fs::read(dir.join("a/runs/ph").join(cell).join("model.ply")).unwrap();
        let pb = std::fs::read(dir.join("b/runs/ph").join(cell).join("model.ply")).unwrap();
        assert!(pa == pb, "{cell}: model.ply differs between --jobs 1 and 2");
    }

    // A changed plan (more iterations) reruns its cells.
    std::fs::write(dir.join("plan.toml"), tiny_plan(35, "")).unwrap();
    let o = reproduce(&["plan.toml", "--out", "a", "--jobs", "2"], dir);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        text(&o).matches("finished earlier, kept").count(),
        0,
        "{}",
        text(&o)
    );
    let csv = std::fs::read_to_string(dir.join("a/results.csv")).unwrap();
    assert!(csv.contains(",35,done,true,"), "{csv}");
}

#[test]
fn a_failing_cell_is_recorded_and_the_others_go_on() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // compact_keep = 2 passes the plan's checks (ranged settings) but not the trainer's
    // compaction check: the cell fails at run time.
    let plan = tiny_plan(
        20,
        "[variants.broken]\nbase = \"unispine\"\ncompact_keep = 2.0\n",
    );
    std::fs::write(dir.join("plan.toml"), plan).unwrap();
    let o = reproduce(&["plan.toml", "--out", "r"], dir);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let csv = std::fs::read_to_string(dir.join("r/results.csv")).unwrap();
    assert_eq!(csv.matches(",done,true,").count(), 4, "{csv}");
    assert_eq!(csv.matches(",failed,false,").count(), 2, "{csv}");
    let md = std::fs::read_to_string(dir.join("r/tables.md")).unwrap();
    assert!(
        md.contains("runs/ph/broken/seed0`: failed") && md.contains("compact.keep"),
        "{md}"
    );

    // Collect over partial results names the missing cells.
    std::fs::remove_dir_all(dir.join("r/runs/ph/xgaussian/seed1")).unwrap();
    let o = reproduce(&["plan.toml", "--out", "r", "--collect"], dir);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("3 of 6 cells have no result")
            && t.contains("runs/ph/xgaussian/seed1 (missing)"),
        "{t}"
    );
}

#[test]
fn bad_plans_are_errors_naming_the_line_before_anything_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let good = tiny_plan(20, "");
    let cases = [
        (
            good.replace("iters = 20", "iters = 20\nspeed = 3"),
            "line 3",
            "speed",
        ),
        (
            good.replace("\"unispine\"", "\"unispine-x\""),
            "line 5",
            "unispine-x",
        ),
        (
            format!("{good}[variants.v]\nbase = \"xgaussian\"\nwarp = 1\n"),
            "line 13",
            "warp",
        ),
        (
            good.replace("data = [", "path = \"nowhere\"\n#"),
            "line 10",
            "nowhere",
        ),
        (good.replace("iters = 20", "iters = -4"), "line 2", "iters"),
        ("name = \"x\"\nseeds = [0]\n".to_string(), "line", "iters"),
    ];
    for (plan, line, word) in cases {
        std::fs::write(dir.join("bad.toml"), &plan).unwrap();
        let o = reproduce(&["bad.toml", "--out", "o"], dir);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{t}\n--\n{plan}");
        assert!(
            t.contains("bad.toml") && t.contains(line) && t.contains(word),
            "{t}\n--\n{plan}"
        );
        assert!(!dir.join("o").exists(), "something ran for a bad plan");
    }
    let o = reproduce(&["no-such-plan"], dir);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("quick"), "{}", text(&o));
    let o = reproduce(&["--show", "table2"], dir);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("name = \"table2\""));
}

/// A Gaussian cell and a neural-field cell, each stopped at iteration 12 of 30 as a preempted
/// job leaves it, resume on the next harness run and end with the uninterrupted model's bits.
#[test]
fn a_stopped_cell_resumes_from_its_checkpoint_with_the_same_bits() {
    for (method, model, started) in [
        ("unispine", "model.ply", "resuming `unispine`"),
        ("intratomo", "model.npz", "resuming `intratomo`"),
    ] {
        stopped_cell_resumes(method, model, started);
    }
}

fn stopped_cell_resumes(method: &str, model: &str, started: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let plan = tiny_plan(30, "")
        .replace("seeds = [0, 1]", "seeds = [0]")
        .replace(
            "methods = [\"xgaussian\", \"unispine\"]",
            &format!("methods = [\"{method}\"]"),
        );
    std::fs::write(dir.join("plan.toml"), plan).unwrap();
    let o = reproduce(&["plan.toml", "--out", "a"], dir);
    assert!(o.status.success(), "{}", text(&o));
    let cell = dir.join(format!("a/runs/ph/{method}/seed0"));
    let straight = std::fs::read(cell.join(model)).unwrap();
    let csv = std::fs::read_to_string(dir.join("a/results.csv")).unwrap();

    // What a preempted cell leaves: the same cell's run stopped at iteration 12 with a
    // checkpoint and `"completed": false`, and its record saying "stopped".
    let rec_path = cell.join("cell.json");
    let rec: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rec_path).unwrap()).unwrap();
    let args: Vec<String> = serde_json::from_value(rec["args"].clone()).unwrap();
    let ds = dir.join("a/datasets/ph");
    let o = common::cli::bin()
        .arg("train")
        .arg("--data")
        .arg(&ds)
        .arg("--out")
        .arg(&cell)
        .args(&args)
        .args(["--stop-after", "12"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let m = std::fs::read_to_string(cell.join("metrics.json")).unwrap();
    assert!(m.contains("\"completed\": false"), "{m}");
    assert!(cell.join("checkpoint.bin").is_file(), "{method}");
    let r = std::fs::read_to_string(&rec_path).unwrap();
    std::fs::write(&rec_path, r.replace("\"done\"", "\"stopped\"")).unwrap();

    let o = reproduce(&["plan.toml", "--out", "a"], dir);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("resumed, done"), "{}", text(&o));
    let log = std::fs::read_to_string(cell.join("train.log")).unwrap();
    assert!(log.contains("resumed from the checkpoint"), "{log}");
    assert!(log.contains(started), "{log}");
    assert!(
        std::fs::read(cell.join(model)).unwrap() == straight,
        "the resumed {method} cell's {model} differs from the uninterrupted one"
    );
    let csv2 = std::fs::read_to_string(dir.join("a/results.csv")).unwrap();
    assert_eq!(deterministic_columns(&csv2), deterministic_columns(&csv));
}

#[test]
fn a_listing_piped_into_a_reader_that_stops_early_ends_quietly() {
    // `unispine reproduce PLAN --list | head -1` on a plan whose listing (5000 cells, ~150 KB)
    // is larger than a pipe's buffer: the reader closes the pipe after one byte.
    let dir = tempfile::tempdir().unwrap();
    let seeds: Vec<String> = (0..5000).map(|s| s.to_string()).collect();
    let plan =
        tiny_plan(1, "").replace("seeds = [0, 1]", &format!("seeds = [{}]", seeds.join(", ")));
    std::fs::write(dir.path().join("big.toml"), plan).unwrap();
    let mut child = common::cli::bin()
        .args(["reproduce", "big.toml", "--list"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = [0u8; 1];
    std::io::Read::read_exact(child.stdout.as_mut().unwrap(), &mut first).unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{:?}", out.status);
}

#[test]
fn the_reduced_table1_plan_runs_unispine_against_fdk_and_the_reduced_fields() {
    let o = reproduce(&["table1", "--list"], &std::env::temp_dir());
    let t = text(&o);
    for m in ["unispine", "fdk", "naf", "intratomo", "tensorf", "nerf"] {
        assert!(t.contains(&format!("runs/ct-crop/{m}/seed2")), "{m}:\n{t}");
    }
    assert!(!t.contains("-full/"), "{t}");
}
