//! Results of a plan: one [`Row`] per cell read back from its run folder (`metrics.json`,
//! `config.json`, `cell.json`), written as `results.csv` / `results.json`, and `tables.md`:
//! per dataset mean +- sd over seeds with n, the paper's numbers beside the matching rows, the
//! verdicts, and the provenance of every row.
//!
//! Longer than 600 lines: every section of `tables.md` is written here from the same rows, one
//! function per section, beside the row type they read.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::plan::Plan;
use super::provenance;
use super::run::{cells, read_record, Cell, Status};
use super::verdict::{self, Obs, Verdict};
use crate::error::{Error, Result};

/// One cell's result.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Row {
    pub index: usize,
    pub dataset: String,
    /// The paper dataset the dataset stands in for, if any.
    pub paper_dataset: Option<String>,
    pub method: String,
    /// The preset the method starts from.
    pub base: String,
    pub sweep_flag: Option<String>,
    pub sweep_value: Option<String>,
    /// The condition axis and value of the cell (None: the base point).
    pub condition: Option<String>,
    pub condition_value: Option<String>,
    pub seed: u64,
    pub iters: usize,
    /// `done`, `running`, `stopped`, `failed` or `missing` (no record).
    pub status: String,
    pub completed: bool,
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub train_time_s: Option<f64>,
    pub fps: Option<f64>,
    pub n_gaussians: Option<usize>,
    /// A compacting cell: Gaussians and test PSNR of its model before pruning (the unbounded
    /// model: bit-identical to a plain run's).
    pub unbounded_n: Option<usize>,
    pub unbounded_psnr: Option<f64>,
    pub peak_memory_mib: Option<f64>,
    /// Wall time of the child process (start-up, data load, training, final evaluation).
    pub wall_s: Option<f64>,
    pub error: Option<String>,
    /// Test PSNR at the evaluation iterations: (iteration, dB).
    pub curve: Vec<(usize, f64)>,
    pub run_dir: String,
    // Provenance.
    pub version: Option<String>,
    pub git_commit: Option<String>,
    pub dataset_checksum: Option<String>,
    pub config_hash: Option<String>,
    pub cpu_model: Option<String>,
    pub cores: Option<usize>,
    pub simd: Option<String>,
    pub threads: Option<usize>,
}

fn num(v: &serde_json::Value, k: &str) -> Option<f64> {
    v.get(k).and_then(|x| x.as_f64()).filter(|x| x.is_finite())
}

/// Read every cell of `plan` from `out`.
pub fn gather(plan: &Plan, out: &Path) -> Vec<Row> {
    cells(plan).iter().map(|c| read_row(plan, out, c)).collect()
}

