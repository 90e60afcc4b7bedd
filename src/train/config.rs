//! `TrainConfig`: every setting of a training run, as JSON (`config.json` of a run) and as
//! named method presets that command-line flags override one by one
//! ([`super::TrainOverrides`]).
//!
//! **Adding a setting** (each is declared once): a field here or in the stage config it belongs
//! to (`#[serde(default)]` so that old `config.json` files still load with the old behaviour),
//! its value in [`TrainConfig::preset`], and one row in the table of [`super::settings`], which
//! declares its allowed range and, if it has one, its `unispine train` flag and help; the flag
//! struct, the code that applies the flags and the validation are generated from that row.
//!
//! Defaults are the UniSpine-GS values (repository orangeisland66/UniSpine-GS, files
//! `config/example.yaml` and `arguments/__init__.py`); every preset but `3dgs-vanilla` shares
//! them and differs only in the intensity model, the initialisation and the loss:
//!
//! | preset | intensity | init | loss | schedule, densify threshold |
//! |---|---|---|---|---|
//! | `3dgs` | view-dependent SH colour | random in the box | (1 - 0.2) L1 + 0.2 D-SSIM | UniSpine-GS, 1.5e-4 |
//! | `xgaussian` | RIRF | ACUI | (1 - 0.2) L1 + 0.2 D-SSIM | UniSpine-GS, 1.5e-4 |
//! | `unispine` | RIRF | ACUI | (1 - 0.2) SPWM-weighted Charbonnier + 0.2 D-SSIM (Eqs. 6-9) | UniSpine-GS, 1.5e-4 |
//! | `spwm-only` | view-dependent SH colour | random in the box | as `unispine` | UniSpine-GS, 1.5e-4 |
//! | `3dgs-vanilla` | view-dependent SH colour | unit cube | (1 - 0.2) L1 + 0.2 D-SSIM | 3DGS's 30,000 iterations, 2e-4 (table and sources at `fn vanilla_3dgs` below) |
//!
//! The densification threshold (`densify.grad_threshold`, `--grad-threshold`, a plan key
//! `grad_threshold = ...` per variant) on the mean NDC gradient norm, in each upstream config:
//! graphdeco-inria/gaussian-splatting `arguments/__init__.py` 2e-4; caiyuanhao1998/X-Gaussian
//! `arguments/__init__.py` 2e-4 (its default) and 2.6e-5 in its medical configs (`config/
//! chest.yaml`, `pelvis.yaml`, ...); orangeisland66/UniSpine-GS `config/example.yaml` 1.5e-4
//! (the value used, our default) and 4e-5 as its `arguments/__init__.py` default.
//!
//! RIRF variant: X-Gaussian's code form `max(0, 0.5 + lambda . f)` (`rirf-xgaussian`) is the
//! training default. It is what the code that introduced the RIRF trains with, and the
//! learning rates of the table were tuned for it; the paper's `sigmoid(lambda . f)` is
//! `--color rirf-paper`. (UniSpine-GS's code at HEAD renders view-dependent SH, i.e. the
//! `3dgs` colour: its vendored
//! `submodules/diff-gaussian-rasterization/cuda_rasterizer/forward.cu` is the view-dependent
//! 3DGS SH rasterizer since commit `adf0330`.)

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::densify::DensifyConfig;
use crate::error::{Error, Result};
use crate::gaussians::init::{InitConfig, InitKind, DEFAULT_FDK_THRESHOLD, DEFAULT_INIT_POINTS};
use crate::loss::spwm::SpwmConfig;
use crate::loss::{DataTerm, LossConfig};
use crate::optim::schedule::ExponLr;
use crate::optim::{AdamConfig, GroupLr};
use crate::render::ColorMode;

/// The iteration count of the paper schedule (UniSpine-GS `iterations: 20000`).
pub const PAPER_ITERATIONS: usize = 20_000;

crate::choice! {
/// Named method presets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// 3D Gaussian splatting baseline: view-dependent SH colour, random init, L1 + D-SSIM.
    Gs3d = "3dgs",
    /// X-Gaussian: RIRF + ACUI, L1 + D-SSIM.
    Xgaussian = "xgaussian",
    /// UniSpine-GS: RIRF + ACUI + SPWM + weighted Charbonnier.
    Unispine = "unispine",
    /// SPWM + weighted Charbonnier without RIRF (SH colour) and without ACUI (random init).
    SpwmOnly = "spwm-only",
    /// Vanilla 3D Gaussian splatting as shipped: its 30,000-iteration defaults, SH colour, the
    /// unit-cube init, L1 + D-SSIM.
    Gs3dVanilla = "3dgs-vanilla",
}
}

