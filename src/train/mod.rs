//! The trainer: method presets ([`config`]), the training loop ([`Trainer`], [`run`]) and its
//! progress events ([`event`]).
//!
//! One iteration (1-based `it`), in the order of UniSpine-GS / X-Gaussian `train.py`:
//! 1. position learning rate from the log-linear schedule at `it`; one more band of features
//!    at every multiple of 1000 (`oneupSHdegree`);
//! 2. the next training view, popped at a seeded random position from a stack that is refilled
//!    with every view when empty (3DGS `viewpoint_stack.pop(randint(...))`);
//! 3. render (f32) -> loss (Eq. 8; SPWM weights of Eqs. 6-7 from the cached per-view prior)
//!    -> backward; a non-finite loss, gradient or parameter stops the run with
//!    [`Error::Diverged`] naming the iteration and the view;
//! 4. test evaluation at the evaluation iterations (before this iteration's update, like
//!    upstream's `training_report`);
//! 5. densification statistics, clone / split / prune, opacity reset ([`crate::densify`]);
//! 6. Adam step, skipped at the last iteration (upstream `if iteration < opt.iterations`), for
//!    no group after a densification (upstream re-creates every tensor, so none has a gradient)
//!    and not for the opacity after a reset.
//!
//! Targets are the projections min-max normalised per view ([`crate::eval::normalise_gt`]).
//! The scene extent is 1.1 x the largest distance of a training camera centre from their mean
//! (3DGS `getNerfppNorm`).
//!
//! Run folder: `config.json`, `metrics.json`, `log.csv`, `model.ply`, `checkpoint.ply` +
//! `checkpoint.json` (the last good state), `previews/test_KK.png` (render | ground truth).

pub mod config;
pub mod event;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::dataset::Dataset;
use crate::densify::TrainState;
use crate::error::{Error, Result};
use crate::eval::{self, EvalResult};
use crate::gaussians::{init, ply, Gaussians};
use crate::image2d::Image2d;
use crate::loss::{self, spwm};
use crate::optim::{Group, N_GROUPS};
use crate::render::{self, RenderSettings};

pub use config::{Method, TrainConfig, TrainOverrides};
pub use event::Event;

/// Scene extent: 1.1 x max distance of the camera centres from their mean (3DGS
/// `getNerfppNorm`, used as `spatial_lr_scale` and in the densification thresholds).
pub fn scene_extent(ds: &Dataset, views: usize) -> f64 {
    let cs: Vec<[f64; 3]> = (0..views).map(|k| ds.train_camera(k).centre).collect();
    let n = cs.len().max(1) as f64;
    let mut m = [0.0; 3];
    for c in &cs {
        for a in 0..3 {
            m[a] += c[a] / n;
        }
    }
    let d = cs
        .iter()
        .map(|c| ((c[0] - m[0]).powi(2) + (c[1] - m[1]).powi(2) + (c[2] - m[2]).powi(2)).sqrt())
        .fold(0.0, f64::max);
    1.1 * d
}

/// What one iteration did.
#[derive(Clone, Debug, PartialEq)]
pub struct StepInfo {
    pub iteration: usize,
    pub view: usize,
    pub loss: loss::LossValue,
    pub psnr: f64,
    pub n_gaussians: usize,
    pub eval: Option<EvalResult>,
    pub densified: Option<crate::densify::DensifyReport>,
}

/// One evaluation point of `metrics.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalPoint {
    pub iteration: usize,
    pub psnr: f64,
    pub ssim: f64,
    pub n_gaussians: usize,
}

/// `metrics.json` of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    pub method: String,
    /// Iterations completed.
    pub iterations: usize,
    /// False when stopped early (Ctrl-C).
    pub completed: bool,
    /// Test PSNR / SSIM at the evaluation iterations.
    pub evals: Vec<EvalPoint>,
    /// Metrics of the last evaluation (the final model when completed).
    pub test_psnr: Option<f64>,
    pub test_ssim: Option<f64>,
    /// Wall time of the training loop (everything from the first to the last iteration,
    /// evaluation passes and checkpoints included), seconds.
    pub train_time_s: f64,
    /// Part of `train_time_s` spent in the test evaluations.
    pub eval_time_s: f64,
    /// Test-view render speed (see `eval::render_fps`).
    pub render_fps: Option<f64>,
    pub render_fps_protocol: String,
    /// Final number of Gaussians.
    pub n_gaussians: usize,
    /// Peak resident memory (VmHWM), bytes.
    pub peak_memory_bytes: Option<u64>,
    /// Scene extent (mm).
    pub extent: f64,
    /// Render settings of the final model (what `unispine eval` uses).
    pub render: RenderSettings,
    /// rayon threads of the run.
    pub threads: usize,
    /// Number of model parameters (baselines: voxels, field weights), when known.
    #[serde(default)]
    pub model_params: Option<u64>,
    /// Size of the saved model in bytes, when known.
    #[serde(default)]
    pub model_bytes: Option<u64>,
}

