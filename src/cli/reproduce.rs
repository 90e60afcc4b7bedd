//! `unispine reproduce PLAN --out DIR [--jobs N]`: run a plan (built-in name or TOML file) and
//! write `results.csv`, `results.json`, `tables.md` (with verdicts) into DIR.
//! `--show NAME` prints a built-in plan; `--task I` runs cell I only (a Slurm array task);
//! `--collect` builds the tables from whatever finished.

use std::path::PathBuf;

use anyhow::Context;

use unispine::reproduce::plan::{Plan, TrainSchema, BUILTIN};
use unispine::reproduce::run::{self, Outcome, RunEvent, RunOptions};
use unispine::reproduce::{aggregate, command};

/// Arguments of `unispine reproduce`.
#[derive(Debug, clap::Args)]
pub struct ReproduceArgs {
    /// A built-in plan (quick, table2, table1, stability, compactness, budgets, each with a
    /// -full twin) or a plan TOML file.
    pub plan: Option<String>,
    /// Output folder (default: reproduce-PLANNAME).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Cells run at once; the cores are split between them (results do not depend on it).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Print a built-in plan as TOML (copy it and edit it).
    #[arg(long, value_name = "NAME")]
    pub show: Option<String>,
    /// List the cells of the plan with their index (for --task) and run folder.
    #[arg(long)]
    pub list: bool,
    /// Run only cell I, 0 <= I < the plan's cell count (what a Slurm array task runs).
    /// `--task` alone reads I from SLURM_ARRAY_TASK_ID.
    #[arg(long, value_name = "I", num_args = 0..=1, allow_negative_numbers = true)]
    pub task: Option<Option<String>>,
    /// Refuse plans with more cells than this (a guard against a mistyped plan).
    #[arg(long, value_name = "N", default_value_t = unispine::reproduce::plan::DEFAULT_MAX_CELLS)]
    pub max_cells: usize,
    /// Only build the tables from the cells that finished.
    #[arg(long)]
    pub collect: bool,
    /// Write a Slurm job array (one task per cell), a dependent collect job and
    /// DIR/slurm/submit.sh instead of running; the datasets are built now, once.
    #[arg(long)]
    pub emit_slurm: bool,
    /// Also write this markdown file (e.g. docs/claims.md): every claim, at the base and at
    /// every condition value, with the command, machine kind and commit in its header.
    #[arg(long, value_name = "FILE")]
    pub claims_doc: Option<PathBuf>,
}

fn fmt_s(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

/// Run `unispine reproduce`.
pub fn run(args: ReproduceArgs) -> anyhow::Result<()> {
    if let Some(name) = &args.show {
        let text = unispine::reproduce::plan::builtin(name).with_context(|| {
            format!(
                "no built-in plan `{name}` (built-in: {})",
                BUILTIN.iter().map(|b| b.0).collect::<Vec<_>>().join(", ")
            )
        })?;
        print!("{text}");
        return Ok(());
    }
    let Some(plan_arg) = &args.plan else {
        anyhow::bail!(
            "give a plan: a built-in name ({}) or a TOML file",
            BUILTIN.iter().map(|b| b.0).collect::<Vec<_>>().join(", ")
        );
    };
    unispine::par::check_workers("--jobs", args.jobs)?;
    let schema = TrainSchema::of_train();
    let plan = Plan::load(plan_arg, &schema)?;
    plan.check_cells(args.max_cells)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("reproduce-{}", plan.name)));
    let cells = run::cells(&plan);
    if args.list {
        for c in &cells {
            println!("{}\t{}", c.index, c.rel_dir(&plan).display());
        }
        return Ok(());
    }
    let task = match &args.task {
        None => None,
        Some(given) => Some(command::task_index(given.as_deref(), cells.len())?),
    };
    let opts = RunOptions {
        out: out.clone(),
        jobs: args.jobs,
        bin: std::env::current_exe().context("locating the unispine binary")?,
        base_dir: command::base_dir(plan_arg),
        cores: command::cores(),
        only: task.map(|t| vec![t]),
    };
    if args.emit_slurm {
        let submit = command::emit_slurm(&plan, plan_arg, &opts, &mut print_event)?;
        println!(
            "{} cells as a Slurm job array ({} cpus, {} per task); submit with: sh {}",
            cells.len(),
            plan.slurm.cpus_per_task,
            plan.slurm.mem,
            submit.display()
        );
        return Ok(());
    }
    let mut extra = String::new();
    let mut failed_now = 0;
    if !args.collect {
        eprintln!(
            "plan `{}`: {} cells ({} datasets x {} methods{} x {} seeds), {} iterations each, \
             {} at once -> {}",
            plan.name,
            cells.len(),
            plan.datasets.len(),
            plan.methods.len(),
            plan.sweep
                .as_ref()
                .map(|s| format!(" x {} {} values", s.values.len(), s.flag))
                .unwrap_or_default(),
            plan.seeds.len(),
            plan.iters,
            args.jobs,
            out.display()
        );
        let sum = run::run_plan(&plan, &opts, &mut print_event)?;
        failed_now = sum.failed;
        if task.is_some() {
            if sum.failed > 0 {
                anyhow::bail!("the cell failed (see its cell.json and train.log)");
            }
            return Ok(());
        }
        if sum.trained > 0 {
            extra = command::harness_line(&sum, args.jobs);
            eprintln!("{}", extra.trim_end());
        }
    }
    // The machine is read only when a claims document is asked for.
    let header = args
        .claims_doc
        .as_ref()
        .map(|_| unispine::reproduce::claims_doc::Header {
            // The program by its name, not the path it was started from.
            command: std::iter::once("unispine".to_string())
                .chain(std::env::args().skip(1))
                .collect::<Vec<_>>()
                .join(" "),
            machine: unispine::reproduce::provenance::Machine::detect(),
        });
    let doc = args.claims_doc.as_deref().zip(header.as_ref());
    let command::Tables {
        rows,
        verdicts,
        doc: tables,
    } = command::write_tables(&plan, &out, &schema.method_help, &extra, doc)
        .context("writing the tables")?;
    print_results(&plan, &rows, &verdicts, &tables, args.claims_doc.as_deref());
    let charts = unispine::report::reproduce::write_report(
        &rows,
        &out,
        &tables,
        plan.floor_db,
        unispine::report::holds::charts(&plan, &rows),
    )?;
    println!(
        "\nreport: {}\ntables: {}\nresults: {}, {}\ncharts: {}",
        out.join("report.html").display(),
        out.join("tables.md").display(),
        out.join("results.csv").display(),
        out.join("results.json").display(),
        charts
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let failed_rows = rows.iter().filter(|r| r.status == "failed").count();
    if !args.collect && (failed_now > 0 || failed_rows > 0) {
        anyhow::bail!(
            "{} cell(s) failed (their errors are above and in tables.md)",
            failed_now.max(failed_rows)
        );
    }
    Ok(())
}

