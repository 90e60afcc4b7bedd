//! Records the git commit of a checkout as `UNISPINE_GIT_COMMIT` (provenance of reproduce
//! results), with `-dirty` appended when the files that build the binary (`src/`, `build.rs`,
//! `Cargo.toml`, `Cargo.lock`) differ from that commit. Outside a checkout, or without git,
//! nothing is set.

use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git").args(args).output().ok()?;
    if !o.status.success() {
        return None;
    }
    Some(String::from_utf8(o.stdout).ok()?.trim().to_string())
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    // An edit of the sources makes the tree dirty (or clean again).
    for p in ["src", "Cargo.toml", "Cargo.lock"] {
        println!("cargo:rerun-if-changed={p}");
    }
    let Some(commit) = git(&["rev-parse", "HEAD"]) else {
        return;
    };
    let changed = ["src", "build.rs", "Cargo.toml", "Cargo.lock"];
    let status = git(&[
        &["status", "--porcelain", "--untracked-files=all", "--"][..],
        &changed[..],
    ]
    .concat());
    let dirty = match status {
        Some(s) if !s.is_empty() => "-dirty",
        _ => "",
    };
    println!("cargo:rustc-env=UNISPINE_GIT_COMMIT={commit}{dirty}");
    // Rebuild when HEAD moves: the HEAD file and the branch it points to (loose or packed).
    if let Some(head) = git(&["rev-parse", "--git-path", "HEAD"]) {
        println!("cargo:rerun-if-changed={head}");
    }
    if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
        if let Some(p) = git(&["rev-parse", "--git-path", &r]) {
            if Path::new(&p).exists() {
                println!("cargo:rerun-if-changed={p}");
            }
        }
    }
    if let Some(p) = git(&["rev-parse", "--git-path", "packed-refs"]) {
        if Path::new(&p).exists() {
            println!("cargo:rerun-if-changed={p}");
        }
    }
}
