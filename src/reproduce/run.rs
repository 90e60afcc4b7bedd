//! Running a plan's cells: each (dataset, method, [sweep value,] seed) is one `unispine train`
//! child process (the same binary) writing its run folder `OUT/runs/DATASET/METHOD/seedK/`.
//!
//! - `--jobs N` runs N cells at once and gives each `max(1, cores / N)` rayon threads
//!   (`--threads` and `RAYON_NUM_THREADS`). Results do not depend on it: training is
//!   bit-identical for any thread count.
//! - Resumable: beside the run's own files the harness writes `cell.json` (the cell's key, its
//!   status, wall time, error, provenance). On a new run a cell whose key matches and whose
//!   `metrics.json` says `"completed": true` is kept; a cell whose key changed (other flags,
//!   iterations or dataset bytes) is deleted and rerun; a stopped or failed cell is rerun.
//! - A failing cell is recorded with its error (the last lines of its `train.log`) and the
//!   others go on.
//! - The library never prints: progress leaves as [`RunEvent`]s.

use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::sync::Mutex;
use std::time::Instant;

use serde::{Deserialize, Serialize};

pub use super::cell::{cells, Cell};
use super::plan::{DatasetSpec, Plan, Source};
use super::provenance::{self, fnv1a, Machine};
use crate::error::{Error, Result};

/// Status of a cell in `cell.json`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    Running,
    Done,
    Stopped,
    Failed,
}

/// `cell.json`: the harness's record of one cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellRecord {
    /// FNV-1a 64 of the cell's train arguments and its dataset checksum (hex).
    pub key: String,
    pub status: Status,
    /// `unispine train` arguments (without `--data`, `--out`, `--threads`).
    pub args: Vec<String>,
    pub dataset_checksum: String,
    /// Wall time of the child process, seconds.
    pub wall_s: f64,
    pub error: Option<String>,
    pub threads: usize,
    pub machine: Machine,
}

/// Where a cell's dataset is.
#[derive(Clone, Debug)]
pub struct ReadyDataset {
    pub name: String,
    pub dir: PathBuf,
    pub checksum: String,
}

/// What happened to a cell.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Finished earlier with the same key: kept.
    Kept,
    /// Trained now (`resumed`: continued from the checkpoint of a stopped run).
    Done { wall_s: f64, resumed: bool },
    /// Failed (message), or its dataset is missing.
    Failed { error: String },
}

/// Progress of `reproduce`.
#[derive(Clone, Debug, PartialEq)]
pub enum RunEvent {
    /// A dataset is being built with `unispine data`.
    DatasetBuilding { name: String },
    /// An optional dataset could not be found or built: its cells are left out.
    DatasetSkipped { name: String, reason: String },
    /// A required dataset could not be built: its cells fail with this error.
    DatasetFailed { name: String, error: String },
    /// Cell `k` (1-based) of `n` started.
    CellStarted { k: usize, n: usize, label: String },
    /// Cell `k` of `n` ended; `eta_s` estimates the time left from the cells trained so far.
    CellEnded {
        k: usize,
        n: usize,
        label: String,
        outcome: Outcome,
        elapsed_s: f64,
        eta_s: Option<f64>,
    },
}

/// Options of a run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Concurrent cells.
    pub jobs: usize,
    /// The `unispine` binary that trains (normally `std::env::current_exe()`).
    pub bin: PathBuf,
    /// Folder that relative paths inside `data` arguments are resolved against.
    pub base_dir: PathBuf,
    /// Cores to split between the jobs (default: available parallelism).
    pub cores: usize,
    /// Run only these cell indices (a Slurm array task runs one).
    pub only: Option<Vec<usize>>,
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// Write a JSON value atomically.
pub fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<()> {
    let s = serde_json::to_string_pretty(v).expect("serialisable");
    write_atomic(path, s.as_bytes())
}

/// Read a cell's `cell.json`, if any.
pub fn read_record(dir: &Path) -> Option<CellRecord> {
    let s = crate::fsio::read_text_bounded(&dir.join("cell.json"), crate::fsio::MAX_TEXT_BYTES);
    serde_json::from_str(&s.ok()?).ok()
}

/// Whether a run folder's `metrics.json` says it completed.
pub fn metrics_completed(dir: &Path) -> bool {
    crate::fsio::read_text_bounded(&dir.join("metrics.json"), crate::fsio::MAX_TEXT_BYTES)
        .ok()
        .and_then(|s| serde_json::from_str::<serde_json::Value>(&s).ok())
        .and_then(|v| v.get("completed").and_then(|c| c.as_bool()))
        .unwrap_or(false)
}

