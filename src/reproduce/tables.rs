//! What a plan's folder receives from its rows: `results.csv`, `results.json` and `tables.md`,
//! the last as a typed [`Doc`]: per dataset mean +- sd over seeds with n and the paper's
//! numbers beside the matching rows, what each row runs, the verdicts on sign
//! ([`super::verdict`]) and magnitude ([`super::magnitude`]), where each claim holds
//! ([`super::holds`]), the cells without a result, the provenance of every row and the
//! compactness ladder ([`super::compactness`]). `report.html` renders the same value.

use std::path::Path;

use super::aggregate::{
    condition_suffix, describe, gather, groups, method_label, o, to_csv, verdicts, Row,
};
use super::plan::Plan;
use super::verdict::{self, Verdict};
use crate::doc::{Block, Doc, Table};
use crate::error::{Error, Result};
use crate::method::Baseline;

fn pm(v: &[f64], prec: usize) -> String {
    let (m, sd, n) = verdict::mean_sd(v);
    match n {
        0 => "-".into(),
        1 => format!("{m:.prec$}"),
        _ => format!("{m:.prec$} ± {sd:.prec$}"),
    }
}

/// [`pm`] with the decimals that give the mean `digits` significant digits (at least 1
/// decimal): fps runs from ~0.1 (NeRF) to ~100 (Gaussians).
fn pm_sig(v: &[f64], digits: i32) -> String {
    let (m, _, _) = verdict::mean_sd(v);
    let mag = if m.is_finite() && m != 0.0 {
        m.abs().log10().floor() as i32
    } else {
        0
    };
    pm(v, (digits - 1 - mag).clamp(1, 6) as usize)
}

/// The heading after which `tables.md` describes the runs rather than their results.
const WHAT_RUNS: &str = "What each method row runs";

/// The part of [`tables`] a terminal shows: title, notes and the per-dataset results.
pub fn results_part(doc: &Doc) -> Doc {
    Doc {
        blocks: doc
            .blocks
            .iter()
            .take_while(|b| !matches!(b, Block::Heading(2, t) if t == WHAT_RUNS))
            .cloned()
            .collect(),
    }
}

fn vals(rs: &[&Row], f: impl Fn(&Row) -> Option<f64>) -> Vec<f64> {
    rs.iter().filter_map(|r| f(r)).collect()
}

/// The whole of `tables.md` (`extra`: a closing paragraph, e.g. the harness's own time).
pub fn tables(
    plan: &Plan,
    rows: &[Row],
    verdicts: &[Verdict],
    preset_help: &[(String, String)],
    extra: &str,
) -> Doc {
    let mut d = Doc::new();
    d.heading(
        1,
        format!(
            "`unispine reproduce {}`: {} iterations{}, seeds {:?}",
            plan.name,
            plan.iters,
            if plan.compress_schedule {
                " (the paper's 20000-iteration schedule compressed)"
            } else {
                ""
            },
            plan.seeds
        ),
    );
    d.para(
        "Test views: PSNR (dB) and SSIM as mean ± sd over seeds (n = completed runs); train time \
         = the training loop's wall time; fps = test views rendered per second. Paper: the \
         paper's own number for the corresponding row, measured on another machine (RTX 3090) \
         at another resolution (1024 x 1024 detector) with the full schedule: compare trends, \
         not values.",
    );
    results(&mut d, plan, rows);
    what_runs(&mut d, plan, preset_help);
    verdicts_section(&mut d, plan, verdicts);
    d.append(super::magnitude::section(plan, rows));
    d.append(super::holds::section(plan, rows, "Where each claim holds"));
    without_result(&mut d, rows);
    provenance(&mut d, rows);
    d.append(super::compactness::section(rows));
    if !extra.trim().is_empty() {
        d.para(extra.trim());
    }
    d
}

