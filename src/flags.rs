//! Settings as command-line flags, declared as data: each stage names its flags (long name,
//! help, value type, named choices) and parses their text, and two readers use the
//! declarations: the binary's command-line parser (which builds its flags from
//! [`FlagSet::flags`]) and reproduction plans (which check a cell's arguments with
//! [`parse_args`] before anything runs). The library itself carries no command-line parser.
//!
//! A named value ([`Choice`]) is declared with [`choice!`](crate::choice!): the enum, its names
//! and the one line of help of each value come from one place.

use std::path::PathBuf;

/// A value chosen by name on the command line, in plans and in `config.json`.
pub trait Choice: Copy + PartialEq + 'static {
    /// Every value with its name and one line of help, in declaration order.
    const CHOICES: &'static [(Self, &'static str, &'static str)];
}

/// The name of `v` (its entry in [`Choice::CHOICES`]).
pub fn choice_name<T: Choice>(v: T) -> &'static str {
    T::CHOICES.iter().find(|c| c.0 == v).map_or("", |c| c.1)
}

/// The value called `s`; the error lists every name.
pub fn parse_choice<T: Choice>(s: &str) -> Result<T, String> {
    T::CHOICES
        .iter()
        .find(|c| c.1 == s)
        .map(|c| c.0)
        .ok_or_else(|| {
            let names: Vec<&str> = T::CHOICES.iter().map(|c| c.1).collect();
            format!("`{s}` is not one of: {}", names.join(", "))
        })
}

/// Declare an enum whose values are chosen by name: `Variant = "name"` per value, after its
/// doc comment (the one line of help). The name is also the value's serde name (the enum
/// derives `serde::Serialize` / `Deserialize`). Implements [`Choice`] and an inherent `name()`.
/// `#[default]` after a value's doc comment marks the `Default` (with `derive(Default)`).
#[macro_export]
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident {
            $(
                $(#[doc = $doc:literal])*
                $(#[default $($def:tt)*])?
                $var:ident = $n:literal
            ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis enum $name {
            $(
                $(#[doc = $doc])*
                $(#[default $($def)*])?
                #[serde(rename = $n)]
                $var,
            )*
        }

        impl $crate::flags::Choice for $name {
            const CHOICES: &'static [(Self, &'static str, &'static str)] =
                &[$(($name::$var, $n, concat!($($doc),*))),*];
        }

        impl $name {
            /// The name used on the command line, in plans and in files.
            pub fn name(self) -> &'static str {
                $crate::flags::choice_name(self)
            }
        }
    };
}

/// A type a flag's text parses into.
pub trait FlagValue: Sized {
    /// The value of one flag's text.
    fn parse_flag(s: &str) -> Result<Self, String>;
    /// The named values with their help, for a [`Choice`] (empty otherwise).
    fn choices() -> Vec<(&'static str, String)> {
        Vec::new()
    }
    /// The placeholder of the value in help texts.
    fn value_name() -> &'static str {
        "VALUE"
    }
}

macro_rules! number_flag {
    ($($t:ty => $hint:literal),*) => {$(
        impl FlagValue for $t {
            fn parse_flag(s: &str) -> Result<Self, String> {
                s.parse().map_err(|e| format!("{e}"))
            }
            fn value_name() -> &'static str {
                $hint
            }
        }
    )*};
}

number_flag!(u64 => "N", usize => "N", f64 => "X");

impl FlagValue for bool {
    fn parse_flag(s: &str) -> Result<Self, String> {
        match s {
            "true" => Ok(true),
            "false" => Ok(false),
            _ => Err("write true or false".into()),
        }
    }
    fn choices() -> Vec<(&'static str, String)> {
        vec![("true", String::new()), ("false", String::new())]
    }
}

impl FlagValue for PathBuf {
    fn parse_flag(s: &str) -> Result<Self, String> {
        if s.is_empty() {
            return Err("an empty path".into());
        }
        Ok(PathBuf::from(s))
    }
    fn value_name() -> &'static str {
        "FILE"
    }
}

/// A comma-separated list.
impl FlagValue for Vec<usize> {
    fn parse_flag(s: &str) -> Result<Self, String> {
        s.split(',').map(usize::parse_flag).collect()
    }
    fn value_name() -> &'static str {
        "N,N,..."
    }
}

