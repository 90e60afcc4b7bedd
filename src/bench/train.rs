//! Where one training iteration's time goes (`unispine bench train`): the `unispine` preset on
//! the CT crop (or the built-in phantom), trained for a warm-up to a realistic Gaussian count
//! (or started from a saved model), then `iters` iterations timed by stage with the trainer's
//! stage timers ([`crate::train::StageTimes`]).
//!
//! Stages: render forward (projection, tile binning, compositing; Eqs. 1-5), loss + SPWM +
//! SSIM (Eqs. 6-9, forward and backward), render backward, Adam, densification (statistics
//! every iteration; a clone / split / prune event amortised over the preset's interval) and
//! bookkeeping (the rest of the step). The rasterizer is render forward + render backward;
//! the target is that everything else takes at most [`NON_RASTERIZER_TARGET`] of the step.
//!
//! The CT crop is built as `unispine data ct --volume V --mask M --detector N` builds it
//! (vertebra labels 25-50 plus 10 mm, recentred, NAF mu, at most 128 voxels per axis,
//! min-max normalised), with `views` training views and one test view.

use std::path::Path;

use crate::dataset::generate::{self, GenerateOptions};
use crate::dataset::Dataset;
use crate::densify::TrainState;
use crate::error::{Error, Result};
use crate::gaussians::Gaussians;
use crate::timer::cpu_seconds;
use crate::train::{stages::STAGES, Method, StageTimes, TrainConfig, Trainer};
use crate::volume::attenuation::{HuConversion, Normalization};
use crate::volume::phantom::{self, PhantomSpec};
use crate::volume::{resample, Volume};

use super::render::process_cpu_seconds;

/// The target share of a training step outside the rasterizer (loss, SPWM, SSIM, Adam,
/// densification, evaluation, bookkeeping): at most 15 % of the step's CPU time.
pub const NON_RASTERIZER_TARGET: f64 = 0.15;

/// Allowed ranges of the training benchmark: square detector sizes (pixels per side), timed
/// iterations, warm-up iterations and training views. A detector of 2048^2 with 100 views
/// holds about 5 GiB of projections, targets and SPWM priors.
pub const TRAIN_SIZES: (usize, usize) = (8, 2048);
pub const TRAIN_ITERS: (usize, usize) = (1, 100_000);
pub const TRAIN_WARMUP: (usize, usize) = (0, 20_000);
pub const TRAIN_VIEWS: (usize, usize) = (1, 100);

/// Check the training benchmark's settings; the error names the flag, the value and the
/// allowed range.
pub fn check_train_cases(sizes: &[usize], iters: usize, warmup: usize, views: usize) -> Result<()> {
    let check = |flag: &str, values: &[usize], (lo, hi): (usize, usize)| {
        if values.is_empty() {
            return Err(Error::invalid(flag, "needs at least one value"));
        }
        match values.iter().find(|&&v| v < lo || v > hi) {
            Some(v) => Err(Error::invalid(
                flag,
                format!("{v} is outside the allowed range [{lo}, {hi}]"),
            )),
            None => Ok(()),
        }
    };
    check("--sizes", sizes, TRAIN_SIZES)?;
    check("--iters", &[iters], TRAIN_ITERS)?;
    check("--warmup", &[warmup], TRAIN_WARMUP)?;
    check("--views", &[views], TRAIN_VIEWS)
}

fn options(size: usize, views: usize, units: &str, how: &str) -> GenerateOptions {
    GenerateOptions {
        train_views: views,
        test_views: 1,
        detector: size,
        volume_units: units.into(),
        volume_normalisation: how.into(),
        ..GenerateOptions::default()
    }
}

/// The CT crop of `unispine data ct --volume V --mask M --detector size` with `views` training
/// views and one test view.
pub fn ct_crop_dataset(volume: &Path, mask: &Path, size: usize, views: usize) -> Result<Dataset> {
    let mut vol = crate::volume::load(volume)?;
    vol.check_finite(&format!("{}", volume.display()))?;
    let labels = crate::volume::load_labels(mask)?;
    let ids: Vec<u16> = (25..=50).collect();
    vol = resample::crop_to_labels(&vol, &labels, ids.as_slice(), 10.0)?;
    resample::recentre(&mut vol);
    HuConversion::NafMu.apply(&mut vol);
    let cap = 128;
    if vol.dims.iter().any(|&d| d > cap) {
        vol = resample::resample_trilinear(&vol, vol.dims.map(|d| d.min(cap)))?;
    }
    Normalization::MinMax.apply(&mut vol)?;
    let o = options(size, views, "normalised [0, 1]", "naf-mu, min-max");
    generate::generate(&vol, &o, &|_, _| {})
}

/// The built-in phantom (128^3 voxels of 1 mm) at `size`^2 with `views` training views.
pub fn phantom_dataset(size: usize, views: usize) -> Result<Dataset> {
    let (vol, _): (Volume<f32>, _) = phantom::generate(&PhantomSpec::default())?;
    let o = options(size, views, "1/mm", "phantom attenuation");
    generate::generate(&vol, &o, &|_, _| {})
}