fn read_row(plan: &Plan, out: &Path, c: &Cell) -> Row {
    let rel = c.rel_dir(plan);
    let dir = out.join(&rel);
    let rec = read_record(&dir);
    let metrics: Option<serde_json::Value> =
        crate::fsio::read_text_bounded(&dir.join("metrics.json"), crate::fsio::MAX_TEXT_BYTES)
            .ok()
            .and_then(|s| serde_json::from_str(&s).ok());
    let m = metrics.as_ref();
    let completed = m
        .and_then(|m| m.get("completed"))
        .and_then(|x| x.as_bool())
        .unwrap_or(false);
    let status = match &rec {
        None => "missing",
        Some(r) => match r.status {
            Status::Done => "done",
            Status::Running => "running",
            Status::Stopped => "stopped",
            Status::Failed => "failed",
        },
    };
    let curve = m
        .and_then(|m| m.get("evals"))
        .and_then(|e| e.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|p| {
                    Some((
                        p.get("iteration")?.as_u64()? as usize,
                        p.get("psnr")?.as_f64()?,
                    ))
                })
                .collect()
        })
        .unwrap_or_default();
    let ok = status == "done" && completed;
    Row {
        index: c.index,
        dataset: c.dataset.clone(),
        paper_dataset: plan
            .datasets
            .iter()
            .find(|d| d.name == c.dataset)
            .and_then(|d| d.paper.clone()),
        method: c.method.name.clone(),
        base: c.method.base.clone(),
        sweep_flag: plan.sweep.as_ref().map(|s| s.flag.clone()),
        sweep_value: c.sweep.clone(),
        condition: plan.point_label(c.point).map(|p| p.0),
        condition_value: plan.point_label(c.point).map(|p| p.1),
        seed: c.seed,
        iters: c.iters(plan),
        status: status.into(),
        completed,
        psnr: m.and_then(|m| num(m, "test_psnr")).filter(|_| ok),
        ssim: m.and_then(|m| num(m, "test_ssim")).filter(|_| ok),
        train_time_s: m.and_then(|m| num(m, "train_time_s")).filter(|_| ok),
        fps: m.and_then(|m| num(m, "render_fps")).filter(|_| ok),
        n_gaussians: m
            .and_then(|m| m.get("n_gaussians"))
            .and_then(|x| x.as_u64())
            .map(|x| x as usize)
            .filter(|_| ok),
        unbounded_n: m
            .and_then(|m| m.get("compaction"))
            .and_then(|c| c.get("n_before"))
            .and_then(|x| x.as_u64())
            .map(|x| x as usize)
            .filter(|_| ok),
        unbounded_psnr: m
            .and_then(|m| m.get("compaction"))
            .and_then(|c| num(c, "psnr_before"))
            .filter(|_| ok),
        peak_memory_mib: m
            .and_then(|m| num(m, "peak_memory_bytes"))
            .map(|b| b / (1024.0 * 1024.0)),
        wall_s: rec.as_ref().map(|r| r.wall_s).filter(|_| ok),
        error: rec.as_ref().and_then(|r| r.error.clone()),
        curve,
        run_dir: rel.display().to_string(),
        version: rec.as_ref().map(|r| r.machine.version.clone()),
        git_commit: rec.as_ref().map(|r| r.machine.git_commit.clone()),
        dataset_checksum: rec
            .as_ref()
            .map(|r| r.dataset_checksum.clone())
            .filter(|s| !s.is_empty()),
        config_hash: provenance::config_hash(&dir),
        cpu_model: rec.as_ref().map(|r| r.machine.cpu_model.clone()),
        cores: rec.as_ref().map(|r| r.machine.cores),
        simd: rec.as_ref().map(|r| r.machine.simd.clone()),
        threads: rec.as_ref().map(|r| r.threads),
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn o<T: ToString>(v: &Option<T>) -> String {
    v.as_ref().map(|x| x.to_string()).unwrap_or_default()
}

/// `results.csv`: one row per cell. Floats are written with Rust's shortest round-trip form, so
/// the file is bit-exact.
pub fn to_csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "index,dataset,paper_dataset,method,base,sweep_flag,sweep_value,condition,\
         condition_value,seed,iters,status,completed,psnr,ssim,train_time_s,fps,n_gaussians,\
         peak_memory_mib,wall_s,run_dir,version,git_commit,dataset_checksum,config_hash,\
         cpu_model,cores,simd,threads,error\n",
    );
    for r in rows {
        let f = [
            r.index.to_string(),
            r.dataset.clone(),
            o(&r.paper_dataset),
            r.method.clone(),
            r.base.clone(),
            o(&r.sweep_flag),
            o(&r.sweep_value),
            o(&r.condition),
            o(&r.condition_value),
            r.seed.to_string(),
            r.iters.to_string(),
            r.status.clone(),
            r.completed.to_string(),
            o(&r.psnr),
            o(&r.ssim),
            o(&r.train_time_s),
            o(&r.fps),
            o(&r.n_gaussians),
            o(&r.peak_memory_mib),
            o(&r.wall_s),
            r.run_dir.clone(),
            o(&r.version),
            o(&r.git_commit),
            o(&r.dataset_checksum),
            o(&r.config_hash),
            o(&r.cpu_model),
            o(&r.cores),
            o(&r.simd),
            o(&r.threads),
            o(&r.error),
        ];
        let line: Vec<String> = f.iter().map(|x| csv_field(x)).collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

/// ` @ axis = value` of a group's rows at a condition's value (empty at the base).
fn condition_suffix(rs: &[&Row]) -> String {
    match rs.first().map(|r| (&r.condition, &r.condition_value)) {
        Some((Some(a), Some(v))) => format!(" @ {a} = {v}"),
        _ => String::new(),
    }
}

/// Pairing observations for the verdicts: key = dataset / seed / sweep value. Rows at a
/// condition's value are left out: a plan's verdicts are those of its base point (the section
/// "Where each claim holds", [`super::holds`], gives the others).
pub fn observations(rows: &[Row]) -> Vec<Obs> {
    rows.iter()
        .filter(|r| r.condition.is_none())
        .filter_map(|r| {
            Some(Obs {
                key: format!("{}/{}/{}", r.dataset, r.seed, o(&r.sweep_value)),
                paper_dataset: r.paper_dataset.clone(),
                method: r.method.clone(),
                psnr: r.psnr?,
                train_time_s: r.train_time_s.unwrap_or(f64::NAN),
                fps: r.fps.unwrap_or(f64::NAN),
            })
        })
        .collect()
}

/// The verdicts of every claim the plan's methods touch.
pub fn verdicts(plan: &Plan, rows: &[Row]) -> Vec<Verdict> {
    let methods: Vec<String> = plan.methods.iter().map(|m| m.name.clone()).collect();
    let obs = observations(rows);
    verdict::claims_for(&methods)
        .iter()
        .map(|c| verdict::evaluate(c, &obs))
        .collect()
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

/// How a method is named in tables and charts: the plan's name, with ` (reduced)` when it runs
/// a reduced neural-field preset (its numbers are not those of the upstream configuration).
pub fn method_label(method: &str, base: &str) -> String {
    if crate::field::FieldConfig::is_reduced(base) && !method.contains("reduced") {
        format!("{method} (reduced)")
    } else {
        method.to_string()
    }
}

/// What a method row runs, in words.
pub fn describe(plan: &Plan, method: &str, preset_help: &[(String, String)]) -> String {
    let Some(m) = plan.methods.iter().find(|m| m.name == method) else {
        return String::new();
    };
    let base_help = preset_help
        .iter()
        .find(|p| p.0 == m.base)
        .map(|p| p.1.trim_end_matches('.').to_string())
        .unwrap_or_default();
    if m.args.is_empty() {
        format!("`{}` preset: {base_help}", m.base)
    } else {
        format!(
            "`{}` preset ({base_help}) with `{}`",
            m.base,
            m.args.join(" ")
        )
    }
}

/// Groups of rows: (dataset, method, sweep value, condition point) in plan order.
pub fn groups(rows: &[Row]) -> Vec<(String, String, Option<String>, Vec<&Row>)> {
    let mut g: Vec<(String, String, Option<String>, Vec<&Row>)> = Vec::new();
    for r in rows {
        match g.iter_mut().find(|x| {
            x.0 == r.dataset
                && x.1 == r.method
                && x.2 == r.sweep_value
                && x.3.first().is_some_and(|f| {
                    f.condition == r.condition && f.condition_value == r.condition_value
                })
        }) {
            Some(x) => x.3.push(r),
            None => g.push((
                r.dataset.clone(),
                r.method.clone(),
                r.sweep_value.clone(),
                vec![r],
            )),
        }
    }
    g
}

fn vals(rs: &[&Row], f: impl Fn(&Row) -> Option<f64>) -> Vec<f64> {
    rs.iter().filter_map(|r| f(r)).collect()
}

/// `tables.md`.
pub fn tables_md(
    plan: &Plan,
    rows: &[Row],
    verdicts: &[Verdict],
    preset_help: &[(String, String)],
    extra: &str,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# `unispine reproduce {}`: {} iterations{}, seeds {:?}\n",
        plan.name,
        plan.iters,
        if plan.compress_schedule {
            " (the paper's 20000-iteration schedule compressed)"
        } else {
            ""
        },
        plan.seeds
    );
    let _ = writeln!(
        s,
        "Test views: PSNR (dB) and SSIM as mean ± sd over seeds (n = completed runs); train time \
         = the training loop's wall time; fps = test views rendered per second. Paper: the \
         paper's own number for the corresponding row, measured on another machine (RTX 3090) \
         at another resolution (1024 x 1024 detector) with the full schedule: compare trends, \
         not values.\n"
    );
    let sweep_col = plan.sweep.as_ref().map(|s| s.flag.clone());
    for d in &plan.datasets {
        let g: Vec<_> = groups(rows).into_iter().filter(|x| x.0 == d.name).collect();
        if g.iter().all(|x| x.3.iter().all(|r| r.status == "missing")) {
            let _ = writeln!(s, "## {}: no results\n", d.name);
            continue;
        }
        let _ = writeln!(
            s,
            "## {}{}\n",
            d.name,
            d.paper
                .as_ref()
                .map(|p| format!(" (stands in for {p})"))
                .unwrap_or_default()
        );
        let _ = writeln!(
            s,
            "| method |{} n | PSNR (dB) | SSIM | train time (s) | fps | Gaussians | paper PSNR / SSIM / time (s) |",
            sweep_col.as_ref().map(|f| format!(" {f} |")).unwrap_or_default()
        );
        let _ = writeln!(
            s,
            "|---|{}---:|---:|---:|---:|---:|---:|---|",
            if sweep_col.is_some() { "---:|" } else { "" }
        );
        for (_, method, sv, rs) in &g {
            let n = rs.iter().filter(|r| r.psnr.is_some()).count();
            let base = rs.first().map(|r| r.base.as_str()).unwrap_or("");
            let paper = d
                .paper
                .as_ref()
                .and_then(|p| verdict::paper_row(p, base))
                .map(|p| format!("{:.2} / {:.4} / {:.0}", p.psnr, p.ssim, p.train_time_s))
                .unwrap_or_default();
            let gaussians = if crate::method::Baseline::parse(base).is_some() {
                "-".to_string()
            } else {
                pm(&vals(rs, |r| r.n_gaussians.map(|x| x as f64)), 0)
            };
            let _ = writeln!(
                s,
                "| {}{} |{} {n} of {} | {} | {} | {} | {} | {gaussians} | {paper} |",
                method_label(method, base),
                condition_suffix(rs),
                sv.as_ref().map(|v| format!(" {v} |")).unwrap_or_default(),
                rs.len(),
                pm(&vals(rs, |r| r.psnr), 2),
                pm(&vals(rs, |r| r.ssim), 4),
                pm(&vals(rs, |r| r.train_time_s), 1),
                pm_sig(&vals(rs, |r| r.fps), 3),
            );
        }
        s.push('\n');
    }
    // What each row runs.
    let _ = writeln!(s, "## What each method row runs\n");
    for m in &plan.methods {
        let _ = writeln!(
            s,
            "- **{}**: {}",
            m.name,
            describe(plan, &m.name, preset_help)
        );
    }
    s.push_str(&super::holds::describe_conditions(plan));
    let base_of = |m: &crate::reproduce::plan::MethodSpec| crate::method::Baseline::parse(&m.base);
    if plan.methods.iter().any(|m| base_of(m).is_none()) {
        let _ = writeln!(
            s,
            "\n{}: `unispine train --iters {}{}{}`.",
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
        );
    }
    if plan
        .methods
        .iter()
        .any(|m| matches!(base_of(m), Some(crate::method::Baseline::Field(_))))
    {
        let fdk = plan
            .methods
            .iter()
            .any(|m| base_of(m) == Some(crate::method::Baseline::Fdk));
        let _ = writeln!(
            s,
            "\nEvery neural-field cell: {}{}.",
            match plan.field_iters {
                Some(n) => format!("`unispine train --iters {n}`"),
                None => "the preset's own schedule".into(),
            },
            if fdk { "; FDK is one pass" } else { "" }
        );
    }
    s.push('\n');
    // Verdicts.
    let _ = writeln!(s, "## Verdicts on the paper's claims\n");
    let _ = writeln!(
        s,
        "| claim | A vs B | pairs | mean difference | 95 % interval | verdict |\n|---|---|---:|---:|---|---|"
    );
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
        let _ = writeln!(
            s,
            "| {} | {} vs {} | {} | {} | {} | **{}** |",
            v.claim.text,
            v.claim.a,
            v.claim.b,
            v.n,
            fmt(v.mean),
            if v.n >= 2 {
                format!("[{}, {}]", fmt(v.lo), fmt(v.hi))
            } else {
                "-".into()
            },
            v.word.as_str()
        );
    }
    let _ = writeln!(
        s,
        "\nPairs: cells of A and B that completed on the same dataset and seed{}; a claim the \
         paper makes for one dataset pairs only the plan datasets standing in for it. Accuracy: d = \
         PSNR(A) - PSNR(B); speed: d = ln(speed ratio), shown as the ratio, tested against the \
         paper's factor. Interval: paired t, mean(d) ± t(0.975, n-1) · sd(d) / sqrt(n). \
         Reproduced: the interval lies wholly above the paper's threshold (0 dB, or ln of the \
         factor); not reproduced: wholly below; otherwise inconclusive (also with fewer than 2 \
         pairs). Not tested: a method of the claim is not in this plan or has no completed \
         pair.\n",
        if plan.sweep.is_some() {
            " (and sweep value)"
        } else {
            ""
        }
    );
    s.push_str(&super::magnitude::section(plan, rows));
    s.push_str(&super::holds::section(plan, rows));
    // Cells that did not complete.
    let bad: Vec<&Row> = rows.iter().filter(|r| r.psnr.is_none()).collect();
    if !bad.is_empty() {
        let _ = writeln!(
            s,
            "## Cells without a result ({} of {})\n",
            bad.len(),
            rows.len()
        );
        for r in bad {
            let _ = writeln!(
                s,
                "- `{}`: {}{}",
                r.run_dir,
                r.status,
                r.error
                    .as_ref()
                    .map(|e| format!(": {}", e.replace('\n', " ")))
                    .unwrap_or_default()
            );
        }
        s.push('\n');
    }
    // Provenance.
    let _ = writeln!(s, "## Provenance\n");
    let mut seen: Vec<String> = Vec::new();
    for r in rows.iter().filter(|r| r.version.is_some()) {
        let line = format!(
            "unispine {} (commit {}), CPU {} ({} cores, SIMD {}), {} threads per run",
            o(&r.version),
            o(&r.git_commit),
            o(&r.cpu_model),
            o(&r.cores),
            o(&r.simd),
            o(&r.threads)
        );
        if !seen.contains(&line) {
            seen.push(line);
        }
    }
    for l in &seen {
        let _ = writeln!(s, "- {l}");
    }
    let mut ds_seen: Vec<String> = Vec::new();
    for r in rows {
        if let Some(c) = &r.dataset_checksum {
            let l = format!("dataset `{}`: checksum {c}", r.dataset);
            if !ds_seen.contains(&l) {
                ds_seen.push(l);
            }
        }
    }
    for l in &ds_seen {
        let _ = writeln!(s, "- {l}");
    }
    let _ = writeln!(
        s,
        "- per row (results.csv): version, git commit, dataset checksum, config hash, CPU, \
         cores, SIMD path, threads"
    );
    s.push_str(&super::compactness::section(rows));
    if !extra.is_empty() {
        s.push('\n');
        s.push_str(extra);
    }
    s
}

