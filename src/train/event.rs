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
