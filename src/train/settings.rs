//! The settings of `unispine train`, each declared once in the `settings!` table below: the
//! `config.json` field it lives in, its allowed range (checked by [`TrainConfig::validate`] on
//! every config: preset, `--config FILE` and flags alike) and the command-line flag that
//! overrides it, with its help. The table generates [`TrainOverrides`] and its flags (a
//! [`FlagSet`]: what the command line and reproduction plans parse), [`TrainOverrides::apply`]
//! and the range checks, so the flags, the saved config and the validation cannot drift apart.
//!
//! A row reads
//!
//! ```text
//! "loss.lambda_dssim"                                  // field, as validation errors name it
//!     range(|c| c.loss.lambda_dssim, ge_le(0.0, 1.0))  // allowed range of the value
//!     flag(
//!         /// Weight of D-SSIM in Eq. (8).             // --help text
//!         lambda_dssim: f64                            // flag --lambda-dssim and its type
//!         => |c, v| c.loss.lambda_dssim = v            // how the flag sets the config
//!     );
//! ```
//!
//! `range(get, r)` checks a number (integers as `f64`), `range_if(get, r)` one that may be
//! absent (`get` returns an `Option<f64>`: off, or a disabled section); `r` is one of
//! [`ge_le`], [`ge_lt`], [`gt_le`], [`gt_lt`] (`ge` = closed, `gt` = open end, bounds may be
//! infinite). Either part may be left out: a setting without a flag is still validated, a flag
//! without a range takes any value its type can hold. The flag's type parses its text
//! ([`FlagValue`]: numbers, `true` / `false`, comma-separated lists, named [`crate::flags::Choice`]s).
//!
//! Adding a setting: give it a field (with a `#[serde(default)]` that keeps old `config.json`
//! files loading with the old behaviour) in [`TrainConfig`] or the stage config it belongs to,
//! its value in [`TrainConfig::preset`], and one row here. Preset semantics: the preset (or
//! `--config FILE`) gives every value, `--iters` and `--compress-schedule` act next, then each
//! flag given replaces its one field, then the whole config is validated.
//!
//! Over 600 lines with its tests (the table and its macro are about 480): the tests check
//! every row's flag, field and range.

use std::path::PathBuf;

use super::compact::CompactConfig;
use super::config::{Method, TrainConfig};
use crate::error::{Error, Result};
use crate::flags::{Flag, FlagSet, FlagValue};
use crate::gaussians::init::{InitKind, MAX_INIT_POINTS};
use crate::loss::DataTerm;
use crate::render::ColorMode;

/// Upper bound on `iterations` (50 x the paper's schedule).
pub const MAX_ITERATIONS: usize = 1_000_000;

/// An allowed interval `lo..hi`, each end closed or open.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    pub lo: f64,
    pub lo_open: bool,
    pub hi: f64,
    pub hi_open: bool,
}

/// `[lo, hi]`.
pub const fn ge_le(lo: f64, hi: f64) -> Interval {
    Interval {
        lo,
        lo_open: false,
        hi,
        hi_open: false,
    }
}

/// `[lo, hi)`.
pub const fn ge_lt(lo: f64, hi: f64) -> Interval {
    Interval {
        lo,
        lo_open: false,
        hi,
        hi_open: true,
    }
}

/// `(lo, hi]`.
pub const fn gt_le(lo: f64, hi: f64) -> Interval {
    Interval {
        lo,
        lo_open: true,
        hi,
        hi_open: false,
    }
}

/// `(lo, hi)`.
pub const fn gt_lt(lo: f64, hi: f64) -> Interval {
    Interval {
        lo,
        lo_open: true,
        hi,
        hi_open: true,
    }
}

const INF: f64 = f64::INFINITY;

/// Error unless `v` is finite and inside `r`; the message names the field and the interval.
fn check_range(field: &str, v: f64, r: Interval) -> Result<()> {
    let above = if r.lo_open { v > r.lo } else { v >= r.lo };
    let below = if r.hi_open { v < r.hi } else { v <= r.hi };
    if v.is_finite() && above && below {
        return Ok(());
    }
    let end = |x: f64| {
        if x.is_infinite() {
            if x > 0.0 {
                "inf".to_string()
            } else {
                "-inf".to_string()
            }
        } else {
            format!("{x}")
        }
    };
    Err(Error::invalid(
        field,
        format!(
            "must be a finite number in {}{}, {}{}, got {v}",
            if r.lo_open { "(" } else { "[" },
            end(r.lo),
            end(r.hi),
            if r.hi_open { ")" } else { "]" }
        ),
    ))
}

