//! `unispine reproduce`: the paper's tables regenerated from a plan (datasets x methods x
//! seeds), with verdicts, provenance, charts and a Slurm job array.
//!
//! Stages, in data-flow order: [`plan`] (TOML -> validated plan) -> [`cell`] (its cells and
//! their `unispine train` arguments) -> [`run`] (cells as
//! `unispine train` child processes into `OUT/runs/DATASET/METHOD/seedK/`, resumable) ->
//! [`aggregate`] (results.csv / results.json, mean +- sd per row) -> [`verdict`] (the paper's
//! claims as paired differences with 95 % intervals) -> [`magnitude`] (the paper's effect
//! against those intervals, per dataset and pooled) -> [`holds`] (each claim at each value of
//! the plan's conditions) -> [`tables`] (`results.csv`, `results.json`, `tables.md`).
//!
//! [`plan`]: crate::reproduce::plan
//! [`cell`]: crate::reproduce::cell
//! [`run`]: crate::reproduce::run
//! [`aggregate`]: crate::reproduce::aggregate
//! [`verdict`]: crate::reproduce::verdict
//! [`magnitude`]: crate::reproduce::magnitude
//! [`holds`]: crate::reproduce::holds
//! [`tables`]: crate::reproduce::tables

pub mod aggregate;
pub mod cell;
pub mod claims_doc;
pub mod command;
pub mod compactness;
pub mod holds;
pub mod magnitude;
pub mod plan;
pub mod provenance;
pub mod run;
pub mod slurm;
pub mod tables;
pub mod verdict;
