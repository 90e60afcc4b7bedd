//! Plan parsing at its edges: seeds, variant names, `all-presets`, plan files and names.

use super::super::*;
use super::{parse, OK};

/// `OK` with its `seeds` and `methods` lines replaced.
fn with(seeds: &str, methods: &str) -> Result<Plan> {
    parse(
        &OK.replace("seeds = [0, 1]", seeds)
            .replace("methods = [\"unispine\", \"v\"]", methods),
    )
}

#[test]
fn seeds_must_be_distinct_and_non_negative() {
    assert!(with("seeds = [0, 1]", "methods = [\"unispine\", \"v\"]").is_ok());
    for seeds in ["seeds = [0, 0]", "seeds = [-1]", "seeds = [2, -3]"] {
        let e = with(seeds, "methods = [\"unispine\", \"v\"]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("seeds"), "{seeds}: {e}");
    }
}

#[test]
fn a_variant_named_like_a_preset_up_to_case_is_refused() {
    let t = OK
        .replace("[variants.v]", "[variants.XGaussian]")
        .replace("\"v\"]", "\"XGaussian\"]");
    let e = parse(&t).unwrap_err().to_string();
    assert!(
        e.contains("`XGaussian` and `xgaussian` differ only in case"),
        "{e}"
    );
}

#[test]
fn all_presets_adds_each_preset_not_listed_once() {
    let p = with(
        "seeds = [0]",
        &format!("methods = [\"3dgs\", \"{ALL_PRESETS}\", \"v\"]"),
    )
    .unwrap();
    let names: Vec<&str> = p.methods.iter().map(|m| m.name.as_str()).collect();
    let schema = TrainSchema::of_train();
    // 3dgs first and once; every other preset after it; the variant too.
    assert_eq!(names[0], "3dgs");
    for m in &schema.methods {
        assert_eq!(
            names.iter().filter(|n| **n == m).count(),
            1,
            "{m}: {names:?}"
        );
    }
    assert!(names.contains(&"v"));
    assert_eq!(names.len(), schema.methods.len() + 1, "{names:?}");
    // A preset listed after `all-presets` is not added twice.
    let p = with(
        "seeds = [0]",
        &format!("methods = [\"{ALL_PRESETS}\", \"3dgs\"]"),
    )
    .unwrap();
    let names: Vec<&str> = p.methods.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(
        names.iter().filter(|n| **n == "3dgs").count(),
        1,
        "{names:?}"
    );
    assert_eq!(names.len(), schema.methods.len(), "{names:?}");
}

#[test]
fn a_plan_file_is_loaded_and_a_missing_name_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("mine.toml");
    std::fs::write(&f, OK).unwrap();
    let schema = TrainSchema::of_train();
    let p = Plan::load(f.to_str().unwrap(), &schema).unwrap();
    assert_eq!(p.seeds, vec![0, 1]);
    let e = Plan::load("no-such-plan", &schema).unwrap_err().to_string();
    assert!(
        e.contains("`no-such-plan` is neither a built-in plan"),
        "{e}"
    );
    // A missing `.toml` path is an error reading that file.
    let gone = dir.path().join("gone.toml");
    let e = Plan::load(gone.to_str().unwrap(), &schema)
        .unwrap_err()
        .to_string();
    assert!(e.contains("gone.toml") && !e.contains("neither"), "{e}");
    assert!(Plan::load("quick", &schema).is_ok());
}
