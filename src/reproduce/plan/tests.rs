//! Plan parsing: good plans, errors naming the line and key, baseline cells' arguments.

use super::*;

fn parse(t: &str) -> Result<Plan> {
    let dir = std::env::temp_dir();
    Plan::parse(t, Path::new("p.toml"), &dir, &TrainSchema::of_train())
}

const OK: &str = "name = \"t\"\niters = 10\nseeds = [0, 1]\nmethods = [\"unispine\", \"v\"]\n\
                  [[datasets]]\nname = \"ph\"\ndata = [\"phantom\", \"--size\", \"16\"]\n\
                  [variants.v]\nbase = \"xgaussian\"\ncolor = \"rirf-paper\"\n";

#[test]
fn a_good_plan_parses() {
    let p = parse(OK).unwrap();
    assert_eq!(p.seeds, vec![0, 1]);
    assert_eq!(p.methods[1].base, "xgaussian");
    assert_eq!(p.methods[1].args, vec!["--color", "rirf-paper"]);
    assert_eq!(
        p.datasets[0].source,
        Source::Data(vec!["phantom".into(), "--size".into(), "16".into()])
    );
}

#[test]
fn errors_name_the_line_and_key() {
    let cases = [
        (
            OK.replace("iters = 10", "iters = 10\nbogus = 1"),
            "line 3",
            "bogus",
        ),
        (
            OK.replace("\"unispine\", \"v\"", "\"unispine\", \"nope\""),
            "line 4",
            "nope",
        ),
        (OK.replace("color = ", "colour = "), "line 10", "colour"),
        (
            OK.replace("\"rirf-paper\"", "\"purple\""),
            "line 8",
            "purple",
        ),
        (
            OK.replace("base = \"xgaussian\"", "base = \"nerf9\""),
            "line 9",
            "nerf9",
        ),
        (
            OK.replace("color = \"rirf-paper\"", "seed = 3"),
            "line 10",
            "seed",
        ),
    ];
    for (text, line, word) in cases {
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains(line) && e.contains(word), "{e}\n--\n{text}");
        assert!(e.contains("p.toml"), "{e}");
    }
    let no_ds = "name = \"t\"\niters = 10\nseeds = [0]\nmethods = [\"unispine\"]\n";
    let e = parse(no_ds).unwrap_err().to_string();
    assert!(e.contains("datasets"), "{e}");
    let missing = OK.replace(
        "data = [\"phantom\", \"--size\", \"16\"]",
        "path = \"no/such\"",
    );
    let e = parse(&missing).unwrap_err().to_string();
    assert!(e.contains("line 7") && e.contains("no/such"), "{e}");
}

#[test]
fn variants_set_the_initialiser_and_the_densification_threshold() {
    let with = |line: &str| OK.replace("color = \"rirf-paper\"", line);
    let p = parse(&with("grad_threshold = 2.6e-5\ninit = \"unit-cube\"")).unwrap();
    assert_eq!(
        p.methods[1].args,
        vec!["--grad-threshold", "0.000026", "--init", "unit-cube"]
    );
    let p = parse(&with("init = \"fdk\"\nfdk_threshold = 0.2")).unwrap();
    assert_eq!(
        p.methods[1].args,
        vec!["--fdk-threshold", "0.2", "--init", "fdk"]
    );
    // Bad values: the key's line, the flag or field, the value.
    for (line, words) in [
        ("init = \"cube\"", ["line 8", "--init", "cube"]),
        (
            "grad_threshold = -1.0",
            ["line 8", "densify.grad_threshold", "-1"],
        ),
        ("init_points = 0", ["line 8", "init.points", "got 0"]),
        (
            "lambda_dssim = 2.0",
            ["line 8", "loss.lambda_dssim", "got 2"],
        ),
    ] {
        let e = parse(&with(line)).unwrap_err().to_string();
        for w in words {
            assert!(e.contains(w), "`{line}`: {e} lacks {w}");
        }
    }
}

#[test]
fn every_builtin_plan_parses() {
    let schema = TrainSchema::of_train();
    for (name, text) in BUILTIN {
        // Paths of built-in plans may be absent here; only optional datasets use `path`.
        let p = Plan::parse(text, Path::new(name), Path::new("."), &schema)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(p.name, name);
    }
}

