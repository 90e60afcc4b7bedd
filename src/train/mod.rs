//! The trainer: method presets ([`config`]) and their settings ([`settings`]), one iteration of the Gaussians ([`Trainer`]) and the
//! progress events ([`event`]); [`crate::session`] drives it through
//! [`crate::method`].
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
//!    upstream's `training_report`), timed on its own;
//! 5. densification statistics, clone / split / prune, opacity reset ([`crate::densify`]);
//! 6. Adam step, skipped at the last iteration (upstream `if iteration < opt.iterations`), for
//!    no group after a densification (upstream re-creates every tensor, so none has a gradient)
//!    and not for the opacity after a reset.
//!
//! Targets are the projections min-max normalised per view ([`crate::dataset::targets`]).
//! The scene extent is 1.1 x the largest distance of a training camera centre from their mean
//! (3DGS `getNerfppNorm`).
//!
//! At the last iteration nothing changes the model after the evaluation (no densification,
//! opacity reset or Adam step), so the model evaluated there is the model saved: upstream
//! `train.py` also calls `scene.save` before that iteration's densification.
//!
//! Divergence ([`Error::Diverged`]) is also declared when nothing is rendered in a training
//! view (no Gaussian visible) and when every Gaussian is more than [`LEAVE_FACTOR`] scene
//! extents from the volume centre.
//!
//! Compaction ([`compact`], optional, not in the paper) replaces the update of its iteration
//! (default: the last of `iterations`) with a prune by importance; `finetune` more iterations
//! follow without densification, statistics or opacity resets.
//!
//! The loop with its events and files is [`crate::session`]; the run folder is [`run_dir`], its
//! resumable state [`checkpoint`]. [`stages`] times the stages of [`Trainer::step`] for
//! `unispine bench train` (off unless [`Trainer::stages`] is set; it changes no result).
//!
//! [`config`]: crate::train::config
//! [`settings`]: crate::train::settings
//! [`Trainer`]: crate::train::Trainer
//! [`event`]: crate::train::event
//! [`LEAVE_FACTOR`]: crate::train::LEAVE_FACTOR
//! [`compact`]: crate::train::compact
//! [`run_dir`]: crate::train::run_dir
//! [`checkpoint`]: crate::train::checkpoint
//! [`stages`]: crate::train::stages
//! [`Trainer::step`]: crate::train::Trainer::step
//! [`Trainer::stages`]: crate::train::Trainer::stages

pub mod checkpoint;
pub mod compact;
pub mod config;
pub mod event;
pub mod run_dir;
pub mod settings;
pub mod stages;

use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::dataset::{targets, Dataset};
use crate::densify::TrainState;
use crate::error::{Error, Result};
use crate::eval;
use crate::gaussians::init;
use crate::image2d::Image2d;
use crate::loss::{self, spwm};
use crate::optim::{Group, N_GROUPS};
use crate::record::{Step, StepEval, Terms};
use crate::render::{self, RenderSettings};

pub use config::{Method, TrainConfig};
pub use event::{Event, IterRate};
pub use run_dir::{Checkpoint, EvalPoint, Metrics, RunDir};
pub use settings::TrainOverrides;
pub use stages::StageTimes;

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