/// Per dataset: one row per (method, sweep value, condition point).
fn results(d: &mut Doc, plan: &Plan, rows: &[Row]) {
    let sweep_col = plan.sweep.as_ref().map(|s| s.flag.clone());
    for ds in &plan.datasets {
        let g: Vec<_> = groups(rows)
            .into_iter()
            .filter(|x| x.0 == ds.name)
            .collect();
        if g.iter().all(|x| x.3.iter().all(|r| r.status == "missing")) {
            d.heading(2, format!("{}: no results", ds.name));
            continue;
        }
        d.heading(
            2,
            format!(
                "{}{}",
                ds.name,
                ds.paper
                    .as_ref()
                    .map(|p| format!(" (stands in for {p})"))
                    .unwrap_or_default()
            ),
        );
        let mut cols = vec![("method", false)];
        if let Some(f) = &sweep_col {
            cols.push((f.as_str(), true));
        }
        cols.extend([
            ("n", true),
            ("PSNR (dB)", true),
            ("SSIM", true),
            ("train time (s)", true),
            ("fps", true),
            ("Gaussians", true),
            ("paper PSNR / SSIM / time (s)", false),
        ]);
        let mut t = Table::new(&cols);
        for (_, method, sv, rs) in &g {
            let n = rs.iter().filter(|r| r.psnr.is_some()).count();
            let base = rs.first().map(|r| r.base.as_str()).unwrap_or("");
            let paper = ds
                .paper
                .as_ref()
                .and_then(|p| verdict::paper_row(p, base))
                .map(|p| format!("{:.2} / {:.4} / {:.0}", p.psnr, p.ssim, p.train_time_s))
                .unwrap_or_default();
            let gaussians = if Baseline::parse(base).is_some() {
                "-".to_string()
            } else {
                pm(&vals(rs, |r| r.n_gaussians.map(|x| x as f64)), 0)
            };
            let mut cells = vec![format!(
                "{}{}",
                method_label(method, base),
                condition_suffix(rs)
            )];
            if sweep_col.is_some() {
                cells.push(sv.clone().unwrap_or_default());
            }
            cells.extend([
                format!("{n} of {}", rs.len()),
                pm(&vals(rs, |r| r.psnr), 2),
                pm(&vals(rs, |r| r.ssim), 4),
                pm(&vals(rs, |r| r.train_time_s), 1),
                pm_sig(&vals(rs, |r| r.fps), 3),
                gaussians,
                paper,
            ]);
            t.row(cells);
        }
        d.table(t);
    }
}

/// "What each method row runs", the conditions, and the command of every cell.
fn what_runs(d: &mut Doc, plan: &Plan, preset_help: &[(String, String)]) {
    d.heading(2, WHAT_RUNS);
    d.list(
        plan.methods
            .iter()
            .map(|m| format!("**{}**: {}", m.name, describe(plan, &m.name, preset_help)))
            .collect(),
    );
    d.append(super::holds::describe_conditions(plan));
    let base_of = |m: &super::plan::MethodSpec| Baseline::parse(&m.base);
    if plan.methods.iter().any(|m| base_of(m).is_none()) {
        d.para(format!(
            "{}: `unispine train --iters {}{}{}`.",
            if plan.methods.iter().any(|m| base_of(m).is_some()) {
                "Every Gaussian cell"
            } else {
                "Every cell"
            },
            plan.iters,
            if plan.compress_schedule {
                " --compress-schedule"
            } else {
                ""
            },
            if plan.train_args.is_empty() {
                String::new()
            } else {
                format!(" {}", plan.train_args.join(" "))
            }
        ));
    }
    if plan
        .methods
        .iter()
        .any(|m| matches!(base_of(m), Some(Baseline::Field(_))))
    {
        let fdk = plan
            .methods
            .iter()
            .any(|m| base_of(m) == Some(Baseline::Fdk));
        d.para(format!(
            "Every neural-field cell: {}{}.",
            match plan.field_iters {
                Some(n) => format!("`unispine train --iters {n}`"),
                None => "the preset's own schedule".into(),
            },
            if fdk { "; FDK is one pass" } else { "" }
        ));
    }
}

/// The verdicts on sign, one row per claim.
fn verdicts_section(d: &mut Doc, plan: &Plan, verdicts: &[Verdict]) {
    d.heading(2, "Verdicts on the paper's claims");
    let mut t = Table::new(&[
        ("claim", false),
        ("A vs B", false),
        ("pairs", true),
        ("mean difference", true),
        ("95 % interval", false),
        ("verdict", false),
    ]);
    for v in verdicts {
        let (unit, conv): (&str, fn(f64) -> f64) = match v.claim.measure {
            verdict::Measure::PsnrGain => (" dB", |x| x),
            _ => ("x", f64::exp),
        };
        let fmt = |x: f64| {
            if x.is_finite() {
                format!("{:.3}{unit}", conv(x))
            } else {
                "-".into()
            }
        };
        t.row(vec![
            v.claim.text.clone(),
            format!("{} vs {}", v.claim.a, v.claim.b),
            v.n.to_string(),
            fmt(v.mean),
            if v.n >= 2 {
                format!("[{}, {}]", fmt(v.lo), fmt(v.hi))
            } else {
                "-".into()
            },
            format!("**{}**", v.word.as_str()),
        ]);
    }
    d.table(t);
    d.para(format!(
        "Pairs: cells of A and B that completed on the same dataset and seed{}; a claim the \
         paper makes for one dataset pairs only the plan datasets standing in for it. Accuracy: d = \
         PSNR(A) - PSNR(B); speed: d = ln(speed ratio), shown as the ratio, tested against the \
         paper's factor. Interval: paired t, mean(d) ± t(0.975, n-1) · sd(d) / sqrt(n). \
         Reproduced: the interval lies wholly above the paper's threshold (0 dB, or ln of the \
         factor); not reproduced: wholly below; otherwise inconclusive (also with fewer than 2 \
         pairs). Not tested: a method of the claim is not in this plan or has no completed \
         pair.",
        if plan.sweep.is_some() {
            " (and sweep value)"
        } else {
            ""
        }
    ));
}

