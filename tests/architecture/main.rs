//! The project's own map: `ARCHITECTURE.md`'s index and the import graph it describes.

#[path = "../common/mod.rs"]
mod common;

mod import_graph;
mod index;
