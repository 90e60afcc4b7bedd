//! Reports: markdown tables and SVG charts read from run folders (`metrics.json`, `log.csv`),
//! so that reports never recompute anything.

pub mod holds;
pub mod reproduce;
pub mod svg;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::train::{Metrics, RunDir};

/// Read a run's `metrics.json` (through [`RunDir`]).
pub fn read_metrics(run: &Path) -> Result<Metrics> {
    RunDir::open(run)?.read_metrics()
}

/// `metrics.json` of a run, `None` when the folder exists but has none (a run still going, or
/// one that failed); other errors (unreadable or malformed file, missing folder) are errors.
fn try_metrics(run: &Path) -> Result<Option<Metrics>> {
    let rd = RunDir::open(run)?;
    if !rd.path(crate::train::run_dir::METRICS).exists() {
        return Ok(None);
    }
    rd.read_metrics().map(Some)
}

fn opt(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        _ => "-".into(),
    }
}

/// A markdown table with one row per run: method, iterations, test PSNR / SSIM, train time,
/// render fps, Gaussian count, peak memory. Every figure of a row describes the run's saved
/// model: a stopped run shows no PSNR / SSIM / fps (its last evaluation was of an earlier
/// model than the Gaussian count), and a folder without `metrics.json` gets a row that says so.
pub fn table(runs: &[PathBuf]) -> Result<String> {
    let mut s = String::from(
        "| run | method | iterations | PSNR (dB) | SSIM | train time (s) | fps | Gaussians | peak memory (MiB) |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in runs {
        let name = r
            .file_name()
            .map(|x| x.to_string_lossy().to_string())
            .unwrap_or_default();
        let Some(m) = try_metrics(r)? else {
            let _ = writeln!(
                s,
                "| {name} | no metrics.json (not finished, or failed) | - | - | - | - | - | - | - |"
            );
            continue;
        };
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

fn run_name(run: &Path) -> String {
    run.file_name()
        .map(|x| x.to_string_lossy().to_string())
        .unwrap_or_else(|| run.display().to_string())
}

/// Speed against accuracy: test PSNR against training wall time and against render fps, one
/// labelled marker per run, one colour per method.
pub fn tradeoff_chart(runs: &[PathBuf]) -> Result<String> {
    let mut methods: Vec<String> = Vec::new();
    let mut time = svg::Panel {
        title: "test PSNR against training time".into(),
        x_label: "training wall time (s)".into(),
        y_label: "test PSNR (dB)".into(),
        ..Default::default()
    };
    let mut fps = svg::Panel {
        title: "test PSNR against render speed".into(),
        x_label: "render speed (test views per second)".into(),
        y_label: "test PSNR (dB)".into(),
        ..Default::default()
    };
    for r in runs {
        let Some(m) = try_metrics(r)? else { continue };
        let Some(psnr) = m.test_psnr else { continue };
        let colour = match methods.iter().position(|x| *x == m.method) {
            Some(i) => i,
            None => {
                methods.push(m.method.clone());
                methods.len() - 1
            }
        };
        let label = format!("{} ({})", run_name(r), m.method);
        time.markers.push(svg::Marker {
            label: label.clone(),
            x: m.train_time_s,
            y: psnr,
            colour,
        });
        if let Some(f) = m.render_fps {
            fps.markers.push(svg::Marker {
                label,
                x: f,
                y: psnr,
                colour,
            });
        }
    }
    Ok(svg::figure(&[time, fps]))
}

/// One run's `log.csv` as (iteration, training PSNR, Gaussian count) rows.
pub fn read_log(run: &Path) -> Result<Vec<(f64, f64, f64)>> {
    let p = run.join("log.csv");
    let s = crate::fsio::read_text_bounded(&p, crate::fsio::MAX_LOG_BYTES)?;
    let mut lines = s.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| h.trim() == name)
            .ok_or_else(|| Error::format(&p, "log", format!("no column `{name}` in the header")))
    };
    let (ci, cp, cn) = (col("iteration")?, col("psnr")?, col("n_gaussians")?);
    let mut rows = Vec::new();
    for (k, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |c: usize| -> Result<f64> {
            f.get(c)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .ok_or_else(|| {
                    Error::format(
                        &p,
                        "log",
                        format!("line {}: column {c} is not a number", k + 2),
                    )
                })
        };
        rows.push((num(ci)?, num(cp)?, num(cn)?));
    }
    Ok(rows)
}