/// The training loop's state; [`Trainer::step`] runs one iteration.
pub struct Trainer<'a> {
    pub cfg: TrainConfig,
    pub ds: &'a Dataset,
    pub state: TrainState<f32>,
    /// Normalised ground truth of the training views in use.
    pub targets: Vec<Image2d<f32>>,
    /// Normalised ground truth of the test views.
    pub test_targets: Vec<Image2d<f32>>,
    /// Cached SPWM prior per training view (when SPWM is on).
    pub priors: Vec<Option<Image2d<f32>>>,
    pub extent: f64,
    /// Last completed iteration.
    pub iteration: usize,
    stack: Vec<usize>,
    rng: ChaCha8Rng,
}

impl<'a> Trainer<'a> {
    /// Set up a run: targets, SPWM priors, extent and the initial Gaussians.
    pub fn new(cfg: TrainConfig, ds: &'a Dataset) -> Result<Self> {
        cfg.validate()?;
        ds.geometry.validate()?;
        let nv = ds
            .train
            .angles
            .len()
            .min(cfg.train_views.unwrap_or(usize::MAX));
        if nv == 0 {
            return Err(Error::invalid("train", "the dataset has no training view"));
        }
        if ds.train.projections.len() < nv {
            return Err(Error::invalid(
                "train.projections",
                "fewer projections than angles",
            ));
        }
        let targets: Vec<Image2d<f32>> = (0..nv)
            .map(|k| eval::normalise_gt(&ds.train.projections[k], &format!("train projection {k}")))
            .collect::<Result<_>>()?;
        let test_targets = eval::test_targets(ds)?;
        let priors = targets
            .iter()
            .map(|t| cfg.spwm.as_ref().map(|c| spwm::view_prior(t, c)))
            .collect();
        let extent = scene_extent(ds, nv);
        let g = init::initialise::<f32>(&ds.geometry, &cfg.init, cfg.color, cfg.seed)?;
        let state = TrainState::new(g, cfg.adam);
        Ok(Trainer {
            rng: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5ee0_0000_0000_0002),
            cfg,
            ds,
            state,
            targets,
            test_targets,
            priors,
            extent,
            iteration: 0,
            stack: Vec::new(),
        })
    }

    /// Render settings at iteration `it`.
    pub fn settings(&self, it: usize) -> RenderSettings {
        RenderSettings {
            color: self.cfg.color,
            active_features: self.cfg.active_features(it),
            background: self.cfg.background,
        }
    }

    fn next_view(&mut self) -> usize {
        if self.stack.is_empty() {
            self.stack = (0..self.targets.len()).collect();
        }
        let k = self.rng.random_range(0..self.stack.len());
        self.stack.remove(k)
    }

    /// Run iteration `self.iteration + 1`.
    pub fn step(&mut self) -> Result<StepInfo> {
        let it = self.iteration + 1;
        let cfg = &self.cfg;
        let lr = cfg.lr.at(it, self.extent);
        let settings = self.settings(it);
        let view = self.next_view();
        let cfg = &self.cfg;
        let diverged = |what: String| Error::Diverged {
            iteration: it,
            what,
        };
        let cam = self.ds.train_camera(view);
        let (img, saved) = render::forward(&self.state.params, &cam, &settings)
            .map_err(|e| diverged(format!("rendering training view {view}: {e}")))?;
        let gt = &self.targets[view];
        let weights = match (&cfg.spwm, &self.priors[view]) {
            (Some(c), Some(p)) => {
                let t = (it as f64 * cfg.spwm_time_scale).round() as usize;
                Some(spwm::weights(p, t, c))
            }
            _ => None,
        };
        let (lv, d_img) = loss::forward_backward(&img, gt, weights.as_ref(), &cfg.loss);
        if !lv.total.is_finite() {
            return Err(diverged(format!(
                "loss is {} on training view {view}",
                lv.total
            )));
        }
        let grads = render::backward(&self.state.params, &cam, &settings, &saved, &d_img);
        if let Err(e) = grads.params.check_finite() {
            return Err(diverged(format!("gradient on training view {view}: {e}")));
        }
        let psnr = eval::psnr(&eval::clamp01(&img), gt);
        let eval = if cfg.is_eval_point(it) {
            Some(eval::evaluate(
                &self.state.params,
                self.ds,
                &self.test_targets,
                &settings,
            )?)
        } else {
            None
        };
        let d = &cfg.densify;
        let mut active = [it < cfg.iterations; N_GROUPS];
        let mut densified = None;
        if d.collects(it) {
            self.state.accumulate(&grads.mean2d_ndc_norm, &grads.radius);
            if d.densifies(it) {
                let seed = cfg.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ it as u64;
                densified =
                    Some(
                        self.state
                            .densify_and_prune(d, self.extent, d.prunes_big(it), seed),
                    );
                active = [false; N_GROUPS];
            }
            if d.resets(it) {
                self.state.reset_opacity(d.reset_opacity_to);
                active[Group::Opacity as usize] = false;
            }
        }
        if active.iter().any(|&a| a) {
            let st = &mut self.state;
            st.adam.step(&mut st.params, &grads.params, &lr, &active);
        }
        if let Err(e) = self.state.params.check_finite() {
            return Err(diverged(format!(
                "parameter after the update on training view {view}: {e}"
            )));
        }
        self.iteration = it;
        Ok(StepInfo {
            iteration: it,
            view,
            loss: lv,
            psnr,
            n_gaussians: self.state.len(),
            eval,
            densified,
        })
    }
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// Write `checkpoint.ply` and `checkpoint.json` (iteration, count, render settings).
pub fn write_checkpoint(
    dir: &Path,
    g: &Gaussians<f32>,
    iteration: usize,
    settings: &RenderSettings,
) -> Result<()> {
    let tmp = dir.join("checkpoint.ply.part");
    ply::write_ply(&tmp, g)?;
    let path = dir.join("checkpoint.ply");
    std::fs::rename(&tmp, &path).map_err(|e| Error::io(&path, e))?;
    let j = serde_json::json!({
        "iteration": iteration,
        "n_gaussians": g.len(),
        "render": settings,
    });
    write_atomic(
        &dir.join("checkpoint.json"),
        serde_json::to_string_pretty(&j).unwrap().as_bytes(),
    )
}