/// Learning rates (UniSpine-GS config values).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LrConfig {
    /// Position lr at the start, times the scene extent (1.9e-4).
    pub position_init: f64,
    /// Position lr at `position_max_steps`, times the scene extent (1.9e-6).
    pub position_final: f64,
    /// `position_lr_delay_mult` (0.01; no effect while `position_delay_steps` = 0, as upstream).
    pub position_delay_mult: f64,
    /// `lr_delay_steps` (0 upstream).
    pub position_delay_steps: usize,
    /// `position_lr_max_steps` (20000).
    pub position_max_steps: usize,
    /// Feature 0 (`f_dc`) lr (0.002).
    pub feature: f64,
    /// Features 1..15 (`f_rest`) use `feature / feature_rest_div` (20).
    pub feature_rest_div: f64,
    /// Opacity (logit) lr (0.008).
    pub opacity: f64,
    /// Log-scale lr (0.005).
    pub scaling: f64,
    /// Quaternion lr (0.001).
    pub rotation: f64,
}

impl Default for LrConfig {
    fn default() -> Self {
        LrConfig {
            position_init: 1.9e-4,
            position_final: 1.9e-6,
            position_delay_mult: 0.01,
            position_delay_steps: 0,
            position_max_steps: 20_000,
            feature: 0.002,
            feature_rest_div: 20.0,
            opacity: 0.008,
            scaling: 0.005,
            rotation: 0.001,
        }
    }
}

impl LrConfig {
    /// The position schedule for a scene extent.
    pub fn position(&self, extent: f64) -> ExponLr {
        ExponLr {
            lr_init: self.position_init * extent,
            lr_final: self.position_final * extent,
            delay_steps: self.position_delay_steps,
            delay_mult: self.position_delay_mult,
            max_steps: self.position_max_steps,
        }
    }
    /// Per-group learning rates at iteration `it` (groups as [`crate::optim::Group`]).
    pub fn at(&self, it: usize, extent: f64) -> GroupLr {
        [
            self.position(extent).at(it),
            self.feature,
            self.feature / self.feature_rest_div,
            self.opacity,
            self.scaling,
            self.rotation,
        ]
    }
}

/// Every setting of a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Preset this config started from.
    pub method: Method,
    /// Dataset folder (informational; `unispine eval` reads it back).
    #[serde(default)]
    pub data: Option<String>,
    /// Training iterations (20000).
    pub iterations: usize,
    /// The iteration count the iteration-based schedules are written for (20000; 30000 for
    /// `3dgs-vanilla`): [`TrainConfig::compress_schedule`] scales them by `iterations /
    /// schedule_iterations`. Left out of the JSON at 20000, so configs written before the
    /// setting existed keep their fingerprint.
    #[serde(
        default = "paper_iterations",
        skip_serializing_if = "is_paper_iterations"
    )]
    pub schedule_iterations: usize,
    /// Seed of the view order, the random init and the split samples.
    pub seed: u64,
    /// Intensity model.
    pub color: ColorMode,
    /// Initialisation.
    pub init: InitConfig,
    /// Learning rates.
    pub lr: LrConfig,
    /// Adam constants.
    pub adam: AdamConfig,
    /// Densification and pruning.
    pub densify: DensifyConfig,
    /// One more band of features (1 -> 4 -> 9 -> 16) every this many iterations (1000).
    pub feature_step_interval: usize,
    /// Loss (Eq. 8).
    pub loss: LossConfig,
    /// SPWM (Eqs. 6-7); `None` = uniform weights.
    pub spwm: Option<SpwmConfig>,
    /// The SPWM warm-up sees iteration `t * spwm_time_scale` (1; set by `compress_schedule`).
    #[serde(default = "one")]
    pub spwm_time_scale: f64,
    /// True once [`TrainConfig::compress_schedule`] has scaled the schedules (a saved config
    /// of such a run must not be compressed again).
    #[serde(default)]
    pub schedule_compressed: bool,
    /// Test evaluation at these iterations (upstream [100, 2000, 20000]; the last iteration is
    /// always evaluated).
    pub eval_iterations: Vec<usize>,
    /// Background intensity (black, 0).
    pub background: f64,
    /// Use only the first `train_views` training views (upstream `train_num = 50`).
    pub train_views: Option<usize>,
    /// Number of test views written as PNG beside their ground truth.
    pub preview_views: usize,
    /// Write a checkpoint every this many iterations (0 = only at the end / on stop).
    pub checkpoint_every: usize,
    /// Compaction after the main schedule (not in the paper; off by default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compact: Option<super::compact::CompactConfig>,
}

