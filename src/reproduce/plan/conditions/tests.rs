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

/// A plan over `3dgs` and `fdk` with the given `[[conditions]]` blocks.
fn plan_with(conditions: &str) -> Result<super::super::Plan> {
    super::super::tests::parse(&format!(
        "name = \"t\"\niters = 10\nseeds = [0]\nmethods = [\"3dgs\", \"fdk\"]\n\
         [[datasets]]\nname = \"ph\"\ndata = [\"phantom\"]\n{conditions}"
    ))
}

#[test]
fn one_axis_per_data_or_train_flag() {
    let block = |axis: &str, v: &str| {
        format!("[[conditions]]\naxis = \"{axis}\"\non = \"data\"\nflag = \"pose-noise-deg\"\nvalues = [{v}]\n")
    };
    let e = plan_with(&(block("a", "0.1") + &block("b", "0.2")))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("flag `pose-noise-deg` is already the axis `a`"),
        "{e}"
    );
    // Another flag is another axis.
    let other = block("b", "0.2").replace("pose-noise-deg", "pose-noise-mm");
    let ok = plan_with(&(block("a", "0.1") + &other));
    assert!(ok.is_ok(), "{:?}", ok.err());
}

#[test]
fn a_gaussian_setting_may_not_act_on_a_baseline() {
    let cond = |methods: &str| {
        format!(
            "[[conditions]]\naxis = \"i\"\non = \"train\"\nflag = \"init\"\n{methods}\
             values = [\"acui\"]\n"
        )
    };
    let e = plan_with(&cond("methods = [\"3dgs\", \"fdk\"]\n"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("`init` is a Gaussian training setting and `fdk` a baseline"),
        "{e}"
    );
    let ok = plan_with(&cond("methods = [\"3dgs\"]\n"));
    assert!(ok.is_ok(), "{:?}", ok.err());
}

#[test]
fn a_data_condition_s_values_are_checked_with_the_kind_of_its_own_flag() {
    let cond = |v: &str| {
        format!(
            "[[conditions]]\naxis = \"d\"\non = \"data\"\nflag = \"detector\"\nvalues = [{v}]\n"
        )
    };
    let e = plan_with(&cond("1.5")).unwrap_err().to_string();
    assert!(e.contains("--detector:"), "{e}");
    let ok = plan_with(&cond("64"));
    assert!(ok.is_ok(), "{:?}", ok.err());
}

#[test]
fn a_data_flag_is_replaced_where_given_and_appended_where_not() {
    let set = |args: &[&str], flag: &str, value: &str| {
        let mut a: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        set_data_flag(&mut a, flag, value);
        a
    };
    assert_eq!(
        set(
            &["phantom", "--detector", "32", "--size", "16"],
            "detector",
            "64"
        ),
        ["phantom", "--detector", "64", "--size", "16"]
    );
    assert_eq!(
        set(&["phantom", "--detector=32"], "detector", "64"),
        ["phantom", "--detector=64"]
    );
    assert_eq!(
        set(&["phantom", "--size", "16"], "detector", "64"),
        ["phantom", "--size", "16", "--detector", "64"]
    );
    // The flag last, with no value after it: the value goes after it.
    assert_eq!(
        set(&["phantom", "--detector"], "detector", "64"),
        ["phantom", "--detector", "64"]
    );
}

#[test]
fn each_data_point_sets_its_own_condition_s_value_and_the_others_bases() {
    let p = plan_with(
        "[[conditions]]\naxis = \"pose\"\non = \"data\"\nflag = \"pose-noise-deg\"\nbase = 0\n\
         values = [0.1, 0.2]\n\
         [[conditions]]\naxis = \"det\"\non = \"data\"\nflag = \"detector\"\nbase = 64\n\
         values = [32]\n",
    )
    .unwrap();
    let args: Vec<Vec<String>> = p
        .dataset_builds()
        .into_iter()
        .map(|d| match d.source {
            Source::Data(a) => a,
            other => panic!("{other:?}"),
        })
        .collect();
    let flags = |a: &[String]| {
        let at = |f: &str| a[a.iter().position(|x| x == f).unwrap() + 1].clone();
        (at("--pose-noise-deg"), at("--detector"))
    };
    let got: Vec<(String, String)> = args.iter().map(|a| flags(a)).collect();
    let want = [("0", "64"), ("0.1", "64"), ("0.2", "64"), ("0", "32")];
    assert_eq!(
        got,
        want.map(|(a, b)| (a.to_string(), b.to_string())),
        "{args:?}"
    );
}