/// The last `n` lines of a file (for error messages).
fn tail(path: &Path, n: usize) -> String {
    let mut s = String::new();
    if let Ok(f) = crate::fsio::open_regular(path) {
        // The end of a log is what says why a run failed: read at most its last 64 KiB.
        let mut f = f;
        let len = f.metadata().map(|m| m.len()).unwrap_or(0);
        let _ = f.seek(std::io::SeekFrom::Start(len.saturating_sub(64 << 10)));
        let mut b = Vec::new();
        let _ = f.take(64 << 10).read_to_end(&mut b);
        s = String::from_utf8_lossy(&b).into_owned();
    }
    let lines: Vec<&str> = s.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(n)..].join(" | ")
}

/// Folder of a dataset built from `data` arguments (`name` is a checked plan name; the folder
/// is refused when a part of it inside `out` is a symbolic link).
pub fn built_dataset_dir(out: &Path, name: &str) -> Result<PathBuf> {
    crate::fsio::path_under(out, &Path::new("datasets").join(name))
}

/// Find or build one dataset. `Ok(None)`: optional and unavailable (reason in the event).
pub fn prepare_dataset(
    d: &DatasetSpec,
    opts: &RunOptions,
    on_event: &mut dyn FnMut(&RunEvent),
) -> Result<Option<ReadyDataset>> {
    let dir = match &d.source {
        Source::Path(p) => {
            if !p.join("dataset.json").is_file() {
                let reason = format!("{} is not a dataset folder (no dataset.json)", p.display());
                if d.optional {
                    on_event(&RunEvent::DatasetSkipped {
                        name: d.name.clone(),
                        reason,
                    });
                    return Ok(None);
                }
                return Err(Error::invalid(format!("datasets.{}", d.name), reason));
            }
            p.clone()
        }
        Source::Data(args) => {
            let dir = built_dataset_dir(&opts.out, &d.name)?;
            let stamp = dir.join("data-args.json");
            let same = crate::fsio::read_text_bounded(&stamp, crate::fsio::MAX_TEXT_BYTES)
                .ok()
                .and_then(|s| serde_json::from_str::<Vec<String>>(&s).ok())
                .is_some_and(|a| a == *args)
                && dir.join("dataset.json").is_file();
            if !same {
                on_event(&RunEvent::DatasetBuilding {
                    name: d.name.clone(),
                });
                if dir.exists() {
                    std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
                }
                std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
                let abs = std::path::absolute(&dir).map_err(|e| Error::io(&dir, e))?;
                let log = dir.join("data.log");
                let logf = std::fs::File::create(&log).map_err(|e| Error::io(&log, e))?;
                let status = Command::new(&opts.bin)
                    .arg("data")
                    .args(args)
                    .arg("--out")
                    .arg(&abs)
                    .current_dir(&opts.base_dir)
                    .stdout(Stdio::from(
                        logf.try_clone().map_err(|e| Error::io(&log, e))?,
                    ))
                    .stderr(Stdio::from(logf))
                    .status()
                    .map_err(|e| Error::io(&opts.bin, e))?;
                if !status.success() {
                    let reason = format!(
                        "`unispine data {}` failed: {}",
                        args.join(" "),
                        tail(&log, 3)
                    );
                    if d.optional {
                        on_event(&RunEvent::DatasetSkipped {
                            name: d.name.clone(),
                            reason,
                        });
                        return Ok(None);
                    }
                    return Err(Error::invalid(format!("datasets.{}", d.name), reason));
                }
                write_json(&stamp, args)?;
            }
            dir
        }
    };
    let checksum = provenance::dataset_checksum(&dir)?;
    Ok(Some(ReadyDataset {
        name: d.name.clone(),
        dir,
        checksum,
    }))
}

/// The key of a cell: its train arguments and its dataset's checksum.
pub fn cell_key(args: &[String], checksum: &str) -> String {
    let mut s = args.join("\u{1f}");
    s.push('\u{1e}');
    s.push_str(checksum);
    format!("{:016x}", fnv1a(s.as_bytes()))
}

