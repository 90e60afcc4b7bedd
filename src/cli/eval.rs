//! `unispine eval --run RUN [--data DIR]`: re-evaluate a saved model (`model.ply`, or the
//! checkpoint of a stopped run) on the test views of its dataset, with the protocol of
//! [`crate::eval`]; prints the metrics and writes `eval.json` into the run folder.

use std::path::PathBuf;

use anyhow::{bail, Context};

use crate::eval;
use crate::gaussians::ply;
use crate::render::RenderSettings;

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

/// The model of a run and its render settings: `model.ply` with `metrics.json`, else the
/// checkpoint.
pub fn load_model(
    run: &std::path::Path,
) -> anyhow::Result<(crate::gaussians::Gaussians<f32>, RenderSettings, PathBuf)> {
    let model = run.join("model.ply");
    let metrics = run.join("metrics.json");
    let (ply_path, json_path, key) = if model.exists() && metrics.exists() {
        (model, metrics, "render")
    } else {
        let c = run.join("checkpoint.ply");
        if !c.exists() {
            bail!(
                "{}: no model.ply (with metrics.json) nor checkpoint.ply",
                run.display()
            );
        }
        (c, run.join("checkpoint.json"), "render")
    };
    let j: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&json_path)
            .with_context(|| format!("reading {}", json_path.display()))?,
    )
    .with_context(|| format!("{}: not JSON", json_path.display()))?;
    let settings: RenderSettings = serde_json::from_value(j[key].clone())
        .with_context(|| format!("{}: field `{key}`", json_path.display()))?;
    let g = ply::read_ply::<f32>(&ply_path)?;
    Ok((g, settings, ply_path))
}

/// Run `unispine eval`.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    super::train::init_threads(args.threads)?;
    let cfg = crate::train::TrainConfig::load(&args.run.join("config.json"))?;
    let data = match (&args.data, &cfg.data) {
        (Some(d), _) => d.clone(),
        (None, Some(d)) => PathBuf::from(d),
        (None, None) => bail!("the run's config.json names no dataset: pass --data"),
    };
    let ds = crate::dataset::store::load(&data)?;
    let (g, settings, ply_path) = load_model(&args.run)?;
    let targets = crate::dataset::targets::test_targets(&ds)?;
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
        "data": data.display().to_string(),
        "psnr": r.psnr,
        "ssim": r.ssim,
        "views": r.views,
        "render_fps": fps,
        "n_gaussians": g.len(),
        "render": settings,
    });
    let out = args.run.join("eval.json");
    std::fs::write(&out, serde_json::to_string_pretty(&j)?)
        .with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}
