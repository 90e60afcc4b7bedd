//! `ARCHITECTURE.md`'s equation -> code -> test index names only files and items that exist:
//! every path (braces and `*` expanded) matches a file or folder, every item after a path is a
//! word of that file, every `module::path::tests` is a module with tests, every
//! `tests/FILE.rs::name` is a function of that file. `paper_notes.md` is held to the same rules
//! for the project's own names (its other code spans name upstream files).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `a{b,c}d` -> [`abd`, `acd`] (one level of braces, repeated).
fn expand(s: &str) -> Vec<String> {
    match (s.find('{'), s.find('}')) {
        (Some(a), Some(b)) if a < b => s[a + 1..b]
            .split(',')
            .flat_map(|alt| expand(&format!("{}{alt}{}", &s[..a], &s[b + 1..])))
            .collect(),
        _ => vec![s.to_string()],
    }
}

/// Whether `name` matches `pat` with `*` standing for any run of characters.
fn wild(pat: &str, name: &str) -> bool {
    match pat.split_once('*') {
        None => pat == name,
        Some((head, tail)) => {
            name.starts_with(head)
                && (0..=name.len() - head.len()).any(|k| wild(tail, &name[head.len() + k..]))
        }
    }
}

/// Existing paths below `base` matching the `/`-separated pattern.
fn glob(base: &Path, pat: &str) -> Vec<PathBuf> {
    let mut found = vec![base.to_path_buf()];
    for seg in pat.split('/').filter(|s| !s.is_empty()) {
        let mut next = Vec::new();
        for p in &found {
            if seg.contains('*') {
                for e in std::fs::read_dir(p).into_iter().flatten().flatten() {
                    if wild(seg, &e.file_name().to_string_lossy()) {
                        next.push(e.path());
                    }
                }
            } else if p.join(seg).exists() {
                next.push(p.join(seg));
            }
        }
        found = next;
    }
    found
}

/// The file of module path `segs` below `src/`, and how many segments it used.
fn module_file(segs: &[&str]) -> Option<(PathBuf, usize)> {
    let src = root().join("src");
    (1..=segs.len()).rev().find_map(|k| {
        let rel = segs[..k].join("/");
        [src.join(format!("{rel}.rs")), src.join(&rel).join("mod.rs")]
            .into_iter()
            .find(|p| p.is_file())
            .map(|p| (p, k))
    })
}

fn has_word(text: &str, w: &str) -> bool {
    text.match_indices(w).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + w.len()..].chars().next();
        let edge = |c: Option<char>| c.is_none_or(|c| !(c.is_alphanumeric() || c == '_'));
        edge(before) && edge(after)
    })
}

#[test]
fn every_file_and_item_the_index_names_exists() {
    let doc = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let table = doc
        .split("## Equation -> code -> test")
        .nth(1)
        .expect("the index section")
        .split("\n## ")
        .next()
        .unwrap();
    let mut checked = 0;
    let mut missing = Vec::new();
    for row in table.lines().filter(|l| l.starts_with('|')).skip(2) {
        for cell in row.split('|').skip(2) {
            let mut last_files: Vec<PathBuf> = Vec::new();
            for span in cell.split('`').skip(1).step_by(2) {
                if span.contains(' ') {
                    continue; // a command line, not a name
                }
                checked += 1;
                if span.contains(".rs::") {
                    if !test_fn_exists(span) {
                        missing.push(span.to_string());
                    }
                } else if span.contains("::") {
                    if !module_item_exists(span) {
                        missing.push(span.to_string());
                    }
                } else if span.contains('/') || span.ends_with(".rs") || span.ends_with(".py") {
                    let mut files = Vec::new();
                    for pat in expand(span) {
                        for base in [root(), root().join("src")] {
                            files.extend(glob(&base, &pat));
                        }
                    }
                    if files.is_empty() {
                        missing.push(span.to_string());
                    }
                    last_files = files.into_iter().filter(|p| p.is_file()).collect();
                } else if !last_files.is_empty() {
                    let ok = last_files
                        .iter()
                        .any(|f| std::fs::read_to_string(f).is_ok_and(|t| has_word(&t, span)));
                    if !ok {
                        missing.push(format!("{span} (in {:?})", last_files));
                    }
                }
            }
        }
    }
    assert!(
        checked > 40,
        "only {checked} names found: is the table still there?"
    );
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md names what does not exist: {missing:#?}"
    );
}

/// Whether a `tests/FILE.rs::name` span names a function of that file.
fn test_fn_exists(span: &str) -> bool {
    span.split_once(".rs::").is_some_and(|(file, item)| {
        std::fs::read_to_string(root().join(format!("{file}.rs")))
            .is_ok_and(|t| t.contains(&format!("fn {item}(")))
    })
}