#[test]
fn schema_lists_the_presets() {
    let s = TrainSchema::of_train();
    for m in ["unispine", "xgaussian", "3dgs", "spwm-only", "fdk", "naf"] {
        assert!(s.methods.iter().any(|x| x == m), "{m} in {:?}", s.methods);
    }
    let help = |m: &str| s.method_help.iter().find(|h| h.0 == m).unwrap().1.clone();
    assert!(help("unispine").contains("SPWM") && help("fdk").contains("FDK"));
    assert!(
        help("naf").starts_with("naf (reduced): hash grid 8 levels"),
        "{}",
        help("naf")
    );
    assert!(
        help("nerf-full").starts_with("nerf-full: frequency"),
        "{}",
        help("nerf-full")
    );
    // The settings' flags, switch or valued, and none of the harness's own.
    for (flag, takes) in [
        ("color", true),
        ("spwm", true),
        ("compress-schedule", false),
    ] {
        assert_eq!(s.flag(flag), Some(&(flag.to_string(), takes)), "{flag}");
    }
    assert!(s.flag("resume").is_none() && s.flag("out").is_none());
}

const BASELINES: &str = "name = \"t\"\niters = 10\ncompress_schedule = true\nseeds = [3]\n\
                         methods = [\"unispine\", \"fdk\", \"naf\", \"tv\"]\n[train]\n\
                         preview_views = 2\n[[datasets]]\nname = \"ph\"\n\
                         data = [\"phantom\", \"--size\", \"16\"]\n\
                         [variants.tv]\nbase = \"tensorf\"\nvm_lines = \"corrected\"\n";

fn args_of(plan: &Plan, method: &str) -> Vec<String> {
    let cells = crate::reproduce::run::cells(plan);
    let c = cells.iter().find(|c| c.method.name == method).unwrap();
    c.train_args(plan)
}

#[test]
fn baseline_cells_get_their_seed_and_only_the_flags_they_take() {
    let p = parse(BASELINES).unwrap();
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    assert_eq!(
        args_of(&p, "unispine"),
        s(&[
            "--method",
            "unispine",
            "--iters",
            "10",
            "--seed",
            "3",
            "--compress-schedule",
            "--preview-views",
            "2"
        ])
    );
    // FDK is one pass: no iterations; the Gaussian settings of [train] are not passed.
    assert_eq!(args_of(&p, "fdk"), s(&["--method", "fdk", "--seed", "3"]));
    assert_eq!(
        args_of(&p, "naf"),
        s(&["--method", "naf", "--iters", "10", "--seed", "3"])
    );
    assert_eq!(
        args_of(&p, "tv"),
        s(&[
            "--method",
            "tensorf",
            "--iters",
            "10",
            "--seed",
            "3",
            "--vm-lines",
            "corrected"
        ])
    );
    // Fields on their own schedule, or on a count of their own.
    let pre = parse(&BASELINES.replace("seeds", "field_iters = \"preset\"\nseeds")).unwrap();
    assert_eq!(args_of(&pre, "naf"), s(&["--method", "naf", "--seed", "3"]));
    assert_eq!(args_of(&pre, "unispine")[3], "10");
    let n = parse(&BASELINES.replace("seeds", "field_iters = 7\nseeds")).unwrap();
    assert_eq!(args_of(&n, "naf")[3], "7");
    // A variant drawing a field's rays from every pixel.
    let all = parse(&BASELINES.replace("vm_lines = \"corrected\"", "rays = \"all\"")).unwrap();
    assert_eq!(
        args_of(&all, "tv")[6..],
        s(&["--rays", "all"])[..],
        "{:?}",
        args_of(&all, "tv")
    );
}

#[test]
fn settings_a_baseline_cannot_follow_are_plan_errors() {
    let cases = [
        (
            BASELINES.replace("seeds", "field_iters = \"all\"\nseeds"),
            "line 4",
            "field_iters",
        ),
        (
            BASELINES.replace("seeds", "field_iters = 0\nseeds"),
            "line 4",
            "field_iters",
        ),
        (
            BASELINES.replace("vm_lines = \"corrected\"", "densify_from = 5"),
            "line 13",
            "densify_from",
        ),
        (
            format!("{BASELINES}[sweep]\nflag = \"max-gaussians\"\nvalues = [10, 20]\n"),
            "line 15",
            "max-gaussians",
        ),
    ];
    for (text, line, word) in cases {
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains(line) && e.contains(word), "{e}\n--\n{text}");
    }
}