/// Run one cell now (unless kept): returns its outcome.
fn run_cell(
    cell: &Cell,
    plan: &Plan,
    ds: std::result::Result<&ReadyDataset, &str>,
    opts: &RunOptions,
    threads: usize,
    machine: &Machine,
) -> Outcome {
    let args = cell.train_args(plan);
    let fail = |error: String| Outcome::Failed { error };
    let dir = match crate::fsio::path_under(&opts.out, &cell.rel_dir(plan)) {
        Ok(d) => d,
        Err(e) => return fail(e.to_string()),
    };
    let ds = match ds {
        Ok(d) => d,
        Err(e) => {
            let rec = CellRecord {
                key: String::new(),
                status: Status::Failed,
                args,
                dataset_checksum: String::new(),
                wall_s: 0.0,
                error: Some(format!("dataset `{}`: {e}", cell.dataset)),
                threads,
                machine: machine.clone(),
            };
            let _ = std::fs::create_dir_all(&dir).map(|_| write_json(&dir.join("cell.json"), &rec));
            return fail(rec.error.unwrap_or_default());
        }
    };
    let key = cell_key(&args, &ds.checksum);
    let mut resume_from = None;
    if let Some(r) = read_record(&dir) {
        if r.key == key && r.status == Status::Done && metrics_completed(&dir) {
            return Outcome::Kept;
        }
        // A stopped run of the same cell (signal, preemption, or a harness killed while it
        // ran): continue from its checkpoint with `train --resume` (same bits as a run that
        // never stopped).
        if r.key == key
            && matches!(r.status, Status::Stopped | Status::Running)
            && dir.join("checkpoint.bin").is_file()
            && dir.join("config.json").is_file()
            && !metrics_completed(&dir)
        {
            resume_from = Some(r.wall_s);
        }
    }
    if let Some(before) = resume_from {
        return train_cell(
            cell,
            &dir,
            &args,
            key,
            ds,
            opts,
            threads,
            machine,
            Some(before),
        );
    }
    if dir.exists() {
        if let Err(e) = std::fs::remove_dir_all(&dir) {
            return fail(format!("{}: {e}", dir.display()));
        }
    }
    if let Err(e) = std::fs::create_dir_all(&dir) {
        return fail(format!("{}: {e}", dir.display()));
    }
    train_cell(cell, &dir, &args, key, ds, opts, threads, machine, None)
}

/// Train a cell into `dir`: from scratch, or (`resumed`: the wall time of the earlier
/// sessions) with `train --resume`, appending to `train.log` after a line saying so.
#[allow(clippy::too_many_arguments)]
fn train_cell(
    cell: &Cell,
    dir: &Path,
    args: &[String],
    key: String,
    ds: &ReadyDataset,
    opts: &RunOptions,
    threads: usize,
    machine: &Machine,
    resumed: Option<f64>,
) -> Outcome {
    let _ = cell;
    let fail = |error: String| Outcome::Failed { error };
    let dir = dir.to_path_buf();
    let args = args.to_vec();
    let mut rec = CellRecord {
        key,
        status: Status::Running,
        args: args.clone(),
        dataset_checksum: ds.checksum.clone(),
        wall_s: 0.0,
        error: None,
        threads,
        machine: machine.clone(),
    };
    if let Err(e) = write_json(&dir.join("cell.json"), &rec) {
        return fail(e.to_string());
    }
    let log = dir.join("train.log");
    let t0 = Instant::now();
    let open = || -> std::io::Result<std::fs::File> {
        match resumed {
            None => std::fs::File::create(&log),
            Some(_) => {
                let mut f = std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(&log)?;
                writeln!(f, "harness: resumed from the checkpoint of the stopped run")?;
                Ok(f)
            }
        }
    };
    let status = open().and_then(|f| {
        let mut cmd = Command::new(&opts.bin);
        cmd.arg("train");
        match resumed {
            None => cmd.arg("--data").arg(&ds.dir).arg("--out").arg(&dir),
            Some(_) => cmd.arg("--resume").arg(&dir).arg("--data").arg(&ds.dir),
        };
        cmd.arg("--threads").arg(threads.to_string());
        if resumed.is_none() {
            cmd.args(&args);
        }
        cmd.env("RAYON_NUM_THREADS", threads.to_string())
            .stdout(Stdio::from(f.try_clone()?))
            .stderr(Stdio::from(f))
            .stdin(Stdio::null())
            .status()
    });
    rec.wall_s = t0.elapsed().as_secs_f64() + resumed.unwrap_or(0.0);
    let outcome = match status {
        Err(e) => {
            rec.status = Status::Failed;
            rec.error = Some(format!("could not start {}: {e}", opts.bin.display()));
            fail(rec.error.clone().unwrap_or_default())
        }
        Ok(s) if s.success() && metrics_completed(&dir) => {
            rec.status = Status::Done;
            Outcome::Done {
                wall_s: rec.wall_s,
                resumed: resumed.is_some(),
            }
        }
        Ok(s) => {
            let stopped = s.success() || s.code() == Some(143);
            rec.status = if stopped {
                Status::Stopped
            } else {
                Status::Failed
            };
            let what = if stopped {
                "stopped before the last iteration".to_string()
            } else {
                format!("exit status {s}")
            };
            rec.error = Some(format!("{what}: {}", tail(&log, 2)));
            fail(rec.error.clone().unwrap_or_default())
        }
    };
    if let Err(e) = write_json(&dir.join("cell.json"), &rec) {
        return fail(e.to_string());
    }
    outcome
}

