//! Stage timers of a training iteration, off unless a benchmark turns them on
//! ([`crate::train::Trainer::stages`]). Timing reads the clocks between the stages of
//! [`crate::train::Trainer::step`] and changes nothing the iteration computes; when off, each
//! stage boundary costs one test of an `Option`.
//!
//! Two clocks: wall time, and the process's CPU time (all threads, `CLOCK_PROCESS_CPUTIME_ID`),
//! which other processes on a shared machine do not inflate (it does count the worker threads
//! of the thread pool while they wait for work).

pub(crate) use crate::timer::Laps;

/// The stages of one iteration, in the order of [`Stages::seconds`].
pub const STAGES: [&str; 7] = [
    "render forward",
    "loss + SPWM + SSIM",
    "render backward",
    "Adam",
    "densification",
    "evaluation",
    "bookkeeping",
];

/// Seconds summed per stage over the iterations timed so far (one clock).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stages {
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
    /// Of [`Stages::densify`]: the clone / split / prune events alone.
    pub densify_events: f64,
    /// Test evaluations inside the iterations (none in a benchmark).
    pub eval: f64,
    /// Whole iterations, from the start of `step` to its return.
    pub step: f64,
}

impl Stages {
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

    /// Seconds per stage in the order of [`STAGES`]; they sum to [`Stages::step`].
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

    fn add(&mut self, o: &Stages) {
        self.render_forward += o.render_forward;
        self.loss += o.loss;
        self.render_backward += o.render_backward;
        self.adam += o.adam;
        self.densify += o.densify;
        self.densify_events += o.densify_events;
        self.eval += o.eval;
        self.step += o.step;
    }
}

/// Wall and process CPU time by stage over the iterations timed so far.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StageTimes {
    pub wall: Stages,
    /// Process CPU time (all threads); NaN where the OS does not tell.
    pub cpu: Stages,
    /// Clone / split / prune events timed.
    pub n_densify_events: usize,
    /// Iterations timed.
    pub steps: usize,
}

impl StageTimes {
    pub(crate) fn add(&mut self, one: &StageTimes) {
        self.wall.add(&one.wall);
        self.cpu.add(&one.cpu);
        self.n_densify_events += one.n_densify_events;
        self.steps += one.steps;
    }
}

/// Build one iteration's [`StageTimes`] from its laps.
#[derive(Default)]
pub(crate) struct Recorder(pub(crate) StageTimes);

impl Recorder {
    /// Set stage `f` of both clocks to `(wall, cpu)`.
    pub(crate) fn set(&mut self, f: fn(&mut Stages) -> &mut f64, (w, c): (f64, f64)) {
        *f(&mut self.0.wall) = w;
        *f(&mut self.0.cpu) = c;
    }

    /// Add `(wall, cpu)` to stage `f` of both clocks.
    pub(crate) fn add(&mut self, f: fn(&mut Stages) -> &mut f64, (w, c): (f64, f64)) {
        *f(&mut self.0.wall) += w;
        *f(&mut self.0.cpu) += c;
    }
}