/// Progress of a plan's run on stderr, one line per event.
fn print_event(e: &RunEvent) {
    match e {
        RunEvent::DatasetBuilding { name } => eprintln!("dataset {name}: building"),
        RunEvent::DatasetSkipped { name, reason } => {
            eprintln!("dataset {name}: skipped (optional): {reason}")
        }
        RunEvent::DatasetFailed { name, error } => {
            eprintln!("dataset {name}: FAILED, its cells fail: {error}")
        }
        RunEvent::CellStarted { k, n, label } => eprintln!("[cell {k}/{n}] {label}: training"),
        RunEvent::CellEnded {
            k,
            n,
            label,
            outcome,
            elapsed_s,
            eta_s,
        } => {
            let what = match outcome {
                Outcome::Kept => "finished earlier, kept".to_string(),
                Outcome::Done { wall_s, resumed } => format!(
                    "{} in {}",
                    if *resumed { "resumed, done" } else { "done" },
                    fmt_s(*wall_s)
                ),
                Outcome::Failed { error } => format!("FAILED: {error}"),
            };
            let left = eta_s
                .map(|s| format!(", about {} left", fmt_s(s)))
                .unwrap_or_default();
            eprintln!(
                "[cell {k}/{n}] {label}: {what} (elapsed {}{left})",
                fmt_s(*elapsed_s)
            );
        }
    }
}

/// The tables and verdicts (everything of `tables.md` before the method descriptions), the
/// magnitude readings, and the cells without a result, on stdout.
fn print_results(
    plan: &Plan,
    rows: &[aggregate::Row],
    verdicts: &[unispine::reproduce::verdict::Verdict],
    tables: &unispine::doc::Doc,
    claims_doc: Option<&std::path::Path>,
) {
    let head = unispine::reproduce::tables::results_part(tables).to_markdown();
    println!("{}", head.trim_end());
    println!();
    for v in verdicts {
        println!("verdict: {:<15} {}", v.word.as_str(), v.claim.text);
    }
    for m in unispine::reproduce::magnitude::scoped(plan, rows) {
        println!(
            "magnitude: [{}] {}: {}",
            m.scope,
            m.verdict.claim.text,
            m.reading()
        );
    }
    if let Some(doc) = claims_doc {
        println!("claims document: {}", doc.display());
    }
    let missing = aggregate::missing(rows);
    if !missing.is_empty() {
        println!(
            "\n{} of {} cells have no result: {}",
            missing.len(),
            rows.len(),
            missing
                .iter()
                .map(|r| format!("{} ({})", r.run_dir, r.status))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}
