//! The import graph of the library's files matches what `ARCHITECTURE.md` says about it: every
//! import cycle between files (a strongly connected component of more than one file) and every
//! import that runs back up the pipeline (from a top-level module to one declared after it in
//! `src/lib.rs`, whose `pub mod` lines are in pipeline order) is listed in its section "Import
//! graph" with the reason it is the natural shape, and nothing listed there is gone.
//!
//! Edges come from `crate::` and `super::` paths (brace groups expanded) outside comments and
//! `#[cfg(test)] mod tests`; a path names the file of its longest prefix that is a module. The
//! command-line front end (`src/main.rs`, `src/cli/`) is the binary, not the library: it has no
//! place in the pipeline's order, and is checked on its own for cycles (it has none).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn src() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file below `dir`, as a path relative to `src/` with `/` separators.
fn rust_files(dir: &Path, out: &mut Vec<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            let rel = p
                .strip_prefix(src())
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            out.push(rel);
        }
    }
}

/// The module path of a file: `drr/mod.rs` -> [drr], `drr/grid.rs` -> [drr, grid].
fn module_of(file: &str) -> Vec<String> {
    let mut segs: Vec<String> = file
        .trim_end_matches(".rs")
        .split('/')
        .map(String::from)
        .collect();
    if matches!(segs.last().map(String::as_str), Some("mod" | "lib")) {
        segs.pop();
    }
    segs
}

/// Source text without comments (line and block; string contents are kept, which only adds
/// edges a reader would also see) and without the unit-test module at the end of a file.
fn code_of(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => text,
    };
    let b = text.as_bytes();
    let (mut out, mut i) = (String::with_capacity(text.len()), 0);
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            let end = text[i + 2..].find("*/").map_or(b.len(), |k| i + 2 + k + 2);
            i = end;
        } else {
            let ch = text[i..].chars().next().unwrap();
            out.push(ch);
            i += ch.len_utf8();
        }
    }
    out
}

/// The paths of a `crate::` / `super::` use starting at `s` (just after the `::`), brace groups
/// expanded: `a::{b, c::d}` -> [a::b, a::c::d].
fn parse_tree(s: &[char], mut i: usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) -> usize {
    let mut path = prefix;
    loop {
        while i < s.len() && s[i].is_whitespace() {
            i += 1;
        }
        if i < s.len() && s[i] == '{' {
            i += 1;
            loop {
                i = parse_tree(s, i, path.clone(), out);
                while i < s.len() && (s[i].is_whitespace() || s[i] == ',') {
                    i += 1;
                }
                if i >= s.len() || s[i] == '}' {
                    return i + 1;
                }
            }
        }
        let start = i;
        while i < s.len() && (s[i].is_alphanumeric() || s[i] == '_') {
            i += 1;
        }
        if i == start {
            out.push(path);
            return i;
        }
        path.push(s[start..i].iter().collect());
        if s[i..].starts_with(&[':', ':']) {
            i += 2;
        } else {
            out.push(path);
            return i;
        }
    }
}

/// The files each file imports (edges of the graph), for the given files.
fn edges(files: &[String], texts: &BTreeMap<String, String>) -> BTreeMap<String, BTreeSet<String>> {
    let modules: BTreeMap<Vec<String>, String> =
        files.iter().map(|f| (module_of(f), f.clone())).collect();
    let resolve = |path: &[String]| {
        (1..=path.len())
            .rev()
            .find_map(|k| modules.get(&path[..k]).cloned())
    };
    let mut graph = BTreeMap::new();
    for f in files {
        let code: Vec<char> = code_of(&texts[f]).chars().collect();
        let me = module_of(f);
        let parent = me[..me.len().saturating_sub(1)].to_vec();
        let mut to = BTreeSet::new();
        let mut i = 0;
        while i < code.len() {
            let word_start = i == 0 || !(code[i - 1].is_alphanumeric() || code[i - 1] == '_');
            let base = if !word_start {
                None
            } else if code[i..].starts_with(&"crate::".chars().collect::<Vec<_>>()) {
                Some((Vec::new(), i + 7))
            } else if code[i..].starts_with(&"super::".chars().collect::<Vec<_>>()) {
                Some((parent.clone(), i + 7))
            } else {
                None
            };
            match base {
                Some((base, at)) => {
                    let mut paths = Vec::new();
                    i = parse_tree(&code, at, base, &mut paths);
                    for p in paths {
                        if let Some(t) = resolve(&p) {
                            if t != *f && !t.ends_with("lib.rs") {
                                to.insert(t);
                            }
                        }
                    }
                }
                None => i += 1,
            }
        }
        graph.insert(f.clone(), to);
    }
    graph
}

