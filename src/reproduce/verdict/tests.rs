//! Tests of the verdict arithmetic: t quantiles, intervals, pairing, claims and the paper's rows.

use super::*;

#[test]
fn interval_matches_a_hand_computed_example() {
    // d = 0.3, 0.5, 0.1: mean 0.3; deviations 0, 0.2, -0.2 -> sd = sqrt(0.08 / 2) = 0.2;
    // se = 0.2 / sqrt(3) = 0.115470; t(0.975, 2) = 4.303 -> half width 0.496867.
    let (m, lo, hi, n) = paired_interval(&[0.3, 0.5, 0.1]);
    assert_eq!(n, 3);
    assert!((m - 0.3).abs() < 1e-12);
    assert!((lo - (0.3 - 0.496_867)).abs() < 1e-5, "{lo}");
    assert!((hi - (0.3 + 0.496_867)).abs() < 1e-5, "{hi}");
    assert_eq!(decide(lo, hi, n, 0.0), Word::Inconclusive);
    // d = 1.0, 1.2, 0.8, 1.0: mean 1.0, sd = sqrt(0.08 / 3) = 0.163299, se = 0.081650,
    // t(0.975, 3) = 3.182 -> [0.740190, 1.259810]: reproduced.
    let (m, lo, hi, n) = paired_interval(&[1.0, 1.2, 0.8, 1.0]);
    assert!((m - 1.0).abs() < 1e-12);
    assert!((lo - 0.740_190).abs() < 1e-5 && (hi - 1.259_810).abs() < 1e-5);
    assert_eq!(decide(lo, hi, n, 0.0), Word::Reproduced);
    assert_eq!(decide(-hi, -lo, n, 0.0), Word::NotReproduced);
    assert_eq!(decide(f64::NAN, f64::NAN, 1, 0.0), Word::Inconclusive);
    assert_eq!(decide(f64::NAN, f64::NAN, 0, 0.0), Word::NotTested);
}

#[test]
fn claims_pair_by_key_and_use_log_ratios_for_speed() {
    let o = |key: &str, method: &str, psnr, t, fps| Obs {
        key: key.into(),
        paper_dataset: Some(
            if key.starts_with('a') {
                "CTSpine3D"
            } else {
                "FeSpine3D"
            }
            .into(),
        ),
        method: method.into(),
        psnr,
        train_time_s: t,
        fps,
    };
    let obs = vec![
        o("a/0", "unispine", 30.0, 10.0, 100.0),
        o("a/0", "naf", 25.0, 100.0, 0.1),
        o("a/1", "unispine", 31.0, 10.0, 100.0),
        o("a/1", "naf", 25.5, 80.0, 0.1),
        o("b/0", "unispine", 29.0, 10.0, 100.0), // no partner: ignored
        // A pair on another paper dataset: counted by the pooled claims, not by the speed
        // claims the paper makes for CTSpine3D.
        o("b/1", "unispine", 20.0, 10.0, 100.0),
        o("b/1", "naf", 21.0, 20.0, 50.0),
    ];
    let claims = claims_for(&["unispine".into(), "naf".into()]);
    let beats = claims
        .iter()
        .find(|c| c.b == "naf" && c.measure == Measure::PsnrGain);
    let v = evaluate(beats.unwrap(), &obs);
    assert_eq!(v.diffs, vec![5.0, 5.5, -1.0]);
    let ct: Vec<Obs> = obs
        .iter()
        .filter(|o| o.key.starts_with('a'))
        .cloned()
        .collect();
    let v = evaluate(beats.unwrap(), &ct);
    assert_eq!(v.diffs, vec![5.0, 5.5]);
    // t(0.975, 1) = 12.706, sd = 0.353553, se = 0.25 -> [2.0735, 8.4265]
    assert!((v.lo - (5.25 - 12.706 * 0.25)).abs() < 1e-9);
    assert_eq!(v.word, Word::Reproduced);
    let speed = claims
        .iter()
        .find(|c| matches!(c.measure, Measure::TrainSpeedup(_)))
        .unwrap();
    let v = evaluate(speed, &obs);
    assert_eq!(v.n, 2, "{:?}", v.diffs);
    assert!((v.diffs[0] - 10f64.ln()).abs() < 1e-12 && (v.diffs[1] - 8f64.ln()).abs() < 1e-12);
    assert!((v.threshold - 6.2f64.ln()).abs() < 1e-12);
    // Render speed: ln(fps(A) / fps(B)), 100 / 0.1 = 1000 on both CT pairs.
    let render = claims
        .iter()
        .find(|c| matches!(c.measure, Measure::RenderSpeedup(_)))
        .unwrap();
    let v = evaluate(render, &obs);
    assert_eq!(v.n, 2, "{:?}", v.diffs);
    assert!(
        v.diffs.iter().all(|d| (d - 1000f64.ln()).abs() < 1e-9),
        "{:?}",
        v.diffs
    );
    assert!((v.threshold - 300f64.ln()).abs() < 1e-12);
    let v = evaluate(&claims[0], &obs); // xgaussian vs 3dgs: no such rows
    assert_eq!(v.word, Word::NotTested);
}

