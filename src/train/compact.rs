//! Compaction (not in the paper): prune the Gaussians that contribute least to the training
//! views, then fine-tune briefly without densification.
//!
//! **Importance score** (LightGaussian's "global significance", Fan et al. 2023, Eq. (3), code
//! `VITA-Group/LightGaussian` `prune.py` `prune_list`): for Gaussian i, the sum over every pixel
//! p of every training view of its blending weight in Eqs. (4)-(5),
//!
//! `score_i = sum_views sum_p alpha_i(p) T_i(p)`,
//!
//! with alpha and T exactly as our compositor defines them ([`crate::render::composite`]:
//! alpha = min(0.99, o G), splats with alpha < 1/255 skipped, the exclusive T < 1e-4 stop, the
//! 16x16 tile lists). Two differences from LightGaussian, both deliberate: (a) no volume factor
//! (their `calculate_v_imp_score` multiplies by (V / V_90%)^0.1 for the `v_important_score`
//! variant; we rank by the blending weight alone); (b) LightGaussian's pinned rasterizer
//! (`compress-diff-gaussian-rasterization`, `forward.cu` `renderCUDA_count`) accumulates the
//! opacity o_i per blended pixel, not alpha_i T_i (a later rasterizer commit multiplies by T);
//! we use the paper's alpha T.
//!
//! **Computation.** The blending weight is the colour cotangent of Eq. (5): with a unit image
//! gradient dL/dC(p) = 1, the compositor's backward gives dL/dc_i = sum_p alpha_i(p) T_i(p).
//! [`importance`] therefore renders each training view (forward) and runs the compositor's
//! backward with an image of ones: per tile, then reduced in tile order
//! ([`crate::render::composite::backward`]), so the score is bit-identical for any thread count
//! and every SIMD path. Views are summed in view order in f64.
//!
//! **Pruning** keeps the `target` Gaussians with the largest score; ties are broken by index
//! (the lower index is kept), so the Gaussians removed are exactly the lowest-ranked ones in a
//! fixed order ([`keep_indices`]). The kept Gaussians stay in their original order and keep
//! their Adam moments ([`crate::densify::TrainState::remap`]).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::gaussians::Gaussians;
use crate::geometry::Camera;
use crate::image2d::Image2d;
use crate::real::Real;
use crate::render::{self, composite, RenderSettings};
use crate::simd::Simd;

/// Compaction settings (`train --compact-keep / --compact-to / --compact-at /
/// --compact-finetune`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompactConfig {
    /// Keep this fraction of the Gaussians, in (0, 1] (rounded up, at least 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep: Option<f64>,
    /// Keep at most this many Gaussians (a budget, >= 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to: Option<usize>,
    /// Compact at this iteration, in [1, iterations] (default: the last training iteration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<usize>,
    /// Fine-tuning iterations after the main schedule (no densification after the compaction).
    #[serde(default)]
    pub finetune: usize,
}

impl CompactConfig {
    /// The iteration whose update the compaction replaces.
    pub fn at_iteration(&self, iterations: usize) -> usize {
        self.at.unwrap_or(iterations)
    }

    /// Gaussians kept out of `n`.
    pub fn target(&self, n: usize) -> usize {
        let t = match (self.keep, self.to) {
            (Some(f), _) => (f * n as f64).ceil() as usize,
            (None, Some(k)) => k,
            (None, None) => n,
        };
        t.clamp(1.min(n), n)
    }

    /// Error (naming the flag and its allowed range) unless exactly one of `keep` / `to` is
    /// set, `keep` is in (0, 1], `to` >= 1 and `at` in [1, `iterations`].
    pub fn validate(&self, iterations: usize) -> Result<()> {
        match (self.keep, self.to) {
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    "--compact-keep / --compact-to (compact.keep, compact.to)",
                    "give one of the two: a fraction to keep or a Gaussian budget",
                ))
            }
            (None, None) => {
                return Err(Error::invalid(
                    "--compact-keep / --compact-to (compact.keep, compact.to)",
                    "compaction needs a fraction to keep (--compact-keep) or a budget \
                     (--compact-to)",
                ))
            }
            (Some(f), None) =>
            {
                #[allow(clippy::neg_cmp_op_on_partial_ord)]
                if !(f > 0.0 && f <= 1.0) {
                    return Err(Error::invalid(
                        "--compact-keep (compact.keep)",
                        format!("must be a fraction in (0, 1], got {f}"),
                    ));
                }
            }
            (None, Some(k)) => {
                if k == 0 {
                    return Err(Error::invalid(
                        "--compact-to (compact.to)",
                        "must be a Gaussian count >= 1, got 0",
                    ));
                }
            }
        }
        if let Some(a) = self.at {
            if a == 0 || a > iterations {
                return Err(Error::invalid(
                    "--compact-at (compact.at)",
                    format!("must be an iteration in [1, {iterations}] (--iters), got {a}"),
                ));
            }
        }
        if self.finetune > crate::train::settings::MAX_ITERATIONS {
            return Err(Error::invalid(
                "--compact-finetune (compact.finetune)",
                format!(
                    "must be in [0, {}], got {}",
                    crate::train::settings::MAX_ITERATIONS,
                    self.finetune
                ),
            ));
        }
        Ok(())
    }
}

