//! Results of a plan: one [`Row`] per cell read back from its run folder (`metrics.json`,
//! `config.json`, `cell.json`), as CSV, the pairing observations and the verdicts, the groups
//! of rows a table shows, and how a method is named. [`super::tables`] writes them out.

use std::path::Path;

use serde::Serialize;

use super::plan::Plan;
use super::provenance;
use super::run::{cells, read_record, Cell, Status};
use super::verdict::{self, Obs, Verdict};

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

pub(super) fn o<T: ToString>(v: &Option<T>) -> String {
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
pub(super) fn condition_suffix(rs: &[&Row]) -> String {
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

/// Which cells have no result (for `--collect` over partial results).
pub fn missing(rows: &[Row]) -> Vec<&Row> {
    rows.iter().filter(|r| r.psnr.is_none()).collect()
}

#[cfg(test)]
mod tests {
    use super::{condition_suffix, describe, gather, groups, method_label, missing, to_csv, Row};
    use crate::reproduce::plan::Plan;
    use std::path::Path;

    /// Rows at a condition's value form their own group, labelled ` @ axis = value`; rows at
    /// the base point are a group without a label; another dataset, method or sweep value is
    /// another group.
    #[test]
    fn rows_at_a_condition_are_grouped_and_labelled_apart() {
        let row = |seed, cond: Option<(&str, &str)>| Row {
            dataset: "d".into(),
            method: "m".into(),
            seed,
            condition: cond.map(|c| c.0.to_string()),
            condition_value: cond.map(|c| c.1.to_string()),
            ..Default::default()
        };
        let mut other_method = row(2, None);
        other_method.method = "n".into();
        let mut other_dataset = row(3, None);
        other_dataset.dataset = "e".into();
        let mut other_sweep = row(4, None);
        other_sweep.sweep_value = Some("0.1".into());
        let rows = [
            row(0, None),
            row(0, Some(("views", "25"))),
            row(1, None),
            row(1, Some(("views", "25"))),
            row(0, Some(("views", "10"))),
            other_method,
            other_dataset,
            other_sweep,
        ];
        let g = groups(&rows);
        let labels: Vec<(String, Vec<u64>)> = g
            .iter()
            .map(|x| (condition_suffix(&x.3), x.3.iter().map(|r| r.seed).collect()))
            .collect();
        assert_eq!(
            labels,
            [
                (String::new(), vec![0, 1]),
                (" @ views = 25".to_string(), vec![0, 1]),
                (" @ views = 10".to_string(), vec![0]),
                (String::new(), vec![2]),
                (String::new(), vec![3]),
                (String::new(), vec![4]),
            ]
        );
    }

    /// A method row in words: its preset's help, and the flags a variant adds.
    #[test]
    fn methods_are_described_by_their_preset_and_flags() {
        let text = "name = \"t\"\niters = 10\nseeds = [0]\nmethods = [\"unispine\", \"v\"]\n\
                    [[datasets]]\nname = \"ph\"\ndata = [\"phantom\", \"--size\", \"16\"]\n\
                    [variants.v]\nbase = \"xgaussian\"\ncolor = \"rirf-paper\"\n";
        let plan = plan(text);
        let help = [
            ("xgaussian".to_string(), "X-Gaussian's RIRF.".to_string()),
            ("unispine".to_string(), "the full method.".to_string()),
        ];
        assert_eq!(
            describe(&plan, "unispine", &help),
            "`unispine` preset: the full method"
        );
        assert_eq!(
            describe(&plan, "v", &help),
            "`xgaussian` preset (X-Gaussian's RIRF) with `--color rirf-paper`"
        );
        assert_eq!(describe(&plan, "absent", &help), "");
    }

    /// A plan from its TOML text (no dataset is built).
    fn plan(text: &str) -> Plan {
        crate::reproduce::plan::tests::parse(text).unwrap()
    }

    /// A run folder written here from the documented files (`cell.json`, `metrics.json`).
    fn write_cell(dir: &Path, status: &str, completed: bool, psnr: f64) {
        std::fs::create_dir_all(dir).unwrap();
        let cell = format!(
            r#"{{"key": "k", "status": "{status}", "args": [], "dataset_checksum": "c0ffee",
                "wall_s": 2.5, "error": null, "threads": 3, "machine": {{"cpu_model": "cpu",
                "cores": 4, "simd": "avx2", "version": "0.1.0", "git_commit": "abc"}}}}"#
        );
        std::fs::write(dir.join("cell.json"), cell).unwrap();
        let metrics = format!(
            r#"{{"completed": {completed}, "test_psnr": {psnr}, "test_ssim": 0.75,
                "train_time_s": 12.0, "render_fps": 40.0, "n_gaussians": 7,
                "peak_memory_bytes": 3145728, "evals": [{{"iteration": 5, "psnr": 20.0}}]}}"#
        );
        std::fs::write(dir.join("metrics.json"), metrics).unwrap();
    }

    /// Each row reads its own cell's folder, names its dataset's paper dataset, and keeps the
    /// figures only of a run that both the record (`done`) and the metrics (`completed`) call
    /// finished; provenance and peak memory are kept for every run that has them.
    #[test]
    fn gather_keeps_the_figures_of_finished_runs_only() {
        let tmp = tempfile::tempdir().unwrap();
        let text = "name = \"t\"\niters = 10\nseeds = [0, 1]\nmethods = [\"unispine\"]\n\
                    [[datasets]]\nname = \"a\"\npaper = \"CTSpine3D\"\n\
                    data = [\"phantom\", \"--size\", \"16\"]\n\
                    [[datasets]]\nname = \"b\"\npaper = \"FeSpine3D\"\n\
                    data = [\"phantom\", \"--size\", \"16\"]\n";
        let plan = plan(text);
        let out = tmp.path();
        let run = |d: &str, s: u64| out.join(format!("runs/{d}/unispine/seed{s}"));
        write_cell(&run("a", 0), "done", true, 30.5);
        write_cell(&run("a", 1), "stopped", true, 31.5);
        write_cell(&run("b", 0), "done", false, 32.5);
        let rows = gather(&plan, out);
        let got: Vec<_> = rows
            .iter()
            .map(|r| {
                (
                    r.dataset.as_str(),
                    r.seed,
                    r.paper_dataset.as_deref(),
                    r.status.as_str(),
                    r.psnr,
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                ("a", 0, Some("CTSpine3D"), "done", Some(30.5)),
                ("a", 1, Some("CTSpine3D"), "stopped", None),
                ("b", 0, Some("FeSpine3D"), "done", None),
                ("b", 1, Some("FeSpine3D"), "missing", None),
            ]
        );
        let r = &rows[0];
        assert_eq!(
            (r.ssim, r.train_time_s, r.fps, r.n_gaussians, r.wall_s),
            (Some(0.75), Some(12.0), Some(40.0), Some(7), Some(2.5))
        );
        assert_eq!(r.curve, [(5, 20.0)]);
        for r in &rows[..3] {
            assert_eq!(r.peak_memory_mib, Some(3.0));
            assert_eq!(r.threads, Some(3));
            assert_eq!(r.cores, Some(4));
            assert_eq!(r.dataset_checksum.as_deref(), Some("c0ffee"));
        }
        assert_eq!(rows[1].wall_s, None);
        assert_eq!(rows[3].peak_memory_mib, None);
    }

    #[test]
    fn reduced_field_presets_are_labelled_as_reduced() {
        assert_eq!(method_label("naf", "naf"), "naf (reduced)");
        assert_eq!(method_label("my-tf", "tensorf"), "my-tf (reduced)");
        assert_eq!(method_label("naf-full", "naf-full"), "naf-full");
        assert_eq!(method_label("unispine", "unispine"), "unispine");
        assert_eq!(method_label("fdk", "fdk"), "fdk");
    }

    /// RFC 4180 read back, written from the RFC: fields split at commas outside quotes, a
    /// quoted field's `""` is one quote, records end at a line break outside quotes.
    fn read_csv(text: &str) -> Vec<Vec<String>> {
        let (mut recs, mut rec, mut f) = (Vec::new(), Vec::new(), String::new());
        let (mut quoted, mut chars) = (false, text.chars().peekable());
        while let Some(c) = chars.next() {
            match (quoted, c) {
                (true, '"') if chars.peek() == Some(&'"') => {
                    chars.next();
                    f.push('"');
                }
                (true, '"') => quoted = false,
                (true, c) => f.push(c),
                (false, '"') => quoted = true,
                (false, ',') => rec.push(std::mem::take(&mut f)),
                (false, '\n') => {
                    rec.push(std::mem::take(&mut f));
                    recs.push(std::mem::take(&mut rec));
                }
                (false, c) => f.push(c),
            }
        }
        recs
    }

    /// Every text survives the CSV (commas, quotes and line breaks quoted) and every float
    /// reads back to the same bits.
    #[test]
    fn results_csv_reads_back_field_for_field() {
        let row = Row {
            index: 3,
            dataset: "ct, crop".into(),
            method: "say \"hi\"".into(),
            seed: 7,
            status: "failed".into(),
            psnr: Some(0.1 + 0.2),
            fps: Some(1e-300),
            cpu_model: Some("AMD EPYC 9R14, 2 cores".into()),
            error: Some("exit status 3:\nboom, \"bad\"".into()),
            ..Default::default()
        };
        let recs = read_csv(&to_csv(&[row.clone(), Row::default()]));
        assert_eq!(recs.len(), 3);
        let head = &recs[0];
        assert_eq!(head.len(), 30);
        assert!(recs.iter().all(|r| r.len() == 30), "{recs:?}");
        let get = |k: &str| {
            let i = head.iter().position(|h| h == k).unwrap();
            recs[1][i].clone()
        };
        assert_eq!(get("index"), "3");
        assert_eq!(get("dataset"), "ct, crop");
        assert_eq!(get("method"), "say \"hi\"");
        assert_eq!(get("cpu_model"), "AMD EPYC 9R14, 2 cores");
        assert_eq!(get("error"), "exit status 3:\nboom, \"bad\"");
        assert_eq!(
            get("psnr").parse::<f64>().unwrap().to_bits(),
            (0.1f64 + 0.2).to_bits()
        );
        assert_eq!(get("fps").parse::<f64>().unwrap(), 1e-300);
        assert_eq!((get("ssim"), get("seed")), (String::new(), "7".into()));
    }

    /// The rows without a test PSNR, in order (what `--collect` lists as missing).
    #[test]
    fn missing_rows_are_those_without_a_result() {
        let r = |index, psnr| Row {
            index,
            psnr,
            ..Default::default()
        };
        let rows = [
            r(0, Some(1.0)),
            r(1, None),
            r(2, Some(f64::NAN)),
            r(3, None),
        ];
        let m: Vec<usize> = missing(&rows).iter().map(|r| r.index).collect();
        assert_eq!(m, [1, 3]);
    }
}
