//! Conditions: axes a plan varies **one at a time** from a base (pose error of the recorded
//! cameras, the initialiser, the preset of a baseline, the detector size, the schedule length).
//!
//! ```toml
//! [[conditions]]
//! axis = "pose-noise"          # a name (the name rule of [`super::names`]); in folder names
//! on = "data"                  # "data": a `unispine data` flag, each value a dataset built once
//! flag = "pose-noise-deg"      #   and shared by the cells at that value
//! base = 0                     # the value of every other cell (optional)
//! values = [0.05, 0.1, 0.2]    # the values tried, each with every other axis at its base
//! [[conditions]]
//! axis = "init"
//! on = "train"                 # "train": a `unispine train` flag (or `iters`: the schedule)
//! flag = "init"
//! methods = ["3dgs"]           # the methods it acts on (default: every method)
//! values = ["acui"]
//! [[conditions]]
//! axis = "preset"
//! on = "method"                # "method": the listed methods are replaced by a preset or a
//! methods = ["3dgs"]           #   [variants.X] of the plan, under the method's own name
//! values = ["3dgs-vanilla"]
//! ```
//!
//! The cells of a plan with conditions: per dataset (x sweep value x seed), every method at the
//! base point, then for each condition and each of its values the methods it acts on. A method
//! a condition does not act on is represented at that condition's points by its base cell (the
//! pairs of the claims use it). Every value follows the name rule of sweep values and the flag's
//! schema (`unispine train`'s parser; for data flags, the kinds of [`DATA_FLAGS`]). Errors name the plan file, the key and the line.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use super::train_flags::{check_train_args, flags_to_args, value_arg, TrainSchema};
use super::{err_at, names, DatasetSpec, MethodSpec, Source};
use crate::error::Result;

/// What a condition acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// A `unispine data` flag: one dataset per value.
    Data,
    /// A `unispine train` flag (or `iters`, the schedule length).
    Train,
    /// The method itself: listed methods replaced by a preset or variant.
    Method,
}

impl Target {
    pub fn as_str(self) -> &'static str {
        match self {
            Target::Data => "data",
            Target::Train => "train",
            Target::Method => "method",
        }
    }
}

/// The kind of value a data flag takes (checked at parse time).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A finite number >= 0.
    NonNegative,
    /// A finite number > 0.
    Positive,
    /// An integer >= 1.
    Count,
    /// An integer >= 0.
    Seed,
    /// Text (checked by `unispine data` itself).
    Text,
}

/// The `unispine data` flags a condition may vary, with the kind of their values: flags every
/// generator subcommand takes (`unispine data` itself checks the whole argument list when the
/// dataset is built).
pub const DATA_FLAGS: [(&str, Kind); 10] = [
    ("pose-noise-deg", Kind::NonNegative),
    ("pose-noise-mm", Kind::NonNegative),
    ("pose-seed", Kind::Seed),
    ("detector", Kind::Count),
    ("train-views", Kind::Count),
    ("test-views", Kind::Count),
    ("span-deg", Kind::Positive),
    ("noise", Kind::Text),
    ("seed", Kind::Seed),
    ("margin", Kind::NonNegative),
];

/// The flag of a train condition that sets the schedule length (the plan's `iters`).
pub const ITERS: &str = "iters";

/// One condition of a plan (see the module header).
#[derive(Clone, Debug, PartialEq)]
pub struct Condition {
    pub axis: String,
    pub on: Target,
    /// The flag (without `--`; `iters` for the schedule; empty for [`Target::Method`]).
    pub flag: String,
    /// The value every cell not at this axis's points gets (None: the flag is not set).
    pub base: Option<String>,
    pub values: Vec<String>,
    /// The methods it acts on (plan method names).
    pub methods: Vec<String>,
    /// For [`Target::Method`]: the method each value stands for (preset or variant).
    pub replacements: Vec<MethodSpec>,
}

