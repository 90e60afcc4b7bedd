//! Reproduction plans: a TOML file naming datasets x methods x seeds with one schedule, parsed
//! with line-numbered errors, plus the built-in plans (`quick`, `table2`, `table1`, `stability`,
//! `compactness`, `budgets`, `gap` and their `-full` twins).
//!
//! Schema (every key but the marked ones is optional):
//!
//! ```toml
//! name = "ablation"                 # required
//! iters = 3000                      # required: training iterations of every cell
//! compress_schedule = true          # scale the paper's 20000-iteration schedule to `iters`
//! field_iters = "preset"            # neural-field cells: "preset" (their own schedule) or a
//!                                   # count; default `iters`
//! seeds = [0, 1, 2]                 # required
//! methods = ["3dgs", "unispine", "paper-sigmoid"]   # required: presets or variants below
//! floor_db = 20.0                   # stability map: cells below this test PSNR are marked
//! [train]                           # `unispine train` flags applied to every cell
//! preview_views = 0
//! [sweep]                           # one more axis: a `unispine train` flag and its values
//! flag = "train-views"
//! values = [5, 10, 25, 50]
//! [[conditions]]                   # axes varied one at a time from the base ([`conditions`])
//! axis = "pose-noise"
//! on = "data"                       # "data", "train" (a flag or `iters`) or "method"
//! flag = "pose-noise-deg"
//! base = 0
//! values = [0.05, 0.1]
//! [slurm]
//! cpus_per_task = 2
//! mem = "4G"
//! time = "02:00:00"
//! [[datasets]]
//! name = "ct-crop"                  # required
//! path = "ct128"                    # a folder written by `unispine data` (relative to the plan)
//! paper = "CTSpine3D"               # the paper's dataset this one stands in for (tables.md)
//! [[datasets]]
//! name = "phantom"
//! data = ["phantom", "--size", "64"]  # or: arguments of `unispine data`, built once
//! optional = true                   # skip the dataset (with a note) when it cannot be built
//! [variants.paper-sigmoid]          # a named method = a preset plus `unispine train` flags
//! base = "unispine"
//! color = "rirf-paper"
//! ```
//!
//! Keys of `[train]` and of a variant are `unispine train` flags without the leading `--`
//! (`_` and `-` are the same). Baseline cells (FDK, the neural fields) get `--seed`, fields
//! `--iters` from `field_iters`, and of `[train]` and the variant's flags only those a baseline
//! takes ([`crate::baseline::FLAGS`]): the rest are Gaussian training settings. Every error names the file, the line and the key, and is raised
//! before anything runs.
//!
//! Longer than 600 lines: the schema of every plan key and its parse-time check sit together,
//! so that a key and its error message cannot drift apart; the parts that stand alone
//! (conditions, `unispine train` flags, the tests) are files of their own.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::error::{Error, Result};

pub mod conditions;
pub mod names;
mod slurm_spec;
mod train_flags;

use slurm_spec::RawSlurm;
pub use slurm_spec::SlurmSpec;

use train_flags::{check_train_args, flags_to_args, value_arg, Flags};
pub use train_flags::{TrainSchema, HARNESS_FLAGS};

/// In `methods`: every preset this build's `unispine train --method` offers that the list does
/// not name itself.
pub const ALL_PRESETS: &str = "all-presets";

/// Where a dataset comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// A dataset folder (absolute, or resolved against the plan's folder).
    Path(PathBuf),
    /// Arguments of `unispine data` (without `--out`), built once into `OUT/datasets/NAME`.
    Data(Vec<String>),
}

/// One dataset of a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetSpec {
    pub name: String,
    pub source: Source,
    /// The paper's dataset this one stands in for (`CTSpine3D`, `FeSpine3D`), if any.
    pub paper: Option<String>,
    /// Skip (with a note) rather than fail when the dataset cannot be built or found.
    pub optional: bool,
}

/// A method of a plan: a preset, or a variant (preset + `unispine train` flags).
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSpec {
    pub name: String,
    pub base: String,
    /// `unispine train` arguments of the variant (`--flag`, value pairs flattened).
    pub args: Vec<String>,
}

/// One more axis of a plan: a `unispine train` flag and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    pub flag: String,
    pub values: Vec<String>,
}

