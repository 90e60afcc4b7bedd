//! The golden files of the repository, embedded at build time (see `build.rs`).

include!(concat!(env!("OUT_DIR"), "/golden_files.rs"));