impl<T: Choice> FlagValue for T {
    fn parse_flag(s: &str) -> Result<Self, String> {
        parse_choice(s)
    }
    fn choices() -> Vec<(&'static str, String)> {
        T::CHOICES
            .iter()
            .map(|c| (c.1, c.2.trim().to_string()))
            .collect()
    }
    fn value_name() -> &'static str {
        "NAME"
    }
}

/// One flag: `--long VALUE`, or `--long` alone for a switch.
#[derive(Clone, Debug)]
pub struct Flag {
    pub long: String,
    pub help: String,
    /// The value's placeholder in help texts; `None` for a switch.
    pub value_name: Option<&'static str>,
    /// Named values and their help (empty: any text `check` accepts).
    pub choices: Vec<(&'static str, String)>,
    /// Checks a value's text (the same parse that sets it).
    pub check: fn(&str) -> Result<(), String>,
}

impl Flag {
    /// `--long VALUE` parsed as a `T`; `long` in snake case is written in kebab case.
    pub fn value<T: FlagValue>(long: &str, help: &str) -> Flag {
        Flag {
            long: long.replace('_', "-"),
            help: help_text(help),
            value_name: Some(T::value_name()),
            choices: T::choices(),
            check: |s| T::parse_flag(s).map(|_| ()),
        }
    }

    /// `--long` alone.
    pub fn switch(long: &str, help: &str) -> Flag {
        Flag {
            long: long.replace('_', "-"),
            help: help_text(help),
            value_name: None,
            choices: Vec::new(),
            check: |_| Ok(()),
        }
    }

