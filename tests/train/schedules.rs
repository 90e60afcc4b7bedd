//! The learning-rate schedules against their closed forms (StepLR, ExponLR) and the Gaussian
//! trainer's per-group rates written from the 3DGS formulas.

use unispine::optim::schedule::{ExponLr, StepLr};
use unispine::train::{Method, TrainConfig};

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
