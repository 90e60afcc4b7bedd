//! The rasterizer (`src/render/`, Eqs. 1-5): golden files of each stage and its backward, the
//! whole render against finite differences, edge cases, the Jacobian clamp on all four sides,
//! bit-identical threads, and `unispine render`.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod composite_edges;
mod determinism;
mod golden_project;
mod golden_render;
mod golden_vjp;
mod gradcheck;
mod jacobian_clamp;
