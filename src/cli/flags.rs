//! clap arguments built from the library's flag declarations ([`unispine::flags`]): a
//! [`FlagSet`] as flattened arguments ([`Flags`]) and a [`Choice`] as a value parser
//! ([`choice`]).

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Arg, ArgAction, ArgGroup, ArgMatches, Args, Command, FromArgMatches, Id};
use unispine::flags::{parse_choice, Choice, FlagSet, FlagValue};

/// A library flag set as clap arguments (`#[command(flatten)]`); the group is named
/// [`FlagSet::GROUP`].
#[derive(Clone, Debug, Default)]
pub struct Flags<T>(pub T);

impl<T: FlagSet> FromArgMatches for Flags<T> {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        let mut t = T::default();
        for f in T::flags() {
            let value = if f.takes_value() {
                match m.get_one::<String>(&f.long) {
                    Some(v) => Some(v.as_str()),
                    None => continue,
                }
            } else if m.get_flag(&f.long) {
                None
            } else {
                continue;
            };
            // The value parser ran the same check: a failure here is a broken declaration.
            t.set(&f.long, value)
                .map_err(|e| clap::Error::raw(clap::error::ErrorKind::InvalidValue, e + "\n"))?;
        }
        Ok(Flags(t))
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
    }
}

impl<T: FlagSet> Args for Flags<T> {
    fn group_id() -> Option<Id> {
        Some(Id::from(T::GROUP))
    }

    fn augment_args(cmd: Command) -> Command {
        let flags = T::flags();
        let ids: Vec<String> = flags.iter().map(|f| f.long.clone()).collect();
        let cmd = flags.into_iter().fold(cmd, |cmd, f| {
            let arg = Arg::new(f.long.clone()).long(f.long).help(f.help);
            cmd.arg(match f.value_name {
                None => arg.action(ArgAction::SetTrue),
                Some(name) if !f.choices.is_empty() => arg.value_name(name).value_parser(
                    PossibleValuesParser::new(f.choices.into_iter().map(|(n, h)| {
                        let v = PossibleValue::new(n);
                        if h.is_empty() {
                            v
                        } else {
                            v.help(h)
                        }
                    })),
                ),
                Some(name) => {
                    let check = f.check;
                    arg.value_name(name)
                        .value_parser(move |s: &str| check(s).map(|()| s.to_string()))
                }
            })
        });
        cmd.group(ArgGroup::new(T::GROUP).multiple(true).args(ids))
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        Self::augment_args(cmd)
    }
}

/// A clap value parser of the named values of `T` (shown with their help by `--help`).
pub fn choice<T: Choice + Clone + Send + Sync>() -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(
        T::choices()
            .into_iter()
            .map(|(n, h)| PossibleValue::new(n).help(h)),
    )
    .map(|s| parse_choice::<T>(&s).expect("a possible value parses"))
}
