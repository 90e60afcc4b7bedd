//! Plan parsing: good plans, errors naming the line and key, baseline cells' arguments.

use super::*;

mod parse_edges;

/// A plan text parsed as the file `p.toml` with the schema of `unispine train` (also used by
/// the unit tests of the other harness modules).
pub(crate) fn parse(t: &str) -> Result<Plan> {
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

// ---------------------------------------------------------------------------------------------
// Conditions.

const COND: &str = "name = \"c\"\niters = 10\nseeds = [0, 1]\n\
                    methods = [\"3dgs\", \"xgaussian\", \"v\"]\n\
                    [variants.v]\nbase = \"unispine\"\nspwm = false\n\
                    [variants.w]\nbase = \"3dgs\"\ngrad_threshold = 2e-4\n\
                    [[conditions]]\naxis = \"pose-noise\"\non = \"data\"\nflag = \"pose-noise-deg\"\n\
                    base = 0\nvalues = [0.1, 0.2]\n\
                    [[conditions]]\naxis = \"init\"\non = \"train\"\nflag = \"init\"\n\
                    methods = [\"3dgs\"]\nvalues = [\"acui\"]\n\
                    [[conditions]]\naxis = \"preset\"\non = \"method\"\nmethods = [\"3dgs\"]\n\
                    values = [\"w\"]\n\
                    [[conditions]]\naxis = \"schedule\"\non = \"train\"\nflag = \"iters\"\n\
                    values = [20]\n\
                    [[datasets]]\nname = \"ph\"\n\
                    data = [\"phantom\", \"--size\", \"16\", \"--detector\", \"16\"]\n\
                    [[datasets]]\nname = \"q\"\ndata = [\"phantom\", \"--size\", \"8\"]\n";

#[test]
fn conditions_expand_one_at_a_time() {
    let p = parse(COND).unwrap();
    assert_eq!(p.conditions.len(), 4);
    // Per dataset and seed: 3 base + 2 x 3 pose + 1 init + 1 preset + 3 schedule = 14.
    assert_eq!(p.method_points(), 14);
    assert_eq!(p.n_cells(), 2 * 14 * 2);
    let cs = crate::reproduce::cell::cells(&p);
    assert_eq!(cs.len(), p.n_cells());
    assert!(cs.iter().enumerate().all(|(i, c)| c.index == i));
    let dirs: Vec<String> = cs
        .iter()
        .filter(|c| c.dataset == "ph" && c.seed == 0)
        .map(|c| c.method_dir(&p))
        .collect();
    assert_eq!(
        dirs,
        [
            "3dgs",
            "xgaussian",
            "v",
            "3dgs@pose-noise=0.1",
            "xgaussian@pose-noise=0.1",
            "v@pose-noise=0.1",
            "3dgs@pose-noise=0.2",
            "xgaussian@pose-noise=0.2",
            "v@pose-noise=0.2",
            "3dgs@init=acui",
            "3dgs@preset=w",
            "3dgs@schedule=20",
            "xgaussian@schedule=20",
            "v@schedule=20",
        ]
    );
    let by = |dir: &str| {
        cs.iter()
            .find(|c| c.dataset == "ph" && c.seed == 1 && c.method_dir(&p) == dir)
            .unwrap()
    };
    // One condition at a time: the init cell has no schedule change, the base dataset, and
    // only its own train flag; the others keep their base values.
    let init = by("3dgs@init=acui");
    let a = init.train_args(&p);
    assert!(a.windows(2).any(|w| w == ["--init", "acui"]), "{a:?}");
    assert!(a.windows(2).any(|w| w == ["--iters", "10"]), "{a:?}");
    assert_eq!(init.data_name(&p), "ph");
    let base = by("3dgs").train_args(&p);
    assert!(!base.contains(&"--init".to_string()), "{base:?}");
    // The schedule condition sets --iters and nothing else.
    let sch = by("v@schedule=20").train_args(&p);
    assert!(sch.windows(2).any(|w| w == ["--iters", "20"]), "{sch:?}");
    assert!(sch.windows(2).any(|w| w == ["--spwm", "false"]), "{sch:?}");
    // The preset condition: the method keeps its name, runs the variant's preset and flags.
    let pre = by("3dgs@preset=w");
    assert_eq!(pre.method.name, "3dgs");
    assert_eq!(pre.method.base, "3dgs");
    assert!(pre
        .train_args(&p)
        .windows(2)
        .any(|w| w == ["--grad-threshold", "0.0002"]));
    // A pose cell reads its own dataset, built once with the value replacing the base.
    let pose = by("xgaussian@pose-noise=0.2");
    assert_eq!(pose.data_name(&p), "ph@pose-noise=0.2");
    let builds = p.dataset_builds();
    let names: Vec<&str> = builds.iter().map(|d| d.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "ph",
            "ph@pose-noise=0.1",
            "ph@pose-noise=0.2",
            "q",
            "q@pose-noise=0.1",
            "q@pose-noise=0.2"
        ]
    );
    let args = |i: usize| match &builds[i].source {
        Source::Data(a) => a.join(" "),
        _ => unreachable!(),
    };
    assert_eq!(
        args(0),
        "phantom --size 16 --detector 16 --pose-noise-deg 0"
    );
    assert_eq!(
        args(2),
        "phantom --size 16 --detector 16 --pose-noise-deg 0.2"
    );
    // Every cell's dataset is one of the builds.
    assert!(cs.iter().all(|c| names.contains(&c.data_name(&p).as_str())));
}

