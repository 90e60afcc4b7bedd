//! Helpers shared by the integration tests (each test file uses some of them).

#![allow(dead_code)]

pub mod cli;
pub mod golden;
pub mod hostile;
pub mod skip;
pub mod tiny;
