//! Embeds the repository's golden files (`../golden/<folder>/<case>.json`) into the module, so
//! an installed package serves them without the source tree.

use std::fmt::Write;
use std::path::Path;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../golden");
    println!("cargo:rerun-if-changed={}", root.display());
    let mut files = Vec::new();
    if let Ok(dirs) = std::fs::read_dir(&root) {
        for d in dirs.flatten() {
            let p = d.path();
            if !p.is_dir() {
                continue;
            }
            println!("cargo:rerun-if-changed={}", p.display());
            for f in std::fs::read_dir(&p).into_iter().flatten().flatten() {
                let fp = f.path();
                if fp.extension().is_some_and(|e| e == "json") {
                    println!("cargo:rerun-if-changed={}", fp.display());
                    files.push(fp.canonicalize().expect("golden file path"));
                }
            }
        }
    }
    files.sort();
    let mut code = String::from(
        "/// (folder, case, JSON text) of every golden file.\npub const FILES: &[(&str, &str, &str)] = &[\n",
    );
    for f in &files {
        let folder = f.parent().unwrap().file_name().unwrap().to_string_lossy();
        let case = f.file_stem().unwrap().to_string_lossy();
        writeln!(
            code,
            "    ({folder:?}, {case:?}, include_str!({:?})),",
            f.display()
        )
        .unwrap();
    }
    code.push_str("];\n");
    let out = Path::new(&std::env::var("OUT_DIR").unwrap()).join("golden_files.rs");
    std::fs::write(out, code).unwrap();
}