fn one() -> f64 {
    1.0
}

fn paper_iterations() -> usize {
    PAPER_ITERATIONS
}

fn is_paper_iterations(n: &usize) -> bool {
    *n == PAPER_ITERATIONS
}

/// Vanilla 3D Gaussian splatting's iteration count (graphdeco-inria/gaussian-splatting
/// `arguments/__init__.py` `OptimizationParams.iterations`).
pub const VANILLA_ITERATIONS: usize = 30_000;

impl TrainConfig {
    /// The preset of `method` with its schedule (the paper's; 3DGS's for `3dgs-vanilla`).
    pub fn preset(method: Method) -> Self {
        if method == Method::Gs3dVanilla {
            return Self::vanilla_3dgs();
        }
        let (color, kind, data_term, spwm) = match method {
            Method::Gs3d | Method::Gs3dVanilla => {
                (ColorMode::Sh, InitKind::Random, DataTerm::L1, None)
            }
            Method::Xgaussian => (ColorMode::RirfXgaussian, InitKind::Acui, DataTerm::L1, None),
            Method::Unispine => (
                ColorMode::RirfXgaussian,
                InitKind::Acui,
                DataTerm::WeightedCharbonnier,
                Some(SpwmConfig::default()),
            ),
            Method::SpwmOnly => (
                ColorMode::Sh,
                InitKind::Random,
                DataTerm::WeightedCharbonnier,
                Some(SpwmConfig::default()),
            ),
        };
        TrainConfig {
            method,
            data: None,
            iterations: PAPER_ITERATIONS,
            schedule_iterations: PAPER_ITERATIONS,
            seed: 0,
            color,
            init: InitConfig {
                kind,
                interval: 8,
                opacity: 0.1,
                intensity: 0.5,
                points: DEFAULT_INIT_POINTS,
                fdk_threshold: DEFAULT_FDK_THRESHOLD,
            },
            lr: LrConfig::default(),
            adam: AdamConfig::default(),
            densify: DensifyConfig::default(),
            feature_step_interval: 1000,
            loss: LossConfig {
                data_term,
                lambda_dssim: 0.2,
                charbonnier_eps: 1e-3,
                delta: 1e-6,
            },
            spwm,
            spwm_time_scale: 1.0,
            schedule_compressed: false,
            eval_iterations: vec![100, 2000, 20_000],
            background: 0.0,
            train_views: Some(50),
            preview_views: 4,
            checkpoint_every: 1000,
            compact: None,
        }
    }