/// The cells that did not complete, with their status and error.
fn without_result(d: &mut Doc, rows: &[Row]) {
    let bad: Vec<&Row> = rows.iter().filter(|r| r.psnr.is_none()).collect();
    if bad.is_empty() {
        return;
    }
    d.heading(
        2,
        format!("Cells without a result ({} of {})", bad.len(), rows.len()),
    );
    d.list(
        bad.iter()
            .map(|r| {
                format!(
                    "`{}`: {}{}",
                    r.run_dir,
                    r.status,
                    r.error
                        .as_ref()
                        .map(|e| format!(": {}", e.replace('\n', " ")))
                        .unwrap_or_default()
                )
            })
            .collect(),
    );
}

/// Every distinct build and machine, and every dataset checksum.
fn provenance(d: &mut Doc, rows: &[Row]) {
    d.heading(2, "Provenance");
    let mut items: Vec<String> = Vec::new();
    let mut push = |l: String| {
        if !items.contains(&l) {
            items.push(l);
        }
    };
    for r in rows.iter().filter(|r| r.version.is_some()) {
        push(format!(
            "unispine {} (commit {}), CPU {} ({} cores, SIMD {}), {} threads per run",
            o(&r.version),
            o(&r.git_commit),
            o(&r.cpu_model),
            o(&r.cores),
            o(&r.simd),
            o(&r.threads)
        ));
    }
    // A data condition builds its own dataset per value: name it beside the checksum (a base
    // row sharing the checksum makes it the base dataset).
    for r in rows {
        if let Some(c) = &r.dataset_checksum {
            let same = |x: &&Row| x.dataset == r.dataset && x.dataset_checksum.as_ref() == Some(c);
            let at = if rows.iter().filter(same).any(|x| x.condition.is_none()) {
                String::new()
            } else {
                match (&r.condition, &r.condition_value) {
                    (Some(a), Some(v)) => format!(" at {a} = {v}"),
                    _ => String::new(),
                }
            };
            push(format!("dataset `{}`{at}: checksum {c}", r.dataset));
        }
    }
    items.push(
        "per row (results.csv): version, git commit, dataset checksum, config hash, CPU, cores, \
         SIMD path, threads"
            .into(),
    );
    d.list(items);
}

/// `results.json`: the rows and the verdicts.
pub fn to_json(plan: &Plan, rows: &[Row], verdicts: &[Verdict]) -> String {
    let v = serde_json::json!({
        "plan": plan.name,
        "iters": plan.iters,
        "compress_schedule": plan.compress_schedule,
        "seeds": plan.seeds,
        "rows": rows,
        "verdicts": verdicts,
        "magnitude": super::magnitude::scoped(plan, rows),
    });
    serde_json::to_string_pretty(&v).expect("serialisable")
}

/// Write `results.csv`, `results.json` and `tables.md` into `out`; returns the verdicts.
pub fn write_all(
    plan: &Plan,
    out: &Path,
    preset_help: &[(String, String)],
    extra: &str,
) -> Result<(Vec<Row>, Vec<Verdict>, Doc)> {
    let rows = gather(plan, out);
    let v = verdicts(plan, &rows);
    let w = |name: &str, text: &str| -> Result<()> {
        let p = out.join(name);
        std::fs::write(&p, text).map_err(|e| Error::io(&p, e))
    };
    w("results.csv", &to_csv(&rows))?;
    w("results.json", &to_json(plan, &rows, &v))?;
    let doc = tables(plan, &rows, &v, preset_help, extra);
    w("tables.md", &doc.to_markdown())?;
    Ok((rows, v, doc))
}

