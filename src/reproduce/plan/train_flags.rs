//! What `unispine train` accepts ([`TrainSchema`], from the library's declarations of methods
//! and settings) and the conversion of a plan's `[train]`, variant and sweep keys into checked
//! `unispine train` arguments.

use std::collections::BTreeMap;
use std::path::Path;

use toml::Spanned;

use super::err_at;
use crate::baseline::BaselineFlags;
use crate::error::Result;
use crate::flags::FlagSet;
use crate::method::TrainMethod;
use crate::train::TrainOverrides;

/// The `unispine train` flags a plan cannot set: the harness sets them for every cell.
pub const HARNESS_FLAGS: [&str; 7] = [
    "data", "out", "method", "iters", "seed", "threads", "config",
];

/// What `unispine train` accepts: its method names ([`TrainMethod::all`]) and the flags of its
/// settings ([`TrainOverrides`], long name and whether it takes a value). Built from the
/// library's declarations, so a method or setting added to `unispine train` is known to plans
/// without a second list.
#[derive(Clone, Debug)]
pub struct TrainSchema {
    pub methods: Vec<String>,
    /// One line of help per method (as `unispine train --help` shows it).
    pub method_help: Vec<(String, String)>,
    pub flags: Vec<(String, bool)>,
}

impl TrainSchema {
    /// The schema of this build's `unispine train`.
    pub fn of_train() -> Self {
        let all = TrainMethod::all();
        let flags = TrainOverrides::flags()
            .into_iter()
            .chain(BaselineFlags::flags())
            .map(|f| {
                let takes_value = f.takes_value();
                (f.long, takes_value)
            })
            .collect();
        TrainSchema {
            methods: all.iter().map(|m| m.0.to_string()).collect(),
            method_help: all.into_iter().map(|(m, h)| (m.to_string(), h)).collect(),
            flags,
        }
    }

    pub(super) fn flag(&self, key: &str) -> Option<&(String, bool)> {
        let k = key.replace('_', "-");
        self.flags.iter().find(|(f, _)| *f == k)
    }
}

/// `unispine train` flags of a TOML table, with their spans.
pub(super) type Flags = BTreeMap<Spanned<String>, Spanned<toml::Value>>;

/// A TOML value as a command-line argument (arrays comma-joined).
pub(super) fn value_arg(v: &toml::Value) -> std::result::Result<String, String> {
    Ok(match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(f) => f.to_string(),
        toml::Value::Boolean(b) => b.to_string(),
        toml::Value::Array(a) => a
            .iter()
            .map(value_arg)
            .collect::<std::result::Result<Vec<_>, _>>()?
            .join(","),
        other => return Err(format!("`{other}` is not a flag value")),
    })
}

/// Turn `[train]`-style flags into arguments, checking each against the schema.
pub(super) fn flags_to_args(
    file: &Path,
    text: &str,
    section: &str,
    flags: &Flags,
    schema: &TrainSchema,
) -> Result<Vec<String>> {
    let mut args = Vec::new();
    for (k, v) in flags {
        let key = k.get_ref().as_str();
        let at = |msg: String| err_at(file, text, k.span(), &format!("{section}.{key}"), msg);
        if HARNESS_FLAGS.contains(&key.replace('_', "-").as_str()) {
            return Err(at(format!(
                "`{key}` is set by the plan itself for every cell ({})",
                HARNESS_FLAGS.join(", ")
            )));
        }
        let Some((flag, takes_value)) = schema.flag(key) else {
            return Err(at(format!(
                "unknown `unispine train` flag `{key}` (known: {})",
                schema
                    .flags
                    .iter()
                    .map(|f| f.0.as_str())
                    .filter(|f| !HARNESS_FLAGS.contains(f))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        };
        if *takes_value {
            let val = value_arg(v.get_ref()).map_err(&at)?;
            if val.starts_with('-') {
                // A negative number as its own argument would parse as a flag.
                args.push(format!("--{flag}={val}"));
            } else {
                args.push(format!("--{flag}"));
                args.push(val);
            }
        } else {
            match v.get_ref() {
                toml::Value::Boolean(true) => args.push(format!("--{flag}")),
                toml::Value::Boolean(false) => {}
                _ => return Err(at(format!("`{key}` is a switch: write true or false"))),
            }
        }
    }
    Ok(args)
}

/// Check the variant `args` of method `base` with the parser of `unispine train`'s settings
/// ([`TrainOverrides`], [`BaselineFlags`]) and, for a Gaussian preset, the allowed range of
/// every value on that preset ([`TrainOverrides::check_on_preset`]); a message on failure.
pub(super) fn check_train_args(base: &str, args: &[String]) -> std::result::Result<(), String> {
    let method = TrainMethod::parse(base)?;
    let (overrides, _) = crate::flags::parse_args::<TrainOverrides, BaselineFlags>(args)?;
    if let Some(m) = method.gaussians() {
        overrides.check_on_preset(m).map_err(|e| e.to_string())?;
    }
    Ok(())
}
