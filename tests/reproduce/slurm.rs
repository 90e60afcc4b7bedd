//! `unispine reproduce --emit-slurm` against a real Slurm: submit a small plan's job array and
//! its dependent collect job, wait, and check that the results equal the local run's bit for
//! bit. Needs a running cluster (`bash scripts/slurm-local.sh start`, which `.ci/run` does);
//! without one the test says so and passes.

use crate::common;
use common::skip;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn slurm_up() -> Result<(), String> {
    let o = Command::new("sinfo")
        .args(["-h", "-N", "-o", "%T"])
        .output()
        .map_err(|e| format!("sinfo not found ({e})"))?;
    let s = String::from_utf8_lossy(&o.stdout).to_string();
    if o.status.success()
        && s.lines()
            .any(|l| matches!(l.trim(), "idle" | "mixed" | "allocated"))
    {
        Ok(())
    } else {
        Err(format!(
            "no usable node (sinfo: {} {})",
            s.trim(),
            String::from_utf8_lossy(&o.stderr).trim()
        ))
    }
}

fn columns(csv: &str) -> Vec<String> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = [
        "dataset",
        "method",
        "seed",
        "status",
        "psnr",
        "ssim",
        "n_gaussians",
        "dataset_checksum",
        "config_hash",
    ]
    .iter()
    .map(|n| header.iter().position(|h| h == n).unwrap())
    .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(" ")
        })
        .collect()
}

fn run(cmd: &mut Command) -> String {
    let o = cmd.output().expect("run");
    let t = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{cmd:?}: {t}");
    t
}

#[test]
fn slurm_array_and_collect_job_equal_the_local_run() {
    if let Err(why) = slurm_up() {
        skip::skipped(
            "the Slurm array test",
            &format!(
                "no Slurm cluster here: {why}. Start one with `bash scripts/slurm-local.sh start`."
            ),
        );
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let plan = "name = \"slurm-tiny\"\niters = 20\ncompress_schedule = true\nseeds = [0, 1]\n\
                methods = [\"3dgs\", \"unispine\"]\n[train]\npreview_views = 0\n\
                [slurm]\ncpus_per_task = 1\nmem = \"1G\"\ntime = \"00:10:00\"\n\
                [[datasets]]\nname = \"ph\"\n\
                data = [\"phantom\", \"--size\", \"32\", \"--detector\", \"32\", \
                \"--train-views\", \"10\", \"--test-views\", \"4\"]\n";
    std::fs::write(dir.join("plan.toml"), plan).unwrap();
    run(common::cli::bin()
        .args(["reproduce", "plan.toml", "--out", "local"])
        .current_dir(dir));
    let t = run(common::cli::bin()
        .args(["reproduce", "plan.toml", "--out", "cluster", "--emit-slurm"])
        .current_dir(dir));
    assert!(t.contains("submit.sh"), "{t}");
    let array = std::fs::read_to_string(dir.join("cluster/slurm/array.sbatch")).unwrap();
    assert!(array.contains("#SBATCH --array=0-3"), "{array}");
    let t = run(Command::new("sh")
        .arg(dir.join("cluster/slurm/submit.sh"))
        .current_dir(dir));
    // "array job A (4 tasks), collect job C"
    let ids: Vec<String> = t
        .split_whitespace()
        .filter(|w| w.trim_end_matches(',').chars().all(|c| c.is_ascii_digit()) && !w.is_empty())
        .map(|w| w.trim_end_matches(',').to_string())
        .collect();
    assert!(ids.len() >= 2, "job ids in: {t}");
    let jobs = format!("{},{}", ids[0], ids.last().unwrap());
    let t0 = Instant::now();
    loop {
        let o = Command::new("squeue")
            .args(["-h", "-j", &jobs, "-o", "%i %T"])
            .output()
            .unwrap();
        let q = String::from_utf8_lossy(&o.stdout).to_string();
        if q.trim().is_empty() {
            break;
        }
        if t0.elapsed() > Duration::from_secs(300) {
            let _ = Command::new("scancel").arg(&ids[0]).status();
            let _ = Command::new("scancel").arg(ids.last().unwrap()).status();
            panic!("Slurm jobs not done after 300 s: {q}");
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let tables = dir.join("cluster/tables.md");
    assert!(
        tables.is_file(),
        "the collect job wrote no tables.md; task logs: {:?}",
        std::fs::read_dir(dir.join("cluster/slurm"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect::<Vec<_>>()
    );
    let a = std::fs::read_to_string(dir.join("local/results.csv")).unwrap();
    let b = std::fs::read_to_string(dir.join("cluster/results.csv")).unwrap();
    assert_eq!(columns(&a), columns(&b));
    assert!(a.contains(",done,true,") && !b.contains(",missing,"), "{b}");
    for cell in ["3dgs/seed0", "unispine/seed1"] {
        let p = |root: &str| {
            std::fs::read(
                Path::new(dir)
                    .join(root)
                    .join("runs/ph")
                    .join(cell)
                    .join("model.ply"),
            )
            .unwrap()
        };
        assert!(p("local") == p("cluster"), "{cell}: model.ply differs");
    }
}