/// A run has diverged when every Gaussian is farther than this many scene extents from the
/// centre of the volume box.
pub const LEAVE_FACTOR: f64 = 10.0;

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
    /// What the compaction did, once it has run.
    pub compaction: Option<compact::Compaction>,
    /// Stage timers of [`Trainer::step`] (`None`, the default: not timed). Timing changes no
    /// result.
    pub stages: Option<StageTimes>,
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
        let targets = targets::train_targets(ds, nv)?;
        let test_targets = targets::test_targets(ds)?;
        let priors = targets
            .iter()
            .map(|t| cfg.spwm.as_ref().map(|c| spwm::view_prior(t, c)))
            .collect();
        let extent = scene_extent(ds, nv);
        let g = init::initialise::<f32>(ds, nv, &cfg.init, cfg.color, cfg.seed)?;
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
            compaction: None,
            stages: None,
            stack: Vec::new(),
        })
    }

    /// Render settings at iteration `it`.
    pub fn settings(&self, it: usize) -> RenderSettings {
        RenderSettings {
            color: self.cfg.color,
            active_features: self.cfg.active_features(it),
            background: self.cfg.background,
            ..Default::default()
        }
    }

    /// `Some(distance of the nearest Gaussian)` when every Gaussian is more than
    /// [`LEAVE_FACTOR`] scene extents from the centre of the volume box.
    fn all_left_the_scene(&self) -> Option<f64> {
        let geo = &self.ds.geometry;
        let limit = LEAVE_FACTOR * self.extent.max(1e-9);
        let mut nearest = f64::INFINITY;
        for m in &self.state.params.means {
            let d2: f64 = (0..3)
                .map(|a| (m[a] as f64 - geo.off_origin[a]).powi(2))
                .sum();
            nearest = nearest.min(d2.sqrt());
            if nearest <= limit {
                return None;
            }
        }
        Some(nearest)
    }

    /// The view-order state: generator word position and the views left in the stack.
    pub fn view_order(&self) -> (u128, Vec<usize>) {
        (self.rng.get_word_pos(), self.stack.clone())
    }

    /// Continue from a checkpoint of a run with the same config and dataset.
    pub fn restore(&mut self, c: &Checkpoint) -> Result<()> {
        let total = self.cfg.total_iterations();
        if c.iteration > total {
            return Err(Error::invalid(
                "checkpoint.iteration",
                format!("{} is beyond the config's {total} iterations", c.iteration),
            ));
        }
        let compacted = self.cfg.compact_at().is_some_and(|a| c.iteration >= a);
        if compacted != c.compaction.is_some() {
            return Err(Error::invalid(
                "checkpoint.compaction",
                format!(
                    "the checkpoint at iteration {} {} a compaction record but the config \
                     compacts at {:?}",
                    c.iteration,
                    if c.compaction.is_some() {
                        "has"
                    } else {
                        "lacks"
                    },
                    self.cfg.compact_at()
                ),
            ));
        }
        if let Some(&v) = c.view_stack.iter().find(|&&v| v >= self.targets.len()) {
            return Err(Error::invalid(
                "checkpoint.view_stack",
                format!(
                    "view {v} but the run has {} training views",
                    self.targets.len()
                ),
            ));
        }
        let n = c.state.len();
        let st = &c.state;
        if st.adam.m.len() != n || st.adam.v.len() != n || st.stats.denom.len() != n {
            return Err(Error::invalid("checkpoint", "arrays of different lengths"));
        }
        self.state = c.state.clone();
        self.rng.set_word_pos(c.rng_word_pos);
        self.stack = c.view_stack.clone();
        self.iteration = c.iteration;
        self.compaction = c.compaction.clone();
        Ok(())
    }

    /// Prune to the compaction target by importance over the training views (see
    /// [`compact`]); `before` is the test evaluation of the model before pruning. Returns the
    /// evaluation of the pruned model.
    fn compact(&mut self, it: usize, before: &StepEval) -> Result<StepEval> {
        let c = self
            .cfg
            .compact
            .clone()
            .expect("called with a compaction config");
        let settings = self.settings(it);
        let cams: Vec<_> = (0..self.targets.len())
            .map(|k| self.ds.train_camera(k))
            .collect();
        let score = compact::importance(&self.state.params, &cams, &settings)?;
        let n = self.state.len();
        let keep = compact::keep_indices(&score, c.target(n));
        let src: Vec<_> = keep.into_iter().map(crate::densify::Source::Keep).collect();
        self.state.remap(&src);
        let te = Instant::now();
        let result = eval::evaluate(&self.state.params, self.ds, &self.test_targets, &settings)?;
        let after = StepEval {
            result,
            n_gaussians: self.state.len(),
            seconds: te.elapsed().as_secs_f64(),
        };
        self.compaction = Some(compact::Compaction {
            iteration: it,
            n_before: n,
            n_after: after.n_gaussians,
            psnr_before: before.result.psnr,
            ssim_before: before.result.ssim,
            psnr_pruned: after.result.psnr,
            ssim_pruned: after.result.ssim,
            score: compact::SCORE_NAME.to_string(),
        });
        Ok(after)
    }

    fn next_view(&mut self) -> usize {
        if self.stack.is_empty() {
            self.stack = (0..self.targets.len()).collect();
        }
        let k = self.rng.random_range(0..self.stack.len());
        self.stack.remove(k)
    }

    /// Run iteration `self.iteration + 1`.
    pub fn step(&mut self) -> Result<Step> {
        let mut laps = stages::Laps::new(self.stages.is_some());
        let mut t = stages::Recorder::default();
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
        t.set(|s| &mut s.render_forward, laps.lap());
        if saved.splats.radius.iter().all(|&r| r == 0) {
            return Err(diverged(format!(
                "nothing is rendered in training view {view}: none of the {} Gaussians is visible",
                self.state.len()
            )));
        }
        let gt = &self.targets[view];
        let weights = match (&cfg.spwm, &self.priors[view]) {
            (Some(c), Some(p)) => {
                let t = (it as f64 * cfg.spwm_time_scale).round() as usize;
                Some(spwm::weights(p, t, c))
            }
            _ => None,
        };
        let (lv, d_img) = loss::forward_backward(&img, gt, weights.as_ref(), &cfg.loss);
        t.set(|s| &mut s.loss, laps.lap());
        if !lv.total.is_finite() {
            return Err(diverged(format!(
                "loss is {} on training view {view}",
                lv.total
            )));
        }
        let grads = render::backward(&self.state.params, &cam, &settings, &saved, &d_img);
        t.set(|s| &mut s.render_backward, laps.lap());
        if let Err(e) = grads.params.check_finite() {
            return Err(diverged(format!("gradient on training view {view}: {e}")));
        }
        let psnr = eval::psnr(&eval::clamp01(&img), gt);
        laps.lap();
        let eval = if cfg.is_eval_point(it) {
            let te = Instant::now();
            let result =
                eval::evaluate(&self.state.params, self.ds, &self.test_targets, &settings)?;
            Some(StepEval {
                result,
                n_gaussians: self.state.len(),
                seconds: te.elapsed().as_secs_f64(),
            })
        } else {
            None
        };
        t.set(|s| &mut s.eval, laps.lap());
        let d = &cfg.densify;
        let last = it == cfg.total_iterations();
        let mut active = [!last; N_GROUPS];
        let mut densified = None;
        let compact_at = cfg.compact_at();
        let mut eval = eval;
        // Nothing changes the model at the last iteration: what was evaluated above is what is
        // saved (upstream saves its model before that iteration's densification too).
        if compact_at == Some(it) {
            // The compaction replaces this iteration's update: the model pruned is the one
            // just evaluated (at the default iteration, the model a plain run saves). Its evaluation goes to
            // the compaction record; the pruned model's is this iteration's evaluation.
            let before = eval
                .take()
                .expect("the compaction iteration is an eval point");
            let mut after = self.compact(it, &before)?;
            after.seconds += before.seconds;
            eval = Some(after);
            active = [false; N_GROUPS];
        } else if d.collects(it) && !last && compact_at.is_none_or(|a| it < a) {
            self.state.accumulate(&grads.mean2d_ndc_norm, &grads.radius);
            if d.densifies(it) {
                t.set(|s| &mut s.densify, laps.lap());
                let seed = cfg.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ it as u64;
                densified =
                    Some(
                        self.state
                            .densify_and_prune(d, self.extent, d.prunes_big(it), seed),
                    );
                active = [false; N_GROUPS];
                let e = laps.lap();
                t.set(|s| &mut s.densify_events, e);
                t.add(|s| &mut s.densify, e);
                t.0.n_densify_events = 1;
            }
            if d.resets(it) {
                self.state.reset_opacity(d.reset_opacity_to);
                active[Group::Opacity as usize] = false;
            }
        }
        t.add(|s| &mut s.densify, laps.lap());
        if active.iter().any(|&a| a) {
            let st = &mut self.state;
            st.adam.step(&mut st.params, &grads.params, &lr, &active);
        }
        t.set(|s| &mut s.adam, laps.lap());
        if let Err(e) = self.state.params.check_finite() {
            return Err(diverged(format!(
                "parameter after the update on training view {view}: {e}"
            )));
        }
        if let Some(far) = self.all_left_the_scene() {
            return Err(diverged(format!(
                "every Gaussian left the scene after the update on training view {view} (the \
                 nearest is {far:.3e} mm from the volume centre, more than {LEAVE_FACTOR} scene \
                 extents)"
            )));
        }
        self.iteration = it;
        if let Some(s) = &mut self.stages {
            t.set(|s| &mut s.step, laps.total());
            t.0.steps = 1;
            s.add(&t.0);
        }
        Ok(Step {
            iteration: it,
            view,
            loss: lv,
            terms: Terms::All,
            psnr,
            lr: lr[Group::Xyz as usize],
            n_gaussians: self.state.len(),
            eval,
            densified,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{Manifest, Split};

    #[test]
    fn extent_matches_upstream_for_50_views_over_180_degrees() {
        // 3DGS `getNerfppNorm` (X-Gaussian `scene/dataset_readers.py`): 1.1 x max |c_i - mean(c)|
        // = 1285.36 mm for DSO = 1000 mm (centre of the camera centres at (20.0, 636.4, 0)).
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