#[cfg(test)]
mod whole;

#[cfg(test)]
mod tests {
    use super::{pm_sig, provenance, results_part, without_result, Row, WHAT_RUNS};
    use crate::doc::{Block, Doc};

    #[test]
    fn the_terminal_part_ends_before_what_each_row_runs() {
        let mut d = Doc::new();
        d.heading(1, "t");
        d.heading(2, "ds");
        d.para("p");
        d.heading(2, WHAT_RUNS);
        d.list(vec!["x".into()]);
        d.heading(2, "Verdicts");
        assert_eq!(results_part(&d).blocks, d.blocks[..3]);
        // Without that heading: everything.
        d.blocks.remove(3);
        assert_eq!(results_part(&d), d);
    }

    #[test]
    fn a_data_condition_s_dataset_is_named_beside_its_checksum() {
        let row = |cond: Option<(&str, &str)>, sum: &str| Row {
            dataset: "d".into(),
            condition: cond.map(|c| c.0.into()),
            condition_value: cond.map(|c| c.1.into()),
            dataset_checksum: Some(sum.into()),
            ..Default::default()
        };
        let rows = [
            row(None, "aaaa"),
            row(Some(("pose-noise", "0.1")), "bbbb"),
            // A train condition runs on the base dataset.
            row(Some(("init", "acui")), "aaaa"),
            row(None, "aaaa"),
        ];
        let mut d = Doc::new();
        provenance(&mut d, &rows);
        let Some(Block::List(items)) = d.blocks.get(1) else {
            panic!("{d:?}")
        };
        assert_eq!(
            items[..2],
            [
                "dataset `d`: checksum aaaa".to_string(),
                "dataset `d` at pose-noise = 0.1: checksum bbbb".to_string()
            ]
        );
        assert_eq!(items.len(), 3, "{items:?}");
    }

    #[test]
    fn fps_keep_three_significant_digits() {
        assert_eq!(pm_sig(&[110.14, 110.16], 3), "110.2 ± 0.0");
        assert_eq!(pm_sig(&[1.93], 3), "1.93");
        assert_eq!(pm_sig(&[0.0817, 0.0817], 3), "0.0817 ± 0.0000");
        assert_eq!(pm_sig(&[0.0], 3), "0.00");
        assert_eq!(pm_sig(&[], 3), "-");
    }

    #[test]
    fn cells_without_a_result_are_counted_and_listed_with_their_error_on_one_line() {
        let row = |dir: &str, status: &str, psnr: Option<f64>, err: Option<&str>| Row {
            run_dir: dir.into(),
            status: status.into(),
            psnr,
            error: err.map(Into::into),
            ..Default::default()
        };
        let rows = [
            row("runs/a", "done", Some(30.0), None),
            row("runs/b", "failed", None, Some("line one\nline two")),
            row("runs/c", "missing", None, None),
        ];
        let mut d = Doc::new();
        without_result(&mut d, &rows);
        assert_eq!(
            d.blocks,
            [
                Block::Heading(2, "Cells without a result (2 of 3)".into()),
                Block::List(vec![
                    "`runs/b`: failed: line one line two".into(),
                    "`runs/c`: missing".into()
                ])
            ]
        );
        // Every cell with a result: no section.
        let mut d = Doc::new();
        without_result(&mut d, &rows[..1]);
        assert!(d.blocks.is_empty());
    }

    #[test]
    fn each_distinct_build_and_machine_is_listed_once() {
        let row = |commit: &str, cores: usize| Row {
            version: Some("0.9".into()),
            git_commit: Some(commit.into()),
            cpu_model: Some("cpu".into()),
            cores: Some(cores),
            simd: Some("avx2".into()),
            threads: Some(2),
            ..Default::default()
        };
        // A row without a record (no version) adds no build line.
        let rows = [row("abc", 2), row("abc", 2), row("def", 4), Row::default()];
        let mut d = Doc::new();
        provenance(&mut d, &rows);
        let Some(Block::List(items)) = d.blocks.get(1) else {
            panic!("{d:?}")
        };
        assert_eq!(
            items[..2],
            [
                "unispine 0.9 (commit abc), CPU cpu (2 cores, SIMD avx2), 2 threads per run"
                    .to_string(),
                "unispine 0.9 (commit def), CPU cpu (4 cores, SIMD avx2), 2 threads per run"
                    .to_string()
            ]
        );
        assert_eq!(items.len(), 3, "{items:?}");
        assert_eq!(d.blocks[0], Block::Heading(2, "Provenance".into()));
    }
}
