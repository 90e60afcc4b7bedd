//! The harness against a stand-in for `unispine`: a shell script that builds a dataset of three
//! small files and "trains" by method (`3dgs` completes, `xgaussian` fails with a message,
//! `unispine` stops once, leaving a checkpoint, and completes when resumed; any method with
//! `--iters 13` exits with success before completing), recording the
//! arguments and `RAYON_NUM_THREADS` it was given. What the harness does with the outcomes
//! (records, keys, kept cells, resumes, reruns, events) is read back from the folder.

use super::*;
use crate::reproduce::plan::tests::parse;

const FAKE: &str = r#"#!/bin/sh
cmd=$1; shift
out=; res=; method=
all="$*"
while [ $# -gt 0 ]; do
  case $1 in
    --out) out=$2; shift ;;
    --resume) res=$2; shift ;;
    --method) method=$2; shift ;;
  esac
  shift
done
if [ "$cmd" = data ]; then
  mkdir -p "$out" && printf '{}' > "$out/dataset.json" && printf t > "$out/train.npy" \
    && printf s > "$out/test.npy"
  exit 0
fi
dir=${out:-$res}
echo "$all" >> "$dir/calls.txt"
echo "$RAYON_NUM_THREADS" >> "$dir/rayon.txt"
case " $all " in
  *" --iters 13 "*) echo "left early"; exit 0 ;;
esac
if [ -n "$res" ]; then
  printf '{"completed": true, "test_psnr": 31.0}' > "$dir/metrics.json"; exit 0
fi
case $method in
  xgaussian) echo "first line"; echo "boom: the loss diverged"; exit 3 ;;
  unispine) printf c > "$dir/checkpoint.bin"; printf '{}' > "$dir/config.json"
    echo "stopping at 5"; exit 143 ;;
esac
printf '{"completed": true, "test_psnr": 30.0}' > "$dir/metrics.json"
"#;

/// The plan: three methods x two seeds on one dataset built by `data`.
fn plan(iters: usize) -> Plan {
    parse(&format!(
        "name = \"f\"\niters = {iters}\nseeds = [0, 1]\n\
         methods = [\"3dgs\", \"xgaussian\", \"unispine\"]\n\
         [[datasets]]\nname = \"ph\"\ndata = [\"phantom\", \"--size\", \"8\"]\n"
    ))
    .unwrap()
}

