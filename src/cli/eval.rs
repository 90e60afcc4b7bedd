//! `unispine eval --run RUN [--data DIR]`: re-evaluate a saved model (`model.ply`, or the
//! checkpoint of a stopped run, read by [`RunDir::read_model`] with the render settings it
//! records) on the test views of its dataset (the one recorded in the run, from any current
//! folder), with the protocol of [`unispine::eval`]; prints the metrics and writes `eval.json`
//! into the run folder.

use std::path::PathBuf;

use anyhow::{bail, Context};

use unispine::eval;
use unispine::train::run_dir::{RunDir, SavedModel};

/// Arguments of `unispine eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Run folder written by `unispine train`.
    #[arg(long)]
    pub run: PathBuf,
    /// Dataset folder (default: the one recorded in the run's config.json).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// rayon threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Run `unispine eval`.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    super::train::init_threads(args.threads)?;
    let rd = RunDir::open(&args.run)?;
    let data = match (&args.data, rd.dataset_path()?) {
        (Some(d), _) => d.clone(),
        (None, Some(d)) => d,
        (None, None) => bail!("the run's config.json names no dataset: pass --data"),
    };
    let ds = unispine::dataset::store::load(&data)
        .with_context(|| format!("the dataset of run {}", args.run.display()))?;
    let SavedModel {
        gaussians: g,
        render: settings,
        path: ply_path,
        iteration,
    } = rd.read_model()?;
    let targets = unispine::dataset::targets::test_targets(&ds)?;
    let r = eval::evaluate(&g, &ds, &targets, &settings)?;
    let (fps, secs) = eval::render_fps(&g, &ds, &settings)?;
    println!(
        "{}: {} Gaussians, {} test views: PSNR {:.3} dB, SSIM {:.4}, render {:.1} fps ({:.3} s per pass)",
        ply_path.display(),
        g.len(),
        r.views.len(),
        r.psnr,
        r.ssim,
        fps,
        secs
    );
    let j = serde_json::json!({
        "model": ply_path.file_name().map(|s| s.to_string_lossy().to_string()),
        "iteration": iteration,
        "data": data.display().to_string(),
        "psnr": r.psnr,
        "ssim": r.ssim,
        "views": r.views,
        "render_fps": fps,
        "n_gaussians": g.len(),
        "render": settings,
    });
    rd.write_eval(&j)?;
    Ok(())
}
