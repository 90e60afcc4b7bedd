//! Every range of the settings table at both endpoints: a table of expected intervals written
//! here, checked against the code's behaviour.

use unispine::train::settings::{declared_ranges, Interval};
use unispine::train::{Method, TrainConfig};

type Set = fn(&mut TrainConfig, f64);

/// Every ranged setting: field, how to set it, its allowed interval and whether it is an
/// integer (written from the documented meaning of each setting, not from the code's table).
fn expected_ranges() -> Vec<(&'static str, Set, Interval, bool)> {
    use unispine::train::settings::{ge_le, ge_lt, gt_le, gt_lt};
    let inf = f64::INFINITY;
    vec![
        (
            "iterations",
            |c, v| c.iterations = v as usize,
            ge_le(1.0, 1e6),
            true,
        ),
        (
            "init.interval",
            |c, v| c.init.interval = v as usize,
            ge_lt(1.0, inf),
            true,
        ),
        (
            "init.opacity",
            |c, v| c.init.opacity = v,
            gt_lt(0.0, 1.0),
            false,
        ),
        (
            "init.points",
            |c, v| c.init.points = v as usize,
            ge_le(1.0, 5_000_000.0),
            true,
        ),
        (
            "init.fdk_threshold",
            |c, v| c.init.fdk_threshold = v,
            gt_lt(0.0, 1.0),
            false,
        ),
        (
            "schedule_iterations",
            |c, v| c.schedule_iterations = v as usize,
            ge_le(1.0, 1_000_000.0),
            true,
        ),
        (
            "init.intensity",
            |c, v| c.init.intensity = v,
            gt_lt(-inf, inf),
            false,
        ),
        (
            "loss.lambda_dssim",
            |c, v| c.loss.lambda_dssim = v,
            ge_le(0.0, 1.0),
            false,
        ),
        (
            "loss.charbonnier_eps",
            |c, v| c.loss.charbonnier_eps = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "loss.delta",
            |c, v| c.loss.delta = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "spwm.alpha",
            |c, v| spwm(c).alpha = v,
            ge_le(0.0, 1.0),
            false,
        ),
        (
            "spwm.hf_lambda",
            |c, v| spwm(c).hf_lambda = v,
            ge_lt(0.0, inf),
            false,
        ),
        (
            "spwm.blur_sigma",
            |c, v| spwm(c).blur_sigma = v,
            gt_le(0.0, 1e3),
            false,
        ),
        (
            "spwm.blur_kernel",
            |c, v| spwm(c).blur_kernel = v as usize,
            ge_le(1.0, 1001.0),
            true,
        ),
        (
            "spwm.quantile",
            |c, v| spwm(c).quantile = v,
            ge_le(0.0, 1.0),
            false,
        ),
        (
            "spwm.tau_max",
            |c, v| spwm(c).tau_max = v,
            ge_le(0.0, 1.0),
            false,
        ),
        (
            "spwm.fixed_tau",
            |c, v| spwm(c).fixed_tau = v,
            ge_le(0.0, 1.0),
            false,
        ),
        (
            "spwm.gate_temperature",
            |c, v| spwm(c).gate_temperature = v,
            gt_lt(0.0, inf),
            false,
        ),
        (
            "spwm_time_scale",
            |c, v| c.spwm_time_scale = v,
            gt_le(0.0, 1e9),
            false,
        ),
        (
            "densify.max_gaussians",
            |c, v| c.densify.max_gaussians = Some(v as usize),
            ge_lt(1.0, inf),
            true,
        ),
        (
            "densify.grad_threshold",
            |c, v| c.densify.grad_threshold = v,
            ge_lt(0.0, inf),
            false,
        ),
        (
            "densify.percent_dense",
            |c, v| c.densify.percent_dense = v,
            ge_le(0.0, 1.0),
            false,
        ),
        (
            "densify.min_opacity",
            |c, v| c.densify.min_opacity = v,
            ge_lt(0.0, 1.0),
            false,
        ),
        (
            "densify.max_screen_px",
            |c, v| c.densify.max_screen_px = v,
            gt_lt(0.0, inf),
            false,
        ),
        (
            "densify.max_world_frac",
            |c, v| c.densify.max_world_frac = v,
            gt_lt(0.0, inf),
            false,
        ),
        (
            "densify.reset_opacity_to",
            |c, v| c.densify.reset_opacity_to = v,
            gt_lt(0.0, 1.0),
            false,
        ),
        (
            "densify.split_scale_div",
            |c, v| c.densify.split_scale_div = v,
            ge_lt(1.0, inf),
            false,
        ),
        (
            "lr.position_init",
            |c, v| c.lr.position_init = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "lr.position_final",
            |c, v| c.lr.position_final = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "lr.position_delay_mult",
            |c, v| c.lr.position_delay_mult = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "lr.feature",
            |c, v| c.lr.feature = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "lr.feature_rest_div",
            |c, v| c.lr.feature_rest_div = v,
            gt_le(0.0, 1e6),
            false,
        ),
        (
            "lr.opacity",
            |c, v| c.lr.opacity = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "lr.scaling",
            |c, v| c.lr.scaling = v,
            gt_le(0.0, 1.0),
            false,
        ),
        (
            "lr.rotation",
            |c, v| c.lr.rotation = v,
            gt_le(0.0, 1.0),
            false,
        ),
        // Adam: beta = 1 never updates a moment and divides by 1 - beta^t = 0.
        (
            "adam.beta1",
            |c, v| c.adam.beta1 = v,
            ge_lt(0.0, 1.0),
            false,
        ),
        (
            "adam.beta2",
            |c, v| c.adam.beta2 = v,
            ge_lt(0.0, 1.0),
            false,
        ),
        ("adam.eps", |c, v| c.adam.eps = v, gt_le(0.0, 1.0), false),
        (
            "background",
            |c, v| c.background = v,
            gt_lt(-inf, inf),
            false,
        ),
        (
            "train_views",
            |c, v| c.train_views = Some(v as usize),
            ge_lt(1.0, inf),
            true,
        ),
    ]
}

