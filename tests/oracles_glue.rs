//! Independent oracles for the glue code: learning-rate schedules (closed forms, and the rate
//! the field trainer reports past its StepLR step), the verdict arithmetic against Student-t
//! quantiles computed here by numerical integration of the t density (every df of the table),
//! pairing of real result rows, and every range of the settings table at both endpoints
//! (a table of expected intervals written here, checked against the code's behaviour).

use unispine::optim::schedule::{ExponLr, StepLr};
use unispine::reproduce::aggregate::{self, Row};
use unispine::reproduce::verdict::{self, Measure};
use unispine::train::settings::{declared_ranges, Interval};
use unispine::train::{Method, TrainConfig};

// ---------------------------------------------------------------------------------------------
// Schedules.

#[test]
fn step_lr_and_expon_lr_follow_their_closed_forms() {
    for &(lr0, step, gamma) in &[(1e-3, 1usize, 0.5), (5e-4, 7, 0.1), (2.0, 100, 0.9)] {
        let s = StepLr { lr0, step, gamma };
        // Iterations 1..=step at lr0, step+1..=2 step at lr0 gamma, ...
        let mut want = lr0;
        for it in 1..=5 * step + 3 {
            if it > 1 && (it - 1) % step == 0 {
                want *= gamma;
            }
            assert!(
                (s.at(it) - want).abs() <= 1e-15 * lr0,
                "step {step} it {it}: {} vs {want}",
                s.at(it)
            );
        }
    }
    // get_expon_lr_func: exp((1 - s) ln a + s ln b) = a^(1 - s) b^s, s = clip(t / T, 0, 1),
    // times the sine warm-up delay_mult + (1 - delay_mult) sin(pi/2 clip(t / D, 0, 1)).
    for &(a, b, d, m, tmax) in &[
        (1.6e-4, 1.6e-6, 0usize, 0.01, 30_000usize),
        (0.3, 0.003, 50, 0.2, 400),
        (1.0, 4.0, 10, 0.5, 25),
    ] {
        let e = ExponLr {
            lr_init: a,
            lr_final: b,
            delay_steps: d,
            delay_mult: m,
            max_steps: tmax,
        };
        for t in (0..=tmax + 10).step_by((tmax / 97).max(1)) {
            let s = (t as f64 / tmax as f64).min(1.0);
            let warm = if d == 0 {
                1.0
            } else {
                m + (1.0 - m) * (std::f64::consts::FRAC_PI_2 * (t as f64 / d as f64).min(1.0)).sin()
            };
            let want = warm * a.powf(1.0 - s) * b.powf(s);
            assert!(
                (e.at(t) - want).abs() <= 1e-12 * want,
                "t {t}: {} vs {want}",
                e.at(t)
            );
        }
    }
}

#[test]
fn the_gaussian_trainer_s_group_rates() {
    let c = TrainConfig::preset(Method::Unispine);
    let l = &c.lr;
    let extent = 37.5;
    for it in [1usize, 2, 500, 10_000, 20_000, 25_000] {
        let lr = l.at(it, extent);
        let s = (it as f64 / l.position_max_steps as f64).min(1.0);
        let pos = (l.position_init * extent).powf(1.0 - s) * (l.position_final * extent).powf(s);
        // Groups: position, feature 0, features 1.., opacity, scaling, rotation.
        let want = [
            pos,
            l.feature,
            l.feature / l.feature_rest_div,
            l.opacity,
            l.scaling,
            l.rotation,
        ];
        for g in 0..6 {
            assert!(
                (lr[g] - want[g]).abs() <= 1e-12 * want[g],
                "it {it} group {g}"
            );
        }
    }
}

