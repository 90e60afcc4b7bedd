//! Plans, output folders, run folders and records as untrusted input: every hostile case ends as
//! a clear error (exit 1, naming the key or file) or runs safely; no generated script runs an
//! injected command; nothing outside the output folder is written or removed (a sentinel
//! folder's listing and checksums are compared before and after); no read of a device or FIFO,
//! no unbounded allocation, no hang. Each run is under a memory limit and a timeout.

use crate::common;

use std::path::{Path, PathBuf};

use common::cli::{run_limited, tree_listing, Limited};

/// Memory limit of each run, MiB (far below what the hostile plans would allocate).
const MEM_MIB: u64 = 1536;
/// Time limit of each run, seconds.
const SECS: u64 = 120;

fn reproduce(args: &[&str], cwd: &Path) -> Limited {
    let mut a = vec!["reproduce"];
    a.extend_from_slice(args);
    run_limited(&a, cwd, &[], MEM_MIB, SECS)
}

/// A folder with a few files beside the output folder: nothing may change in it.
fn sentinel(root: &Path) -> PathBuf {
    let s = root.join("sentinel");
    std::fs::create_dir_all(s.join("fdk/seed0")).unwrap();
    std::fs::write(s.join("keep.txt"), "keep me").unwrap();
    std::fs::write(s.join("fdk/seed0/cell.json"), "{}").unwrap();
    s
}

/// A temporary folder with a sentinel folder (and its listing) and an FDK plan `p.toml`.
fn setup() -> (tempfile::TempDir, PathBuf, Vec<String>, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let sent = sentinel(d.path());
    let before = tree_listing(&sent);
    let plan = d.path().join("p.toml");
    std::fs::write(&plan, fdk_plan("p")).unwrap();
    (d, sent, before, plan)
}

/// Assert exit 1 with a message containing each of `words`, and no panic.
fn refused(r: &Limited, words: &[&str]) {
    assert_eq!(r.code, 1, "exit {}\n{}", r.code, r.stderr);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    for w in words {
        assert!(r.stderr.contains(w), "no `{w}` in:\n{}", r.stderr);
    }
}

const DATA: &str = r#"data = ["phantom", "--size", "32", "--detector", "32", "--train-views", "6", "--test-views", "2"]"#;

/// A plan of FDK cells (fast) on a tiny phantom built by the plan.
fn fdk_plan(name: &str) -> String {
    format!(
        "name = \"{name}\"\niters = 10\nseeds = [0]\nmethods = [\"fdk\"]\n\
         [[datasets]]\nname = \"ph\"\n{DATA}\n"
    )
}

