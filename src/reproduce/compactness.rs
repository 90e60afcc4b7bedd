//! The compactness summary of `tables.md`: per dataset and method, the smallest compacted model
//! within 0.1 dB of the unbounded one.
//!
//! Each compacting cell (`train --compact-*`) records the unbounded model it pruned (its
//! Gaussian count and test PSNR before pruning: the model a plain run of the same seed saves, bit
//! for bit). For each rung of the ladder (sweep value) the per-seed drop d_s = PSNR(compacted,
//! s) - PSNR(unbounded, s) is paired by seed; a rung is **within 0.1 dB** when the mean of d_s
//! over the seeds is >= -0.1 dB (every seed is also shown through the worst d_s). The smallest
//! such rung by mean Gaussian count is reported with its mean count and mean render fps.

use crate::doc::{Doc, Table};

use super::aggregate::{groups, Row};

/// Tolerance of "within 0.1 dB".
pub const WITHIN_DB: f64 = 0.1;

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// One rung of a method's ladder: (sweep value, mean count, mean PSNR, mean fps, mean drop,
/// worst drop, seeds).
type Rung = (String, f64, f64, f64, f64, f64, usize);

/// The rungs of one (dataset, method) with results, and the unbounded model's mean count and
/// PSNR.
fn ladder(rows: &[Row], dataset: &str, method: &str) -> (Vec<Rung>, Option<(f64, f64)>) {
    let mut rungs = Vec::new();
    let mut unb_n = Vec::new();
    let mut unb_p = Vec::new();
    for (d, m, v, rs) in groups(rows) {
        if d != dataset || m != method {
            continue;
        }
        let ok: Vec<&&Row> = rs
            .iter()
            .filter(|r| r.psnr.is_some() && r.unbounded_psnr.is_some())
            .collect();
        if ok.is_empty() {
            continue;
        }
        let drops: Vec<f64> = ok
            .iter()
            .map(|r| r.psnr.unwrap() - r.unbounded_psnr.unwrap())
            .collect();
        let n: Vec<f64> = ok
            .iter()
            .filter_map(|r| r.n_gaussians.map(|x| x as f64))
            .collect();
        let p: Vec<f64> = ok.iter().filter_map(|r| r.psnr).collect();
        let f: Vec<f64> = ok.iter().filter_map(|r| r.fps).collect();
        for r in &ok {
            // One unbounded model per seed (every rung of a seed prunes the same model).
            if !unb_n.iter().any(|(s, _): &(u64, f64)| *s == r.seed) {
                unb_n.push((r.seed, r.unbounded_n.unwrap_or(0) as f64));
                unb_p.push(r.unbounded_psnr.unwrap());
            }
        }
        rungs.push((
            v.unwrap_or_default(),
            mean(&n),
            mean(&p),
            if f.is_empty() { f64::NAN } else { mean(&f) },
            mean(&drops),
            drops.iter().cloned().fold(f64::INFINITY, f64::min),
            ok.len(),
        ));
    }
    let unb = (!unb_p.is_empty()).then(|| {
        let n: Vec<f64> = unb_n.iter().map(|x| x.1).collect();
        (mean(&n), mean(&unb_p))
    });
    rungs.sort_by(|a, b| a.1.total_cmp(&b.1));
    (rungs, unb)
}

/// The unbounded model of every (dataset, method) with compacting cells: (dataset, method,
/// mean count, mean PSNR), for the charts.
pub fn unbounded(rows: &[Row]) -> Vec<(String, String, f64, f64)> {
    let mut out = Vec::new();
    for (d, m, _, _) in groups(rows) {
        if out
            .iter()
            .any(|x: &(String, String, f64, f64)| x.0 == d && x.1 == m)
        {
            continue;
        }
        if let (_, Some((n, p))) = ladder(rows, &d, &m) {
            out.push((d, m, n, p));
        }
    }
    out
}

