//! Table 1's baselines behind `unispine train --method NAME` (their names are in the registry,
//! [`crate::method::Baseline`]; their runs are [`crate::method::fdk`] and
//! [`crate::method::field`]): their settings, the scoring of predicted line integrals on the
//! test views, and their run-folder files (the same `metrics.json` as the Gaussian trainer's,
//! so `unispine report` takes the rows as they are).
//!
//! Scoring: a baseline predicts raw line integrals (the dataset's units). Each test view's
//! prediction is mapped with the same affine map that normalises its ground truth
//! (`(p - min(gt)) / (max(gt) - min(gt))`, [`crate::dataset::targets::normalise_gt`]),
//! clamped to [0, 1] like a Gaussian render, and scored with [`crate::eval::psnr`] and
//! [`crate::loss::ssim::ssim`] against the normalised ground truth. This is PSNR / SSIM with the
//! data range of each ground-truth view; it does not rescale the prediction by its own range
//! (which would hide a scale error).
//!
//! Render speed: one warm-up render of the first test view, then three timed passes over every
//! test view (forward only, no metrics); fps = views / seconds of the median pass, as
//! [`crate::eval::render_fps`] does for the Gaussians.
//!
//! Run folder: `config.json` (method and settings), `metrics.json` ([`Metrics`]), `log.csv`
//! (the columns of the Gaussian trainer's), the model (`model.npy` for FDK: f32 `[x, y, z]`
//! volume, x fastest on disk, numpy reads it as an ordinary `[x, y, z]` array), and
//! `previews/test_KK.png` (render | ground truth).
//!
//! [`Metrics`]: crate::train::Metrics

use std::path::Path;
use std::time::Instant;

use ndarray::{Array3, ShapeBuilder};

use crate::dataset::Dataset;
use crate::drr::{self, Projector};
use crate::error::{Error, Result};
use crate::eval::{self, EvalResult, ViewMetrics};
use crate::field::encode::VmLines;
use crate::field::RayPixels;
use crate::image2d::Image2d;
use crate::train::run_dir::METRICS;
use crate::train::{EvalPoint, Metrics, RunDir};
use crate::volume::Volume;

/// The projector that made the dataset's projections (from `manifest.projector`): re-projecting
/// with the same operator charges no operator mismatch to the baseline.
pub fn dataset_projector(ds: &Dataset) -> drr::Method {
    if ds.manifest.projector.starts_with("trilinear") {
        drr::Method::Trilinear
    } else {
        drr::Method::Siddon
    }
}

/// Score predicted line integrals (one per test view, in test order) against the raw
/// ground truth `gt` (see the module doc).
pub fn score_line_integrals(pred: &[Image2d<f32>], gt: &[Image2d<f32>]) -> Result<EvalResult> {
    if pred.len() != gt.len() || gt.is_empty() {
        return Err(Error::invalid(
            "test",
            format!(
                "{} predictions for {} test views (need one per view, at least one)",
                pred.len(),
                gt.len()
            ),
        ));
    }
    let mut views = Vec::with_capacity(gt.len());
    for (k, (p, g)) in pred.iter().zip(gt).enumerate() {
        let what = format!("test projection {k}");
        if p.width != g.width || p.height != g.height {
            return Err(Error::invalid(
                format!("prediction {k}"),
                format!(
                    "{}x{} but the test view is {}x{}",
                    p.height, p.width, g.height, g.width
                ),
            ));
        }
        crate::error::check_finite(&format!("prediction {k}"), &p.data)?;
        let target = crate::dataset::targets::normalise_gt(g, &what)?;
        let (lo, hi) = g
            .data
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |a, &v| {
                (a.0.min(v as f64), a.1.max(v as f64))
            });
        let r = hi - lo;
        let mapped = Image2d::from_vec(
            p.width,
            p.height,
            p.data
                .iter()
                .map(|&v| ((v as f64 - lo) / r) as f32)
                .collect(),
        );
        let img = eval::clamp01(&mapped);
        views.push(ViewMetrics {
            psnr: eval::psnr(&img, &target),
            ssim: crate::loss::ssim::ssim(&img, &target),
        });
    }
    let n = views.len() as f64;
    Ok(EvalResult {
        psnr: views.iter().map(|v| v.psnr).sum::<f64>() / n,
        ssim: views.iter().map(|v| v.ssim).sum::<f64>() / n,
        views,
    })
}