    /// `3dgs-vanilla`: graphdeco-inria/gaussian-splatting's defaults as shipped (file
    /// `arguments/__init__.py`, `OptimizationParams`, read at commit `82bc469`; `train.py` and
    /// `scene/gaussian_model.py` where named):
    ///
    /// | setting | value | upstream |
    /// |---|---|---|
    /// | iterations | 30,000 | `iterations = 30_000` |
    /// | position lr | 1.6e-4 -> 1.6e-6 x extent over 30,000 | `position_lr_init`, `_final`, `_max_steps` |
    /// | position lr delay mult | 0.01 (no effect, no delay steps) | `position_lr_delay_mult` |
    /// | feature lr (`f_dc`; `f_rest` / 20) | 0.0025 | `feature_lr`; `/ 20.0` in `gaussian_model.py` |
    /// | opacity lr | 0.05 | `opacity_lr` (0.025 in later versions of the file) |
    /// | scaling lr | 0.005 | `scaling_lr` |
    /// | rotation lr | 0.001 | `rotation_lr` |
    /// | percent dense | 0.01 | `percent_dense` |
    /// | lambda D-SSIM | 0.2 | `lambda_dssim` |
    /// | densify from / until / every | 500 / 15,000 / 100 | `densify_from_iter`, `densify_until_iter`, `densification_interval` |
    /// | densify gradient threshold | 2e-4 | `densify_grad_threshold` |
    /// | opacity reset | every 3,000 | `opacity_reset_interval` |
    /// | SH degree step | every 1,000 | `train.py`: `oneupSHdegree` at `iteration % 1000 == 0` |
    /// | test iterations | 7,000, 30,000 | `train.py` `--test_iterations` default |
    ///
    /// Colour: view-dependent SH (vanilla 3DGS has no other). Init: `unit-cube`, the one point
    /// cloud vanilla 3DGS makes without structure-from-motion points (its `scene/
    /// dataset_readers.py` `readNerfSyntheticInfo`: 100,000 points in [-1.3, 1.3)^3), which
    /// X-ray views cannot give (the scanner's cameras need no SfM, and SfM finds no points in
    /// transmission images); it is also the upstream X-Gaussian / UniSpine-GS code's only
    /// non-ACUI initialiser. Everything else (Adam, pruning, opacity reset value, split,
    /// background, evaluation) is shared with every preset and is 3DGS's already.
    fn vanilla_3dgs() -> Self {
        let mut c = Self::preset(Method::Gs3d);
        c.method = Method::Gs3dVanilla;
        c.init.kind = InitKind::UnitCube;
        c.iterations = VANILLA_ITERATIONS;
        c.schedule_iterations = VANILLA_ITERATIONS;
        c.lr = LrConfig {
            position_init: 1.6e-4,
            position_final: 1.6e-6,
            position_delay_mult: 0.01,
            position_delay_steps: 0,
            position_max_steps: 30_000,
            feature: 0.0025,
            feature_rest_div: 20.0,
            opacity: 0.05,
            scaling: 0.005,
            rotation: 0.001,
        };
        let d = &mut c.densify;
        d.from_iter = 500;
        d.until_iter = 15_000;
        d.interval = 100;
        d.grad_threshold = 2e-4;
        d.percent_dense = 0.01;
        d.opacity_reset_interval = 3000;
        c.feature_step_interval = 1000;
        c.loss.lambda_dssim = 0.2;
        c.eval_iterations = vec![7000, 30_000];
        c
    }

    /// Scale every iteration-based schedule (position lr, densification, opacity reset, feature
    /// steps, SPWM warm-up, evaluation points) from the `schedule_iterations` it is written for
    /// (the paper's 20000, or 30000 for `3dgs-vanilla`) to `self.iterations`, for short runs
    /// that still go through every phase. [`super::TrainOverrides::apply`] refuses a config
    /// already compressed (`schedule_compressed`).
    pub fn compress_schedule(&mut self) {
        self.schedule_compressed = true;
        let f = self.iterations as f64 / self.schedule_iterations.max(1) as f64;
        self.schedule_iterations = self.iterations;
        let s = |x: usize| ((x as f64 * f).round() as usize).max(1);
        let d = &mut self.densify;
        d.from_iter = s(d.from_iter);
        d.until_iter = s(d.until_iter);
        d.interval = s(d.interval);
        d.opacity_reset_interval = s(d.opacity_reset_interval);
        self.lr.position_max_steps = self.iterations.max(1);
        self.lr.position_delay_steps = (self.lr.position_delay_steps as f64 * f).round() as usize;
        self.feature_step_interval = s(self.feature_step_interval);
        self.spwm_time_scale = 1.0 / f.max(1e-12);
        self.eval_iterations = self.eval_iterations.iter().map(|&x| s(x)).collect();
        self.checkpoint_every = s(self.checkpoint_every);
    }

    /// Iterations of the whole run: `iterations`, plus the fine-tuning after a compaction.
    pub fn total_iterations(&self) -> usize {
        self.iterations + self.compact.as_ref().map_or(0, |c| c.finetune)
    }

    /// The iteration whose update a compaction replaces (`None`: no compaction).
    pub fn compact_at(&self) -> Option<usize> {
        self.compact
            .as_ref()
            .map(|c| c.at_iteration(self.iterations))
    }

    /// Evaluation iterations within the run, sorted, with the last iteration (and the
    /// compaction iteration) included.
    pub fn eval_points(&self) -> Vec<usize> {
        let total = self.total_iterations();
        let mut v: Vec<usize> = self
            .eval_iterations
            .iter()
            .cloned()
            .filter(|&x| x >= 1 && x <= total)
            .collect();
        v.extend(self.compact_at());
        v.push(total);
        v.sort_unstable();
        v.dedup();
        v
    }