/// The `tables.md` section (empty when no cell compacted).
pub fn section(rows: &[Row]) -> Doc {
    let mut d = Doc::new();
    if rows.iter().all(|r| r.unbounded_psnr.is_none()) {
        return d;
    }
    let flag = rows
        .iter()
        .find_map(|r| r.sweep_flag.clone())
        .unwrap_or_else(|| "compaction".into());
    d.heading(
        2,
        format!("Compactness: the smallest model within {WITHIN_DB} dB of the unbounded one"),
    );
    d.para(format!(
        "Unbounded = the model each compacting run pruned (densification without a budget; the \
         same bits as a plain run of that seed). Compacted = pruned by the alpha*T importance \
         over the training views, then fine-tuned. A rung is within {WITHIN_DB} dB when the \
         mean over seeds of the paired drop PSNR(compacted) - PSNR(unbounded) is >= \
         -{WITHIN_DB} dB; counts, PSNR and fps are means over seeds; fps is of the compacted \
         (saved) model."
    ));
    let mut seen: Vec<(String, String)> = Vec::new();
    for (ds, m, _, _) in groups(rows) {
        if seen.contains(&(ds.clone(), m.clone())) {
            continue;
        }
        seen.push((ds.clone(), m.clone()));
        let (rungs, unb) = ladder(rows, &ds, &m);
        let Some((un, up)) = unb else { continue };
        d.para(format!("**{ds} / {m}**"));
        let within = format!("within {WITHIN_DB} dB");
        let mut t = Table::new(&[
            (flag.as_str(), true),
            ("Gaussians", true),
            ("test PSNR (dB)", true),
            ("drop, mean (worst)", true),
            ("fps", true),
            ("seeds", true),
            (within.as_str(), false),
        ]);
        let mut cells = vec![
            "unbounded".to_string(),
            format!("{un:.0}"),
            format!("{up:.3}"),
        ];
        cells.resize(7, String::new());
        t.row(cells);
        for r in &rungs {
            t.row(vec![
                r.0.clone(),
                format!("{:.0}", r.1),
                format!("{:.3}", r.2),
                format!("{:+.3} ({:+.3})", r.4, r.5),
                format!("{:.1}", r.3),
                r.6.to_string(),
                if r.4 >= -WITHIN_DB { "yes" } else { "no" }.to_string(),
            ]);
        }
        d.table(t);
        d.para(match rungs.iter().find(|r| r.4 >= -WITHIN_DB) {
            Some(r) => format!(
                "**Smallest within {WITHIN_DB} dB: {flag} {}: {:.0} Gaussians ({:.0} % of the \
                 unbounded {un:.0}), {:.3} dB (mean drop {:+.3} dB), {:.1} fps.**",
                r.0,
                r.1,
                100.0 * r.1 / un.max(1.0),
                r.2,
                r.4,
                r.3
            ),
            None => format!(
                "**No rung is within {WITHIN_DB} dB: the unbounded model ({un:.0} Gaussians) is \
                 the smallest.**"
            ),
        });
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(value: &str, seed: u64, n: usize, psnr: f64, unb: (usize, f64)) -> Row {
        Row {
            index: 0,
            dataset: "d".into(),
            method: "m".into(),
            base: "m".into(),
            sweep_flag: Some("compact-keep".into()),
            sweep_value: Some(value.into()),
            seed,
            iters: 10,
            status: "done".into(),
            completed: true,
            psnr: Some(psnr),
            fps: Some(100.0 + n as f64),
            n_gaussians: Some(n),
            unbounded_n: Some(unb.0),
            unbounded_psnr: Some(unb.1),
            ..Default::default()
        }
    }

    #[test]
    fn the_smallest_rung_whose_mean_paired_drop_is_within_the_tolerance() {
        // Unbounded: seed 0 1000 Gaussians at 30.0 dB, seed 1 1200 at 31.0 dB.
        let (u0, u1) = ((1000, 30.0), (1200, 31.0));
        let rows = vec![
            // 0.1: drops -0.30 and -0.02, mean -0.16: not within.
            row("0.1", 0, 100, 29.70, u0),
            row("0.1", 1, 120, 30.98, u1),
            // 0.3: drops -0.15 and -0.03, mean -0.09: within (one seed alone is not).
            row("0.3", 0, 300, 29.85, u0),
            row("0.3", 1, 360, 30.97, u1),
            // 0.6: drops +0.1, 0: within, but larger.
            row("0.6", 0, 600, 30.10, u0),
            row("0.6", 1, 720, 31.00, u1),
        ];
        let s = section(&rows).to_markdown();
        assert!(s.contains("| unbounded | 1100 | 30.500 |"), "{s}");
        assert!(
            s.contains("Smallest within 0.1 dB: compact-keep 0.3: 330 Gaussians (30 % of the unbounded 1100)"),
            "{s}"
        );
        assert!(
            s.contains("| 0.1 | 110 | 30.340 | -0.160 (-0.300) | 210.0 | 2 | no |"),
            "{s}"
        );
        assert_eq!(
            unbounded(&rows),
            vec![("d".into(), "m".into(), 1100.0, 30.5)]
        );
        // No compacting cell: no section.
        let plain: Vec<Row> = rows
            .iter()
            .map(|r| Row {
                unbounded_psnr: None,
                ..r.clone()
            })
            .collect();
        assert!(section(&plain).is_empty());
    }

    #[test]
    fn rungs_are_ordered_by_count_failed_cells_are_left_out_and_the_bound_is_inclusive() {
        // Unbounded: 0.1 dB at 1000 Gaussians (seed 0). Drops are exact in binary: 0.0 - 0.1 is
        // -0.1 exactly, the bound itself.
        let u = (1000, 0.1);
        let mut failed = row("0.05", 0, 50, 0.0, u);
        failed.psnr = None;
        let mut no_fps = row("0.4", 0, 400, 0.0, u);
        no_fps.fps = None;
        let rows = vec![
            // Listed largest first: the table and the choice go by count, not by plan order.
            row("0.8", 0, 800, 0.1, u),
            no_fps,
            row("0.2", 0, 200, -0.5, u),
            failed,
        ];
        let s = section(&rows).to_markdown();
        let (i2, i4, i8) = (
            s.find("| 0.2 |").unwrap(),
            s.find("| 0.4 |").unwrap(),
            s.find("| 0.8 |").unwrap(),
        );
        assert!(i2 < i4 && i4 < i8, "{s}");
        // A failed cell is no rung; a drop of exactly -0.1 dB is within; no fps is NaN.
        assert!(!s.contains("| 0.05 |"), "{s}");
        assert!(
            s.contains("| 0.4 | 400 | 0.000 | -0.100 (-0.100) | NaN | 1 | yes |"),
            "{s}"
        );
        assert!(
            s.contains("| 0.2 | 200 | -0.500 | -0.600 (-0.600) | 300.0 | 1 | no |"),
            "{s}"
        );
        assert!(
            s.contains("Smallest within 0.1 dB: compact-keep 0.4: 400 Gaussians (40 % of the unbounded 1000), 0.000 dB (mean drop -0.100 dB), NaN fps."),
            "{s}"
        );
    }

    #[test]
    fn with_no_rung_within_the_unbounded_model_is_the_smallest_per_dataset_and_method() {
        let mut rows = vec![
            row("0.1", 0, 100, 29.0, (900, 30.0)),
            row("0.1", 1, 140, 28.0, (1100, 30.0)),
        ];
        // Another method on the same dataset with its own ladder, and a plain cell (no
        // unbounded model) that adds nothing.
        let mut other = row("0.5", 0, 50, 30.0, (100, 30.0));
        other.method = "k".into();
        rows.push(other);
        let mut plain = row("0.9", 0, 5, 10.0, (0, 0.0));
        plain.unbounded_psnr = None;
        rows.push(plain);
        let s = section(&rows).to_markdown();
        assert!(s.contains("**d / m**") && s.contains("**d / k**"), "{s}");
        assert!(
            s.contains("**No rung is within 0.1 dB: the unbounded model (1000 Gaussians) is the smallest.**"),
            "{s}"
        );
        assert!(
            s.contains("| 0.1 | 120 | 28.500 | -1.500 (-2.000) | 220.0 | 2 | no |"),
            "{s}"
        );
        assert!(!s.contains("| 0.9 |"), "{s}");
        assert_eq!(
            unbounded(&rows),
            vec![
                ("d".into(), "m".into(), 1000.0, 30.0),
                ("d".into(), "k".into(), 100.0, 30.0)
            ]
        );
    }
}