/// Frames per second of `render(view)` over `n` views (protocol in the module doc), and the
/// seconds of the median pass.
pub fn views_fps(n: usize, render: &dyn Fn(usize) -> Result<()>) -> Result<(f64, f64)> {
    if n == 0 {
        return Err(Error::invalid("test", "the dataset has no test view"));
    }
    render(0)?;
    let mut times = Vec::with_capacity(3);
    for _ in 0..3 {
        let t = Instant::now();
        for k in 0..n {
            render(k)?;
        }
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok((n as f64 / times[1].max(1e-12), times[1]))
}

/// Write a volume as an f32 `[x, y, z]` npy (Fortran order, so the bytes are our x-fastest
/// layout).
pub fn write_volume_npy(path: &Path, v: &Volume<f32>) -> Result<()> {
    let arr = Array3::from_shape_vec((v.dims[0], v.dims[1], v.dims[2]).f(), v.data.clone())
        .map_err(|e| Error::format(path, "shape", e.to_string()))?;
    ndarray_npy::write_npy(path, &arr).map_err(|e| Error::format(path, "npy", e.to_string()))
}

/// The re-projection of a reconstruction at each angle of a split.
pub(crate) fn project_views(
    proj: &Projector<'_, f32>,
    angles: &[f64],
) -> Result<Vec<Image2d<f32>>> {
    angles.iter().map(|&a| proj.view(a)).collect()
}

/// `metrics.json` of a baseline run after `iterations`: `ev` is the test score of the final
/// model (absent when the run stopped early, which makes it incomplete); no Gaussians; the
/// model is `n_params` f32 values.
pub(crate) fn baseline_metrics(
    method: String,
    iterations: usize,
    ev: Option<&EvalResult>,
    (train_time_s, eval_time_s): (f64, f64),
    (render_fps, render_fps_protocol): (Option<f64>, String),
    n_params: usize,
) -> Metrics {
    Metrics {
        method,
        iterations,
        completed: ev.is_some(),
        evals: ev
            .iter()
            .map(|e| EvalPoint {
                iteration: iterations,
                psnr: e.psnr,
                ssim: e.ssim,
                n_gaussians: 0,
            })
            .collect(),
        test_psnr: ev.map(|e| e.psnr),
        test_ssim: ev.map(|e| e.ssim),
        train_time_s,
        eval_time_s,
        render_fps,
        render_fps_protocol,
        n_gaussians: 0,
        peak_memory_bytes: eval::peak_memory_bytes(),
        extent: 0.0,
        render: Default::default(),
        threads: rayon::current_num_threads(),
        compaction: None,
        model_bytes: Some(n_params as u64 * 4),
    }
}

/// Write `previews/test_KK.png` of `previews` of the test `renders` (view, render in raw line
/// integrals), evenly spaced, each beside its ground truth, both mapped with the ground truth's
/// range.
pub fn write_previews(
    rd: &RunDir,
    ds: &Dataset,
    renders: &[(usize, Image2d<f32>)],
    previews: usize,
) -> Result<()> {
    let pdir = rd.path("previews");
    std::fs::create_dir_all(&pdir).map_err(|e| Error::io(&pdir, e))?;
    let n = renders.len();
    let k = previews.min(n);
    for j in 0..k {
        let (v, render) = &renders[j * n / k.max(1)];
        let v = *v;
        let gt = &ds.test.projections[v];
        let (lo, hi) = gt
            .data
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |a, &x| {
                (a.0.min(x), a.1.max(x))
            });
        let map = |img: &Image2d<f32>| {
            let r = (hi - lo).max(f32::MIN_POSITIVE);
            Image2d::from_vec(
                img.width,
                img.height,
                img.data.iter().map(|&x| (x - lo) / r).collect(),
            )
        };
        rd.write_preview(&format!("test_{v:02}.png"), &map(render), &map(gt))?;
    }
    Ok(())
}

