//! Scale-out on Slurm: `unispine reproduce PLAN --out DIR --emit-slurm` writes
//! - `DIR/slurm/array.sbatch`: a job array with one task per cell, each running
//!   `unispine reproduce PLAN --out DIR --task $SLURM_ARRAY_TASK_ID` with the plan's
//!   `[slurm]` resources (`--cpus-per-task`, `--mem`, `--time`) and `--requeue`;
//! - `DIR/slurm/collect.sbatch`: `unispine reproduce PLAN --out DIR --collect`;
//! - `DIR/slurm/submit.sh`: submits the array, then the collect job with
//!   `--dependency=afterok:<array id> --kill-on-invalid-dep=yes` (without it a failed task
//!   leaves the collect job pending forever), and prints both ids.
//!
//! The datasets are built by `--emit-slurm` itself, once, so that the array tasks share them
//! instead of racing to build the same folder. A preempted task (SIGTERM) is requeued and its
//! cell runs again (a cell that finished is kept).

use std::path::Path;

use super::plan::Plan;
use super::run::cells;
use crate::error::{Error, Result};

/// Quote a string for a POSIX shell.
pub fn sh_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+=:,@".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// A path as a quoted shell word; a path with a line break or a NUL is refused (`what` names it
/// in the error), since no quoting keeps a line break out of a `#SBATCH` line or a log.
pub fn sh_path(what: &str, p: &Path) -> Result<String> {
    let s = p
        .to_str()
        .ok_or_else(|| Error::invalid(what, format!("{} is not valid UTF-8", p.display())))?;
    if s.contains(['\n', '\r', '\0']) {
        return Err(Error::invalid(
            what,
            format!("{s:?} contains a line break or NUL: refused in a generated script"),
        ));
    }
    Ok(sh_quote(s))
}

/// The three files (name, text) for a plan. `bin`, `plan_arg` (a built-in name or an absolute
/// plan path), `out` and `workdir` (where relative paths of the plan resolve) are written as
/// given: pass absolute paths.
///
/// No text of the plan reaches a `#SBATCH` line or a command except the plan's name (checked
/// by [`super::plan::names`]) and the `[slurm]` values (checked against their grammars by
/// [`super::plan::SlurmSpec`]); paths are quoted and appear only in commands, never in a
/// `#SBATCH` line: the jobs start in `OUT/slurm/` (where `submit.sh` submits them, so their
/// logs land there) and change to `workdir` in the script.
pub fn scripts(
    plan: &Plan,
    bin: &Path,
    plan_arg: &str,
    out: &Path,
    workdir: &Path,
) -> Result<Vec<(String, String)>> {
    let n = cells(plan).len();
    if plan_arg.contains(['\n', '\r', '\0']) {
        return Err(Error::invalid(
            "PLAN",
            format!("{plan_arg:?} contains a line break or NUL: refused in a generated script"),
        ));
    }
    let slurm_dir = out.join("slurm");
    let (bin, out_q, wd, sd) = (
        sh_path("unispine binary", bin)?,
        sh_path("--out", out)?,
        sh_path("plan folder", workdir)?,
        sh_path("--out", &slurm_dir)?,
    );
    let plan_q = sh_quote(plan_arg);
    let mut common = format!("#SBATCH --job-name=unispine-{}\n", plan.name);
    if let Some(p) = &plan.slurm.partition {
        common.push_str(&format!("#SBATCH --partition={p}\n"));
    }
    if let Some(a) = &plan.slurm.account {
        common.push_str(&format!("#SBATCH --account={a}\n"));
    }
    let array = format!(
        "#!/bin/bash\n\
         # One task per cell of the plan ({n} cells); written by unispine reproduce --emit-slurm.\n\
         {common}\
         #SBATCH --array=0-{last}\n\
         #SBATCH --cpus-per-task={cpus}\n\
         #SBATCH --mem={mem}\n\
         #SBATCH --time={time}\n\
         #SBATCH --requeue\n\
         #SBATCH --output=task_%A_%a.txt\n\
         cd {wd} || exit 1\n\
         exec {bin} reproduce {plan_q} --out {out_q} --task \"$SLURM_ARRAY_TASK_ID\"\n",
        last = n.saturating_sub(1),
        cpus = plan.slurm.cpus_per_task,
        mem = plan.slurm.mem,
        time = plan.slurm.time,
    );
    let collect = format!(
        "#!/bin/bash\n\
         # Tables, verdicts and charts of the plan from the cells that finished.\n\
         {common}\
         #SBATCH --cpus-per-task=1\n\
         #SBATCH --mem=2G\n\
         #SBATCH --time=01:00:00\n\
         #SBATCH --output=collect_%j.txt\n\
         cd {wd} || exit 1\n\
         exec {bin} reproduce {plan_q} --out {out_q} --collect\n",
    );
    let results = sh_path("--out", &out.join("tables.md"))?;
    let report = sh_path("--out", &out.join("report.html"))?;
    let submit = format!(
        "#!/bin/sh\n\
         # Submit the plan: the job array, then the collect job once every task succeeded.\n\
         set -eu\n\
         cd {sd}\n\
         array=$(sbatch --parsable array.sbatch)\n\
         array=${{array%%;*}}\n\
         collect=$(sbatch --parsable --dependency=afterok:\"$array\" --kill-on-invalid-dep=yes collect.sbatch)\n\
         collect=${{collect%%;*}}\n\
         echo \"array job $array ({n} tasks), collect job $collect\"\n\
         printf 'results: %s, %s\\n' {results} {report}\n",
    );
    Ok(vec![
        ("array.sbatch".into(), array),
        ("collect.sbatch".into(), collect),
        ("submit.sh".into(), submit),
    ])
}

