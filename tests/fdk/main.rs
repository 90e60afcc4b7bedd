//! FDK (`src/fdk.rs`): TIGRE's filter and closed forms, and the cone-beam weights at a large
//! cone angle.

#[path = "../common/mod.rs"]
mod common;

mod closed_forms;
mod cone_weights;
