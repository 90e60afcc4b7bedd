//! Table 1's baselines behind `unispine train --method NAME`: the method names, the scoring of
//! predicted line integrals on the test views, and the run folder (the same `metrics.json` as
//! the Gaussian trainer's, so `unispine report` takes the rows as they are).
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
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use ndarray::{Array3, ShapeBuilder};

mod field_run;
use field_run::field_config_json;
pub use field_run::{resume, run_field, FIELD_CHECKPOINT_EVERY, FIELD_FPS_VIEWS};

use crate::dataset::Dataset;
use crate::drr::{self, Projector};
use crate::error::{Error, Result};
use crate::eval::{self, EvalResult, ViewMetrics};
use crate::field::encode::VmLines;
use crate::field::{EncoderConfig, FieldConfig, RayPixels};
use crate::fsio;
use crate::image2d::Image2d;
use crate::train::run_dir::CONFIG;
use crate::train::{EvalPoint, Event, Method, Metrics, RunDir};
use crate::volume::Volume;

/// A baseline method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Baseline {
    /// FDK (TIGRE semantics) from the training views, re-projected at the test views.
    Fdk,
    /// A neural attenuation field preset of [`crate::field`] (`naf`, `naf-full`, ...).
    Field(&'static str),
}

impl Baseline {
    /// Every baseline name, in table order.
    pub fn names() -> Vec<&'static str> {
        let mut v = vec!["fdk"];
        v.extend(crate::field::PRESETS);
        v
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Fdk => "fdk",
            Baseline::Field(p) => p,
        }
    }

    /// One line on what the baseline runs (as `unispine train --help` and `tables.md` show it).
    pub fn help(self) -> String {
        match self {
            Baseline::Fdk => {
                "FDK (TIGRE semantics: cosine weights, Ram-Lak, 1/U^2 backprojection) \
                              from the training views, re-projected at the test views"
                    .into()
            }
            Baseline::Field(p) => FieldConfig::preset(p, 1)
                .map(|c| c.describe())
                .unwrap_or_default(),
        }
    }

    /// The baseline called `name`, if any.
    pub fn parse(name: &str) -> Option<Baseline> {
        if name == "fdk" {
            return Some(Baseline::Fdk);
        }
        crate::field::PRESETS
            .into_iter()
            .find(|p| *p == name)
            .map(Baseline::Field)
    }
}

/// A method of `unispine train --method`: a Gaussian preset of [`crate::train`] or a baseline.
/// The one list of method names, read by the command line and by reproduction plans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrainMethod {
    Gaussians(Method),
    Baseline(Baseline),
}

impl TrainMethod {
    /// The Gaussian preset, when the method is one.
    pub fn gaussians(self) -> Option<Method> {
        match self {
            TrainMethod::Gaussians(m) => Some(m),
            TrainMethod::Baseline(_) => None,
        }
    }

    /// Every method name with its one line of help: the presets in declaration order, then the
    /// baselines in table order.
    pub fn all() -> Vec<(&'static str, String)> {
        let presets = <Method as clap::ValueEnum>::value_variants()
            .iter()
            .map(|m| {
                let help = clap::ValueEnum::to_possible_value(m)
                    .and_then(|v| v.get_help().map(|h| h.to_string()))
                    .unwrap_or_default();
                (m.name(), help)
            });
        let baselines = Baseline::names().into_iter().map(|b| {
            let help = Baseline::parse(b).map(Baseline::help).unwrap_or_default();
            (b, help)
        });
        presets.chain(baselines).collect()
    }

    /// The method called `name`; the error lists every name.
    pub fn parse(name: &str) -> std::result::Result<TrainMethod, String> {
        if let Some(b) = Baseline::parse(name) {
            return Ok(TrainMethod::Baseline(b));
        }
        <Method as clap::ValueEnum>::from_str(name, false)
            .map(TrainMethod::Gaussians)
            .map_err(|_| {
                let names: Vec<&str> = TrainMethod::all().into_iter().map(|m| m.0).collect();
                format!("unknown method `{name}` (one of: {})", names.join(", "))
            })
    }
}

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

/// Everything a baseline produced, before it is written.
pub struct Outcome {
    pub metrics: Metrics,
    /// Settings for `config.json`.
    pub config: serde_json::Value,
    /// `log.csv` text.
    pub log: String,
    /// (test view, render in raw line integrals) for the previews.
    pub test_renders: Vec<(usize, Image2d<f32>)>,
}