/// Strongly connected components of more than one file (Tarjan), each sorted.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> BTreeSet<Vec<String>> {
    struct T<'g> {
        g: &'g BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'g str, usize>,
        low: BTreeMap<&'g str, usize>,
        stack: Vec<&'g str>,
        on: BTreeSet<&'g str>,
        out: BTreeSet<Vec<String>>,
    }
    fn visit<'g>(t: &mut T<'g>, v: &'g str) {
        let n = t.index.len();
        t.index.insert(v, n);
        t.low.insert(v, n);
        t.stack.push(v);
        t.on.insert(v);
        for w in t.g.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !t.index.contains_key(w) {
                visit(t, w);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.insert(comp);
            }
        }
    }
    let mut t = T {
        g: graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: BTreeSet::new(),
    };
    for v in graph.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

/// Imports from a top-level module to one declared after it in `lib.rs`.
fn back_up(graph: &BTreeMap<String, BTreeSet<String>>, order: &[String]) -> BTreeSet<String> {
    let rank = |f: &str| {
        let top = f.split('/').next().unwrap().trim_end_matches(".rs");
        order.iter().position(|m| m == top)
    };
    let mut out = BTreeSet::new();
    for (a, bs) in graph {
        for b in bs {
            if let (Some(ra), Some(rb)) = (rank(a), rank(b)) {
                if rb > ra {
                    out.insert(format!("{a} -> {b}"));
                }
            }
        }
    }
    out
}

/// The library's graph and its top-level modules in `lib.rs` order.
fn library() -> (BTreeMap<String, BTreeSet<String>>, Vec<String>) {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    files.retain(|f| f != "main.rs" && !f.starts_with("cli/"));
    let texts = files
        .iter()
        .map(|f| (f.clone(), std::fs::read_to_string(src().join(f)).unwrap()))
        .collect();
    let order = texts_lib_order(&std::fs::read_to_string(src().join("lib.rs")).unwrap());
    (edges(&files, &texts), order)
}

fn texts_lib_order(lib: &str) -> Vec<String> {
    lib.lines()
        .filter_map(|l| l.strip_prefix("pub mod "))
        .map(|m| m.trim_end_matches(';').trim().to_string())
        .collect()
}

/// What `ARCHITECTURE.md`'s section "Import graph" lists: cycles as "`a.rs` <-> `b.rs`" (more
/// files joined by further "<->") and back-up imports as "`a.rs` -> `b.rs`", each at the start
/// of a list item.
fn documented() -> (BTreeSet<Vec<String>>, BTreeSet<String>) {
    let doc = std::fs::read_to_string(src().join("../ARCHITECTURE.md")).unwrap();
    let section = doc
        .split("\n## ")
        .find(|s| s.starts_with("Import graph"))
        .expect("ARCHITECTURE.md has a section `## Import graph`");
    let (mut cyc, mut up) = (BTreeSet::new(), BTreeSet::new());
    // List items, their continuation lines (indented) joined.
    let mut items: Vec<String> = Vec::new();
    for l in section.lines() {
        if let Some(item) = l.strip_prefix("- ") {
            items.push(item.to_string());
        } else if let (Some(last), true) = (items.last_mut(), l.starts_with("  ")) {
            last.push(' ');
            last.push_str(l.trim());
        }
    }
    for line in &items {
        let head = line.split(':').next().unwrap_or("");
        let names = |sep: &str| -> Vec<String> {
            head.split(sep)
                .map(|s| s.trim().trim_matches('`').to_string())
                .collect()
        };
        if head.contains("<->") {
            let mut files = names("<->");
            files.sort();
            cyc.insert(files);
        } else if head.contains("->") {
            let files = names("->");
            up.insert(format!("{} -> {}", files[0], files[1]));
        }
    }
    (cyc, up)
}