fn options(tmp: &Path, jobs: usize, only: Option<Vec<usize>>) -> RunOptions {
    let bin = tmp.join("fake-unispine");
    if !bin.exists() {
        std::fs::write(&bin, FAKE).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&bin, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    RunOptions {
        out: tmp.join("out"),
        jobs,
        bin,
        base_dir: tmp.to_path_buf(),
        cores: 4,
        only,
    }
}

fn run(plan: &Plan, opts: &RunOptions) -> (RunSummary, Vec<RunEvent>) {
    let mut ev = Vec::new();
    let s = run_plan(plan, opts, &mut |e| ev.push(e.clone())).unwrap();
    (s, ev)
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The events of a run of `n` cells with `jobs` jobs: each cell starts and ends once, numbered
/// 1..=n, and each end's estimate of the time left is the mean wall time of the cells trained
/// so far (as their outcomes give it) times the cells left over the jobs, none before a cell
/// was trained.
fn check_events(ev: &[RunEvent], n: usize, jobs: usize) {
    let (mut started, mut ended) = (Vec::new(), Vec::new());
    let (mut wall, mut trained) = (0.0f64, 0usize);
    for e in ev {
        match e {
            RunEvent::CellStarted { k, n: m, .. } => {
                assert_eq!(*m, n);
                started.push(*k);
            }
            RunEvent::CellEnded {
                k,
                n: m,
                outcome,
                eta_s,
                ..
            } => {
                assert_eq!(*m, n);
                ended.push(*k);
                if let Outcome::Done { wall_s, .. } = outcome {
                    wall += wall_s;
                    trained += 1;
                }
                let left = n - ended.len();
                let want = (trained > 0).then(|| wall / trained as f64 * left as f64 / jobs as f64);
                assert_eq!(*eta_s, want, "{e:?}");
            }
            _ => {}
        }
    }
    started.sort_unstable();
    ended.sort_unstable();
    let all: Vec<usize> = (1..=n).collect();
    assert_eq!((started, ended), (all.clone(), all));
}

#[test]
fn cells_are_recorded_kept_resumed_and_rerun_by_their_outcome() {
    let tmp = tempfile::tempdir().unwrap();
    let p = plan(10);
    let opts = options(tmp.path(), 2, None);
    let (s, ev) = run(&p, &opts);
    assert_eq!(
        (s.cells, s.trained, s.kept, s.failed),
        (6, 2, 0, 4),
        "{ev:#?}"
    );
    check_events(&ev, 6, 2);
    // The summary's wall time is the trained cells' own.
    let done: f64 = ev
        .iter()
        .filter_map(|e| match e {
            RunEvent::CellEnded {
                outcome: Outcome::Done { wall_s, .. },
                ..
            } => Some(*wall_s),
            _ => None,
        })
        .sum();
    assert_eq!(s.cells_wall_s, done);
    assert!(done > 0.0 && s.total_wall_s >= done / 2.0);
    let cell = |m: &str, seed: u64| opts.out.join(format!("runs/ph/{m}/seed{seed}"));
    let rec = |m: &str, seed: u64| read_record(&cell(m, seed)).unwrap();
    let checksum = provenance::dataset_checksum(&opts.out.join("datasets/ph")).unwrap();
    for seed in 0..2 {
        let r = rec("3dgs", seed);
        assert_eq!(r.status, Status::Done);
        assert_eq!(r.dataset_checksum, checksum);
        assert_eq!(r.key, cell_key(&r.args, &checksum));
        assert_eq!(
            r.args.join(" "),
            format!("--method 3dgs --iters 10 --seed {seed}")
        );
        // Two jobs share four cores: two threads each, by flag and by environment.
        let calls = read(&cell("3dgs", seed).join("calls.txt"));
        assert!(calls.starts_with("--data "), "{calls}");
        assert!(calls.contains(" --threads 2 --method 3dgs"), "{calls}");
        assert_eq!(read(&cell("3dgs", seed).join("rayon.txt")), "2\n");
        let x = rec("xgaussian", seed);
        assert_eq!(x.status, Status::Failed);
        assert_eq!(
            x.error.as_deref(),
            Some("exit status exit status: 3: first line | boom: the loss diverged")
        );
        let u = rec("unispine", seed);
        assert_eq!(u.status, Status::Stopped);
        assert_eq!(
            u.error.as_deref(),
            Some("stopped before the last iteration: stopping at 5")
        );
    }
    let ended: Vec<&Outcome> = ev
        .iter()
        .filter_map(|e| match e {
            RunEvent::CellEnded { outcome, .. } => Some(outcome),
            _ => None,
        })
        .collect();
    assert_eq!(ended.len(), 6);
    let started = ev
        .iter()
        .filter(|e| matches!(e, RunEvent::CellStarted { n: 6, .. }))
        .count();
    assert_eq!(started, 6);
    assert!(ev.contains(&RunEvent::DatasetBuilding { name: "ph".into() }));
    // The last cell to end has none left: its estimate is 0 s.
    match ev.last() {
        Some(RunEvent::CellEnded { eta_s, .. }) => assert_eq!(*eta_s, Some(0.0)),
        e => panic!("{e:?}"),
    }

    // Again: the finished cells are kept, the stopped ones resumed, the failed ones rerun; the
    // dataset is not rebuilt.
    std::fs::write(cell("3dgs", 0).join("mark"), "").unwrap();
    let (s, ev) = run(&p, &options(tmp.path(), 1, None));
    assert_eq!((s.cells, s.trained, s.kept, s.failed), (6, 2, 2, 2));
    check_events(&ev, 6, 1);
    assert!(!ev
        .iter()
        .any(|e| matches!(e, RunEvent::DatasetBuilding { .. })));
    assert!(cell("3dgs", 0).join("mark").exists());
    for seed in 0..2 {
        let u = rec("unispine", seed);
        assert_eq!(u.status, Status::Done);
        let log = read(&cell("unispine", seed).join("train.log"));
        assert!(
            log.contains(
                "stopping at 5\nharness: resumed from the checkpoint of the stopped run\n"
            ),
            "{log}"
        );
        let calls = read(&cell("unispine", seed).join("calls.txt"));
        let last = calls.lines().last().unwrap();
        assert!(last.starts_with("--resume "), "{last}");
        assert!(last.ends_with("--threads 4"), "{last}");
        // A failed cell starts afresh: one call in its folder.
        assert_eq!(
            read(&cell("xgaussian", seed).join("calls.txt"))
                .lines()
                .count(),
            1
        );
    }
    assert!(ev.iter().any(|e| matches!(
        e,
        RunEvent::CellEnded {
            outcome: Outcome::Done { resumed: true, .. },
            ..
        }
    )));

    // Another schedule is another key: the finished cells are trained again from scratch.
    let (s, _) = run(&plan(12), &options(tmp.path(), 1, Some(vec![0, 1])));
    assert_eq!((s.cells, s.trained, s.kept), (2, 2, 0));
    assert!(!cell("3dgs", 0).join("mark").exists());
    assert_eq!(rec("3dgs", 1).args[3], "12");
}

#[test]
fn only_existing_cells_may_be_chosen() {
    let tmp = tempfile::tempdir().unwrap();
    let e = run_plan(
        &plan(10),
        &options(tmp.path(), 1, Some(vec![6])),
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("cell 6 does not exist: the plan has 6 cells"),
        "{e}"
    );
    // Cell 5 (unispine, seed 1) alone.
    let (s, ev) = run(&plan(10), &options(tmp.path(), 3, Some(vec![5])));
    assert_eq!((s.cells, s.failed), (1, 1));
    assert!(ev.iter().any(|e| matches!(
        e,
        RunEvent::CellStarted { k: 1, n: 1, label } if label == "ph/unispine/seed1"
    )));
}

#[test]
fn a_missing_binary_is_a_failed_cell_that_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let mut o = options(tmp.path(), 1, Some(vec![0]));
    // A dataset folder in place, so only the training child is missing.
    let ds = crate::reproduce::provenance::tests::ready_folder(tmp.path());
    let p = parse(&format!(
        "name = \"f\"\niters = 10\nseeds = [0]\nmethods = [\"3dgs\"]\n\
         [[datasets]]\nname = \"ph\"\npath = \"{}\"\n",
        ds.display()
    ))
    .unwrap();
    o.bin = tmp.path().join("no-such-binary");
    let mut ev = Vec::new();
    let s = run_plan(&p, &o, &mut |e| ev.push(e.clone())).unwrap();
    assert_eq!(s.failed, 1);
    let r = read_record(&o.out.join("runs/ph/3dgs/seed0")).unwrap();
    assert_eq!(r.status, Status::Failed);
    let e = r.error.unwrap();
    assert!(
        e.starts_with("could not start ") && e.contains("no-such-binary"),
        "{e}"
    );
}

#[test]
fn tail_gives_the_last_non_blank_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let f = tmp.path().join("log");
    std::fs::write(&f, "a\n\nb\n  \nc\nd\n\n").unwrap();
    assert_eq!(tail(&f, 2), "c | d");
    assert_eq!(tail(&f, 9), "a | b | c | d");
    assert_eq!(tail(&tmp.path().join("none"), 2), "");
    // Only the last 64 KiB are read.
    let mut big = "x\n".repeat(40_000);
    big.push_str("end\n");
    std::fs::write(&f, &big).unwrap();
    assert_eq!(tail(&f, 1), "end");
}