    /// Whether the test views are evaluated after (1-based) iteration `it`: the same set as
    /// [`TrainConfig::eval_points`], without building it.
    pub fn is_eval_point(&self, it: usize) -> bool {
        let total = self.total_iterations();
        (1..=total).contains(&it)
            && (it == total || self.compact_at() == Some(it) || self.eval_iterations.contains(&it))
    }

    /// Number of active features at (1-based) iteration `it`: 1, then one more SH band at every
    /// multiple of `feature_step_interval` (upstream `oneupSHdegree` at `iteration % 1000 == 0`).
    pub fn active_features(&self, it: usize) -> usize {
        let steps = it
            .checked_div(self.feature_step_interval)
            .unwrap_or(0)
            .min(3);
        (steps + 1) * (steps + 1)
    }

    /// Check values a run cannot work with, before iteration 1; the error names the field and
    /// gives its allowed range (the ranges are declared with the flags in [`super::settings`]).
    pub fn validate(&self) -> Result<()> {
        super::settings::check_ranges(self)?;
        if let Some(c) = &self.compact {
            c.validate(self.iterations)?;
        }
        Ok(())
    }

    /// Read a config JSON.
    pub fn load(path: &Path) -> Result<Self> {
        let s = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        serde_json::from_str(&s).map_err(|e| Error::format(path, "config", e.to_string()))
    }