/// A parsed, validated plan.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    pub name: String,
    pub iters: usize,
    pub compress_schedule: bool,
    /// Iterations of neural-field cells: `None` = each preset's own schedule.
    pub field_iters: Option<usize>,
    pub seeds: Vec<u64>,
    pub methods: Vec<MethodSpec>,
    pub datasets: Vec<DatasetSpec>,
    /// `unispine train` arguments for every cell.
    pub train_args: Vec<String>,
    pub sweep: Option<Sweep>,
    /// Axes varied one at a time from the base ([`conditions`]).
    pub conditions: Vec<conditions::Condition>,
    pub floor_db: Option<f64>,
    pub slurm: SlurmSpec,
    /// The TOML text the plan was parsed from (hashed into each cell's key).
    pub text: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlan {
    name: Spanned<String>,
    iters: Spanned<i64>,
    #[serde(default)]
    compress_schedule: bool,
    #[serde(default)]
    field_iters: Option<Spanned<toml::Value>>,
    seeds: Spanned<Vec<i64>>,
    methods: Spanned<Vec<Spanned<String>>>,
    #[serde(default)]
    datasets: Vec<Spanned<RawDataset>>,
    #[serde(default)]
    variants: BTreeMap<Spanned<String>, Spanned<Flags>>,
    #[serde(default)]
    train: Flags,
    #[serde(default)]
    sweep: Option<Spanned<RawSweep>>,
    #[serde(default)]
    conditions: Vec<Spanned<conditions::RawCondition>>,
    #[serde(default)]
    floor_db: Option<f64>,
    #[serde(default)]
    slurm: Option<RawSlurm>,
    #[serde(default)]
    description: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDataset {
    name: Spanned<String>,
    #[serde(default)]
    path: Option<Spanned<String>>,
    #[serde(default)]
    data: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    paper: Option<String>,
    #[serde(default)]
    optional: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSweep {
    flag: Spanned<String>,
    values: Vec<Spanned<toml::Value>>,
}

/// 1-based line of byte offset `at` in `text`.
pub fn line_of(text: &str, at: usize) -> usize {
    text.as_bytes()[..at.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// A plan error at a span: `FILE: field `KEY`: line N: MSG`.
fn err_at(file: &Path, text: &str, span: std::ops::Range<usize>, key: &str, msg: String) -> Error {
    Error::format(
        file,
        key,
        format!("line {}: {msg}", line_of(text, span.start)),
    )
}

impl Plan {
    /// Parse and validate plan text. `file` names it in errors; relative dataset paths are
    /// resolved against `base_dir`.
    pub fn parse(text: &str, file: &Path, base_dir: &Path, schema: &TrainSchema) -> Result<Plan> {
        let raw: RawPlan = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_of(text, s.start)).unwrap_or(0);
            Error::format(file, "plan", format!("line {line}: {}", e.message().trim()))
        })?;
        let _ = &raw.description;
        let name = raw.name.get_ref().trim().to_string();
        if let Err(m) = names::check(&name) {
            return Err(err_at(file, text, raw.name.span(), "name", m));
        }
        let iters = *raw.iters.get_ref();
        let max_iters = crate::train::settings::MAX_ITERATIONS as i64;
        if !(1..=max_iters).contains(&iters) {
            return Err(err_at(
                file,
                text,
                raw.iters.span(),
                "iters",
                format!("{iters} is outside [1, {max_iters}]"),
            ));
        }
        let field_iters = match &raw.field_iters {
            None => Some(iters as usize),
            Some(v) => match v.get_ref() {
                toml::Value::String(p) if p == "preset" => None,
                toml::Value::Integer(n)
                    if (1..=crate::field::MAX_ITERATIONS as i64).contains(n) =>
                {
                    Some(*n as usize)
                }
                _ => {
                    return Err(err_at(
                        file,
                        text,
                        v.span(),
                        "field_iters",
                        format!(
                            "must be \"preset\" or a count in [1, {}]",
                            crate::field::MAX_ITERATIONS
                        ),
                    ))
                }
            },
        };
        let mut seeds = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for &s in raw.seeds.get_ref() {
            if s < 0 || !seen.insert(s) {
                return Err(err_at(
                    file,
                    text,
                    raw.seeds.span(),
                    "seeds",
                    format!("seed {s} is negative or repeated"),
                ));
            }
            seeds.push(s as u64);
        }
        if seeds.is_empty() {
            return Err(err_at(
                file,
                text,
                raw.seeds.span(),
                "seeds",
                "is empty".into(),
            ));
        }
        let train_args = flags_to_args(file, text, "train", &raw.train, schema)?;
        // Variants.
        let mut variants: BTreeMap<String, MethodSpec> = BTreeMap::new();
        for (vname, body) in &raw.variants {
            let vn = vname.get_ref().clone();
            if let Err(m) = names::check(&vn) {
                return Err(err_at(
                    file,
                    text,
                    vname.span(),
                    "variants",
                    format!("variant name {vn:?} {m}"),
                ));
            }
            if let Some(other) = variants
                .keys()
                .chain(schema.methods.iter())
                .find(|o| **o != vn && names::normalise(o) == names::normalise(&vn))
            {
                return Err(err_at(
                    file,
                    text,
                    vname.span(),
                    &format!("variants.{vn}"),
                    format!("`{vn}` and `{other}` differ only in case (one folder on some disks)"),
                ));
            }
            if schema.methods.contains(&vn) {
                return Err(err_at(
                    file,
                    text,
                    vname.span(),
                    &format!("variants.{vn}"),
                    "a variant cannot reuse a preset's name".into(),
                ));
            }
            let mut flags = body.get_ref().clone();
            let Some(base) = flags.remove("base") else {
                return Err(err_at(
                    file,
                    text,
                    body.span(),
                    &format!("variants.{vn}"),
                    "missing `base` (the preset it starts from)".into(),
                ));
            };
            let b = match base.get_ref() {
                toml::Value::String(s) if schema.methods.contains(s) => s.clone(),
                other => {
                    return Err(err_at(
                        file,
                        text,
                        base.span(),
                        &format!("variants.{vn}.base"),
                        format!(
                            "unknown method {other} (this build offers: {})",
                            schema.methods.join(", ")
                        ),
                    ))
                }
            };
            let section = format!("variants.{vn}");
            let args = flags_to_args(file, text, &section, &flags, schema)?;
            if crate::method::Baseline::parse(&b).is_some() {
                if let Some((k, _)) = flags.iter().find(|(k, _)| {
                    !crate::baseline::FLAGS.contains(&k.get_ref().replace('_', "-").as_str())
                }) {
                    return Err(err_at(
                        file,
                        text,
                        k.span(),
                        &format!("{section}.{}", k.get_ref()),
                        format!(
                            "a Gaussian training setting: the baseline `{b}` takes only --{}",
                            crate::baseline::FLAGS.join(", --")
                        ),
                    ));
                }
            }
            let mut all = train_args.clone();
            all.extend(args.iter().cloned());
            if let Err(m) = check_train_args(&b, &all) {
                return Err(err_at(file, text, vname.span(), &section, m));
            }
            variants.insert(
                vn.clone(),
                MethodSpec {
                    name: vn,
                    base: b,
                    args,
                },
            );
        }
        // Methods.
        let mut methods = Vec::new();
        let mut names: Vec<Spanned<String>> = Vec::new();
        for m in raw.methods.get_ref() {
            if m.get_ref() == ALL_PRESETS {
                for p in &schema.methods {
                    let listed = raw.methods.get_ref().iter().any(|x| x.get_ref() == p);
                    if !listed && !names.iter().any(|x| x.get_ref() == p) {
                        names.push(Spanned::new(m.span(), p.clone()));
                    }
                }
            } else {
                names.push(m.clone());
            }
        }
        for m in &names {
            let n = m.get_ref();
            let spec = if let Some(v) = variants.get(n) {
                v.clone()
            } else if schema.methods.contains(n) {
                MethodSpec {
                    name: n.clone(),
                    base: n.clone(),
                    args: vec![],
                }
            } else {
                return Err(err_at(
                    file,
                    text,
                    m.span(),
                    "methods",
                    format!(
                        "unknown method `{n}`: neither a preset of this build ({}) nor a \
                         [variants.{n}] table",
                        schema.methods.join(", ")
                    ),
                ));
            };
            if methods
                .iter()
                .any(|x: &MethodSpec| names::normalise(&x.name) == names::normalise(n))
            {
                return Err(err_at(
                    file,
                    text,
                    m.span(),
                    "methods",
                    format!("`{n}` is listed twice"),
                ));
            }
            methods.push(spec);
        }
        if methods.is_empty() {
            return Err(err_at(
                file,
                text,
                raw.methods.span(),
                "methods",
                "is empty".into(),
            ));
        }
        if let Err(m) = check_train_args("unispine", &train_args) {
            return Err(Error::format(file, "train", m));
        }
        // Datasets.
        let mut datasets: Vec<DatasetSpec> = Vec::new();
        for d in &raw.datasets {
            let dn = d.get_ref().name.get_ref().clone();
            let key = format!("datasets.{dn}");
            let at_d = |msg: String| err_at(file, text, d.span(), &key, msg);
            if let Err(m) = names::check(&dn) {
                return Err(err_at(
                    file,
                    text,
                    d.get_ref().name.span(),
                    "datasets.name",
                    format!("{dn:?} {m}"),
                ));
            }
            if datasets
                .iter()
                .any(|x| names::normalise(&x.name) == names::normalise(&dn))
            {
                return Err(at_d(format!("dataset `{dn}` is listed twice")));
            }
            let raw_d = d.get_ref();
            let source =
                match (&raw_d.path, &raw_d.data) {
                    (Some(p), None) => {
                        let pb = PathBuf::from(p.get_ref());
                        let full = if pb.is_absolute() {
                            pb
                        } else {
                            base_dir.join(pb)
                        };
                        if !raw_d.optional && !full.join("dataset.json").is_file() {
                            return Err(err_at(
                                file,
                                text,
                                p.span(),
                                &format!("{key}.path"),
                                format!(
                                    "{} is not a dataset folder (no dataset.json; make one with \
                                 `unispine data`)",
                                    full.display()
                                ),
                            ));
                        }
                        Source::Path(full)
                    }
                    (None, Some(a)) => {
                        if a.get_ref().is_empty() {
                            return Err(at_d("`data` is empty".into()));
                        }
                        if a.get_ref().iter().any(|x| x == "--out") {
                            return Err(at_d(
                                "`data` must not contain --out (the plan chooses it)".into(),
                            ));
                        }
                        Source::Data(a.get_ref().clone())
                    }
                    _ => return Err(at_d(
                        "give exactly one of `path` (a dataset folder) or `data` (arguments of \
                         `unispine data`)"
                            .into(),
                    )),
                };
            datasets.push(DatasetSpec {
                name: dn,
                source,
                paper: raw_d.paper.clone(),
                optional: raw_d.optional,
            });
        }
        if datasets.is_empty() {
            return Err(Error::format(
                file,
                "datasets",
                "missing: give at least one [[datasets]] table",
            ));
        }
        // Sweep.
        let sweep = match &raw.sweep {
            None => None,
            Some(s) => {
                let s_ref = s.get_ref();
                let key = s_ref.flag.get_ref();
                let mut map = BTreeMap::new();
                map.insert(
                    s_ref.flag.clone(),
                    Spanned::new(s.span(), toml::Value::Integer(0)),
                );
                // Reuse the flag checks (unknown / harness flags) with a dummy value.
                flags_to_args(file, text, "sweep.flag", &map, schema)?;
                let flag = key.replace('_', "-");
                let mut values = Vec::new();
                for v in &s_ref.values {
                    let a = value_arg(v.get_ref())
                        .map_err(|m| err_at(file, text, v.span(), "sweep.values", m))?;
                    if let Err(m) = names::check_value(&a) {
                        return Err(err_at(
                            file,
                            text,
                            v.span(),
                            "sweep.values",
                            format!("value {a:?} {m}"),
                        ));
                    }
                    if let Some(prev) = values
                        .iter()
                        .find(|p: &&String| names::normalise_value(p) == names::normalise_value(&a))
                    {
                        return Err(err_at(
                            file,
                            text,
                            v.span(),
                            "sweep.values",
                            format!("{a:?} repeats {prev:?} (two cells would share one folder)"),
                        ));
                    }
                    let mut args = train_args.clone();
                    args.push(format!("--{flag}"));
                    args.push(a.clone());
                    if let Err(m) = check_train_args("unispine", &args) {
                        return Err(err_at(file, text, v.span(), "sweep.values", m));
                    }
                    values.push(a);
                }
                if values.is_empty() {
                    return Err(err_at(
                        file,
                        text,
                        s.span(),
                        "sweep.values",
                        "is empty".into(),
                    ));
                }
                if let Some(m) = methods.iter().find(|m| {
                    crate::method::Baseline::parse(&m.base).is_some()
                        && !crate::baseline::FLAGS.contains(&flag.as_str())
                }) {
                    return Err(err_at(
                        file,
                        text,
                        s_ref.flag.span(),
                        "sweep.flag",
                        format!(
                            "`{flag}` is a Gaussian training setting: the baseline `{}` cannot \
                             follow the sweep (baselines take --{})",
                            m.name,
                            crate::baseline::FLAGS.join(", --")
                        ),
                    ));
                }
                Some(Sweep { flag, values })
            }
        };
        let conditions = conditions::parse(
            &raw.conditions,
            &conditions::Ctx {
                file,
                text,
                schema,
                train_args: &train_args,
                methods: &methods,
                variants: &variants,
                datasets: &datasets,
            },
        )?;
        let slurm = match raw.slurm {
            None => SlurmSpec::default(),
            Some(s) => SlurmSpec::from_raw(s, file, text)?,
        };
        Ok(Plan {
            name,
            iters: iters as usize,
            compress_schedule: raw.compress_schedule,
            field_iters,
            seeds,
            methods,
            datasets,
            train_args,
            sweep,
            conditions,
            floor_db: raw.floor_db,
            slurm,
            text: text.to_string(),
        })
    }

    /// Read a plan: a built-in name ([`builtin`]) or a TOML file.
    pub fn load(name_or_path: &str, schema: &TrainSchema) -> Result<Plan> {
        if let Some(text) = builtin(name_or_path) {
            let file = PathBuf::from(format!("<built-in plan {name_or_path}>"));
            return Plan::parse(text, &file, Path::new("."), schema);
        }
        let p = Path::new(name_or_path);
        if std::fs::symlink_metadata(p).is_err() && !name_or_path.ends_with(".toml") {
            return Err(Error::invalid(
                "PLAN",
                format!(
                    "`{name_or_path}` is neither a built-in plan ({}) nor a file",
                    BUILTIN.iter().map(|b| b.0).collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        let text = crate::fsio::read_text_bounded(p, MAX_PLAN_BYTES)?;
        let base = p.parent().unwrap_or(Path::new(".")).to_path_buf();
        Plan::parse(&text, p, &base, schema)
    }
}

/// Largest plan file read: 1 MiB.
pub const MAX_PLAN_BYTES: u64 = 1 << 20;

/// Most cells a plan may have unless raised (`unispine reproduce --max-cells N`).
pub const DEFAULT_MAX_CELLS: usize = 10_000;

impl Plan {
    /// Number of cells (datasets x methods, each at the base and at the values of the
    /// conditions acting on it, x sweep values x seeds), saturating.
    pub fn n_cells(&self) -> usize {
        [
            self.datasets.len(),
            self.method_points(),
            self.sweep.as_ref().map_or(1, |s| s.values.len()),
            self.seeds.len(),
        ]
        .iter()
        .fold(1usize, |a, &b| a.saturating_mul(b))
    }

    /// Error when the plan has more than `max` cells (before any cell is listed or run).
    pub fn check_cells(&self, max: usize) -> Result<()> {
        let n = self.n_cells();
        if n > max {
            return Err(Error::invalid(
                "--max-cells",
                format!(
                    "plan `{}` has {n} cells ({} datasets x {} methods (with their condition values) x {} sweep values x {} seeds), more than the {max} allowed; raise the limit with --max-cells {n} if that is meant",
                    self.name,
                    self.datasets.len(),
                    self.method_points(),
                    self.sweep.as_ref().map_or(1, |s| s.values.len()),
                    self.seeds.len()
                ),
            ));
        }
        Ok(())
    }
}

/// The built-in plans: name and TOML text.
pub const BUILTIN: [(&str, &str); 14] = [
    ("quick", include_str!("../plans/quick.toml")),
    ("table2", include_str!("../plans/table2.toml")),
    ("table2-full", include_str!("../plans/table2-full.toml")),
    ("table1", include_str!("../plans/table1.toml")),
    ("table1-full", include_str!("../plans/table1-full.toml")),
    ("stability", include_str!("../plans/stability.toml")),
    (
        "stability-full",
        include_str!("../plans/stability-full.toml"),
    ),
    ("compactness", include_str!("../plans/compactness.toml")),
    (
        "compactness-full",
        include_str!("../plans/compactness-full.toml"),
    ),
    ("budgets", include_str!("../plans/budgets.toml")),
    ("budgets-full", include_str!("../plans/budgets-full.toml")),
    ("quick-full", include_str!("../plans/quick-full.toml")),
    ("gap", include_str!("../plans/gap.toml")),
    ("gap-full", include_str!("../plans/gap-full.toml")),
];

/// The TOML text of a built-in plan.
pub fn builtin(name: &str) -> Option<&'static str> {
    BUILTIN.iter().find(|b| b.0 == name).map(|b| b.1)
}

#[cfg(test)]
pub(crate) mod tests;