/// Moving mean over `w` consecutive values (the first w-1 outputs average what is there).
pub(crate) fn moving_mean(v: &[f64], w: usize) -> Vec<f64> {
    let w = w.max(1);
    let mut out = Vec::with_capacity(v.len());
    let mut sum = 0.0;
    for i in 0..v.len() {
        sum += v[i];
        if i >= w {
            sum -= v[i - w];
        }
        out.push(sum / (i + 1).min(w) as f64);
    }
    out
}

/// Keep at most `max` points, evenly spaced, always the last one.
pub(crate) fn thin<T: Copy>(v: &[T], max: usize) -> Vec<T> {
    let step = v.len().div_ceil(max.max(1)).max(1);
    let mut out: Vec<T> = v.iter().step_by(step).copied().collect();
    if let Some(&last) = v.last() {
        if !(v.len() - 1).is_multiple_of(step) {
            out.push(last);
        }
    }
    out
}

/// Training curves: training-view PSNR (moving mean over 1 % of the run), test PSNR at the
/// evaluation iterations, and the Gaussian count, against iteration; one line per run.
pub fn curves_chart(runs: &[PathBuf]) -> Result<String> {
    let mut train = svg::Panel {
        title: "training PSNR (moving mean over 1 % of the run)".into(),
        x_label: "iteration".into(),
        y_label: "PSNR of the training view (dB)".into(),
        ..Default::default()
    };
    let mut test = svg::Panel {
        title: "test PSNR at the evaluation iterations".into(),
        x_label: "iteration".into(),
        y_label: "test PSNR (dB)".into(),
        ..Default::default()
    };
    let mut count = svg::Panel {
        title: "number of Gaussians".into(),
        x_label: "iteration".into(),
        y_label: "Gaussians".into(),
        log_y: true,
        ..Default::default()
    };
    for r in runs {
        let label = run_name(r);
        let Some(m) = try_metrics(r)? else { continue };
        let log = read_log(r)?;
        let psnr: Vec<f64> = log.iter().map(|x| x.1).collect();
        let smooth = moving_mean(&psnr, log.len().div_ceil(100));
        let pts: Vec<(f64, f64)> = log.iter().zip(&smooth).map(|(x, s)| (x.0, *s)).collect();
        train.lines.push(svg::Line {
            label: label.clone(),
            points: thin(&pts, 1000),
        });
        test.lines.push(svg::Line {
            label: label.clone(),
            points: m
                .evals
                .iter()
                .map(|e| (e.iteration as f64, e.psnr))
                .collect(),
        });
        let n: Vec<(f64, f64)> = log.iter().map(|x| (x.0, x.2)).collect();
        count.lines.push(svg::Line {
            label,
            points: thin(&n, 1000),
        });
    }
    Ok(svg::figure(&[train, test, count]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_mean_matches_direct_sums() {
        let v: Vec<f64> = (0..20).map(|i| ((i * 7) % 11) as f64).collect();
        let m = moving_mean(&v, 4);
        for i in 0..v.len() {
            let lo = i.saturating_sub(3);
            let direct: f64 = v[lo..=i].iter().sum::<f64>() / (i - lo + 1) as f64;
            assert!((m[i] - direct).abs() < 1e-12);
        }
    }

    #[test]
    fn thin_keeps_first_and_last() {
        let v: Vec<usize> = (0..10).collect();
        assert_eq!(thin(&v, 4), vec![0, 3, 6, 9]);
        assert_eq!(thin(&v, 3), vec![0, 4, 8, 9]);
        assert_eq!(thin(&v, 100), v);
    }
}