/// Whether `a::b::c` names a module of the crate and words of its file (a trailing `tests` may
/// be a `tests.rs` beside it).
fn module_item_exists(span: &str) -> bool {
    let segs: Vec<&str> = span.split("::").collect();
    module_file(&segs).is_some_and(|(file, used)| {
        let text = std::fs::read_to_string(&file).unwrap();
        let dir = if file.ends_with("mod.rs") {
            file.parent().unwrap().to_path_buf()
        } else {
            file.with_extension("")
        };
        segs[used..]
            .iter()
            .all(|s| has_word(&text, s) || (*s == "tests" && dir.join("tests.rs").is_file()))
    })
}

/// Whether `path` (braces and `*` expanded) matches something below the root or `src/`.
fn path_exists(span: &str) -> bool {
    expand(span).iter().all(|pat| {
        [root(), root().join("src")]
            .iter()
            .any(|base| !glob(base, pat).is_empty())
    })
}

#[test]
fn every_project_name_in_paper_notes_exists() {
    let doc = std::fs::read_to_string(root().join("paper_notes.md")).unwrap();
    const PROJECT_DIRS: [&str; 7] = [
        "tests/", "tools/", "golden/", "docs/", "scripts/", "benches/", "python/",
    ];
    let top_module = |seg: &str| {
        let src = root().join("src");
        src.join(format!("{seg}.rs")).is_file() || src.join(seg).join("mod.rs").is_file()
    };
    let (mut checked, mut missing) = (0, Vec::new());
    for span in doc.split('`').skip(1).step_by(2) {
        if span.contains(char::is_whitespace) || span.is_empty() {
            continue;
        }
        let ok = if span.contains(".rs::") {
            test_fn_exists(span)
        } else if span.contains("::") {
            if !top_module(span.split("::").next().unwrap()) {
                continue; // a type's item or a test file's function, named in context
            }
            module_item_exists(span)
        } else if span.ends_with(".rs") || PROJECT_DIRS.iter().any(|d| span.starts_with(d)) {
            path_exists(span)
        } else {
            continue;
        };
        checked += 1;
        if !ok {
            missing.push(span.to_string());
        }
    }
    assert!(
        checked > 100,
        "only {checked} names found in paper_notes.md"
    );
    assert!(
        missing.is_empty(),
        "paper_notes.md names what does not exist: {missing:#?}"
    );
}

#[test]
fn the_checker_sees_a_wrong_name() {
    assert!(wild("eq0*-vjp", "eq01-covariance-vjp"));
    assert!(!wild("eq0*-vjp", "eq01-covariance"));
    assert_eq!(expand("math/{quat,covariance}.rs").len(), 2);
    assert!(module_file(&["render", "project", "tests"]).is_some());
    assert!(!glob(&root().join("src"), "train/no_such_file.rs")
        .iter()
        .any(|p| p.exists()));
    assert!(has_word("pub struct Metrics {", "Metrics"));
    assert!(module_item_exists("render::project::tests"));
    assert!(!module_item_exists("render::project::no_such_item"));
    assert!(test_fn_exists(
        "tests/architecture/index.rs::the_checker_sees_a_wrong_name"
    ));
    assert!(!test_fn_exists("tests/architecture/index.rs::no_such_test"));
    assert!(path_exists("render/{project,tiles}.rs") && !path_exists("render/{project,nope}.rs"));
    assert!(!has_word("pub struct MetricsX {", "Metrics"));
}

/// Every `.rs` file below `src/`.
fn source_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(&root().join("src"), &mut files);
    files
}

/// Every source file of the library and the front end over 600 lines says why in its module
/// documentation (a line with "600 lines").
#[test]
fn a_long_file_says_why_in_its_header() {
    let files = source_files();
    let mut silent = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let header: Vec<&str> = text.lines().take_while(|l| l.starts_with("//!")).collect();
        if text.lines().count() > 600 && !header.iter().any(|l| l.contains("600 lines")) {
            silent.push(f.strip_prefix(root()).unwrap().display().to_string());
        }
    }
    assert!(files.len() > 50, "found {} source files", files.len());
    assert!(
        silent.is_empty(),
        "over 600 lines without a reason: {silent:?}"
    );
}

/// No string literal on one line of `src/` holds a run of four or more spaces after text: the
/// mark of a line break folded into a message by an edit (a message then prints with a gap of
/// twenty spaces). Continuation lines (`\` at the end) are the way to wrap a long message.
#[test]
fn no_message_holds_a_folded_line_break() {
    let gap = |s: &str| {
        let t = s.trim_start();
        t.find("    ").is_some_and(|i| !t[i..].trim().is_empty())
    };
    let files = source_files();
    let mut found = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("//") {
                continue;
            }
            // The parts between quotes (odd pieces); escaped quotes do not occur in a gap.
            let inside = line.split('"').skip(1).step_by(2);
            if inside.into_iter().any(gap) {
                let rel = f.strip_prefix(root()).unwrap().display().to_string();
                found.push(format!("{rel}:{}", n + 1));
            }
        }
    }
    assert!(gap("a {len}-byte file                      cannot"));
    assert!(!gap("    indented") && !gap("a  b"));
    assert!(
        found.is_empty(),
        "string literals with a folded line break: {found:?}"
    );
}