    /// Whether the flag takes a value.
    pub fn takes_value(&self) -> bool {
        self.value_name.is_some()
    }
}

/// Doc-comment lines (each starting with a space) as one line of help.
fn help_text(doc: &str) -> String {
    doc.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A group of flags parsed into one struct.
pub trait FlagSet: Default {
    /// The name of the group (what a command line's conflicts name).
    const GROUP: &'static str;
    /// Every flag of the group, in declaration order.
    fn flags() -> Vec<Flag>;
    /// Set flag `long` (kebab case) from its text (`None` for a switch given).
    fn set(&mut self, long: &str, value: Option<&str>) -> Result<(), String>;
}

/// No flags.
impl FlagSet for () {
    const GROUP: &'static str = "";
    fn flags() -> Vec<Flag> {
        Vec::new()
    }
    fn set(&mut self, long: &str, _: Option<&str>) -> Result<(), String> {
        Err(format!("unexpected argument '--{long}'"))
    }
}

/// [`parse_args`] into one flag set.
pub fn parse_set<A: FlagSet>(args: &[String]) -> Result<A, String> {
    parse_args::<A, ()>(args).map(|p| p.0)
}

/// Parse `--long VALUE`, `--long=VALUE` and `--switch` arguments into two flag sets (each flag
/// at most once); the error names the argument.
pub fn parse_args<A: FlagSet, B: FlagSet>(args: &[String]) -> Result<(A, B), String> {
    let (fa, fb) = (A::flags(), B::flags());
    let (mut a, mut b) = (A::default(), B::default());
    let mut seen: Vec<String> = Vec::new();
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let Some(body) = arg.strip_prefix("--") else {
            return Err(format!("unexpected argument '{arg}'"));
        };
        let (long, inline) = match body.split_once('=') {
            Some((l, v)) => (l, Some(v.to_string())),
            None => (body, None),
        };
        let Some((flag, in_a)) = fa
            .iter()
            .map(|f| (f, true))
            .chain(fb.iter().map(|f| (f, false)))
            .find(|(f, _)| f.long == long)
        else {
            return Err(format!("unexpected argument '--{long}'"));
        };
        if seen.iter().any(|s| s == long) {
            return Err(format!(
                "the argument '--{long}' cannot be used multiple times"
            ));
        }
        seen.push(long.to_string());
        let value = match (flag.takes_value(), inline) {
            (true, Some(v)) => Some(v),
            (true, None) => match it.next() {
                Some(v) => Some(v.clone()),
                None => {
                    return Err(format!(
                        "a value is required for '--{long}' but none was supplied"
                    ))
                }
            },
            (false, Some(v)) => {
                return Err(format!(
                    "unexpected value '{v}' for '--{long}': it is a switch"
                ))
            }
            (false, None) => None,
        };
        if let Some(v) = &value {
            (flag.check)(v).map_err(|e| format!("invalid value '{v}' for '--{long}': {e}"))?;
        }
        let set = if in_a {
            a.set(long, value.as_deref())
        } else {
            b.set(long, value.as_deref())
        };
        set.map_err(|e| format!("invalid value for '--{long}': {e}"))?;
    }
    Ok((a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    choice! {
        #[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        enum Fruit {
            /// A red one,
            /// in two lines.
            Apple = "apple",
            /// A long one.
            Banana = "banana-split",
        }
    }

    #[derive(Default, Debug, PartialEq)]
    struct A {
        n: Option<usize>,
        x: Option<f64>,
        on: bool,
    }

    impl FlagSet for A {
        const GROUP: &'static str = "A";
        fn flags() -> Vec<Flag> {
            vec![
                Flag::value::<usize>("n_items", " How many."),
                Flag::value::<f64>("x", ""),
                Flag::switch("on", ""),
            ]
        }
        fn set(&mut self, long: &str, v: Option<&str>) -> Result<(), String> {
            match long {
                "n-items" => self.n = Some(usize::parse_flag(v.unwrap_or(""))?),
                "x" => self.x = Some(f64::parse_flag(v.unwrap_or(""))?),
                "on" => self.on = true,
                _ => return Err(format!("no flag {long}")),
            }
            Ok(())
        }
    }

    #[derive(Default, Debug, PartialEq)]
    struct B {
        fruit: Option<Fruit>,
    }

    impl FlagSet for B {
        const GROUP: &'static str = "B";
        fn flags() -> Vec<Flag> {
            vec![Flag::value::<Fruit>("fruit", "")]
        }
        fn set(&mut self, _: &str, v: Option<&str>) -> Result<(), String> {
            self.fruit = Some(Fruit::parse_flag(v.unwrap_or(""))?);
            Ok(())
        }
    }

    fn args(s: &[&str]) -> Vec<String> {
        s.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_choice_has_its_names_and_help() {
        assert_eq!(Fruit::Banana.name(), "banana-split");
        assert_eq!(parse_choice::<Fruit>("apple"), Ok(Fruit::Apple));
        let e = parse_choice::<Fruit>("Apple").unwrap_err();
        assert!(e.contains("apple, banana-split"), "{e}");
        assert_eq!(
            Fruit::choices(),
            [
                ("apple", "A red one, in two lines.".to_string()),
                ("banana-split", "A long one.".to_string())
            ]
        );
    }

    #[test]
    fn arguments_parse_into_both_sets() {
        let (a, b): (A, B) = parse_args(&args(&[
            "--x=-1.5",
            "--fruit",
            "banana-split",
            "--on",
            "--n-items",
            "3",
        ]))
        .unwrap();
        assert_eq!(
            a,
            A {
                n: Some(3),
                x: Some(-1.5),
                on: true
            }
        );
        assert_eq!(b.fruit, Some(Fruit::Banana));
        assert_eq!(A::flags()[0].help, "How many.");
        assert_eq!(A::flags()[0].long, "n-items");
    }

    #[test]
    fn bad_arguments_are_named() {
        for (argv, want) in [
            (&["--n-items", "x"][..], "invalid value 'x' for '--n-items'"),
            (&["--n-items"], "a value is required for '--n-items'"),
            (&["--on=true"], "unexpected value 'true' for '--on'"),
            (&["--y", "1"], "unexpected argument '--y'"),
            (&["x"], "unexpected argument 'x'"),
            (&["--on", "--on"], "'--on' cannot be used multiple times"),
            (
                &["--fruit", "pear"],
                "`pear` is not one of: apple, banana-split",
            ),
        ] {
            let e = parse_args::<A, B>(&args(argv)).unwrap_err();
            assert!(e.contains(want), "{argv:?}: {e}");
        }
    }

    #[test]
    fn values_parse_as_their_type() {
        assert_eq!(Vec::<usize>::parse_flag("4,5"), Ok(vec![4, 5]));
        assert!(Vec::<usize>::parse_flag("4,,5").is_err());
        assert_eq!(bool::parse_flag("false"), Ok(false));
        assert!(bool::parse_flag("yes").is_err());
        assert!(PathBuf::parse_flag("").is_err());
        assert!(u64::parse_flag("-1").is_err());
    }
}
