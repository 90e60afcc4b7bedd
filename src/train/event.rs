//! Progress events of a training run, consumed by the CLI's progress bar (or by tests).

use crate::densify::DensifyReport;

/// Something that happened during training.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// The loop is about to start.
    Started {
        total: usize,
        n_gaussians: usize,
        train_views: usize,
        test_views: usize,
        extent: f64,
    },
    /// One iteration finished.
    Progress {
        iteration: usize,
        total: usize,
        loss: f64,
        psnr: f64,
        n_gaussians: usize,
        its_per_sec: f64,
    },
    /// Test metrics at an evaluation iteration.
    Eval {
        iteration: usize,
        psnr: f64,
        ssim: f64,
        n_gaussians: usize,
    },
    /// Clone / split / prune happened.
    Densified {
        iteration: usize,
        report: DensifyReport,
    },
    /// A checkpoint was written.
    Checkpoint { iteration: usize },
    /// The run stopped on request (Ctrl-C) after this iteration.
    Stopped { iteration: usize },
}

/// The iterations-per-second figure of [`Event::Progress`]: iterations counted over windows of
/// about one second (the first iteration reports at once, from its own time).
#[derive(Debug)]
pub struct IterRate {
    window_start: std::time::Instant,
    in_window: usize,
    rate: f64,
}

impl Default for IterRate {
    fn default() -> Self {
        IterRate {
            window_start: std::time::Instant::now(),
            in_window: 0,
            rate: 0.0,
        }
    }
}

impl IterRate {
    /// Count one iteration; returns the current rate.
    pub fn tick(&mut self) -> f64 {
        self.in_window += 1;
        let dt = self.window_start.elapsed().as_secs_f64();
        if dt >= 1.0 || self.rate == 0.0 {
            self.rate = self.in_window as f64 / dt.max(1e-9);
            if dt >= 1.0 {
                self.window_start = std::time::Instant::now();
                self.in_window = 0;
            }
        }
        self.rate
    }
}