/// Summary of a run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunSummary {
    pub cells: usize,
    pub kept: usize,
    pub trained: usize,
    pub failed: usize,
    /// Sum of the trained cells' child wall times, seconds.
    pub cells_wall_s: f64,
    /// Wall time of the whole run (datasets included), seconds.
    pub total_wall_s: f64,
}

/// Prepare every dataset and run the plan's cells (those of `opts.only`, if given).
pub fn run_plan(
    plan: &Plan,
    opts: &RunOptions,
    on_event: &mut dyn FnMut(&RunEvent),
) -> Result<RunSummary> {
    let t0 = Instant::now();
    std::fs::create_dir_all(&opts.out).map_err(|e| Error::io(&opts.out, e))?;
    let all = cells(plan);
    let chosen: Vec<Cell> = match &opts.only {
        Some(ix) => {
            for &i in ix {
                if i >= all.len() {
                    return Err(Error::invalid(
                        "task",
                        format!("cell {i} does not exist: the plan has {} cells", all.len()),
                    ));
                }
            }
            all.iter()
                .filter(|c| ix.contains(&c.index))
                .cloned()
                .collect()
        }
        None => all.clone(),
    };
    // Datasets the chosen cells need, each prepared once.
    let mut ready: Vec<(String, std::result::Result<ReadyDataset, String>)> = Vec::new();
    // One dataset per plan dataset and data-condition value ([`Plan::dataset_builds`]).
    for d in &plan.dataset_builds() {
        if !chosen.iter().any(|c| c.data_name(plan) == d.name) {
            continue;
        }
        match prepare_dataset(d, opts, on_event) {
            Ok(Some(r)) => ready.push((d.name.clone(), Ok(r))),
            Ok(None) => {}
            Err(e) => {
                on_event(&RunEvent::DatasetFailed {
                    name: d.name.clone(),
                    error: e.to_string(),
                });
                ready.push((d.name.clone(), Err(e.to_string())));
            }
        }
    }
    // Cells of skipped (optional, unavailable) datasets are left out.
    let todo: Vec<Cell> = chosen
        .into_iter()
        .filter(|c| ready.iter().any(|r| r.0 == c.data_name(plan)))
        .collect();
    let n = todo.len();
    let jobs = opts.jobs.clamp(1, n.max(1));
    let threads = (opts.cores / jobs).max(1);
    let machine = Machine::detect();
    let next = Mutex::new(0usize);
    let (tx, rx) = mpsc::channel::<(usize, bool, Outcome)>();
    let mut summary = RunSummary {
        cells: n,
        ..Default::default()
    };
    std::thread::scope(|s| {
        for _ in 0..jobs {
            let tx = tx.clone();
            let (todo, ready, next, machine) = (&todo, &ready, &next, &machine);
            s.spawn(move || loop {
                let i = {
                    let mut g = crate::par::lock(next);
                    let i = *g;
                    *g += 1;
                    i
                };
                if i >= todo.len() {
                    break;
                }
                let c = &todo[i];
                let _ = tx.send((i, true, Outcome::Kept));
                let ds = ready
                    .iter()
                    .find(|r| r.0 == c.data_name(plan))
                    .map(|r| r.1.as_ref().map_err(|e| e.as_str()))
                    .unwrap_or(Err("not prepared"));
                let o = run_cell(c, plan, ds, opts, threads, machine);
                let _ = tx.send((i, false, o));
            });
        }
        drop(tx);
        let mut ended = 0usize;
        let mut trained_wall = 0.0;
        let mut trained = 0usize;
        for (i, started, outcome) in rx {
            let label = todo[i].label(plan);
            if started {
                on_event(&RunEvent::CellStarted { k: i + 1, n, label });
                continue;
            }
            ended += 1;
            match &outcome {
                Outcome::Kept => summary.kept += 1,
                Outcome::Done { wall_s, .. } => {
                    summary.trained += 1;
                    trained += 1;
                    trained_wall += wall_s;
                }
                Outcome::Failed { .. } => summary.failed += 1,
            }
            let left = n - ended;
            let eta_s =
                (trained > 0).then(|| trained_wall / trained as f64 * left as f64 / jobs as f64);
            on_event(&RunEvent::CellEnded {
                k: i + 1,
                n,
                label,
                outcome,
                elapsed_s: t0.elapsed().as_secs_f64(),
                eta_s,
            });
        }
        summary.cells_wall_s = trained_wall;
    });
    summary.total_wall_s = t0.elapsed().as_secs_f64();
    Ok(summary)
}

#[cfg(all(test, unix))]
mod tests;