/// An image as 8-bit grey with values in [0, 1] (clamped).
fn to_u8(img: &Image2d<f32>) -> Vec<u8> {
    img.data
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect()
}

/// Write `render | ground truth` side by side as a PNG.
pub fn write_preview(path: &Path, render: &Image2d<f32>, gt: &Image2d<f32>) -> Result<()> {
    let (w, h) = (render.width, render.height);
    let gap = 4;
    let mut buf = image::GrayImage::new((2 * w + gap) as u32, h as u32);
    let (a, b) = (to_u8(render), to_u8(gt));
    for r in 0..h {
        for c in 0..w {
            buf.put_pixel(c as u32, r as u32, image::Luma([a[r * w + c]]));
            buf.put_pixel((w + gap + c) as u32, r as u32, image::Luma([b[r * w + c]]));
        }
    }
    buf.save(path)
        .map_err(|e| Error::format(path, "png", e.to_string()))
}

/// Train `cfg` on `ds`, writing the run folder `out` (when given), reporting to `on_event`;
/// `stop` (set by Ctrl-C) ends the run cleanly after the current iteration with a checkpoint.
pub fn run(
    cfg: &TrainConfig,
    ds: &Dataset,
    out: Option<&Path>,
    stop: &AtomicBool,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let mut tr = Trainer::new(cfg.clone(), ds)?;
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        cfg.save(&dir.join("config.json"))?;
        write_checkpoint(dir, &tr.state.params, 0, &tr.settings(1))?;
    }
    on_event(&Event::Started {
        total: cfg.iterations,
        n_gaussians: tr.state.len(),
        train_views: tr.targets.len(),
        test_views: tr.test_targets.len(),
        extent: tr.extent,
    });
    let mut log = String::from("iteration,view,loss,data,ssim,psnr,n_gaussians,seconds\n");
    let mut evals = Vec::new();
    let mut eval_time = 0.0;
    let t0 = Instant::now();
    let (mut win_t, mut win_it) = (Instant::now(), 0usize);
    let mut its_per_sec = 0.0;
    let mut completed = true;
    let flush_log = |log: &str| -> Result<()> {
        if let Some(dir) = out {
            write_atomic(&dir.join("log.csv"), log.as_bytes())?;
        }
        Ok(())
    };
    while tr.iteration < cfg.iterations {
        if stop.load(Ordering::SeqCst) {
            completed = false;
            on_event(&Event::Stopped {
                iteration: tr.iteration,
            });
            break;
        }
        let te = Instant::now();
        let info = match tr.step() {
            Ok(i) => i,
            Err(e) => {
                flush_log(&log)?;
                return Err(e);
            }
        };
        let it = info.iteration;
        if let Some(e) = &info.eval {
            eval_time += te.elapsed().as_secs_f64();
            evals.push(EvalPoint {
                iteration: it,
                psnr: e.psnr,
                ssim: e.ssim,
                n_gaussians: info.n_gaussians,
            });
            on_event(&Event::Eval {
                iteration: it,
                psnr: e.psnr,
                ssim: e.ssim,
                n_gaussians: info.n_gaussians,
            });
        }
        if let Some(r) = info.densified {
            on_event(&Event::Densified {
                iteration: it,
                report: r,
            });
        }
        let _ = writeln!(
            log,
            "{it},{},{:.9e},{:.9e},{:.9e},{:.6},{},{:.3}",
            info.view,
            info.loss.total,
            info.loss.data,
            info.loss.ssim,
            info.psnr,
            info.n_gaussians,
            t0.elapsed().as_secs_f64()
        );
        win_it += 1;
        let dt = win_t.elapsed().as_secs_f64();
        if dt >= 1.0 || its_per_sec == 0.0 {
            its_per_sec = win_it as f64 / dt.max(1e-9);
            if dt >= 1.0 {
                win_t = Instant::now();
                win_it = 0;
            }
        }
        on_event(&Event::Progress {
            iteration: it,
            total: cfg.iterations,
            loss: info.loss.total,
            psnr: info.psnr,
            n_gaussians: info.n_gaussians,
            its_per_sec,
        });
        if let Some(dir) = out {
            if cfg.checkpoint_every > 0 && it % cfg.checkpoint_every == 0 && it < cfg.iterations {
                write_checkpoint(dir, &tr.state.params, it, &tr.settings(it + 1))?;
                flush_log(&log)?;
                on_event(&Event::Checkpoint { iteration: it });
            }
        }
    }
    let train_time = t0.elapsed().as_secs_f64();
    let final_settings = tr.settings(tr.iteration.max(1));
    let g = &tr.state.params;
    let render_fps = if completed {
        Some(eval::render_fps(g, ds, &final_settings)?.0)
    } else {
        None
    };
    if let Some(dir) = out {
        write_checkpoint(dir, g, tr.iteration, &final_settings)?;
        on_event(&Event::Checkpoint {
            iteration: tr.iteration,
        });
        flush_log(&log)?;
        if completed {
            ply::write_ply(&dir.join("model.ply"), g)?;
            let pdir = dir.join("previews");
            std::fs::create_dir_all(&pdir).map_err(|e| Error::io(&pdir, e))?;
            let n = tr.test_targets.len();
            let k = cfg.preview_views.min(n);
            for j in 0..k {
                let v = j * n / k.max(1);
                let (img, _) = render::forward(g, &ds.test_camera(v), &final_settings)?;
                write_preview(
                    &pdir.join(format!("test_{v:02}.png")),
                    &img,
                    &tr.test_targets[v],
                )?;
            }
        }
    }
    let last = evals.last().cloned();
    let metrics = Metrics {
        method: cfg.method.name().to_string(),
        iterations: tr.iteration,
        completed,
        test_psnr: last.as_ref().map(|e| e.psnr),
        test_ssim: last.as_ref().map(|e| e.ssim),
        evals,
        train_time_s: train_time,
        eval_time_s: eval_time,
        render_fps,
        render_fps_protocol: "test views, forward only (project + tiles + composite), f32, one warm-up render, median of 3 timed passes".into(),
        n_gaussians: g.len(),
        peak_memory_bytes: eval::peak_memory_bytes(),
        extent: tr.extent,
        render: final_settings,
        threads: rayon::current_num_threads(),
        model_params: None,
        model_bytes: None,
    };
    if let Some(dir) = out {
        let s = serde_json::to_string_pretty(&metrics).expect("metrics serialise");
        write_atomic(&dir.join("metrics.json"), s.as_bytes())?;
    }
    Ok(metrics)
}

/// Paths of a run folder.
pub fn run_paths(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    (
        dir.join("config.json"),
        dir.join("metrics.json"),
        dir.join("model.ply"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{Manifest, Split};

    #[test]
    fn extent_matches_upstream_for_50_views_over_180_degrees() {
        // research section 2: 1.1 x max |c_i - mean(c)| = 1285.36 mm for DSO = 1000 mm.
        let angles: Vec<f64> = (0..50)
            .map(|k| k as f64 * std::f64::consts::PI / 50.0)
            .collect();
        let ds = Dataset {
            geometry: crate::geometry::ConeBeam::centred([8, 8], [1.0, 1.0], [8, 8, 8], [1.0; 3]),
            train: Split {
                angles,
                projections: vec![],
            },
            test: Split::default(),
            manifest: Manifest::default(),
            volume: None,
        };
        let e = scene_extent(&ds, 50);
        assert!((e - 1285.36).abs() < 0.01, "{e}");
    }
}
