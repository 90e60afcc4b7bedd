//! What `unispine reproduce` does between reading its flags and printing: where a plan file's
//! relative paths start, which cell a Slurm array task runs, how many cores the cells share,
//! writing a Slurm job array, the harness's own line, and the tables and claims document built
//! from the finished cells. The front end maps flags to these calls and events to lines.

use std::path::{Path, PathBuf};

use super::aggregate::Row;
use super::claims_doc::{self, Header};
use super::plan::Plan;
use super::run::{self, RunEvent, RunOptions, RunSummary};
use super::tables;
use super::verdict::Verdict;
use crate::doc::Doc;
use crate::error::{Error, Result};

/// The folder a plan's relative paths start from: the plan file's folder, or the current
/// folder for a built-in plan (`plan_arg` is what the user gave: a name or a file).
pub fn base_dir(plan_arg: &str) -> PathBuf {
    let p = Path::new(plan_arg);
    match p.parent() {
        Some(d) if p.is_file() && !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// The cell an array task runs: `given` (from `--task I`), else `SLURM_ARRAY_TASK_ID`; an
/// error names the source and the allowed range.
pub fn task_index(given: Option<&str>, n_cells: usize) -> Result<usize> {
    let (what, v) = match given {
        Some(v) => ("--task", v.to_string()),
        None => (
            "SLURM_ARRAY_TASK_ID",
            std::env::var("SLURM_ARRAY_TASK_ID")
                .map_err(|_| Error::invalid("--task", "without I needs SLURM_ARRAY_TASK_ID"))?,
        ),
    };
    match v.trim().parse::<usize>() {
        Ok(i) if i < n_cells => Ok(i),
        _ => Err(Error::invalid(
            what,
            format!(
                "`{v}` is not a cell index in 0..={} (the plan has {n_cells} cells)",
                n_cells.saturating_sub(1)
            ),
        )),
    }
}

/// The cores the cells share: `SLURM_CPUS_PER_TASK` inside a Slurm task, else the machine's.
pub fn cores() -> usize {
    cores_of(
        std::env::var("SLURM_CPUS_PER_TASK").ok().as_deref(),
        std::thread::available_parallelism().map_or(1, |n| n.get()),
    )
}

/// [`cores`] from the variable's text (if set) and the machine's cores: a positive count in
/// the variable wins.
fn cores_of(slurm: Option<&str>, machine: usize) -> usize {
    slurm
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or(machine)
}

/// Write the Slurm job array of `plan` (one task per cell, a dependent collect job) into
/// `opts.out`, after building its datasets once; returns the `submit.sh` to run. Paths that
/// cannot be written into a script are refused before anything is built.
pub fn emit_slurm(
    plan: &Plan,
    plan_arg: &str,
    opts: &RunOptions,
    on_event: &mut dyn FnMut(&RunEvent),
) -> Result<PathBuf> {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let plan_ref = if super::plan::builtin(plan_arg).is_some() {
        plan_arg.to_string()
    } else {
        abs(Path::new(plan_arg)).display().to_string()
    };
    super::slurm::sh_path("--out", &abs(&opts.out))?;
    super::slurm::sh_path("PLAN", &abs(Path::new(plan_arg)))?;
    std::fs::create_dir_all(&opts.out).map_err(|e| Error::io(&opts.out, e))?;
    for d in &plan.dataset_builds() {
        run::prepare_dataset(d, opts, on_event)?;
    }
    super::slurm::write_scripts(
        plan,
        &abs(&opts.bin),
        &plan_ref,
        &abs(&opts.out),
        &abs(&opts.base_dir),
    )
}

/// The harness's line for `tables.md` and the terminal after a run that trained cells (with
/// one job, the datasets' and harness's share of the runs' time).
pub fn harness_line(sum: &RunSummary, jobs: usize) -> String {
    let overhead = sum.total_wall_s - sum.cells_wall_s;
    format!(
        "Harness: {} cells trained, {} kept, {} failed; the runs took {:.1} s of wall time, the \
         whole command {:.1} s with {} job(s){}.\n",
        sum.trained,
        sum.kept,
        sum.failed,
        sum.cells_wall_s,
        sum.total_wall_s,
        jobs,
        if jobs == 1 {
            format!(
                " (datasets and harness: {:.1} s, {:.2} % of the runs' time)",
                overhead,
                100.0 * overhead / sum.cells_wall_s.max(1e-9)
            )
        } else {
            String::new()
        }
    )
}

/// What [`write_tables`] wrote.
pub struct Tables {
    pub rows: Vec<Row>,
    pub verdicts: Vec<Verdict>,
    /// `tables.md` as a document (`report.html` renders it again).
    pub doc: Doc,
}

/// `results.csv`, `results.json` and `tables.md` from the cells in `out` (`extra`: a line for
/// `tables.md`, e.g. [`harness_line`]), and the claims document at `claims_doc` when given.
pub fn write_tables(
    plan: &Plan,
    out: &Path,
    preset_help: &[(String, String)],
    extra: &str,
    claims_doc: Option<(&Path, &Header)>,
) -> Result<Tables> {
    let (rows, verdicts, doc) = tables::write_all(plan, out, preset_help, extra)?;
    if let Some((doc, header)) = claims_doc {
        let text = claims_doc::render(plan, &rows, header).to_markdown();
        crate::fsio::write_atomic(doc, text.as_bytes())?;
    }
    Ok(Tables {
        rows,
        verdicts,
        doc,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_file_s_folder_is_the_base() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("p.toml");
        std::fs::write(&f, "").unwrap();
        assert_eq!(base_dir(f.to_str().unwrap()), dir.path());
        assert_eq!(base_dir("quick"), PathBuf::from("."));
        // A name that is not a file.
        assert_eq!(base_dir("no/such/plan.toml"), PathBuf::from("."));
    }

    #[test]
    fn a_task_index_is_checked_against_the_cells() {
        assert_eq!(task_index(Some("3"), 4).unwrap(), 3);
        assert_eq!(task_index(Some(" 0 "), 1).unwrap(), 0);
        for (v, n) in [("4", 4), ("-1", 4), ("x", 4), ("0", 0)] {
            let e = task_index(Some(v), n).unwrap_err().to_string();
            assert!(
                e.contains("--task") && e.contains(&format!("{n} cells")),
                "{e}"
            );
        }
    }

    #[test]
    fn the_harness_line_gives_the_overhead_with_one_job() {
        let s = RunSummary {
            cells: 3,
            kept: 1,
            trained: 2,
            failed: 0,
            cells_wall_s: 100.0,
            total_wall_s: 101.0,
        };
        let one = harness_line(&s, 1);
        assert!(one.contains("1.0 s, 1.00 % of the runs' time"), "{one}");
        assert!(!harness_line(&s, 2).contains('%'));
    }

    #[test]
    fn slurm_s_cpus_per_task_wins_when_it_is_a_positive_count() {
        assert_eq!(cores_of(Some("3"), 8), 3);
        assert_eq!(cores_of(Some("1"), 8), 1);
        for v in ["0", "-2", "two", ""] {
            assert_eq!(cores_of(Some(v), 8), 8, "{v:?}");
        }
        assert_eq!(cores_of(None, 5), 5);
        let machine = std::thread::available_parallelism().map_or(1, |n| n.get());
        let env = std::env::var("SLURM_CPUS_PER_TASK").ok();
        assert_eq!(cores(), cores_of(env.as_deref(), machine));
        assert!(cores() >= 1);
    }

    /// The array of a plan whose dataset is a ready folder: the datasets are checked (their
    /// checksums read), the scripts land in `OUT/slurm/` and `submit.sh` is returned.
    #[test]
    fn emit_slurm_returns_the_submit_script_it_wrote() {
        let tmp = tempfile::tempdir().unwrap();
        let ds = crate::reproduce::provenance::tests::ready_folder(tmp.path());
        let text = format!(
            "name = \"e\"\niters = 10\nseeds = [0, 1, 2]\nmethods = [\"3dgs\"]\n\
             [[datasets]]\nname = \"d\"\npath = \"{}\"\n",
            ds.display()
        );
        let plan = crate::reproduce::plan::tests::parse(&text).unwrap();
        let out = tmp.path().join("out");
        let plan_file = tmp.path().join("e.toml");
        let opts = RunOptions {
            out: out.clone(),
            jobs: 1,
            bin: PathBuf::from("/opt/unispine/bin/unispine"),
            base_dir: tmp.path().to_path_buf(),
            cores: 2,
            only: None,
        };
        let submit = emit_slurm(&plan, plan_file.to_str().unwrap(), &opts, &mut |_| {}).unwrap();
        assert_eq!(submit, out.join("slurm").join("submit.sh"));
        let text = std::fs::read_to_string(&submit).unwrap();
        assert!(text.contains("sbatch"), "{text}");
        let array = std::fs::read_to_string(out.join("slurm").join("array.sbatch")).unwrap();
        assert!(array.contains("#SBATCH --array=0-2"), "{array}");
        assert!(
            array.contains(&format!(
                "exec /opt/unispine/bin/unispine reproduce {} --out {} --task",
                plan_file.display(),
                out.display()
            )),
            "{array}"
        );
        // A dataset folder that is not one is refused before any script is written.
        std::fs::remove_file(ds.join("dataset.json")).unwrap();
        let out2 = tmp.path().join("out2");
        let e = emit_slurm(
            &plan,
            plan_file.to_str().unwrap(),
            &RunOptions {
                out: out2.clone(),
                ..opts
            },
            &mut |_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("datasets.d") && e.contains("no dataset.json"),
            "{e}"
        );
        assert!(!out2.join("slurm").exists());
    }
}