/// Write the scripts into `out/slurm/` (executable); returns the path of `submit.sh`.
pub fn write_scripts(
    plan: &Plan,
    bin: &Path,
    plan_arg: &str,
    out: &Path,
    workdir: &Path,
) -> Result<std::path::PathBuf> {
    let texts = scripts(plan, bin, plan_arg, out, workdir)?;
    let dir = crate::fsio::path_under(out, Path::new("slurm"))?;
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut submit = dir.join("submit.sh");
    for (name, text) in texts {
        let p = dir.join(&name);
        crate::fsio::write_atomic(&p, text.as_bytes())?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755))
                .map_err(|e| Error::io(&p, e))?;
        }
        if name == "submit.sh" {
            submit = p;
        }
    }
    Ok(submit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::plan::TrainSchema;

    #[test]
    fn scripts_name_every_cell_and_the_dependency() {
        let text = crate::reproduce::plan::builtin("quick").unwrap();
        let plan = Plan::parse(
            text,
            Path::new("quick"),
            Path::new("."),
            &TrainSchema::of_train(),
        )
        .unwrap();
        let s = scripts(
            &plan,
            Path::new("/opt/u s/unispine"),
            "quick",
            Path::new("/data/out"),
            Path::new("/data"),
        )
        .unwrap();
        let n = cells(&plan).len();
        assert!(s[0].1.contains(&format!("#SBATCH --array=0-{}", n - 1)));
        assert!(s[0]
            .1
            .contains("exec '/opt/u s/unispine' reproduce quick --out /data/out --task"));
        assert!(s[0].1.contains("#SBATCH --requeue"));
        assert!(s[1].1.contains("--collect"));
        assert!(s[2]
            .1
            .contains("--dependency=afterok:\"$array\" --kill-on-invalid-dep=yes collect.sbatch"));
        assert_eq!(sh_quote("it's"), "'it'\\''s'");
    }

    /// The scripts land in `OUT/slurm/`, executable, with the texts [`scripts`] gives; the
    /// path returned is that of `submit.sh`.
    #[test]
    fn write_scripts_leaves_executable_scripts_and_returns_submit() {
        let tmp = tempfile::tempdir().unwrap();
        let plan =
            crate::reproduce::plan::tests::parse(crate::reproduce::holds::tests::PLAN).unwrap();
        let (bin, out) = (Path::new("/opt/unispine"), tmp.path());
        let submit = write_scripts(&plan, bin, "h.toml", out, Path::new("/w")).unwrap();
        assert_eq!(submit, out.join("slurm").join("submit.sh"));
        let texts = scripts(&plan, bin, "h.toml", out, Path::new("/w")).unwrap();
        assert_eq!(texts.len(), 3);
        for (name, text) in texts {
            let p = out.join("slurm").join(&name);
            assert_eq!(std::fs::read_to_string(&p).unwrap(), text, "{name}");
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                let mode = std::fs::metadata(&p).unwrap().permissions().mode();
                assert_eq!(mode & 0o777, 0o755, "{name}");
            }
        }
    }
}