/// FDK from the training views, re-projected at the test views with the dataset's projector.
/// The re-projection of a reconstruction at each angle of a split.
fn project_views(proj: &Projector<'_, f32>, angles: &[f64]) -> Result<Vec<Image2d<f32>>> {
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

/// FDK from the training views, re-projected with our DRR and scored at the test views.
pub fn run_fdk(ds: &Dataset) -> Result<(Outcome, Volume<f32>)> {
    crate::dataset::store::check(ds)?;
    if ds.manifest.pose_noise.is_some() {
        // FDK filters and back-projects along the circular orbit; perturbed recorded cameras
        // leave it, so running it on the nominal angles would ignore the condition.
        return Err(Error::invalid(
            "manifest.pose_noise",
            "FDK needs the circular orbit: this dataset's recorded training cameras carry pose \
             noise (make it with --pose-noise-deg 0 --pose-noise-mm 0 for FDK)",
        ));
    }
    let t0 = Instant::now();
    let vol = crate::fdk::reconstruct(&ds.geometry, &ds.train.angles, &ds.train.projections)?;
    let train_time = t0.elapsed().as_secs_f64();
    let method = dataset_projector(ds);
    let proj = Projector::new(&vol, &ds.geometry, method)?;
    let te = Instant::now();
    let test_renders = project_views(&proj, &ds.test.angles)?;
    let ev = score_line_integrals(&test_renders, &ds.test.projections)?;
    let eval_time = te.elapsed().as_secs_f64();
    let train_renders = project_views(&proj, &ds.train.angles)?;
    let train_fit = score_line_integrals(&train_renders, &ds.train.projections)?;
    let (fps, _) = views_fps(ds.test.angles.len(), &|k| {
        std::hint::black_box(proj.view(ds.test.angles[k])?);
        Ok(())
    })?;
    let protocol = format!(
        "test views, forward only ({} DRR of the reconstructed volume), f32, one warm-up \
         render, median of 3 timed passes",
        ds.manifest.projector
    );
    let metrics = baseline_metrics(
        Baseline::Fdk.name().into(),
        1,
        Some(&ev),
        (train_time, eval_time),
        (Some(fps), protocol),
        vol.data.len(),
    );
    let config = serde_json::json!({
        "method": "fdk",
        "algorithm": "FDK, TIGRE Python semantics: cosine weighting, Ram-Lak (ramp_flat, scale (DSD/DSO)(2 pi/N)/(4 du)), voxel-driven backprojection weighted by 1/U^2, no Parker",
        "train_views": ds.train.angles.len(),
        "test_views": ds.test.angles.len(),
        "grid": { "nVoxel": ds.geometry.n_voxel, "dVoxel": ds.geometry.d_voxel, "offOrigin": ds.geometry.off_origin },
        "reprojection": ds.manifest.projector,
    });
    let log = format!(
        "iteration,view,loss,data,ssim,psnr,n_gaussians,seconds\n1,0,0,0,{:.9e},{:.6},0,{:.3}\n",
        train_fit.ssim, train_fit.psnr, train_time
    );
    Ok((
        Outcome {
            metrics,
            config,
            log,
            test_renders: test_renders.into_iter().enumerate().collect(),
        },
        vol,
    ))
}

/// Write the run folder `dir` of an outcome (the model is written by the caller).
pub fn write_run(
    dir: &Path,
    rd: &crate::train::RunDir,
    ds: &Dataset,
    o: &Outcome,
    previews: usize,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let w = |name: &str, text: String| -> Result<()> {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| Error::io(&p, e))
    };
    w(
        "config.json",
        serde_json::to_string_pretty(&o.config).expect("config serialises") + "\n",
    )?;
    w("log.csv", o.log.clone())?;
    let pdir = dir.join("previews");
    std::fs::create_dir_all(&pdir).map_err(|e| Error::io(&pdir, e))?;
    let n = o.test_renders.len();
    let k = previews.min(n);
    for j in 0..k {
        let (v, render) = &o.test_renders[j * n / k.max(1)];
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
    w(
        "metrics.json",
        serde_json::to_string_pretty(&o.metrics).expect("metrics serialise"),
    )
}

/// Writes a run's model into its folder.
type ModelWriter = Box<dyn Fn(&Path) -> Result<()>>;

/// The `unispine train` flags a baseline run takes besides `--data`, `--out` and `--method`
/// (the other settings are the Gaussian trainer's; a baseline run given one is an error).
pub const FLAGS: [&str; 5] = ["iters", "seed", "vm-lines", "rays", "threads"];

/// The `unispine train` flags that only baselines read (declared here so that reproduction
/// plans know them too).
#[derive(Clone, Debug, Default, clap::Args)]
pub struct BaselineFlags {
    /// TensoRF's line factor (tensorf, tensorf-full only): `upstream` (default; SAX-NeRF reads
    /// the plane at (0, w) instead of the line vector) or `corrected` (the line vector).
    #[arg(long, value_enum)]
    pub vm_lines: Option<VmLines>,
    /// The pixels a neural field's training rays are drawn from: `positive` (default; the
    /// upstream trainers' pixels with projection > 0, which leaves space crossed only by
    /// background rays unconstrained) or `all` (every pixel; not an upstream setting, labelled
    /// `all pixels` in tables).
    #[arg(long, value_enum)]
    pub rays: Option<RayPixels>,
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
    /// Stop a field run (with a checkpoint) once this many iterations are done.
    pub stop_after: Option<usize>,
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

/// Run `baseline` on `ds`, writing the run folder `out` when given, with `opts`
/// ([`BaselineOptions`]); `stop` ends a field run early (no evaluation); `on_event` receives
/// [`Event::Progress`] after each field iteration.
pub fn run(
    baseline: Baseline,
    ds: &Dataset,
    out: Option<&Path>,
    opts: BaselineOptions,
    stop: &AtomicBool,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let iters = opts.iters;
    check_vm_lines(baseline.name(), opts.vm_lines)?;
    // A field run's folder is set up when it starts (checkpoints go there); FDK's at the end.
    let mut store = None;
    let (o, write_model): (Outcome, ModelWriter) = match baseline {
        Baseline::Fdk => {
            if iters.is_some() {
                return Err(Error::invalid(
                    "--iters",
                    "fdk is a single pass (no iterations)",
                ));
            }
            if opts.rays.is_some() {
                return Err(Error::invalid(
                    "--rays",
                    "fdk uses every pixel of every view (no ray sampling)",
                ));
            }
            let (o, vol) = run_fdk(ds)?;
            (
                o,
                Box::new(move |dir: &Path| write_volume_npy(&dir.join("model.npy"), &vol)),
            )
        }
        Baseline::Field(name) => {
            let mut cfg = FieldConfig::preset(name, ds.train.angles.len())?;
            if let Some(n) = iters {
                if n == 0 || n > crate::field::MAX_ITERATIONS {
                    return Err(Error::invalid(
                        "--iters",
                        format!(
                            "{n} is outside the allowed range [1, {}]",
                            crate::field::MAX_ITERATIONS
                        ),
                    ));
                }
                cfg.set_iterations(n);
            }
            if let Some(seed) = opts.seed {
                cfg.seed = seed;
            }
            if let Some(r) = opts.rays {
                cfg.ray_pixels = r;
            }
            if let (Some(l), EncoderConfig::TensorVm { lines, .. }) =
                (opts.vm_lines, &mut cfg.encoder)
            {
                *lines = l;
            }
            cfg.validate()?;
            store = out.map(RunDir::create).transpose()?;
            if let Some(rd) = &store {
                fsio::write_json_atomic(&rd.path(CONFIG), &field_config_json(&cfg, &[]))?;
            }
            let (o, field) = run_field(
                cfg,
                ds,
                (stop, opts.stop_after),
                on_event,
                store.as_ref(),
                None,
            )?;
            (
                o,
                Box::new(move |dir: &Path| {
                    crate::field::model::save(&dir.join("model.npz"), &field)
                }),
            )
        }
    };
    let store = match store {
        Some(rd) => Some(rd),
        None => out.map(RunDir::create).transpose()?,
    };
    if let Some(rd) = store {
        write_model(rd.root())?;
        write_run(rd.root(), &rd, ds, &o, 4)?;
    }
    Ok(o.metrics)
}
