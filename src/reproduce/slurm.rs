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

/// The three files (name, text) for a plan. `bin`, `plan_arg` (a built-in name or an absolute
/// plan path), `out` and `workdir` (where relative paths of the plan resolve) are written as
/// given: pass absolute paths.
pub fn scripts(
    plan: &Plan,
    bin: &Path,
    plan_arg: &str,
    out: &Path,
    workdir: &Path,
) -> Vec<(String, String)> {
    let n = cells(plan).len();
    let q = |p: &Path| sh_quote(&p.display().to_string());
    let slurm_dir = out.join("slurm");
    let common = format!(
        "#SBATCH --job-name=unispine-{name}\n#SBATCH --chdir={wd}\n",
        name = plan.name,
        wd = q(workdir)
    );
    let array = format!(
        "#!/bin/bash\n\
         # One task per cell of plan `{name}` ({n} cells); written by unispine reproduce --emit-slurm.\n\
         {common}\
         #SBATCH --array=0-{last}\n\
         #SBATCH --cpus-per-task={cpus}\n\
         #SBATCH --mem={mem}\n\
         #SBATCH --time={time}\n\
         #SBATCH --requeue\n\
         #SBATCH --output={sd}/task_%A_%a.txt\n\
         exec {bin} reproduce {plan_arg} --out {out} --task \"$SLURM_ARRAY_TASK_ID\"\n",
        name = plan.name,
        last = n.saturating_sub(1),
        cpus = plan.slurm.cpus_per_task,
        mem = plan.slurm.mem,
        time = plan.slurm.time,
        sd = q(&slurm_dir),
        bin = q(bin),
        plan_arg = sh_quote(plan_arg),
        out = q(out),
    );
    let collect = format!(
        "#!/bin/bash\n\
         # Tables, verdicts and charts of plan `{name}` from the cells that finished.\n\
         {common}\
         #SBATCH --cpus-per-task=1\n\
         #SBATCH --mem=2G\n\
         #SBATCH --time=01:00:00\n\
         #SBATCH --output={sd}/collect_%j.txt\n\
         exec {bin} reproduce {plan_arg} --out {out} --collect\n",
        name = plan.name,
        sd = q(&slurm_dir),
        bin = q(bin),
        plan_arg = sh_quote(plan_arg),
        out = q(out),
    );
    let submit = format!(
        "#!/bin/sh\n\
         # Submit plan `{name}`: the job array, then the collect job once every task succeeded.\n\
         set -eu\n\
         cd {sd}\n\
         array=$(sbatch --parsable array.sbatch)\n\
         array=${{array%%;*}}\n\
         collect=$(sbatch --parsable --dependency=afterok:\"$array\" --kill-on-invalid-dep=yes collect.sbatch)\n\
         collect=${{collect%%;*}}\n\
         echo \"array job $array ({n} tasks), collect job $collect\"\n\
         echo \"results: {out}/tables.md, {out}/report.html\"\n",
        name = plan.name,
        sd = q(&slurm_dir),
        out = out.display(),
    );
    vec![
        ("array.sbatch".into(), array),
        ("collect.sbatch".into(), collect),
        ("submit.sh".into(), submit),
    ]
}

/// Write the scripts into `out/slurm/` (executable); returns the path of `submit.sh`.
pub fn write_scripts(
    plan: &Plan,
    bin: &Path,
    plan_arg: &str,
    out: &Path,
    workdir: &Path,
) -> Result<std::path::PathBuf> {
    let dir = out.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut submit = dir.join("submit.sh");
    for (name, text) in scripts(plan, bin, plan_arg, out, workdir) {
        let p = dir.join(&name);
        std::fs::write(&p, text).map_err(|e| Error::io(&p, e))?;
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
        );
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
}