#[test]
fn a_data_flag_already_given_is_replaced() {
    let t = COND.replace(
        "flag = \"pose-noise-deg\"\nbase = 0\nvalues = [0.1, 0.2]",
        "flag = \"detector\"\nvalues = [32]",
    );
    let p = parse(&t).unwrap();
    let b = p.dataset_builds();
    assert_eq!(
        b[1].source,
        Source::Data(
            ["phantom", "--size", "16", "--detector", "32"]
                .map(String::from)
                .to_vec()
        )
    );
    assert_eq!(
        b[3].source,
        Source::Data(
            ["phantom", "--size", "8", "--detector", "32"]
                .map(String::from)
                .to_vec()
        )
    );
}

#[test]
fn hostile_conditions_are_refused_with_line_and_key() {
    let pose = "values = [0.1, 0.2]";
    let cases: Vec<(String, &str, &str)> = vec![
        (
            COND.replace("axis = \"init\"", "axis = \"../x\""),
            "line 18",
            "conditions.axis",
        ),
        (
            COND.replace("axis = \"init\"", "axis = \"pose-noise\""),
            "line 18",
            "repeats",
        ),
        (COND.replace(pose, "values = [-0.1]"), "line 16", "-0.1"),
        (COND.replace(pose, "values = [\"nan\"]"), "line 16", "nan"),
        (
            COND.replace(pose, "values = [0.1, 1e-1]"),
            "line 16",
            "repeats",
        ),
        (COND.replace(pose, "values = [0]"), "line 16", "repeats"),
        (COND.replace(pose, "values = [\"a/b\"]"), "line 16", "a/b"),
        (COND.replace(pose, "values = []"), "line 16", "empty"),
        (
            COND.replace("flag = \"pose-noise-deg\"", "flag = \"out\""),
            "line 14",
            "out",
        ),
        (
            COND.replace("flag = \"init\"", "flag = \"colour\""),
            "line 20",
            "colour",
        ),
        (
            COND.replace("flag = \"init\"", "flag = \"seed\""),
            "line 20",
            "seed",
        ),
        (
            COND.replace("values = [\"acui\"]", "values = [\"sphere\"]"),
            "line 22",
            "sphere",
        ),
        (
            COND.replace("on = \"data\"", "on = \"disk\""),
            "line 13",
            "disk",
        ),
        (
            COND.replace("values = [\"w\"]", "values = [\"nope\"]"),
            "line 27",
            "nope",
        ),
        (
            COND.replace("values = [\"w\"]", "values = [\"3dgs\"]"),
            "line 27",
            "itself",
        ),
        (
            COND.replace(
                "methods = [\"3dgs\"]\nvalues = [\"acui\"]",
                "methods = [\"nerf\"]\nvalues = [\"acui\"]",
            ),
            "line 21",
            "nerf",
        ),
        (
            COND.replace("values = [20]", "values = [0]"),
            "line 32",
            "iters",
        ),
        (
            COND.replace("values = [20]", "values = [1e12]"),
            "line 32",
            "iters",
        ),
        (
            COND.replace("flag = \"iters\"\n", ""),
            "line 28",
            "missing `flag`",
        ),
        (
            COND.replace(
                "on = \"data\"\nflag = \"pose-noise-deg\"",
                "on = \"data\"\nflag = \"volume\"",
            ),
            "line 14",
            "volume",
        ),
        (
            COND.replace("on = \"data\"", "on = \"data\"\nbogus = 1"),
            "line 14",
            "bogus",
        ),
    ];
    for (text, line, word) in cases {
        let e = parse(&text).unwrap_err().to_string();
        assert!(
            e.contains(line) && e.contains(word) && e.contains("p.toml"),
            "{e}\n--\n{text}"
        );
    }
    // A data condition needs datasets the plan builds.
    let d = tempfile::tempdir().unwrap();
    let path_ds = COND.replace(
        "data = [\"phantom\", \"--size\", \"8\"]",
        "path = \"ds\"\noptional = true",
    );
    let e = Plan::parse(
        &path_ds,
        Path::new("p.toml"),
        d.path(),
        &TrainSchema::of_train(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("conditions.pose-noise") && e.contains("`q`"),
        "{e}"
    );
}

#[test]
fn too_many_condition_cells_are_refused_before_anything_runs() {
    let many: Vec<String> = (1..=1300)
        .map(|i| format!("{}", i as f64 / 10000.0))
        .collect();
    let t = COND.replace(
        "values = [0.1, 0.2]",
        &format!("values = [{}]", many.join(", ")),
    );
    let p = parse(&t).unwrap();
    // 3 base + 1300 x 3 pose + 1 + 1 + 3 = 3908 per dataset and seed.
    assert_eq!(p.n_cells(), 2 * 3908 * 2);
    let e = p.check_cells(DEFAULT_MAX_CELLS).unwrap_err().to_string();
    assert!(
        e.contains("15632 cells") && e.contains("--max-cells"),
        "{e}"
    );
    assert!(p.check_cells(15632).is_ok());
}

#[test]
fn the_charbonnier_only_variant_is_unispine_without_spwm_with_plain_charbonnier() {
    let p = Plan::load("gap", &TrainSchema::of_train()).unwrap();
    let v = p
        .methods
        .iter()
        .find(|m| m.name == "charbonnier-only")
        .unwrap();
    assert_eq!(v.base, "unispine");
    let o: crate::train::TrainOverrides = crate::flags::parse_set(&v.args).unwrap();
    let cfg = o.apply(crate::train::Method::Unispine, None).unwrap();
    let preset = crate::train::TrainOverrides::default()
        .apply(crate::train::Method::Unispine, None)
        .unwrap();
    assert!(cfg.spwm.is_none());
    assert_eq!(cfg.loss.data_term, crate::loss::DataTerm::Charbonnier);
    assert!(preset.spwm.is_some());
    assert_eq!(
        preset.loss.data_term,
        crate::loss::DataTerm::WeightedCharbonnier
    );
    // Everything else is the unispine preset's.
    let mut same = cfg.clone();
    same.spwm = preset.spwm.clone();
    same.loss.data_term = preset.loss.data_term;
    assert_eq!(same, preset);
}

#[test]
fn a_replacing_preset_runs_with_its_own_settings() {
    // In `gap`, the init and threshold axes have the `3dgs` preset's values as their base;
    // those are not vanilla 3DGS's (unit cube, 2e-4), so its cells must not receive them.
    let p = Plan::load("gap", &TrainSchema::of_train()).unwrap();
    let cs = crate::reproduce::cell::cells(&p);
    let args = |dir: &str| {
        cs.iter()
            .find(|c| c.dataset == "ct-crop" && c.seed == 0 && c.method_dir(&p) == dir)
            .unwrap()
            .train_args(&p)
    };
    let has = |a: &[String], f: &str, v: &str| a.windows(2).any(|w| w[0] == f && w[1] == v);
    let vanilla = args("3dgs@preset=3dgs-vanilla");
    assert!(has(&vanilla, "--method", "3dgs-vanilla"), "{vanilla:?}");
    assert!(
        !vanilla
            .iter()
            .any(|a| a == "--init" || a == "--grad-threshold"),
        "{vanilla:?}"
    );
    // Every other 3dgs cell keeps the base values of the axes it is not on.
    let base = args("3dgs");
    assert!(has(&base, "--init", "random") && has(&base, "--grad-threshold", "0.00015"));
    let cube = args("3dgs@init=unit-cube");
    assert!(has(&cube, "--init", "unit-cube") && has(&cube, "--grad-threshold", "0.00015"));
    let thr = args("3dgs@upstream-grad-threshold=0.0002");
    assert!(has(&thr, "--init", "random") && has(&thr, "--grad-threshold", "0.0002"));
}

#[test]
fn a_switch_in_a_variant_is_its_flag_when_true_and_nothing_when_false() {
    let on = parse(&format!("{OK}compress_schedule = true\n")).unwrap();
    assert_eq!(
        on.methods[1].args,
        vec!["--color", "rirf-paper", "--compress-schedule"]
    );
    let off = parse(&format!("{OK}compress_schedule = false\n")).unwrap();
    assert_eq!(off.methods[1].args, vec!["--color", "rirf-paper"]);
    let e = parse(&format!("{OK}compress_schedule = 1\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("is a switch"), "{e}");
}