/// Generates [`TrainOverrides`], [`TrainOverrides::apply`]'s flag part and [`check_ranges`]
/// from one table; see the module documentation for the row syntax.
macro_rules! settings {
    ($(
        $field:literal
        $(range($get:expr, $range:expr))?
        $(range_if($get_opt:expr, $range_opt:expr))?
        $(flag($(#[doc = $doc:literal])* $name:ident : $ty:ty => |$c:ident, $v:ident| $set:expr))?
        ;
    )*) => {
        /// Command-line overrides of a preset (each flag replaces one field; see
        /// [`crate::train::settings`]); their flags are [`FlagSet::flags`].
        #[derive(Clone, Debug, Default)]
        pub struct TrainOverrides {
            /// Start from this config JSON (e.g. a run's `config.json`) instead of the preset.
            pub config: Option<PathBuf>,
            $($(
                $(#[doc = $doc])*
                pub $name: Option<$ty>,
            )?)*
            /// Scale every schedule (lr, densification, resets, feature steps, SPWM warm-up, eval
            /// points) from 20000 iterations to --iters.
            pub compress_schedule: bool,
        }

        impl FlagSet for TrainOverrides {
            const GROUP: &'static str = "TrainOverrides";

            fn flags() -> Vec<Flag> {
                let mut v = vec![Flag::value::<PathBuf>(
                    "config",
                    "Start from this config JSON (e.g. a run's `config.json`) instead of the \
                     preset.",
                )];
                $($(
                    v.push(Flag::value::<$ty>(stringify!($name), concat!($($doc),*)));
                )?)*
                v.push(Flag::switch(
                    "compress_schedule",
                    "Scale every schedule (lr, densification, resets, feature steps, SPWM \
                     warm-up, eval points) from 20000 iterations to --iters.",
                ));
                v
            }

            fn set(&mut self, long: &str, value: Option<&str>) -> std::result::Result<(), String> {
                let long = long.replace('-', "_");
                let text = value.unwrap_or_default();
                if long == "config" {
                    self.config = Some(PathBuf::parse_flag(text)?);
                    return Ok(());
                }
                $($(
                    if long == stringify!($name) {
                        self.$name = Some(<$ty as FlagValue>::parse_flag(text)?);
                        return Ok(());
                    }
                )?)*
                if long == "compress_schedule" {
                    self.compress_schedule = true;
                    return Ok(());
                }
                Err(format!("unknown flag `--{}`", long.replace('_', "-")))
            }
        }

        impl TrainOverrides {
            /// The flags given, as `--name`, in declaration order.
            pub fn given(&self) -> Vec<String> {
                let mut v = Vec::new();
                if self.config.is_some() {
                    v.push("--config".to_string());
                }
                $($(
                    if self.$name.is_some() {
                        v.push(format!("--{}", stringify!($name).replace('_', "-")));
                    }
                )?)*
                if self.compress_schedule {
                    v.push("--compress-schedule".to_string());
                }
                v
            }

            /// Replace the field of every flag given.
            fn set_flags(&self, cfg: &mut TrainConfig) {
                $($(
                    if let Some($v) = self.$name.clone() {
                        let $c = &mut *cfg;
                        $set;
                    }
                )?)*
            }
        }

        /// Check every declared range (in table order); the error names the field and its
        /// allowed range.
        pub(crate) fn check_ranges(c: &TrainConfig) -> Result<()> {
            $(
                $({
                    let get: fn(&TrainConfig) -> f64 = $get;
                    check_range($field, get(c), $range)?;
                })?
                $({
                    let get: fn(&TrainConfig) -> Option<f64> = $get_opt;
                    if let Some(v) = get(c) {
                        check_range($field, v, $range_opt)?;
                    }
                })?
            )*
            Ok(())
        }

        /// The `config.json` field of every row of the table.
        pub fn declared_fields() -> Vec<&'static str> {
            vec![$($field),*]
        }

        /// Every row with a range: its field and allowed interval, in table order (tests check
        /// their own table of expected intervals against it, endpoint by endpoint).
        pub fn declared_ranges() -> Vec<(&'static str, Interval)> {
            vec![$(
                $(($field, $range),)?
                $(($field, $range_opt),)?
            )*]
        }
    };
}

settings! {
    "iterations" range(|c| c.iterations as f64, ge_le(1.0, MAX_ITERATIONS as f64));
    "schedule_iterations"
        range(|c| c.schedule_iterations as f64, ge_le(1.0, MAX_ITERATIONS as f64));
    "seed" flag(
        /// Seed of the view order, random init and split samples.
        seed: u64 => |c, v| c.seed = v
    );
    "color" flag(
        /// Intensity model: rirf-paper, rirf-xgaussian or sh.
        color: ColorMode => |c, v| c.color = v
    );
    "init.kind" flag(
        /// Initialisation: acui, random, unit-cube or fdk.
        init: InitKind => |c, v| c.init.kind = v
    );
    "init.points" range(|c| c.init.points as f64, ge_le(1.0, MAX_INIT_POINTS as f64)) flag(
        /// Points of the unit-cube and fdk initialisers (upstream unit cube: 100000).
        init_points: usize => |c, v| c.init.points = v
    );
    "init.fdk_threshold" range(|c| c.init.fdk_threshold, gt_lt(0.0, 1.0)) flag(
        /// fdk initialiser: voxels above this fraction of the FDK volume's maximum (0.1).
        fdk_threshold: f64 => |c, v| c.init.fdk_threshold = v
    );
    "init.interval" range(|c| c.init.interval as f64, ge_lt(1.0, INF)) flag(
        /// ACUI grid step in voxels.
        acui_interval: usize => |c, v| c.init.interval = v
    );
    "init.opacity" range(|c| c.init.opacity, gt_lt(0.0, 1.0));
    "init.intensity" range(|c| c.init.intensity, gt_lt(-INF, INF)) flag(
        /// Initial intensity of every Gaussian (upstream's uint8 round trip gives 127/255).
        init_intensity: f64 => |c, v| c.init.intensity = v
    );
    "loss.data_term" flag(
        /// Data term: l1, charbonnier or weighted-charbonnier.
        data_term: DataTerm => |c, v| c.loss.data_term = v
    );
    "loss.lambda_dssim" range(|c| c.loss.lambda_dssim, ge_le(0.0, 1.0)) flag(
        /// Weight of D-SSIM in Eq. (8).
        lambda_dssim: f64 => |c, v| c.loss.lambda_dssim = v
    );
    "loss.charbonnier_eps" range(|c| c.loss.charbonnier_eps, gt_le(0.0, 1.0));
    "loss.delta" range(|c| c.loss.delta, gt_le(0.0, 1.0));
    "spwm" flag(
        /// SPWM weights on (true) or off (false).
        spwm: bool => |c, on| c.spwm = if on { Some(c.spwm.clone().unwrap_or_default()) } else { None }
    );
    "spwm.alpha" range_if(|c| c.spwm.as_ref().map(|w| w.alpha), ge_le(0.0, 1.0));
    "spwm.hf_lambda" range_if(|c| c.spwm.as_ref().map(|w| w.hf_lambda), ge_lt(0.0, INF));
    "spwm.blur_sigma" range_if(|c| c.spwm.as_ref().map(|w| w.blur_sigma), gt_le(0.0, 1e3));
    "spwm.blur_kernel"
        range_if(|c| c.spwm.as_ref().map(|w| w.blur_kernel as f64), ge_le(1.0, 1001.0));
    "spwm.quantile" range_if(|c| c.spwm.as_ref().map(|w| w.quantile), ge_le(0.0, 1.0));
    "spwm.tau_max" range_if(|c| c.spwm.as_ref().map(|w| w.tau_max), ge_le(0.0, 1.0));
    "spwm.fixed_tau" range_if(|c| c.spwm.as_ref().map(|w| w.fixed_tau), ge_le(0.0, 1.0));
    "spwm.gate_temperature"
        range_if(|c| c.spwm.as_ref().map(|w| w.gate_temperature), gt_lt(0.0, INF));
    "spwm_time_scale" range(|c| c.spwm_time_scale, gt_le(0.0, 1e9));
    "densify.max_gaussians"
        range_if(|c| c.densify.max_gaussians.map(|m| m as f64), ge_lt(1.0, INF))
        flag(
            /// Upper bound on the number of Gaussians (off by default).
            max_gaussians: usize => |c, v| c.densify.max_gaussians = Some(v)
        );
    "densify.grad_threshold" range(|c| c.densify.grad_threshold, ge_lt(0.0, INF)) flag(
        /// Densification threshold on the mean NDC gradient norm.
        grad_threshold: f64 => |c, v| c.densify.grad_threshold = v
    );
    "densify.from_iter" flag(
        /// Densify after this iteration.
        densify_from: usize => |c, v| c.densify.from_iter = v
    );
    "densify.until_iter" flag(
        /// Densify before this iteration.
        densify_until: usize => |c, v| c.densify.until_iter = v
    );
    "densify.interval" flag(
        /// Densify every this many iterations.
        densify_interval: usize => |c, v| c.densify.interval = v
    );
    "densify.upstream_radii_reset" flag(
        /// Reproduce upstream's radius reset before the screen-size prune (true/false).
        upstream_radii_reset: bool => |c, v| c.densify.upstream_radii_reset = v
    );
    "densify.percent_dense" range(|c| c.densify.percent_dense, ge_le(0.0, 1.0));
    "densify.min_opacity" range(|c| c.densify.min_opacity, ge_lt(0.0, 1.0));
    "densify.max_screen_px" range(|c| c.densify.max_screen_px, gt_lt(0.0, INF));
    "densify.max_world_frac" range(|c| c.densify.max_world_frac, gt_lt(0.0, INF));
    "densify.reset_opacity_to" range(|c| c.densify.reset_opacity_to, gt_lt(0.0, 1.0));
    "densify.split_scale_div" range(|c| c.densify.split_scale_div, ge_lt(1.0, INF));
    // Learning rates: a step of the full scene extent per iteration is the most that can make
    // sense (upstream 1.6e-4 to 1.9e-4).
    "lr.position_init" range(|c| c.lr.position_init, gt_le(0.0, 1.0)) flag(
        /// Position learning rate at the start (times the extent).
        position_lr_init: f64 => |c, v| c.lr.position_init = v
    );
    "lr.position_final" range(|c| c.lr.position_final, gt_le(0.0, 1.0)) flag(
        /// Position learning rate at the end (times the extent).
        position_lr_final: f64 => |c, v| c.lr.position_final = v
    );
    "lr.position_delay_mult" range(|c| c.lr.position_delay_mult, gt_le(0.0, 1.0));
    "lr.feature" range(|c| c.lr.feature, gt_le(0.0, 1.0));
    "lr.feature_rest_div" range(|c| c.lr.feature_rest_div, gt_le(0.0, 1e6));
    "lr.opacity" range(|c| c.lr.opacity, gt_le(0.0, 1.0));
    "lr.scaling" range(|c| c.lr.scaling, gt_le(0.0, 1.0));
    "lr.rotation" range(|c| c.lr.rotation, gt_le(0.0, 1.0));
    // beta = 1 never updates the moments and divides by 1 - beta^t = 0; eps = 0 divides by
    // zero where a gradient is zero.
    "adam.beta1" range(|c| c.adam.beta1, ge_lt(0.0, 1.0));
    "adam.beta2" range(|c| c.adam.beta2, ge_lt(0.0, 1.0));
    "adam.eps" range(|c| c.adam.eps, gt_le(0.0, 1.0));
    "background" range(|c| c.background, gt_lt(-INF, INF));
    "eval_iterations" flag(
        /// Evaluate on the test views at these iterations (comma-separated).
        eval_iterations: Vec<usize> => |c, v| c.eval_iterations = v
    );
    "train_views" range_if(|c| c.train_views.map(|v| v as f64), ge_lt(1.0, INF)) flag(
        /// Use only the first N training views (upstream 50).
        train_views: usize => |c, v| c.train_views = Some(v)
    );
    "checkpoint_every" flag(
        /// Checkpoint every N iterations (0: only at the end).
        checkpoint_every: usize => |c, v| c.checkpoint_every = v
    );
    "preview_views" flag(
        /// Number of test views saved as PNG beside the ground truth.
        preview_views: usize => |c, v| c.preview_views = v
    );
    // Compaction (see `super::compact`): keep and to replace the config's pair (giving both is
    // refused in `apply`); the section's own checks run in `CompactConfig::validate`.
    "compact.keep" flag(
        /// Compaction: keep this fraction (0, 1] of the Gaussians, ranked by their alpha*T over
        /// the training views.
        compact_keep: f64 => |c, v| {
            let k = c.compact.get_or_insert_with(CompactConfig::default);
            k.keep = Some(v);
            k.to = None;
        }
    );
    "compact.to" flag(
        /// Compaction: keep at most this many Gaussians (a budget >= 1).
        compact_to: usize => |c, v| {
            let k = c.compact.get_or_insert_with(CompactConfig::default);
            k.to = Some(v);
            k.keep = None;
        }
    );
    "compact.at" flag(
        /// Compaction: replace the update of this iteration (default: the last of --iters).
        compact_at: usize => |c, v| c.compact.get_or_insert_with(CompactConfig::default).at = Some(v)
    );
    "compact.finetune" flag(
        /// Compaction: fine-tune this many iterations after --iters, without densification.
        compact_finetune: usize => |c, v| {
            c.compact.get_or_insert_with(CompactConfig::default).finetune = v
        }
    );
}

impl TrainOverrides {
    /// The config for `method` and `iterations` with these overrides applied, validated.
    pub fn apply(&self, method: Method, iterations: Option<usize>) -> Result<TrainConfig> {
        let mut c = match &self.config {
            Some(p) => TrainConfig::load(p)?,
            None => TrainConfig::preset(method),
        };
        if let Some(n) = iterations {
            c.iterations = n;
        }
        if self.compress_schedule {
            if c.schedule_compressed {
                return Err(Error::invalid(
                    "--compress-schedule",
                    "the config's schedule is already compressed (it comes from a run made with \
                     --compress-schedule); compressing it again would shrink every phase twice: \
                     drop --compress-schedule, or start from the preset",
                ));
            }
            c.compress_schedule();
        }
        self.check_compact_flags(&c)?;
        self.set_flags(&mut c);
        c.validate()?;
        Ok(c)
    }

    /// Range-check the flags given on `method`'s preset: what a reproduction plan can check
    /// before any cell runs (the error names the field, its range and the value).
    pub fn check_on_preset(&self, method: Method) -> Result<()> {
        let mut c = TrainConfig::preset(method);
        self.set_flags(&mut c);
        check_ranges(&c)
    }

    /// `--compact-keep` and `--compact-to` exclude each other; `--compact-at` and
    /// `--compact-finetune` need a compaction, from a size flag or the config.
    fn check_compact_flags(&self, c: &TrainConfig) -> Result<()> {
        if self.compact_keep.is_some() && self.compact_to.is_some() {
            return Err(Error::invalid(
                "--compact-keep / --compact-to (compact.keep, compact.to)",
                "give one of the two: a fraction to keep or a Gaussian budget",
            ));
        }
        let size = self.compact_keep.is_some() || self.compact_to.is_some();
        if !size && c.compact.is_none() {
            for (flag, given) in [
                ("--compact-at", self.compact_at.is_some()),
                ("--compact-finetune", self.compact_finetune.is_some()),
            ] {
                if given {
                    return Err(Error::invalid(
                        flag,
                        "needs a compaction: give --compact-keep FRACTION or --compact-to N",
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_field_is_declared_once() {
        let d = declared_fields();
        let mut fields = d.clone();
        fields.sort_unstable();
        let n = fields.len();
        fields.dedup();
        assert_eq!(fields.len(), n, "a field declared twice");
        // Every declared field is a real config.json path.
        // (with every optional section present and the settings left out of the JSON at their
        // default set otherwise, so their fields are in the JSON)
        let mut c = TrainConfig::preset(Method::Unispine);
        c.init.points = 7;
        c.init.fdk_threshold = 0.3;
        c.schedule_iterations = 30_000;
        c.compact = Some(CompactConfig {
            keep: Some(0.5),
            to: Some(1),
            at: Some(1),
            finetune: 1,
        });
        let v = serde_json::to_value(c).unwrap();
        for field in &d {
            let mut at = &v;
            for part in field.split('.') {
                at = at
                    .get(part)
                    .unwrap_or_else(|| panic!("{field} is not a config.json field"));
            }
        }
    }

    #[test]
    fn the_flags_keep_their_names() {
        let flags = TrainOverrides::flags();
        let longs: Vec<&str> = flags.iter().map(|f| f.long.as_str()).collect();
        assert_eq!(
            longs,
            [
                "config",
                "seed",
                "color",
                "init",
                "init-points",
                "fdk-threshold",
                "acui-interval",
                "init-intensity",
                "data-term",
                "lambda-dssim",
                "spwm",
                "max-gaussians",
                "grad-threshold",
                "densify-from",
                "densify-until",
                "densify-interval",
                "upstream-radii-reset",
                "position-lr-init",
                "position-lr-final",
                "eval-iterations",
                "train-views",
                "checkpoint-every",
                "preview-views",
                "compact-keep",
                "compact-to",
                "compact-at",
                "compact-finetune",
                "compress-schedule",
            ]
        );
    }

    #[test]
    fn each_flag_sets_its_field() {
        let argv = [
            "--seed",
            "7",
            "--color",
            "sh",
            "--init",
            "random",
            "--acui-interval",
            "3",
            "--init-intensity",
            "0.25",
            "--data-term",
            "l1",
            "--lambda-dssim",
            "0.5",
            "--spwm",
            "false",
            "--max-gaussians",
            "99",
            "--grad-threshold",
            "0.001",
            "--densify-from",
            "11",
            "--densify-until",
            "12",
            "--densify-interval",
            "13",
            "--upstream-radii-reset",
            "true",
            "--position-lr-init",
            "0.5",
            "--position-lr-final",
            "0.25",
            "--eval-iterations",
            "4,5",
            "--train-views",
            "6",
            "--checkpoint-every",
            "8",
            "--preview-views",
            "9",
        ];
        let argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
        let o: TrainOverrides = crate::flags::parse_set(&argv).unwrap();
        let c = o.apply(Method::Unispine, Some(100)).unwrap();
        let mut want = TrainConfig::preset(Method::Unispine);
        want.iterations = 100;
        want.seed = 7;
        want.color = ColorMode::Sh;
        want.init.kind = InitKind::Random;
        want.init.interval = 3;
        want.init.intensity = 0.25;
        want.loss.data_term = DataTerm::L1;
        want.loss.lambda_dssim = 0.5;
        want.spwm = None;
        want.densify.max_gaussians = Some(99);
        want.densify.grad_threshold = 0.001;
        want.densify.from_iter = 11;
        want.densify.until_iter = 12;
        want.densify.interval = 13;
        want.densify.upstream_radii_reset = true;
        want.lr.position_init = 0.5;
        want.lr.position_final = 0.25;
        want.eval_iterations = vec![4, 5];
        want.train_views = Some(6);
        want.checkpoint_every = 8;
        want.preview_views = 9;
        assert_eq!(c, want);
        // A flag is validated like the config field it sets.
        let argv = ["--lambda-dssim".to_string(), "2".to_string()];
        let e = crate::flags::parse_set::<TrainOverrides>(&argv)
            .unwrap()
            .apply(Method::Unispine, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("loss.lambda_dssim") && e.contains("[0, 1]"),
            "{e}"
        );
    }

    #[test]
    fn a_compressed_config_is_not_compressed_twice() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = TrainConfig::preset(Method::Unispine);
        c.iterations = 2000;
        c.compress_schedule();
        let p = dir.path().join("config.json");
        c.save(&p).unwrap();
        let o = TrainOverrides {
            config: Some(p.clone()),
            ..Default::default()
        };
        assert_eq!(o.apply(Method::Unispine, None).unwrap(), c);
        let o = TrainOverrides {
            config: Some(p),
            compress_schedule: true,
            ..Default::default()
        };
        let e = o.apply(Method::Unispine, None).unwrap_err().to_string();
        assert!(e.contains("already compressed"), "{e}");
    }
}