#[test]
fn cycles_and_back_up_imports_are_the_documented_ones() {
    let (graph, order) = library();
    assert!(order.len() > 10, "lib.rs lists its modules: {order:?}");
    let (doc_cycles, doc_up) = documented();
    let found = cycles(&graph);
    let up = back_up(&graph, &order);
    let undocumented: Vec<_> = found.difference(&doc_cycles).collect();
    let gone: Vec<_> = doc_cycles.difference(&found).collect();
    assert!(
        undocumented.is_empty() && gone.is_empty(),
        "import cycles not in ARCHITECTURE.md's \"Import graph\": {undocumented:?}; listed there \
         but gone: {gone:?}"
    );
    let undocumented: Vec<_> = up.difference(&doc_up).collect();
    let gone: Vec<_> = doc_up.difference(&up).collect();
    assert!(
        undocumented.is_empty() && gone.is_empty(),
        "imports back up the pipeline (lib.rs order) not in ARCHITECTURE.md's \"Import graph\": \
         {undocumented:?}; listed there but gone: {gone:?}"
    );
}

#[test]
fn the_graph_sees_groups_super_and_cycles() {
    let files: Vec<String> = ["a/mod.rs", "a/b.rs", "a/c.rs", "d.rs", "e.rs"]
        .map(String::from)
        .to_vec();
    let texts: BTreeMap<String, String> = [
        ("a/mod.rs", "mod b; mod c;"),
        // A group with a nested path, a `super::` path, and a comment that names `e`.
        (
            "a/b.rs",
            "use crate::{d::X, a::c::{Y, Z}};\n// crate::e::W\nfn f() { super::c::g() }",
        ),
        (
            "a/c.rs",
            "use super::b::f;\n#[cfg(test)]\nmod tests { use crate::e::Q; }",
        ),
        ("d.rs", "pub fn h() { crate::e::k() }"),
        ("e.rs", "/* crate::d::h */ pub fn k() {}"),
    ]
    .into_iter()
    .map(|(f, t)| (f.to_string(), t.to_string()))
    .collect();
    let g = edges(&files, &texts);
    let set = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    assert_eq!(g["a/b.rs"], set(&["d.rs", "a/c.rs"]));
    assert_eq!(g["a/c.rs"], set(&["a/b.rs"]));
    assert_eq!(g["d.rs"], set(&["e.rs"]));
    assert_eq!(g["e.rs"], set(&[]));
    let c = cycles(&g);
    assert_eq!(
        c,
        BTreeSet::from([vec!["a/b.rs".to_string(), "a/c.rs".to_string()]])
    );
    let order = texts_lib_order("pub mod e;\npub mod a;\npub mod d;");
    let up = back_up(&g, &order);
    assert_eq!(up, BTreeSet::from(["a/b.rs -> d.rs".to_string()]));
}

/// The front end (`src/main.rs` and `src/cli/`, the binary) has no import cycle between its
/// files either: a command's parts are children of its module (`cli/bench/` holds the
/// benchmark commands, reached from `cli/bench/mod.rs` by their bare names).
#[test]
fn the_front_end_has_no_import_cycle() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    files.retain(|f| f == "main.rs" || f.starts_with("cli/"));
    assert!(files.len() > 10, "front-end files: {files:?}");
    let texts = files
        .iter()
        .map(|f| (f.clone(), std::fs::read_to_string(src().join(f)).unwrap()))
        .collect();
    let graph = edges(&files, &texts);
    assert!(
        graph.values().map(|e| e.len()).sum::<usize>() > 5,
        "the front end's files import each other: {graph:?}"
    );
    let found = cycles(&graph);
    assert!(
        found.is_empty(),
        "import cycles in the front end: {found:?}"
    );
}
