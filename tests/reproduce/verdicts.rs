//! The verdict arithmetic against Student-t quantiles computed here by numerical integration
//! of the t density (every df of the table), and pairing of real result rows by dataset, seed
//! and sweep value.

use unispine::reproduce::aggregate::{self, Row};
use unispine::reproduce::verdict::{self, Measure};

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
