//! A plan's `[slurm]` table: the resources of each array task. Every value is checked against
//! a strict grammar when the plan is parsed, because it is written into `#SBATCH` lines:
//! - `cpus_per_task`: 1 to 1024;
//! - `mem`: digits with an optional unit, `\d+[KMGT]?` (`4G`, `4000M`, `512`);
//! - `time`: `[D-]HH:MM:SS` (`02:00:00`, `1-12:00:00`);
//! - `partition`, `account` (optional): 1 to 64 of `A-Z a-z 0-9 . _ -`, not starting with `-`.

use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use super::err_at;
use crate::error::Result;

/// Slurm resources per array task.
#[derive(Clone, Debug, PartialEq)]
pub struct SlurmSpec {
    pub cpus_per_task: usize,
    pub mem: String,
    pub time: String,
    pub partition: Option<String>,
    pub account: Option<String>,
}

impl Default for SlurmSpec {
    fn default() -> Self {
        SlurmSpec {
            cpus_per_task: 2,
            mem: "4G".into(),
            time: "24:00:00".into(),
            partition: None,
            account: None,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSlurm {
    #[serde(default)]
    cpus_per_task: Option<Spanned<i64>>,
    #[serde(default)]
    mem: Option<Spanned<String>>,
    #[serde(default)]
    time: Option<Spanned<String>>,
    #[serde(default)]
    partition: Option<Spanned<String>>,
    #[serde(default)]
    account: Option<Spanned<String>>,
}

/// `\d+[KMGT]?`
pub fn valid_mem(s: &str) -> bool {
    let digits = s.strip_suffix(['K', 'M', 'G', 'T']).unwrap_or(s);
    !digits.is_empty() && digits.len() <= 12 && digits.bytes().all(|b| b.is_ascii_digit())
}

/// `[D-]HH:MM:SS` with minutes and seconds below 60.
pub fn valid_time(s: &str) -> bool {
    let (days, hms) = match s.split_once('-') {
        Some((d, rest)) => (Some(d), rest),
        None => (None, s),
    };
    let num = |t: &str, max_len: usize| {
        !t.is_empty() && t.len() <= max_len && t.bytes().all(|b| b.is_ascii_digit())
    };
    if days.is_some_and(|d| !num(d, 4)) {
        return false;
    }
    let parts: Vec<&str> = hms.split(':').collect();
    parts.len() == 3
        && num(parts[0], 3)
        && parts[1..]
            .iter()
            .all(|p| p.len() == 2 && num(p, 2) && p.parse::<u32>().is_ok_and(|v| v < 60))
}

/// A partition or account name.
pub fn valid_slurm_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && !s.starts_with('-')
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
}

impl SlurmSpec {
    pub(super) fn from_raw(raw: RawSlurm, file: &Path, text: &str) -> Result<SlurmSpec> {
        let d = SlurmSpec::default();
        let check = |v: Option<Spanned<String>>,
                     key: &str,
                     ok: fn(&str) -> bool,
                     grammar: &str|
         -> Result<Option<String>> {
            match v {
                None => Ok(None),
                Some(v) if ok(v.get_ref()) => Ok(Some(v.into_inner())),
                Some(v) => Err(err_at(
                    file,
                    text,
                    v.span(),
                    &format!("slurm.{key}"),
                    format!("{:?} is not of the form {grammar}", v.get_ref()),
                )),
            }
        };
        let cpus_per_task = match raw.cpus_per_task {
            None => d.cpus_per_task,
            Some(c) if (1..=1024).contains(c.get_ref()) => *c.get_ref() as usize,
            Some(c) => {
                return Err(err_at(
                    file,
                    text,
                    c.span(),
                    "slurm.cpus_per_task",
                    format!("{} is outside [1, 1024]", c.get_ref()),
                ))
            }
        };
        Ok(SlurmSpec {
            cpus_per_task,
            mem: check(raw.mem, "mem", valid_mem, "DIGITS[K|M|G|T] (e.g. 4G)")?.unwrap_or(d.mem),
            time: check(raw.time, "time", valid_time, "[D-]HH:MM:SS (e.g. 02:00:00)")?
                .unwrap_or(d.time),
            partition: check(
                raw.partition,
                "partition",
                valid_slurm_name,
                "a name of letters, digits, . _ -",
            )?,
            account: check(
                raw.account,
                "account",
                valid_slurm_name,
                "a name of letters, digits, . _ -",
            )?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grammars_accept_slurm_values_and_refuse_anything_else() {
        for ok in ["4G", "4000M", "512", "1T", "64K"] {
            assert!(valid_mem(ok), "{ok}");
        }
        for bad in [
            "",
            "G",
            "4GB",
            "4 G",
            "4G\n#SBATCH --x",
            "-4G",
            "4g",
            "$(id)",
        ] {
            assert!(!valid_mem(bad), "{bad:?}");
        }
        for ok in ["02:00:00", "1-12:00:00", "100:59:59", "0:00:01"] {
            assert!(valid_time(ok), "{ok}");
        }
        for bad in [
            "",
            "2:00",
            "02:60:00",
            "02:00:60",
            "1-",
            "-02:00:00",
            "02:00:00\nid",
            "02:00:00 ",
            "a-02:00:00",
            "02:0:00",
        ] {
            assert!(!valid_time(bad), "{bad:?}");
        }
        for ok in ["debug", "gpu-a100", "acct_1.x"] {
            assert!(valid_slurm_name(ok), "{ok}");
        }
        for bad in ["", "-p", "a b", "a;b", "a\nb", "a'b"] {
            assert!(!valid_slurm_name(bad), "{bad:?}");
        }
    }

    /// Every length bound of the grammars at both sides of its limit.
    #[test]
    fn length_bounds_hold_at_both_endpoints() {
        assert!(valid_mem(&format!("{}G", "9".repeat(12))));
        assert!(!valid_mem(&format!("{}G", "9".repeat(13))));
        assert!(valid_mem(&"9".repeat(12)));
        assert!(!valid_mem(&"9".repeat(13)));
        assert!(valid_time("9999-00:00:00"));
        assert!(!valid_time("99999-00:00:00"));
        assert!(valid_time("999:00:00"));
        assert!(!valid_time("9999:00:00"));
        assert!(valid_time("00:59:00") && valid_time("00:00:59"));
        assert!(!valid_time("00:5:00") && !valid_time("00:000:00"));
        assert!(valid_slurm_name(&"p".repeat(64)));
        assert!(!valid_slurm_name(&"p".repeat(65)));
        assert!(
            valid_slurm_name("a-"),
            "`-` is allowed after the first character"
        );
    }

    /// A plan with one variant.
    const OK: &str = "name = \"t\"\niters = 10\nseeds = [0]\nmethods = [\"v\"]\n\
                      [[datasets]]\nname = \"ph\"\ndata = [\"phantom\"]\n\
                      [variants.v]\nbase = \"xgaussian\"\n";

    use super::super::tests::parse;

    #[test]
    fn a_slurm_table_is_kept_value_for_value_and_each_bad_value_is_named() {
        let t = format!(
            "{OK}[slurm]\ncpus_per_task = 1024\nmem = \"16G\"\ntime = \"1-00:00:00\"\n\
             partition = \"gpu-a\"\naccount = \"lab_1\"\n"
        );
        // `[slurm]` after `[variants.v]` is a table of its own.
        let p = parse(&t).unwrap();
        let want = SlurmSpec {
            cpus_per_task: 1024,
            mem: "16G".into(),
            time: "1-00:00:00".into(),
            partition: Some("gpu-a".into()),
            account: Some("lab_1".into()),
        };
        assert_eq!(p.slurm, want);
        assert_eq!(parse(OK).unwrap().slurm, SlurmSpec::default());
        for (bad, key) in [
            ("cpus_per_task = 1025", "slurm.cpus_per_task"),
            ("cpus_per_task = 0", "slurm.cpus_per_task"),
            ("mem = \"4GB\"", "slurm.mem"),
            ("time = \"2:00\"", "slurm.time"),
            ("partition = \"-p\"", "slurm.partition"),
            ("account = \"a b\"", "slurm.account"),
        ] {
            let e = parse(&format!("{OK}[slurm]\n{bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(key) && e.contains("p.toml"), "{bad}: {e}");
        }
    }
}
