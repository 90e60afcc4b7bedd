//! Stage timers of a training iteration, off unless a benchmark turns them on
//! ([`crate::train::Trainer::stages`]). Timing reads the clock between the stages of
//! [`crate::train::Trainer::step`] and changes nothing the iteration computes; when off, each
//! stage boundary costs one test of an `Option`.

use std::time::Instant;

/// The stages of one iteration, in the order [`StageTimes::seconds`] lists them.
pub const STAGES: [&str; 7] = [
    "render forward",
    "loss + SPWM + SSIM",
    "render backward",
    "Adam",
    "densification",
    "evaluation",
    "bookkeeping",
];

/// Wall time summed per stage over the iterations timed so far, seconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Projection, tile binning and compositing (`render::forward`).
    pub render_forward: f64,
    /// SPWM weights (Eq. 7), data term, SSIM and the loss gradient (Eqs. 8-9).
    pub loss: f64,
    /// Gradients of compositing and projection (`render::backward`).
    pub render_backward: f64,
    /// Adam update.
    pub adam: f64,
    /// Densification statistics, opacity resets and the clone / split / prune events.
    pub densify: f64,
    /// Of [`StageTimes::densify`]: the clone / split / prune events alone.
    pub densify_events: f64,
    /// Clone / split / prune events timed.
    pub n_densify_events: usize,
    /// Test evaluations inside the iterations (none in a benchmark).
    pub eval: f64,
    /// Whole iterations, from the start of `step` to its return.
    pub step: f64,
    /// Iterations timed.
    pub steps: usize,
}

impl StageTimes {
    /// The time of everything that is not a named stage: view choice, finiteness and
    /// divergence checks, the training PSNR.
    pub fn bookkeeping(&self) -> f64 {
        self.step
            - (self.render_forward
                + self.loss
                + self.render_backward
                + self.adam
                + self.densify
                + self.eval)
    }

    /// Seconds per stage in the order of [`STAGES`]; they sum to [`StageTimes::step`].
    pub fn seconds(&self) -> [f64; 7] {
        [
            self.render_forward,
            self.loss,
            self.render_backward,
            self.adam,
            self.densify,
            self.eval,
            self.bookkeeping(),
        ]
    }
}

/// A lap clock that reads the time only when `on`.
pub(crate) struct Laps {
    last: Option<Instant>,
    start: Option<Instant>,
}

impl Laps {
    pub(crate) fn new(on: bool) -> Self {
        let now = on.then(Instant::now);
        Laps {
            last: now,
            start: now,
        }
    }

    /// Seconds since the previous lap (0 when off).
    #[inline]
    pub(crate) fn lap(&mut self) -> f64 {
        match &mut self.last {
            Some(t) => {
                let now = Instant::now();
                let d = (now - *t).as_secs_f64();
                *t = now;
                d
            }
            None => 0.0,
        }
    }

    /// Seconds since the clock started (0 when off).
    pub(crate) fn total(&self) -> f64 {
        self.start.map_or(0.0, |s| s.elapsed().as_secs_f64())
    }
}