/// Which cells have no result (for `--collect` over partial results).
pub fn missing(rows: &[Row]) -> Vec<&Row> {
    rows.iter().filter(|r| r.psnr.is_none()).collect()
}

/// Write `results.csv`, `results.json` and `tables.md` into `out`; returns the verdicts.
pub fn write_all(
    plan: &Plan,
    out: &Path,
    preset_help: &[(String, String)],
    extra: &str,
) -> Result<(Vec<Row>, Vec<Verdict>, String)> {
    let rows = gather(plan, out);
    let v = verdicts(plan, &rows);
    let w = |name: &str, text: &str| -> Result<()> {
        let p = out.join(name);
        std::fs::write(&p, text).map_err(|e| Error::io(&p, e))
    };
    w("results.csv", &to_csv(&rows))?;
    w("results.json", &to_json(plan, &rows, &v))?;
    let md = tables_md(plan, &rows, &v, preset_help, extra);
    w("tables.md", &md)?;
    Ok((rows, v, md))
}

#[cfg(test)]
mod tests {
    use super::{method_label, pm_sig};

    #[test]
    fn fps_keep_three_significant_digits() {
        assert_eq!(pm_sig(&[110.14, 110.16], 3), "110.2 ± 0.0");
        assert_eq!(pm_sig(&[1.93], 3), "1.93");
        assert_eq!(pm_sig(&[0.0817, 0.0817], 3), "0.0817 ± 0.0000");
        assert_eq!(pm_sig(&[0.0], 3), "0.00");
        assert_eq!(pm_sig(&[], 3), "-");
    }

    #[test]
    fn reduced_field_presets_are_labelled_as_reduced() {
        assert_eq!(method_label("naf", "naf"), "naf (reduced)");
        assert_eq!(method_label("my-tf", "tensorf"), "my-tf (reduced)");
        assert_eq!(method_label("naf-full", "naf-full"), "naf-full");
        assert_eq!(method_label("unispine", "unispine"), "unispine");
        assert_eq!(method_label("fdk", "fdk"), "fdk");
    }
}