#[test]
fn t_quantiles_are_the_table_values() {
    assert_eq!(t975(1), 12.706);
    assert_eq!(t975(2), 4.303);
    assert_eq!(t975(30), 2.042);
    // Exact: df 60 -> 2.000, df 120 -> 1.980.
    assert!((t975(60) - 2.000).abs() < 0.002);
    assert!((t975(120) - 1.980).abs() < 0.002);
}

#[test]
fn an_interval_must_lie_wholly_on_one_side_and_be_finite() {
    // Touching the threshold is not "wholly above / below".
    assert_eq!(decide(0.0, 1.0, 3, 0.0), Word::Inconclusive);
    assert_eq!(decide(-1.0, 0.0, 3, 0.0), Word::Inconclusive);
    assert_eq!(decide(1e-9, 1.0, 3, 0.0), Word::Reproduced);
    assert_eq!(decide(-1.0, -1e-9, 3, 0.0), Word::NotReproduced);
    // One pair: inconclusive even with a finite interval above.
    assert_eq!(decide(0.5, 1.0, 1, 0.0), Word::Inconclusive);
    // Either end not finite: inconclusive, whatever the other end says.
    assert_eq!(decide(1.0, f64::INFINITY, 5, 0.0), Word::Inconclusive);
    assert_eq!(decide(f64::NEG_INFINITY, -1.0, 5, 0.0), Word::Inconclusive);
    assert_eq!(decide(1.0, 2.0, 0, 0.0), Word::NotTested);
}

#[test]
fn a_baseline_claim_exists_only_for_the_baselines_in_the_plan() {
    let names = |ms: &[&str]| -> Vec<String> {
        let v: Vec<String> = ms.iter().map(|m| m.to_string()).collect();
        claims_for(&v)
            .into_iter()
            .filter(|c| c.text.contains("(Table 1: beats every baseline)"))
            .map(|c| c.b)
            .collect()
    };
    assert!(names(&["unispine", "xgaussian"]).is_empty());
    assert_eq!(names(&["unispine", "naf", "xgaussian"]), ["naf"]);
    assert_eq!(names(&["fdk", "unispine", "tensorf"]), ["fdk", "tensorf"]);
}

/// Table 1 prints train times in whole minutes, and the paper's text derives ratios from
/// them (Sec. 4.2: "15 min, which is 6.2x faster than NAF (93 min)"; on FeSpine3D "7 min,
/// about 4.1x faster than IntraTomo (29 min) and 66.6x faster than NeRF (466 min)", "646x
/// speedup over NAF (0.23 fps)", "over 300x ... NAF (0.37 fps)").
#[test]
fn table_1_rows_agree_with_the_ratios_the_paper_s_text_states() {
    let t1: Vec<&PaperRow> = PAPER.iter().filter(|r| r.table == 1).collect();
    assert_eq!(t1.len(), 10);
    for r in &t1 {
        let min = r.train_time_s / 60.0;
        assert!(
            min.fract() == 0.0 && (1.0..=1000.0).contains(&min),
            "{} {}: {} s is not whole minutes",
            r.dataset,
            r.method,
            r.train_time_s
        );
    }
    let row = |d: &str, m: &str| {
        *t1.iter()
            .find(|r| r.dataset == d && r.method == m)
            .unwrap_or_else(|| panic!("no Table 1 row {d} {m}"))
    };
    let ours_ct = row("CTSpine3D", "unispine-t1");
    assert_eq!(ours_ct.train_time_s, 15.0 * 60.0);
    let ratio = |a: f64, b: f64, stated: f64, digits: i32| {
        let k = 10f64.powi(digits);
        assert_eq!((a / b * k).round() / k, stated, "{a} / {b}");
    };
    ratio(
        row("CTSpine3D", "naf").train_time_s,
        ours_ct.train_time_s,
        6.2,
        1,
    );
    assert!(ours_ct.fps.unwrap() / row("CTSpine3D", "naf").fps.unwrap() > 300.0);
    let ours_fe = row("FeSpine3D", "unispine-t1").train_time_s;
    assert_eq!(ours_fe, 7.0 * 60.0);
    ratio(row("FeSpine3D", "intratomo").train_time_s, ours_fe, 4.1, 1);
    ratio(row("FeSpine3D", "nerf").train_time_s, ours_fe, 66.6, 1);
    ratio(148.50, row("FeSpine3D", "naf").fps.unwrap(), 646.0, 0);
    // Every baseline of each dataset is slower to train than ours.
    for r in t1.iter().filter(|r| r.method != "unispine-t1") {
        let ours = if r.dataset == "FeSpine3D" {
            ours_fe
        } else {
            ours_ct.train_time_s
        };
        assert!(r.train_time_s > ours, "{} {}", r.dataset, r.method);
    }
}

#[test]
fn a_paper_row_is_found_by_dataset_and_method_together() {
    let r = paper_row("CTSpine3D", "xgaussian").unwrap();
    assert_eq!(
        (r.table, r.psnr, r.ssim, r.train_time_s),
        (2, 46.04, 0.9926, 756.0)
    );
    let r = paper_row("FeSpine3D", "xgaussian").unwrap();
    assert_eq!((r.psnr, r.train_time_s), (39.91, 782.0));
    let r = paper_row("FeSpine3D", "naf").unwrap();
    assert_eq!((r.table, r.psnr, r.fps), (1, 23.78, Some(0.23)));
    assert!(paper_row("CTSpine3D", "no-such-method").is_none());
    assert!(paper_row("Other", "xgaussian").is_none());
}
