//! The checks of a condition's values and keys.

use super::*;

/// Every kind of data-flag value at both sides of its bound.
#[test]
fn each_kind_of_value_is_checked_at_both_sides_of_its_bound() {
    let cases = [
        (Kind::NonNegative, "0", true),
        (Kind::NonNegative, "-0.001", false),
        (Kind::NonNegative, "inf", false),
        (Kind::Positive, "0.001", true),
        (Kind::Positive, "0", false),
        (Kind::Positive, "-1", false),
        (Kind::Positive, "NaN", false),
        (Kind::Count, "1", true),
        (Kind::Count, "0", false),
        (Kind::Count, "1.5", false),
        (Kind::Seed, "0", true),
        (Kind::Seed, "18446744073709551615", true),
        (Kind::Seed, "-1", false),
        (Kind::Seed, "x", false),
        (Kind::Text, "gaussian:0.1", true),
    ];
    for (kind, v, ok) in cases {
        assert_eq!(check_kind(kind, v).is_ok(), ok, "{kind:?} {v:?}");
    }
}

/// `as_str` is the `unispine` subcommand a claims description names (`unispine data
/// --pose-noise-deg`): the key `on` a plan's condition was written with.
#[test]
fn each_condition_target_names_the_key_it_was_read_from() {
    for key in ["data", "train", "method"] {
        let text = format!(
            "name = \"t\"\niters = 10\nseeds = [0]\nmethods = [\"3dgs\", \"w\"]\n\
             [[datasets]]\nname = \"ph\"\ndata = [\"phantom\"]\n\
             [variants.w]\nbase = \"3dgs-vanilla\"\n\
             [[conditions]]\naxis = \"a\"\non = \"{key}\"\n{}",
            match key {
                "data" => "flag = \"pose-noise-deg\"\nvalues = [0.1]\n",
                "train" => "flag = \"init\"\nmethods = [\"3dgs\"]\nvalues = [\"acui\"]\n",
                _ => "methods = [\"3dgs\"]\nvalues = [\"w\"]\n",
            }
        );
        let p = super::super::tests::parse(&text).unwrap_or_else(|e| panic!("{key}: {e}"));
        assert_eq!(p.conditions[0].on.as_str(), key);
    }
}