impl Condition {
    /// Whether this condition acts on the plan method `m`.
    pub fn acts_on(&self, m: &str) -> bool {
        self.methods.iter().any(|x| x == m)
    }
    /// The label of the base point on this axis.
    pub fn base_label(&self) -> String {
        match (&self.base, self.on) {
            (Some(b), _) => b.clone(),
            (None, Target::Method) => "own preset".into(),
            (None, _) => "default".into(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCondition {
    axis: Spanned<String>,
    on: Spanned<String>,
    #[serde(default)]
    flag: Option<Spanned<String>>,
    #[serde(default)]
    base: Option<Spanned<toml::Value>>,
    values: Spanned<Vec<Spanned<toml::Value>>>,
    #[serde(default)]
    methods: Option<Spanned<Vec<Spanned<String>>>>,
}

/// Check a data flag's value against its kind.
fn check_kind(kind: Kind, v: &str) -> std::result::Result<(), String> {
    let num = v.parse::<f64>().ok().filter(|x| x.is_finite());
    let int = v.parse::<u64>().ok();
    match kind {
        Kind::NonNegative if num.is_some_and(|x| x >= 0.0) => Ok(()),
        Kind::NonNegative => Err(format!("{v:?} is not a finite number >= 0")),
        Kind::Positive if num.is_some_and(|x| x > 0.0) => Ok(()),
        Kind::Positive => Err(format!("{v:?} is not a finite number > 0")),
        Kind::Count if int.is_some_and(|x| x >= 1) => Ok(()),
        Kind::Count => Err(format!("{v:?} is not an integer >= 1")),
        Kind::Seed if int.is_some() => Ok(()),
        Kind::Seed => Err(format!("{v:?} is not an integer >= 0")),
        Kind::Text => Ok(()),
    }
}

/// Everything a condition is checked against.
pub(super) struct Ctx<'a> {
    pub file: &'a Path,
    pub text: &'a str,
    pub schema: &'a TrainSchema,
    pub train_args: &'a [String],
    pub methods: &'a [MethodSpec],
    pub variants: &'a BTreeMap<String, MethodSpec>,
    pub datasets: &'a [DatasetSpec],
}

/// Parse and check the plan's `[[conditions]]`.
pub(super) fn parse(raw: &[Spanned<RawCondition>], cx: &Ctx) -> Result<Vec<Condition>> {
    let mut out: Vec<Condition> = Vec::new();
    for rc in raw {
        let c = parse_one(rc, cx)?;
        if let Some(prev) = out
            .iter()
            .find(|p| names::normalise(&p.axis) == names::normalise(&c.axis))
        {
            return Err(err_at(
                cx.file,
                cx.text,
                rc.get_ref().axis.span(),
                "conditions.axis",
                format!("axis `{}` repeats `{}`", c.axis, prev.axis),
            ));
        }
        if let Some(prev) = out
            .iter()
            .find(|p| p.on == c.on && c.on != Target::Method && p.flag == c.flag)
        {
            return Err(err_at(
                cx.file,
                cx.text,
                rc.span(),
                &format!("conditions.{}", c.axis),
                format!(
                    "flag `{}` is already the axis `{}` (one axis per flag)",
                    c.flag, prev.axis
                ),
            ));
        }
        out.push(c);
    }
    Ok(out)
}

fn parse_one(rc: &Spanned<RawCondition>, cx: &Ctx) -> Result<Condition> {
    let r = rc.get_ref();
    let axis = r.axis.get_ref().clone();
    let at = |span: std::ops::Range<usize>, key: &str, msg: String| {
        err_at(cx.file, cx.text, span, key, msg)
    };
    if let Err(m) = names::check(&axis) {
        return Err(at(
            r.axis.span(),
            "conditions.axis",
            format!("axis name {axis:?} {m}"),
        ));
    }
    let key = format!("conditions.{axis}");
    let on = match r.on.get_ref().as_str() {
        "data" => Target::Data,
        "train" => Target::Train,
        "method" => Target::Method,
        other => {
            return Err(at(
                r.on.span(),
                &format!("{key}.on"),
                format!("`{other}` is not one of data, train, method"),
            ))
        }
    };
    // The methods it acts on.
    let methods: Vec<String> = match &r.methods {
        None => {
            if on == Target::Method {
                return Err(at(
                    rc.span(),
                    &key,
                    "`on = \"method\"` needs `methods` (the methods replaced)".into(),
                ));
            }
            cx.methods.iter().map(|m| m.name.clone()).collect()
        }
        Some(ms) => {
            let mut v: Vec<String> = Vec::new();
            for m in ms.get_ref() {
                let n = m.get_ref();
                if !cx.methods.iter().any(|x| &x.name == n) {
                    return Err(at(
                        m.span(),
                        &format!("{key}.methods"),
                        format!("`{n}` is not a method of the plan's `methods`"),
                    ));
                }
                if v.contains(n) {
                    return Err(at(
                        m.span(),
                        &format!("{key}.methods"),
                        format!("`{n}` is listed twice"),
                    ));
                }
                v.push(n.clone());
            }
            if v.is_empty() {
                return Err(at(ms.span(), &format!("{key}.methods"), "is empty".into()));
            }
            v
        }
    };
    // The flag.
    let flag = match (on, &r.flag) {
        (Target::Method, None) => String::new(),
        (Target::Method, Some(f)) => {
            return Err(at(
                f.span(),
                &format!("{key}.flag"),
                "a method condition takes no flag (its values are methods)".into(),
            ))
        }
        (_, None) => {
            return Err(at(
                rc.span(),
                &key,
                format!(
                    "missing `flag` (the `unispine {}` flag it varies)",
                    on.as_str()
                ),
            ))
        }
        (Target::Data, Some(f)) => {
            let k = f.get_ref().replace('_', "-");
            if !DATA_FLAGS.iter().any(|d| d.0 == k) {
                return Err(at(
                    f.span(),
                    &format!("{key}.flag"),
                    format!(
                        "`{k}` is not a `unispine data` flag a condition may vary (known: {})",
                        DATA_FLAGS.map(|d| d.0).join(", ")
                    ),
                ));
            }
            k
        }
        (Target::Train, Some(f)) => {
            let k = f.get_ref().replace('_', "-");
            if k != ITERS {
                let mut map = BTreeMap::new();
                map.insert(f.clone(), Spanned::new(f.span(), toml::Value::Integer(0)));
                flags_to_args(cx.file, cx.text, &format!("{key}.flag"), &map, cx.schema)?;
                let baseline = methods.iter().find(|m| {
                    cx.methods
                        .iter()
                        .any(|x| &x.name == *m && crate::method::Baseline::parse(&x.base).is_some())
                        && !crate::baseline::FLAGS.contains(&k.as_str())
                });
                if let Some(b) = baseline {
                    return Err(at(
                        f.span(),
                        &format!("{key}.flag"),
                        format!(
                            "`{k}` is a Gaussian training setting and `{b}` a baseline: list \
                             the methods it acts on in `methods`"
                        ),
                    ));
                }
            }
            k
        }
    };
    if on == Target::Data {
        if let Some(d) = cx
            .datasets
            .iter()
            .find(|d| !matches!(d.source, Source::Data(_)))
        {
            return Err(at(
                rc.span(),
                &key,
                format!(
                    "dataset `{}` is a folder (`path`): a data condition needs every dataset \
                     built by the plan (`data`)",
                    d.name
                ),
            ));
        }
    }
    // Values (and the base).
    let check_value = |v: &Spanned<toml::Value>, what: &str| -> Result<String> {
        let k = format!("{key}.{what}");
        let a = value_arg(v.get_ref()).map_err(|m| at(v.span(), &k, m))?;
        if let Err(m) = names::check_value(&a) {
            return Err(at(v.span(), &k, format!("value {a:?} {m}")));
        }
        match on {
            Target::Data => {
                let kind = DATA_FLAGS
                    .iter()
                    .find(|d| d.0 == flag)
                    .map_or(Kind::Text, |d| d.1);
                check_kind(kind, &a).map_err(|m| at(v.span(), &k, format!("--{flag}: {m}")))?;
            }
            Target::Train if flag == ITERS => {
                let max = crate::train::settings::MAX_ITERATIONS as u64;
                if !a.parse::<u64>().is_ok_and(|n| (1..=max).contains(&n)) {
                    return Err(at(
                        v.span(),
                        &k,
                        format!("iters {a:?} is not an integer in [1, {max}]"),
                    ));
                }
            }
            Target::Train => {
                for m in cx.methods.iter().filter(|m| methods.contains(&m.name)) {
                    let mut args = cx.train_args.to_vec();
                    args.extend(m.args.iter().cloned());
                    args.push(format!("--{flag}"));
                    args.push(a.clone());
                    if crate::method::Baseline::parse(&m.base).is_some() {
                        continue;
                    }
                    check_train_args(&m.base, &args)
                        .map_err(|e| at(v.span(), &k, format!("for `{}`: {e}", m.name)))?;
                }
            }
            Target::Method => {
                if !(cx.schema.methods.contains(&a) || cx.variants.contains_key(&a)) {
                    return Err(at(
                        v.span(),
                        &k,
                        format!(
                            "`{a}` is neither a preset of this build ({}) nor a [variants.{a}] \
                             table",
                            cx.schema.methods.join(", ")
                        ),
                    ));
                }
                if methods.contains(&a) {
                    return Err(at(
                        v.span(),
                        &k,
                        format!("`{a}` replaces itself (that is the base point)"),
                    ));
                }
            }
        }
        Ok(a)
    };
    let base = match (&r.base, on) {
        (Some(b), Target::Method) => {
            return Err(at(
                b.span(),
                &format!("{key}.base"),
                "a method condition's base is the method itself: remove `base`".into(),
            ))
        }
        (Some(b), _) => Some(check_value(b, "base")?),
        (None, _) => None,
    };
    let mut values: Vec<String> = Vec::new();
    for v in r.values.get_ref() {
        let a = check_value(v, "values")?;
        if let Some(prev) = values
            .iter()
            .chain(base.iter())
            .find(|p| names::normalise_value(p) == names::normalise_value(&a))
        {
            return Err(at(
                v.span(),
                &format!("{key}.values"),
                format!("{a:?} repeats {prev:?} (the base or another value)"),
            ));
        }
        values.push(a);
    }
    if values.is_empty() {
        return Err(at(
            r.values.span(),
            &format!("{key}.values"),
            "is empty".into(),
        ));
    }
    let replacements = if on == Target::Method {
        values
            .iter()
            .map(|v| {
                cx.variants.get(v).cloned().unwrap_or_else(|| MethodSpec {
                    name: v.clone(),
                    base: v.clone(),
                    args: vec![],
                })
            })
            .collect()
    } else {
        vec![]
    };
    Ok(Condition {
        axis,
        on,
        flag,
        base,
        values,
        methods,
        replacements,
    })
}

/// Set `--flag value` in `unispine data` arguments: replace the flag's value when the
/// arguments already give it (a flag left last without a value gets it), else append it.
pub fn set_data_flag(args: &mut Vec<String>, flag: &str, value: &str) {
    let f = format!("--{flag}");
    if let Some(i) = args.iter().position(|a| *a == f) {
        if i + 1 < args.len() {
            args[i + 1] = value.to_string();
        } else {
            args.push(value.to_string());
        }
        return;
    }
    let eq = format!("{f}=");
    if let Some(i) = args.iter().position(|a| a.starts_with(&eq)) {
        args[i] = format!("{f}={value}");
        return;
    }
    args.push(f);
    args.push(value.to_string());
}

/// A point of a plan's condition space: None = the base, Some((c, v)) = condition c at its
/// value v (every other condition at its base).
pub type Point = Option<(usize, usize)>;

impl super::Plan {
    /// Method x point pairs per dataset, sweep value and seed: every method at the base, plus
    /// each condition's values for the methods it acts on (saturating).
    pub fn method_points(&self) -> usize {
        self.conditions.iter().fold(self.methods.len(), |a, c| {
            a.saturating_add(c.values.len().saturating_mul(c.methods.len()))
        })
    }

    /// The points in cell order: the base, then each condition's values.
    pub fn points(&self) -> Vec<Point> {
        let mut p = vec![None];
        for (ci, c) in self.conditions.iter().enumerate() {
            p.extend((0..c.values.len()).map(|vi| Some((ci, vi))));
        }
        p
    }

    /// `axis=value` of a point (None at the base).
    pub fn point_label(&self, p: Point) -> Option<(String, String)> {
        let (ci, vi) = p?;
        let c = &self.conditions[ci];
        Some((c.axis.clone(), c.values[vi].clone()))
    }

    /// The dataset a cell of `dataset` at point `p` reads: the folder name below
    /// `OUT/datasets/` (`NAME`, or `NAME@axis=value` at a data condition's value).
    pub fn data_name(&self, dataset: &str, p: Point) -> String {
        match p {
            Some((ci, vi)) if self.conditions[ci].on == Target::Data => {
                let c = &self.conditions[ci];
                format!("{dataset}@{}={}", c.axis, c.values[vi])
            }
            _ => dataset.to_string(),
        }
    }

    /// Every dataset the plan builds or reads, once: each plan dataset at the base (with the
    /// base values of the data conditions) and at each value of each data condition. The name
    /// of each is its [`Self::data_name`].
    pub fn dataset_builds(&self) -> Vec<DatasetSpec> {
        let mut out = Vec::new();
        for d in &self.datasets {
            for p in self.points() {
                if p.is_some()
                    && !matches!(p, Some((ci, _)) if self.conditions[ci].on == Target::Data)
                {
                    continue;
                }
                let source = match &d.source {
                    Source::Data(a) => {
                        let mut args = a.clone();
                        for (ci, c) in self.conditions.iter().enumerate() {
                            if c.on != Target::Data {
                                continue;
                            }
                            let v = match p {
                                Some((pc, vi)) if pc == ci => Some(&c.values[vi]),
                                _ => c.base.as_ref(),
                            };
                            if let Some(v) = v {
                                set_data_flag(&mut args, &c.flag, v);
                            }
                        }
                        Source::Data(args)
                    }
                    other => other.clone(),
                };
                out.push(DatasetSpec {
                    name: self.data_name(&d.name, p),
                    source,
                    paper: d.paper.clone(),
                    optional: d.optional,
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;