fn spwm(c: &mut TrainConfig) -> &mut unispine::loss::spwm::SpwmConfig {
    c.spwm.get_or_insert_with(Default::default)
}

#[test]
fn every_settings_range_at_both_endpoints() {
    let table = expected_ranges();
    // The table here covers every ranged row of the code's table (and nothing else).
    let mut ours: Vec<&str> = table.iter().map(|r| r.0).collect();
    let mut code: Vec<&str> = declared_ranges().iter().map(|r| r.0).collect();
    ours.sort_unstable();
    code.sort_unstable();
    assert_eq!(ours, code);
    let check = |field: &str, set: Set, v: f64, ok: bool| {
        let mut c = TrainConfig::preset(Method::Unispine);
        set(&mut c, v);
        let r = c.validate();
        assert_eq!(r.is_ok(), ok, "{field} = {v}: {r:?}");
        if let Err(e) = r {
            assert!(e.to_string().contains(field), "{field} = {v}: {e}");
        }
    };
    for (field, set, r, int) in table {
        // A step just past an endpoint: 1 for integers, a relative 1e-9 (or 1e-9) otherwise.
        let eps = |x: f64| if int { 1.0 } else { 1e-9 * x.abs().max(1.0) };
        if r.lo.is_finite() {
            check(field, set, r.lo, !r.lo_open);
            check(field, set, r.lo + eps(r.lo), true);
            if !(int && r.lo == 0.0) {
                check(field, set, r.lo - eps(r.lo), false);
            }
        } else {
            check(field, set, -f64::MAX, true);
            if !int {
                check(field, set, f64::NEG_INFINITY, false);
            }
        }
        if r.hi.is_finite() {
            check(field, set, r.hi, !r.hi_open);
            check(field, set, r.hi - eps(r.hi), true);
            check(field, set, r.hi + eps(r.hi), false);
        } else if int {
            // usize::MAX as f64 is finite: accepted by an open infinite end.
            check(field, set, 1e15, true);
        } else {
            check(field, set, f64::MAX, true);
            check(field, set, f64::INFINITY, false);
        }
        if !int {
            check(field, set, f64::NAN, false);
        }
    }
}
