//! What one training iteration of any method did ([`Step`]): the one step record of the
//! Gaussian trainer ([`crate::train::Trainer::step`]) and the neural-field trainer
//! ([`crate::field::train::FieldTrainer::step`]), read by the session driver
//! ([`crate::session`]) for `log.csv` and the progress events; and what an evaluation during
//! training found ([`EvalPoint`], kept by `metrics.json` and by checkpoints).

use crate::densify::DensifyReport;
use crate::eval::EvalResult;
use crate::loss::LossValue;

/// One evaluation point of `metrics.json` (and of a checkpoint, so that a resumed run keeps
/// its history).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalPoint {
    pub iteration: usize,
    pub psnr: f64,
    pub ssim: f64,
    /// Gaussians of the evaluated model (before that iteration's densification).
    pub n_gaussians: usize,
}

/// Which terms of [`Step::loss`] a method computes (the others print as `0` in `log.csv`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Terms {
    /// Loss, data term and SSIM (the Gaussians).
    All,
    /// The loss alone, which is its data term (the neural fields: mean squared error).
    Loss,
    /// No loss: the SSIM and PSNR of the fit to the training views (FDK).
    Fit,
}

/// What one iteration did.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    pub iteration: usize,
    /// The training view (of a Gaussian or field iteration; 0 for FDK).
    pub view: usize,
    pub loss: LossValue,
    /// Which of `loss`'s terms are computed.
    pub terms: Terms,
    /// Training PSNR of the iteration (dB).
    pub psnr: f64,
    /// Learning rate of the iteration (the Gaussians: of the means' group).
    pub lr: f64,
    /// Gaussians after the iteration (0 for the other methods).
    pub n_gaussians: usize,
    /// The test evaluation at this iteration, if any.
    pub eval: Option<StepEval>,
    /// Clone / split / prune at this iteration, if any.
    pub densified: Option<DensifyReport>,
}

/// The test evaluation of an iteration: of the model before that iteration's densification
/// and update (at the last iteration, the model that is saved).
#[derive(Clone, Debug, PartialEq)]
pub struct StepEval {
    pub result: EvalResult,
    /// Gaussians of the evaluated model.
    pub n_gaussians: usize,
    /// Wall time of the evaluation alone (rendering and scoring the test views), seconds.
    pub seconds: f64,
}

impl Step {
    /// The `log.csv` row of the step ([`crate::train::run_dir::LOG_HEADER`]) at `seconds` of
    /// training, with its newline.
    pub fn log_row(&self, seconds: f64) -> String {
        let (it, view, l) = (self.iteration, self.view, &self.loss);
        match self.terms {
            Terms::All => format!(
                "{it},{view},{:.9e},{:.9e},{:.9e},{:.6},{},{seconds:.3}\n",
                l.total, l.data, l.ssim, self.psnr, self.n_gaussians
            ),
            Terms::Loss => format!(
                "{it},{view},{:.9e},{:.9e},0,{:.6},0,{seconds:.3}\n",
                l.total, l.data, self.psnr
            ),
            Terms::Fit => format!(
                "{it},{view},0,0,{:.9e},{:.6},0,{seconds:.3}\n",
                l.ssim, self.psnr
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(terms: Terms) -> Step {
        Step {
            iteration: 3,
            view: 1,
            loss: LossValue {
                total: 0.25,
                data: 0.125,
                ssim: 0.5,
            },
            terms,
            psnr: 12.5,
            lr: 1e-3,
            n_gaussians: 7,
            eval: None,
            densified: None,
        }
    }

    #[test]
    fn log_rows_print_only_the_computed_terms() {
        assert_eq!(
            step(Terms::All).log_row(1.5),
            "3,1,2.500000000e-1,1.250000000e-1,5.000000000e-1,12.500000,7,1.500\n"
        );
        assert_eq!(
            step(Terms::Loss).log_row(1.5),
            "3,1,2.500000000e-1,1.250000000e-1,0,12.500000,0,1.500\n"
        );
        assert_eq!(
            step(Terms::Fit).log_row(1.5),
            "3,1,0,0,5.000000000e-1,12.500000,0,1.500\n"
        );
    }
}