/// What a compaction did (recorded in `metrics.json` and the checkpoint).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Compaction {
    /// The iteration whose update the compaction replaced.
    pub iteration: usize,
    /// Gaussians before and after pruning.
    pub n_before: usize,
    pub n_after: usize,
    /// Test PSNR / SSIM of the model before pruning (the model a run of `iteration`
    /// iterations saves).
    pub psnr_before: f64,
    pub ssim_before: f64,
    /// Test PSNR / SSIM right after pruning, before fine-tuning.
    pub psnr_pruned: f64,
    pub ssim_pruned: f64,
    /// The importance score used.
    pub score: String,
}

/// Name of the score recorded in [`Compaction::score`].
pub const SCORE_NAME: &str = "sum over training-view pixels of alpha*T (Eqs. 4-5; LightGaussian global significance without the volume factor)";

/// The importance of every Gaussian of `g` over the views `cams` (see the module doc):
/// sum over views (in order) and pixels of alpha_i T_i. Bit-identical for any thread count.
pub fn importance<R: Real>(
    g: &Gaussians<R>,
    cams: &[Camera],
    settings: &RenderSettings,
) -> Result<Vec<f64>> {
    importance_with(Simd::active(), g, cams, settings)
}

/// [`importance`] with the compositor's kernels compiled for `simd` (every path gives the
/// same bits).
pub fn importance_with<R: Real>(
    simd: Simd,
    g: &Gaussians<R>,
    cams: &[Camera],
    settings: &RenderSettings,
) -> Result<Vec<f64>> {
    let mut score = vec![0.0f64; g.len()];
    for cam in cams {
        let (splats, _) = render::project::forward(g, cam, settings)?;
        let bg = R::c(settings.background);
        let (_, saved) = composite::forward_with(simd, &splats, cam.width, cam.height, bg);
        let ones = Image2d::filled(cam.width, cam.height, R::one());
        // Eq. (5): d C / d c_i = sum_p alpha_i T_i, reduced per tile then in tile order.
        let d = composite::backward_with(simd, &splats, &saved, &ones);
        for (s, c) in score.iter_mut().zip(&d.color) {
            *s += c.f64();
        }
    }
    Ok(score)
}

/// Indices (ascending) of the `target` Gaussians with the largest `score`; ties keep the lower
/// index. A NaN score ranks below every number.
pub fn keep_indices(score: &[f64], target: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..score.len()).collect();
    let key = |i: usize| {
        if score[i].is_nan() {
            f64::NEG_INFINITY
        } else {
            score[i]
        }
    };
    order.sort_by(|&a, &b| key(b).total_cmp(&key(a)).then(a.cmp(&b)));
    order.truncate(target.min(score.len()));
    order.sort_unstable();
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keep_drops_the_lowest_with_lower_index_winning_ties() {
        let s = [3.0, 1.0, 2.0, 1.0, 5.0, 1.0];
        assert_eq!(keep_indices(&s, 3), vec![0, 2, 4]);
        // One of the three tied 1.0s survives: the lowest index.
        assert_eq!(keep_indices(&s, 4), vec![0, 1, 2, 4]);
        assert_eq!(keep_indices(&s, 5), vec![0, 1, 2, 3, 4]);
        assert_eq!(keep_indices(&s, 10), vec![0, 1, 2, 3, 4, 5]);
        assert_eq!(keep_indices(&[f64::NAN, 0.0], 1), vec![1]);
    }

    #[test]
    fn target_rounds_up_and_stays_in_range() {
        let c = |keep, to| CompactConfig {
            keep,
            to,
            at: None,
            finetune: 0,
        };
        assert_eq!(c(Some(0.5), None).target(7), 4);
        assert_eq!(c(Some(1e-9), None).target(7), 1);
        assert_eq!(c(Some(1.0), None).target(7), 7);
        assert_eq!(c(None, Some(3)).target(7), 3);
        assert_eq!(c(None, Some(30)).target(7), 7);
        assert_eq!(c(None, Some(3)).target(0), 0);
    }

    #[test]
    fn bad_settings_name_the_flag() {
        let c = |keep, to, at| CompactConfig {
            keep,
            to,
            at,
            finetune: 0,
        };
        let msg = |c: CompactConfig| c.validate(100).unwrap_err().to_string();
        for f in [0.0, -0.5, 1.5, f64::NAN] {
            assert!(
                msg(c(Some(f), None, None)).contains("--compact-keep"),
                "{f}"
            );
        }
        assert!(msg(c(None, Some(0), None)).contains("--compact-to"));
        assert!(msg(c(None, None, None)).contains("--compact-keep / --compact-to"));
        assert!(msg(c(Some(0.5), Some(3), None)).contains("--compact-keep / --compact-to"));
        assert!(msg(c(Some(0.5), None, Some(0))).contains("--compact-at"));
        assert!(msg(c(Some(0.5), None, Some(101))).contains("--compact-at"));
        assert!(c(Some(1.0), None, Some(100)).validate(100).is_ok());
        assert!(c(None, Some(1), Some(1)).validate(100).is_ok());
    }
}