/// A stopped cell resumes only from a whole run folder of the same cell; a child that exits
/// with success before completing is a stopped cell; a dataset folder that lost its files is
/// built again; a resumed cell's wall time adds the earlier sessions'.
#[test]
fn resuming_needs_the_checkpoint_and_the_config() {
    let tmp = tempfile::tempdir().unwrap();
    let p = plan(10);
    // Cells 4 and 5: unispine, seeds 0 and 1, both stopped.
    let (s, _) = run(&p, &options(tmp.path(), 1, Some(vec![4, 5])));
    assert_eq!(s.failed, 2);
    let out = tmp.path().join("out");
    let cell = |seed: u64| out.join(format!("runs/ph/unispine/seed{seed}"));
    std::fs::remove_file(cell(0).join("checkpoint.bin")).unwrap();
    std::fs::remove_file(cell(1).join("config.json")).unwrap();
    std::fs::remove_file(out.join("datasets/ph/dataset.json")).unwrap();
    let (s, ev) = run(&p, &options(tmp.path(), 1, Some(vec![4, 5])));
    assert_eq!((s.trained, s.failed), (0, 2));
    assert!(ev.contains(&RunEvent::DatasetBuilding { name: "ph".into() }));
    for seed in 0..2 {
        // Started afresh: the folder was emptied, one call, and it stopped again.
        let calls = read(&cell(seed).join("calls.txt"));
        assert_eq!(calls.lines().count(), 1, "{calls}");
        assert!(calls.starts_with("--data "), "{calls}");
        assert_eq!(read_record(&cell(seed)).unwrap().status, Status::Stopped);
    }
    // The earlier sessions' wall time, as recorded, is added to a resumed run's.
    let mut r = read_record(&cell(0)).unwrap();
    r.wall_s = 100.0;
    write_json(&cell(0).join("cell.json"), &r).unwrap();
    let (s, _) = run(&p, &options(tmp.path(), 1, Some(vec![4])));
    assert_eq!(s.trained, 1);
    let w = read_record(&cell(0)).unwrap().wall_s;
    assert!((100.0..160.0).contains(&w), "{w}");
    // Success without `"completed": true` is a stop, not a finished cell.
    let (s, _) = run(&plan(13), &options(tmp.path(), 1, Some(vec![0])));
    assert_eq!((s.trained, s.failed), (0, 1));
    let r = read_record(&out.join("runs/ph/3dgs/seed0")).unwrap();
    assert_eq!(r.status, Status::Stopped);
    assert_eq!(
        r.error.as_deref(),
        Some("stopped before the last iteration: left early")
    );
}