/// What [`time_train`] measured.
#[derive(Clone, Debug)]
pub struct TrainBench {
    /// Detector pixels per side.
    pub size: usize,
    /// Gaussians at the first and after the last timed iteration.
    pub gaussians: (usize, usize),
    /// Schedule position of the first timed iteration (1-based).
    pub first_iteration: usize,
    /// Stage timers summed over the timed iterations.
    pub stages: StageTimes,
    /// Whether the timed iterations are in the densification phase of the schedule.
    pub densify_phase: bool,
    /// Mean (wall, process CPU) seconds of one clone / split / prune event (timed in the
    /// window, or on a copy of the state after it when no event fell in the window; 0 outside
    /// the phase).
    pub densify_event: (f64, f64),
    /// The preset's densification interval.
    pub densify_interval: usize,
    /// Process CPU time (all threads) per timed iteration from `/proc` (Linux; None
    /// elsewhere), a check of the stage timers' CPU clock.
    pub cpu_per_iteration: Option<f64>,
}

/// Which clock [`TrainBench::per_iteration`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clock {
    Wall,
    /// Process CPU time, all threads.
    Cpu,
}

impl TrainBench {
    /// Seconds per iteration by stage ([`STAGES`] order) with the densification events
    /// amortised over the interval: the statistics and resets every iteration plus one event
    /// / interval.
    pub fn per_iteration(&self, clock: Clock) -> [f64; 7] {
        let (s, event) = match clock {
            Clock::Wall => (&self.stages.wall, self.densify_event.0),
            Clock::Cpu => (&self.stages.cpu, self.densify_event.1),
        };
        let n = self.stages.steps.max(1) as f64;
        let mut v = s.seconds().map(|x| x / n);
        v[4] -= s.densify_events / n;
        if self.densify_phase {
            v[4] += event / self.densify_interval.max(1) as f64;
        }
        v
    }

    /// The step time of [`TrainBench::per_iteration`] (the sum of its stages).
    pub fn step(&self, clock: Clock) -> f64 {
        self.per_iteration(clock).iter().sum()
    }

    /// Share of the step outside the rasterizer (everything but render forward and backward).
    pub fn non_rasterizer_share(&self, clock: Clock) -> f64 {
        let v = self.per_iteration(clock);
        1.0 - (v[0] + v[2]) / self.step(clock)
    }

    /// The stage names with their per-iteration (wall, CPU) seconds.
    pub fn rows(&self) -> Vec<(&'static str, f64, f64)> {
        let (w, c) = (
            self.per_iteration(Clock::Wall),
            self.per_iteration(Clock::Cpu),
        );
        (0..STAGES.len()).map(|k| (STAGES[k], w[k], c[k])).collect()
    }
}

/// Train the `unispine` preset (paper schedule, 20k iterations, no test evaluations) on `ds`:
/// `warmup` iterations, or, with `model`, start from those Gaussians at schedule position
/// `warmup` (fresh Adam moments and densification statistics) and run one untimed iteration;
/// then time `iters` iterations.
pub fn time_train(
    ds: &Dataset,
    warmup: usize,
    iters: usize,
    model: Option<Gaussians<f32>>,
) -> Result<TrainBench> {
    let mut cfg = TrainConfig::preset(Method::Unispine);
    cfg.eval_iterations = vec![];
    cfg.iterations = cfg.iterations.max(warmup + iters + 2);
    let size = ds.geometry.n_detector[0];
    let mut tr = Trainer::new(cfg.clone(), ds)?;
    match model {
        Some(g) => {
            tr.state = TrainState::new(g, cfg.adam);
            tr.iteration = warmup;
            // One untimed step: the first one pays one-time costs that a run amortises (at
            // 1024^2 the loss's images take first-touch page faults as the heap grows to
            // them; with 10 timed steps that put the non-rasterizer share at 26-29 % against
            // 22 % over 40).
            tr.step()?;
        }
        None => {
            for _ in 0..warmup {
                tr.step()?;
            }
        }
    }
    let n0 = tr.state.len();
    let first_iteration = tr.iteration + 1;
    tr.stages = Some(StageTimes::default());
    let cpu0 = process_cpu_seconds();
    for _ in 0..iters {
        tr.step()?;
    }
    let cpu = match (cpu0, process_cpu_seconds()) {
        (Some(a), Some(b)) => Some((b - a) / iters as f64),
        _ => None,
    };
    let stages = tr.stages.take().unwrap_or_default();
    let d = &cfg.densify;
    let last = tr.iteration;
    let densify_phase = (first_iteration..=last).any(|it| it > d.from_iter && it < d.until_iter);
    let densify_event = if !densify_phase {
        (0.0, 0.0)
    } else if stages.n_densify_events > 0 {
        let k = stages.n_densify_events as f64;
        (
            stages.wall.densify_events / k,
            stages.cpu.densify_events / k,
        )
    } else {
        let mut st = tr.state.clone();
        let c0 = cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID);
        let t0 = std::time::Instant::now();
        std::hint::black_box(st.densify_and_prune(d, tr.extent, d.prunes_big(last), cfg.seed));
        (
            t0.elapsed().as_secs_f64(),
            cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID) - c0,
        )
    };
    Ok(TrainBench {
        size,
        gaussians: (n0, tr.state.len()),
        first_iteration,
        stages,
        densify_phase,
        densify_event,
        densify_interval: d.interval,
        cpu_per_iteration: cpu,
    })
}
