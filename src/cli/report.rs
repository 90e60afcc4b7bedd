//! `unispine report RUN...`: one markdown table comparing finished runs, read from their
//! `metrics.json` files (nothing is recomputed), and optionally two SVG charts.

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
    /// Also write two SVG charts into this folder: `tradeoff.svg` (test PSNR against training
    /// time and against render fps) and `curves.svg` (training PSNR, test PSNR and Gaussian
    /// count against iteration, from each run's `log.csv`).
    #[arg(long)]
    pub charts: Option<PathBuf>,
}

/// Print (and optionally write) the table.
pub fn run(a: ReportArgs) -> anyhow::Result<()> {
    let table = unispine::report::table(&a.runs)?;
    print!("{table}");
    if let Some(p) = a.out {
        unispine::fsio::write_atomic(&p, table.as_bytes())?;
    }
    if let Some(dir) = a.charts {
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        for (name, svg) in [
            ("tradeoff.svg", unispine::report::tradeoff_chart(&a.runs)?),
            ("curves.svg", unispine::report::curves_chart(&a.runs)?),
        ] {
            let p = dir.join(name);
            unispine::fsio::write_atomic(&p, svg.as_bytes())?;
            eprintln!("wrote {}", p.display());
        }
    }
    Ok(())
}