#[test]
fn hostile_names_values_and_sizes_are_refused_when_the_plan_is_parsed() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    let sent = sentinel(root);
    let before = tree_listing(&sent);
    let base = |name: &str, extra: &str| {
        format!(
            "name = {name}\niters = 10\nseeds = [0]\nmethods = [\"fdk\"]\n{extra}\n\
             [[datasets]]\nname = \"ph\"\n{DATA}\n"
        )
    };
    let variant = |v: &str| {
        format!(
            "name = \"p\"\niters = 10\nseeds = [0]\nmethods = [\"{v}\"]\n\
             [variants.\"{v}\"]\nbase = \"fdk\"\n[[datasets]]\nname = \"ph\"\n{DATA}\n"
        )
    };
    let dataset = |n: &str| {
        format!(
            "name = \"p\"\niters = 10\nseeds = [0]\nmethods = [\"fdk\"]\n\
             [[datasets]]\nname = \"{n}\"\n{DATA}\n"
        )
    };
    let long = "n".repeat(300);
    let cases: Vec<(String, &str)> = vec![
        (base("\"x\\n#SBATCH --wrap=touch PWNED\"", ""), "name"),
        (base("\"$(touch PWNED)\"", ""), "name"),
        (base("\"a b\"", ""), "name"),
        (
            base(
                "\"p\"",
                "[slurm]\nmem = \"4G\\n#SBATCH --wrap=touch PWNED\"",
            ),
            "slurm.mem",
        ),
        (
            base("\"p\"", "[slurm]\ntime = \"01:00:00; touch PWNED\""),
            "slurm.time",
        ),
        (
            base("\"p\"", "[slurm]\npartition = \"a b\""),
            "slurm.partition",
        ),
        (
            base("\"p\"", "[slurm]\naccount = \"$(id)\""),
            "slurm.account",
        ),
        (
            base("\"p\"", "[slurm]\ncpus_per_task = 0"),
            "slurm.cpus_per_task",
        ),
        (variant("../escape"), "variants"),
        (variant("/abs"), "variants"),
        (variant("zz/../xgaussian"), "variants"),
        (variant("FDK"), "differ only in case"),
        (dataset(".."), "datasets.name"),
        (dataset("a/b"), "datasets.name"),
        (dataset(&long), "datasets.name"),
        (dataset("a\\u0000b"), "datasets.name"),
        (
            base("\"p\"", "").replace("iters = 10", "iters = 2000000"),
            "iters",
        ),
        (
            base("\"p\"", "").replace("seeds = [0]", "seeds = [0, 1, 0]"),
            "seeds",
        ),
    ];
    for (k, (text, key)) in cases.iter().enumerate() {
        let plan = root.join(format!("plan{k}.toml"));
        std::fs::write(&plan, text).unwrap();
        let out = root.join(format!("out{k}"));
        let r = reproduce(
            &[plan.to_str().unwrap(), "--out", out.to_str().unwrap()],
            root,
        );
        refused(&r, &[key, plan.to_str().unwrap()]);
        assert!(!out.exists(), "case {k}: the output folder was created");
    }
    // Sweep values that would share a folder or leave it.
    let sweep = |values: &str| {
        format!(
            "name = \"p\"\niters = 10\nseeds = [0]\nmethods = [\"unispine\"]\n\
             [sweep]\nflag = \"train-views\"\nvalues = {values}\n[[datasets]]\nname = \"ph\"\n{DATA}\n"
        )
    };
    for values in ["[5, 5]", "[5, 5.0]", "[\"5\", 5]"] {
        let plan = root.join("sweep.toml");
        std::fs::write(&plan, sweep(values)).unwrap();
        let r = reproduce(&[plan.to_str().unwrap(), "--list"], root);
        refused(&r, &["sweep.values", "repeats"]);
    }
    // Too many cells: refused before any cell is listed (no multi-GB allocation), linear in
    // the number of seeds.
    let names = |p: &str, n: usize| -> String {
        (0..n)
            .map(|i| format!("\"{p}{i}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut big = format!(
        "name = \"big\"\niters = 10\nseeds = [{}]\nmethods = [{}]\n",
        (0..300)
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(", "),
        names("v", 300)
    );
    for i in 0..300 {
        big += &format!("[variants.v{i}]\nbase = \"fdk\"\n");
    }
    for i in 0..300 {
        big += &format!("[[datasets]]\nname = \"d{i}\"\n{DATA}\n");
    }
    let plan = root.join("big.toml");
    std::fs::write(&plan, &big).unwrap();
    let r = reproduce(&[plan.to_str().unwrap(), "--list"], root);
    refused(&r, &["--max-cells", "27000000 cells"]);
    let many_seeds = format!(
        "name = \"seeds\"\niters = 10\nseeds = [{}]\nmethods = [\"fdk\"]\n\
         [[datasets]]\nname = \"ph\"\n{DATA}\n",
        (0..100_000)
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(",")
    );
    std::fs::write(&plan, &many_seeds).unwrap();
    let r = reproduce(&[plan.to_str().unwrap(), "--list"], root);
    refused(&r, &["--max-cells", "100000 cells"]);
    // Raising the cap lists them.
    let r = reproduce(
        &[plan.to_str().unwrap(), "--list", "--max-cells", "100000"],
        root,
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(r.stdout.lines().count(), 100_000);
    // Plan paths that are not regular files: refused before reading.
    let fifo = root.join("plan.fifo.toml");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    for (p, what) in [
        ("/dev/zero", "a device"),
        ("/dev/urandom", "a device"),
        (fifo.to_str().unwrap(), "a FIFO"),
    ] {
        let r = reproduce(&[p, "--list"], root);
        refused(&r, &[p, what]);
    }
    let huge = root.join("huge.toml");
    std::fs::write(&huge, format!("# {}\n", "x".repeat(2 << 20))).unwrap();
    refused(
        &reproduce(&[huge.to_str().unwrap(), "--list"], root),
        &["larger than"],
    );
    assert_eq!(tree_listing(&sent), before);
}

#[test]
fn task_indices_outside_the_plan_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let plan = d.path().join("p.toml");
    std::fs::write(&plan, fdk_plan("p")).unwrap();
    let p = plan.to_str().unwrap();
    for t in ["-1", "1", "99", "x"] {
        refused(
            &reproduce(&[p, "--task", t, "--out", "o"], d.path()),
            &["invalid `--task`", "0..=0"],
        );
    }
    let r = run_limited(
        &["reproduce", p, "--task", "--out", "o"],
        d.path(),
        &[("SLURM_ARRAY_TASK_ID", "-1")],
        MEM_MIB,
        SECS,
    );
    refused(&r, &["invalid `SLURM_ARRAY_TASK_ID`"]);
    assert!(!d.path().join("o").exists());
}

/// Write a stub `sbatch` into `dir` that logs its arguments and prints a job id.
fn stub_sbatch(dir: &Path) {
    let p = dir.join("sbatch");
    std::fs::write(
        &p,
        "#!/bin/sh\nprintf '%s\\n' \"$*\" >> \"$STUB_LOG\"\necho 4242\n",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
}

#[test]
fn generated_scripts_run_no_injected_command() {
    let (d, sent, before, plan) = setup();
    let root = d.path();
    // An output folder whose name would run commands if it were not quoted.
    let out = root.join("out it's $(touch PWNED1) `touch PWNED2` \"q\"; touch PWNED3");
    let r = reproduce(
        &[
            plan.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--emit-slurm",
        ],
        root,
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let slurm = out.join("slurm");
    for f in ["array.sbatch", "collect.sbatch", "submit.sh"] {
        let text = std::fs::read_to_string(slurm.join(f)).unwrap();
        for line in text.lines().filter(|l| l.starts_with("#SBATCH")) {
            assert!(
                line.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "# =-_%.:".contains(c)),
                "{f}: plan or path text in `{line}`"
            );
        }
    }
    let stub = root.join("stub");
    std::fs::create_dir(&stub).unwrap();
    stub_sbatch(&stub);
    let log = root.join("sbatch.log");
    let path = format!("{}:{}", stub.display(), std::env::var("PATH").unwrap());
    let run_script = |shell: &str, f: &str, env: &[(&str, &str)]| {
        let o = std::process::Command::new(shell)
            .arg(slurm.join(f))
            .current_dir(&slurm)
            .env("PATH", &path)
            .env("STUB_LOG", &log)
            .envs(env.iter().copied())
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).to_string(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (code, stdout, stderr) = run_script("sh", "submit.sh", &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stdout.contains("array job 4242 (1 tasks), collect job 4242"),
        "{stdout}"
    );
    assert!(
        stdout.contains(out.join("tables.md").to_str().unwrap()),
        "{stdout}"
    );
    let calls = std::fs::read_to_string(&log).unwrap();
    assert_eq!(calls.lines().count(), 2, "{calls}");
    assert!(calls.contains("--dependency=afterok:4242"), "{calls}");
    // The array task and the collect job, run as Slurm would (from OUT/slurm).
    let (code, _, stderr) = run_script("bash", "array.sbatch", &[("SLURM_ARRAY_TASK_ID", "0")]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(out.join("runs/ph/fdk/seed0/metrics.json").is_file());
    let (code, _, stderr) = run_script("bash", "collect.sbatch", &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(out.join("report.html").is_file());
    // No injected command ran, anywhere it could have.
    for dir in [root.to_path_buf(), slurm.clone(), out.clone()] {
        for k in 1..=3 {
            assert!(
                !dir.join(format!("PWNED{k}")).exists(),
                "PWNED{k} in {dir:?}"
            );
        }
    }
    // An output folder with a line break cannot be written into a script.
    let bad = root.join("o\n#SBATCH --wrap=touch PWNED");
    let r = reproduce(
        &[
            plan.to_str().unwrap(),
            "--out",
            bad.to_str().unwrap(),
            "--emit-slurm",
        ],
        root,
    );
    refused(&r, &["--out", "line break"]);
    assert!(!bad.join("slurm").exists());
    assert_eq!(tree_listing(&sent), before);
}

#[test]
fn nothing_is_written_or_removed_through_a_link_or_read_from_a_device() {
    let (d, sent, before, plan) = setup();
    let root = d.path();
    let out = root.join("out");
    let args = [plan.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let r = reproduce(&args, root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // A link planted where a run folder goes: the cell fails, the rerun exits 1, and nothing
    // is removed or written through the link.
    std::fs::remove_dir_all(out.join("runs/ph")).unwrap();
    std::os::unix::fs::symlink(&sent, out.join("runs/ph")).unwrap();
    let r = reproduce(&args, root);
    refused(&r, &["symbolic link", "failed"]);
    assert_eq!(tree_listing(&sent), before);
    // The same for the folder of a built dataset.
    std::fs::remove_file(out.join("runs/ph")).unwrap();
    std::fs::remove_dir_all(out.join("datasets/ph")).unwrap();
    std::os::unix::fs::symlink(&sent, out.join("datasets/ph")).unwrap();
    let r = reproduce(&args, root);
    refused(&r, &["symbolic link"]);
    assert_eq!(tree_listing(&sent), before);
    std::fs::remove_file(out.join("datasets/ph")).unwrap();
    let r = reproduce(&args, root);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // Records linked to devices and FIFOs: --collect reads none of them and does not hang.
    let cell = out.join("runs/ph/fdk/seed0");
    for f in ["metrics.json", "log.csv"] {
        std::fs::remove_file(cell.join(f)).unwrap();
        std::os::unix::fs::symlink("/dev/zero", cell.join(f)).unwrap();
    }
    std::fs::remove_file(cell.join("cell.json")).unwrap();
    let c = std::ffi::CString::new(cell.join("cell.json").to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let mut collect = args.to_vec();
    collect.push("--collect");
    let r = reproduce(&collect, root);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    assert!(r.stdout.contains("have no result"), "{}", r.stdout);
    // A dataset folder whose projections are a link to /dev/zero: refused before reading.
    let ds = root.join("ds");
    std::fs::create_dir(&ds).unwrap();
    std::fs::copy(
        out.join("datasets/ph/dataset.json"),
        ds.join("dataset.json"),
    )
    .unwrap();
    std::os::unix::fs::symlink("/dev/zero", ds.join("train.npy")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", ds.join("test.npy")).unwrap();
    let p2 = root.join("p2.toml");
    std::fs::write(
        &p2,
        "name = \"p2\"\niters = 10\nseeds = [0]\nmethods = [\"fdk\"]\n\
         [[datasets]]\nname = \"zero\"\npath = \"ds\"\n",
    )
    .unwrap();
    let r = reproduce(&[p2.to_str().unwrap(), "--out", "out2"], root);
    refused(&r, &["train.npy", "a device"]);
    assert_eq!(tree_listing(&sent), before);
}