#[test]
fn the_field_trainer_reports_and_uses_step_lr_past_its_step() {
    use unispine::dataset::generate::{generate, GenerateOptions};
    use unispine::field::train::FieldTrainer;
    use unispine::field::FieldConfig;
    let mut vol = unispine::volume::Volume::<f32>::zeros([12, 12, 12], [5.0; 3]);
    for z in 4..8 {
        for y in 4..8 {
            for x in 4..8 {
                vol.data[(z * 12 + y) * 12 + x] = 0.02;
            }
        }
    }
    let opts = GenerateOptions {
        train_views: 2,
        test_views: 1,
        detector: 12,
        ..Default::default()
    };
    let ds = generate(&vol, &opts, &|_, _| {}).unwrap();
    let mut cfg = FieldConfig::preset("intratomo", 2).unwrap();
    cfg.n_rays = 16;
    cfg.n_samples = 8;
    cfg.lr_step = 3;
    cfg.lr_gamma = 0.5;
    let lr0 = cfg.lr;
    let mut flat = cfg.clone();
    flat.lr_gamma = 1.0;
    let mut tr = FieldTrainer::new(cfg, &ds).unwrap();
    let mut tr_flat = FieldTrainer::new(flat, &ds).unwrap();
    let params = |t: &FieldTrainer| t.checkpoint(0.0, "").params;
    for it in 1..=10usize {
        let (before, before_flat) = (params(&tr), params(&tr_flat));
        let st = tr.step().unwrap();
        let st_flat = tr_flat.step().unwrap();
        let want = lr0 * 0.5f64.powi(((it - 1) / 3) as i32);
        assert_eq!(st.iteration, it);
        assert!(
            (st.lr - want).abs() <= 1e-15 * lr0,
            "it {it}: lr {} vs {want}",
            st.lr
        );
        assert_eq!(st_flat.lr, lr0, "it {it}");
        // Iterations 1-3 run at lr0 in both runs (same bits); iteration 4 starts from the same
        // state with the same gradient and Adam moments, so its update is half the flat run's.
        let step = |a: &[f32], b: &[f32]| -> Vec<f64> {
            a.iter()
                .zip(b)
                .map(|(x, y)| (*y as f64) - (*x as f64))
                .collect()
        };
        let (after, after_flat) = (params(&tr), params(&tr_flat));
        if it <= 3 {
            assert_eq!(after, after_flat, "it {it}");
        }
        if it == 4 {
            assert_eq!(before, before_flat);
            let (d, d_flat) = (step(&before, &after), step(&before_flat, &after_flat));
            let big = d_flat.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(big > 0.1 * lr0, "{big}");
            for (x, y) in d.iter().zip(&d_flat) {
                // f32 parameters: the updates are rounded to the parameter's ulp.
                let ulp = 4.0
                    * f32::EPSILON as f64
                    * before.iter().fold(1.0f32, |m, p| m.max(p.abs())) as f64;
                assert!((x - 0.5 * y).abs() <= ulp, "update {x} vs half of {y}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Student t quantiles and the verdict arithmetic.

/// The t density's normalising constant Gamma((v+1)/2) / (sqrt(v pi) Gamma(v/2)), from the
/// exact ratios Gamma(1)/Gamma(1/2) = 1/sqrt(pi), Gamma(3/2)/Gamma(1) = sqrt(pi)/2 and
/// r(v + 2) = r(v) (v + 1) / v.
fn t_norm(df: usize) -> f64 {
    let pi = std::f64::consts::PI;
    let mut r = if df % 2 == 1 {
        1.0 / pi.sqrt()
    } else {
        pi.sqrt() / 2.0
    };
    let mut v = if df % 2 == 1 { 1 } else { 2 };
    while v < df {
        r *= (v + 1) as f64 / v as f64;
        v += 2;
    }
    r / (df as f64 * pi).sqrt()
}

/// P(0 < T < x) by composite Simpson on 4000 panels.
fn t_mass(df: usize, x: f64) -> f64 {
    let c = t_norm(df);
    let f = |t: f64| c * (1.0 + t * t / df as f64).powf(-(df as f64 + 1.0) / 2.0);
    let n = 4000;
    let h = x / n as f64;
    let mut s = f(0.0) + f(x);
    for i in 1..n {
        s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(i as f64 * h);
    }
    s * h / 3.0
}

/// t(0.975, df) by bisection on P(0 < T < x) = 0.475.
fn t975_exact(df: usize) -> f64 {
    let (mut lo, mut hi) = (0.0, 50.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if t_mass(df, mid) < 0.475 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn t_quantiles_against_numerical_integration_for_every_df() {
    // The oracle against the closed forms for df 1 and 2.
    let p = 0.975f64;
    assert!((t975_exact(1) - (std::f64::consts::PI * (p - 0.5)).tan()).abs() < 1e-7);
    let a = 2.0 * p - 1.0;
    assert!((t975_exact(2) - a * (2.0 / (1.0 - a * a)).sqrt()).abs() < 1e-7);
    // The table: three decimals, correctly rounded.
    for df in 1..=30 {
        let (got, want) = (verdict::t975(df), t975_exact(df));
        assert!(
            (got - want).abs() <= 0.0005 + 1e-9,
            "t(0.975, {df}) = {got}, exact {want:.5}"
        );
    }
    // Beyond the table: the interpolation in 1/df stays within 0.002.
    for df in (31..=120).chain([200, 500]) {
        let (got, want) = (verdict::t975(df), t975_exact(df));
        assert!(
            (got - want).abs() < 0.002,
            "t(0.975, {df}) = {got}, exact {want:.5}"
        );
    }
    assert!(verdict::t975(0).is_infinite());
}

#[test]
fn paired_intervals_against_an_independent_computation() {
    for n in 2..=31usize {
        // Deterministic, irregular differences.
        let d: Vec<f64> = (0..n)
            .map(|i| 0.4 + ((i * 37 + n * 11) % 23) as f64 / 10.0 - 1.1)
            .collect();
        let (m, lo, hi, k) = verdict::paired_interval(&d);
        assert_eq!(k, n);
        // Welford's running mean and variance.
        let (mut mean, mut m2) = (0.0, 0.0);
        for (i, &x) in d.iter().enumerate() {
            let delta = x - mean;
            mean += delta / (i + 1) as f64;
            m2 += delta * (x - mean);
        }
        let se = (m2 / (n - 1) as f64).sqrt() / (n as f64).sqrt();
        let half = t975_exact(n - 1) * se;
        assert!((m - mean).abs() < 1e-12, "n {n}");
        // The table's rounding (<= 0.0005) is the only difference.
        assert!(
            (lo - (mean - half)).abs() <= (0.0005 + 1e-9) * se + 1e-12,
            "n {n}: lo {lo}"
        );
        assert!(
            (hi - (mean + half)).abs() <= (0.0005 + 1e-9) * se + 1e-12,
            "n {n}: hi {hi}"
        );
        // The verdict word follows the interval.
        let w = verdict::decide(lo, hi, n, 0.0);
        let want = if mean - half > 0.0 {
            verdict::Word::Reproduced
        } else if mean + half < 0.0 {
            verdict::Word::NotReproduced
        } else {
            verdict::Word::Inconclusive
        };
        if (mean.abs() - half).abs() > 0.001 * se {
            assert_eq!(w, want, "n {n}: [{lo}, {hi}]");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Pairing of result rows.

fn row(dataset: &str, method: &str, seed: u64, sweep: Option<&str>, psnr: Option<f64>) -> Row {
    Row {
        index: 0,
        dataset: dataset.into(),
        paper_dataset: Some("CTSpine3D".into()),
        method: method.into(),
        base: method.into(),
        sweep_flag: sweep.map(|_| "--lambda-dssim".into()),
        sweep_value: sweep.map(Into::into),
        seed,
        iters: 30,
        status: if psnr.is_some() { "done" } else { "failed" }.into(),
        completed: psnr.is_some(),
        psnr,
        ssim: psnr.map(|_| 0.9),
        train_time_s: psnr.map(|p| 100.0 / p),
        fps: psnr.map(|p| p * 2.0),
        run_dir: format!("runs/{dataset}/{method}/seed{seed}"),
        ..Default::default()
    }
}

#[test]
fn verdicts_pair_rows_by_dataset_seed_and_sweep_value() {
    // Two datasets x three seeds x two sweep values x {unispine, xgaussian}; each PSNR distinct,
    // one cell failed (its pair drops out).
    let mut rows = Vec::new();
    let mut want = Vec::new();
    for (di, ds) in ["ph", "ct"].iter().enumerate() {
        for seed in 0..3u64 {
            for (si, sw) in ["0.1", "0.3"].iter().enumerate() {
                let base = 20.0 + di as f64 * 5.0 + seed as f64 * 1.5 + si as f64 * 0.25;
                let gain = 0.1 + 0.37 * ((di * 6 + seed as usize * 2 + si) % 5) as f64;
                let failed = di == 1 && seed == 2 && si == 0;
                rows.push(row(ds, "xgaussian", seed, Some(sw), Some(base)));
                let p = (!failed).then_some(base + gain);
                rows.push(row(ds, "unispine", seed, Some(sw), p));
                if !failed {
                    want.push(gain);
                }
            }
        }
    }
    // Rows in another order than the pairs (the pairing must not depend on it).
    rows.reverse();
    let obs = aggregate::observations(&rows);
    let claims = verdict::claims_for(&["xgaussian".into(), "unispine".into()]);
    let spwm = claims
        .iter()
        .find(|c| c.a == "unispine" && c.b == "xgaussian" && c.measure == Measure::PsnrGain)
        .unwrap();
    let v = verdict::evaluate(spwm, &obs);
    let sorted = |mut x: Vec<f64>| {
        x.sort_by(f64::total_cmp);
        x
    };
    assert_eq!(v.n, want.len());
    let (got, want) = (sorted(v.diffs.clone()), sorted(want));
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 1e-12, "pairs {got:?} vs {want:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// The settings table at both endpoints.

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