/// Write a baseline's `metrics.json` (pretty JSON without a final newline, as baseline runs
/// have always written it; the Gaussians' ends with one, [`RunDir::write_metrics`]).
pub fn write_metrics(rd: &RunDir, m: &Metrics) -> Result<()> {
    let text = serde_json::to_string_pretty(m).expect("metrics serialise");
    crate::fsio::write_atomic(&rd.path(METRICS), text.as_bytes())
}

/// The `unispine train` flags a baseline run takes besides `--data`, `--out` and `--method`
/// (the other settings are the Gaussian trainer's; a baseline run given one is an error).
pub const FLAGS: [&str; 5] = ["iters", "seed", "vm-lines", "rays", "threads"];

/// The `unispine train` flags that only baselines read (declared here so that reproduction
/// plans know them too).
#[derive(Clone, Debug, Default)]
pub struct BaselineFlags {
    /// TensoRF's line factor (tensorf, tensorf-full only).
    pub vm_lines: Option<VmLines>,
    /// The pixels a neural field's training rays are drawn from.
    pub rays: Option<RayPixels>,
}

impl crate::flags::FlagSet for BaselineFlags {
    const GROUP: &'static str = "BaselineFlags";

    fn flags() -> Vec<crate::flags::Flag> {
        use crate::flags::Flag;
        vec![
            Flag::value::<VmLines>(
                "vm-lines",
                "TensoRF's line factor (tensorf, tensorf-full only): `upstream` (default; \
                 SAX-NeRF reads the plane at (0, w) instead of the line vector) or `corrected` \
                 (the line vector).",
            ),
            Flag::value::<RayPixels>(
                "rays",
                "The pixels a neural field's training rays are drawn from: `positive` \
                 (default; the upstream trainers' pixels with projection > 0, which leaves space \
                 crossed only by background rays unconstrained) or `all` (every pixel; not an \
                 upstream setting, labelled `all pixels` in tables).",
            ),
        ]
    }

    fn set(&mut self, long: &str, value: Option<&str>) -> std::result::Result<(), String> {
        use crate::flags::FlagValue;
        let text = value.unwrap_or_default();
        match long {
            "vm-lines" => self.vm_lines = Some(VmLines::parse_flag(text)?),
            "rays" => self.rays = Some(RayPixels::parse_flag(text)?),
            _ => return Err(format!("unknown flag `--{long}`")),
        }
        Ok(())
    }
}

/// Settings of a baseline run beyond its preset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BaselineOptions {
    /// Replaces a field preset's iteration count (an error for FDK).
    pub iters: Option<usize>,
    /// Seed of a field's initialisation, ray batches and stratified samples (default 0). FDK
    /// draws nothing at random: its result does not depend on the seed.
    pub seed: Option<u64>,
    /// TensoRF's line factor (`tensorf*` presets only; default the preset's, `upstream`).
    pub vm_lines: Option<VmLines>,
    /// The pixels a field's rays are drawn from (default the upstream `positive`; an error for
    /// FDK).
    pub rays: Option<RayPixels>,
}

/// `--vm-lines` is given only to a TensoRF preset (`method`: the method's name).
pub fn check_vm_lines(method: &str, vm_lines: Option<VmLines>) -> Result<()> {
    if vm_lines.is_some() && !method.starts_with("tensorf") {
        return Err(Error::invalid(
            "--vm-lines",
            format!("only for the TensoRF presets (tensorf, tensorf-full), not `{method}`"),
        ));
    }
    Ok(())
}
