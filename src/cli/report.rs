//! `unispine report RUN...`: one markdown table comparing finished runs, read from their
//! `metrics.json` files (nothing is recomputed).

use std::path::PathBuf;

use anyhow::Context;

/// Arguments of `unispine report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// Run folders written by `unispine train` (one table row each, in this order).
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Also write the table to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Print (and optionally write) the table.
pub fn run(a: ReportArgs) -> anyhow::Result<()> {
    let table = crate::report::table(&a.runs)?;
    print!("{table}");
    if let Some(p) = a.out {
        std::fs::write(&p, &table).with_context(|| format!("{}: cannot write", p.display()))?;
    }
    Ok(())
}
