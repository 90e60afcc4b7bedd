//! Reports: markdown tables read from run folders (`metrics.json`, `config.json`), so that
//! reports never recompute anything.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::train::Metrics;

/// Read a run's `metrics.json`.
pub fn read_metrics(run: &Path) -> Result<Metrics> {
    let p = run.join("metrics.json");
    let s = std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))?;
    serde_json::from_str(&s).map_err(|e| Error::format(&p, "metrics", e.to_string()))
}

fn opt(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        _ => "-".into(),
    }
}

/// A markdown table with one row per run: method, iterations, test PSNR / SSIM, train time,
/// render fps, Gaussian count, peak memory.
pub fn table(runs: &[PathBuf]) -> Result<String> {
    let mut s = String::from(
        "| run | method | iterations | PSNR (dB) | SSIM | train time (s) | fps | Gaussians | peak memory (MiB) |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in runs {
        let m = read_metrics(r)?;
        let name = r
            .file_name()
            .map(|x| x.to_string_lossy().to_string())
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "| {name} | {} | {}{} | {} | {} | {:.1} | {} | {} | {} |",
            m.method,
            m.iterations,
            if m.completed { "" } else { " (stopped)" },
            opt(m.test_psnr, 2),
            opt(m.test_ssim, 4),
            m.train_time_s,
            opt(m.render_fps, 1),
            m.n_gaussians,
            opt(m.peak_memory_bytes.map(|b| b as f64 / (1024.0 * 1024.0)), 0),
        );
    }
    Ok(s)
}