    /// Write as pretty JSON (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::fsio::write_json_atomic(path, self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_names_the_bad_field() {
        let mut c = TrainConfig::preset(Method::Unispine);
        assert!(c.validate().is_ok());
        c.background = f64::NAN;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("background"), "{e}");
        let mut c = TrainConfig::preset(Method::Unispine);
        c.lr.opacity = -1.0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("lr.opacity"), "{e}");
    }

    #[test]
    fn values_that_cannot_work_are_refused_with_their_range() {
        type Edit = fn(&mut TrainConfig);
        let cases: [(Edit, &str, &str); 7] = [
            (|c| c.lr.position_init = 1e30, "lr.position_init", "(0, 1]"),
            (|c| c.adam.beta1 = 1.0, "adam.beta1", "[0, 1)"),
            (|c| c.adam.eps = 0.0, "adam.eps", "(0, 1]"),
            (
                |c| c.densify.percent_dense = -0.01,
                "densify.percent_dense",
                "[0, 1]",
            ),
            (
                |c| c.spwm.as_mut().unwrap().quantile = 2.0,
                "spwm.quantile",
                "[0, 1]",
            ),
            (|c| c.iterations = 0, "iterations", "[1, 1000000]"),
            (
                |c| c.background = f64::INFINITY,
                "background",
                "(-inf, inf)",
            ),
        ];
        for (edit, field, range) in cases {
            let mut c = TrainConfig::preset(Method::Unispine);
            edit(&mut c);
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(field) && e.contains(range), "{e}");
        }
    }

    #[test]
    fn active_features_follow_one_up_sh_degree() {
        let c = TrainConfig::preset(Method::Unispine);
        let got: Vec<usize> = [1, 999, 1000, 1999, 2000, 3000, 20000]
            .iter()
            .map(|&i| c.active_features(i))
            .collect();
        assert_eq!(got, vec![1, 1, 4, 4, 9, 16, 16]);
    }

    #[test]
    fn vanilla_3dgs_is_graphdeco_defaults_as_shipped() {
        // graphdeco-inria/gaussian-splatting, arguments/__init__.py (OptimizationParams):
        //   iterations = 30_000, position_lr_init = 0.00016, position_lr_final = 0.0000016,
        //   position_lr_delay_mult = 0.01, position_lr_max_steps = 30_000, feature_lr = 0.0025,
        //   opacity_lr = 0.05, scaling_lr = 0.005, rotation_lr = 0.001, percent_dense = 0.01,
        //   lambda_dssim = 0.2, densification_interval = 100, opacity_reset_interval = 3000,
        //   densify_from_iter = 500, densify_until_iter = 15_000,
        //   densify_grad_threshold = 0.0002;
        // train.py: oneupSHdegree every 1000, --test_iterations 7_000 30_000;
        // gaussian_model.py: f_rest lr = feature_lr / 20.0.
        let c = TrainConfig::preset(Method::Gs3dVanilla);
        assert!(c.validate().is_ok());
        assert_eq!(c.method.name(), "3dgs-vanilla");
        assert_eq!(c.iterations, 30000);
        assert_eq!(c.schedule_iterations, 30000);
        assert_eq!(c.lr.position_init, 0.00016);
        assert_eq!(c.lr.position_final, 0.0000016);
        assert_eq!(c.lr.position_delay_mult, 0.01);
        assert_eq!(c.lr.position_delay_steps, 0);
        assert_eq!(c.lr.position_max_steps, 30000);
        assert_eq!(c.lr.feature, 0.0025);
        assert_eq!(c.lr.feature_rest_div, 20.0);
        assert_eq!(c.lr.opacity, 0.05);
        assert_eq!(c.lr.scaling, 0.005);
        assert_eq!(c.lr.rotation, 0.001);
        assert_eq!(c.densify.percent_dense, 0.01);
        assert_eq!(c.loss.lambda_dssim, 0.2);
        assert_eq!(c.densify.interval, 100);
        assert_eq!(c.densify.opacity_reset_interval, 3000);
        assert_eq!(c.densify.from_iter, 500);
        assert_eq!(c.densify.until_iter, 15000);
        assert_eq!(c.densify.grad_threshold, 0.0002);
        assert_eq!(c.feature_step_interval, 1000);
        assert_eq!(c.eval_iterations, vec![7000, 30000]);
        assert_eq!(c.color, ColorMode::Sh);
        assert_eq!(c.init.kind, InitKind::UnitCube);
        assert_eq!(c.init.points, 100_000);
        assert_eq!(c.loss.data_term, DataTerm::L1);
        assert!(c.spwm.is_none());
        // Round trip through config.json, with the schedule length kept.
        let back: TrainConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
    }

    #[test]
    fn compression_scales_each_preset_from_its_own_schedule() {
        // The same fraction of the run for a 20000- and a 30000-iteration preset.
        let mut u = TrainConfig::preset(Method::Unispine);
        u.iterations = 2000;
        u.compress_schedule();
        let mut v = TrainConfig::preset(Method::Gs3dVanilla);
        v.iterations = 3000;
        v.compress_schedule();
        // 3DGS: densify 500..15000 every 100, reset 3000, SH step 1000, eval 7000, 30000 -> / 10.
        assert_eq!(v.densify.from_iter, 50);
        assert_eq!(v.densify.until_iter, 1500);
        assert_eq!(v.densify.interval, 10);
        assert_eq!(v.densify.opacity_reset_interval, 300);
        assert_eq!(v.feature_step_interval, 100);
        assert_eq!(v.lr.position_max_steps, 3000);
        assert_eq!(v.eval_points(), vec![700, 3000]);
        assert!((v.spwm_time_scale - 10.0).abs() < 1e-12);
        assert_eq!(v.schedule_iterations, 3000);
        assert_eq!(u.feature_step_interval, v.feature_step_interval);
        // A 20000-iteration preset written before the field existed reads as 20000.
        let mut j = serde_json::to_value(TrainConfig::preset(Method::Gs3d)).unwrap();
        assert!(j.get("schedule_iterations").is_none());
        j.as_object_mut().unwrap().remove("schedule_iterations");
        let old: TrainConfig = serde_json::from_value(j).unwrap();
        assert_eq!(old.schedule_iterations, PAPER_ITERATIONS);
    }

    #[test]
    fn compressed_schedule_keeps_the_phases() {
        let mut c = TrainConfig::preset(Method::Unispine);
        c.iterations = 2000;
        c.compress_schedule();
        assert_eq!(c.densify.from_iter, 50);
        assert_eq!(c.densify.until_iter, 800);
        assert_eq!(c.densify.interval, 20);
        assert_eq!(c.densify.opacity_reset_interval, 400);
        assert_eq!(c.feature_step_interval, 100);
        assert_eq!(c.lr.position_max_steps, 2000);
        assert_eq!(c.eval_points(), vec![10, 200, 2000]);
        let marked: Vec<usize> = (0..=2001).filter(|&it| c.is_eval_point(it)).collect();
        assert_eq!(marked, c.eval_points());
        c.eval_iterations = vec![0, 5, 3000];
        let marked: Vec<usize> = (0..=3001).filter(|&it| c.is_eval_point(it)).collect();
        assert_eq!(marked, vec![5, 2000]);
        assert_eq!(marked, c.eval_points());
        assert!((c.spwm_time_scale - 10.0).abs() < 1e-12);
    }
}
