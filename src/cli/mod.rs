//! Command-line front end: one file per subcommand, each with its clap `Args` and `run`.

pub mod bench;
pub mod data;
pub mod drr;
pub mod eval;
pub mod flags;
pub mod gradcheck;
pub mod progress;
pub mod render;
pub mod report;
pub mod reproduce;
pub mod signals;
pub mod train;

use clap::{Parser, Subcommand};

/// unispine: a pure-CPU, deterministic reference for UniSpine-GS (X-ray / ultrasound Gaussian
/// splatting).
#[derive(Debug, Parser)]
#[command(name = "unispine", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands, in pipeline order.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Make a projection dataset (phantom, CT, ultrasound) or import a NAF / X-Gaussian pickle.
    Data(data::DataArgs),
    /// Project a volume with our DRR ray-marcher for given angles.
    Drr(drr::DrrArgs),
    /// Render Gaussians from a PLY for one view; optionally the gradient of sum(W * image).
    Render(render::RenderArgs),
    /// Check every analytic gradient against central finite differences (f64) and print a table.
    Gradcheck(gradcheck::GradcheckArgs),
    /// Train a model (methods: unispine, xgaussian, 3dgs, spwm-only, 3dgs-vanilla, and the
    /// baselines fdk, naf, intratomo, tensorf, nerf[-full]).
    Train(Box<train::TrainArgs>),
    /// Re-evaluate a saved run on its test views.
    Eval(eval::EvalArgs),
    /// Compare finished runs: one markdown table row per run folder (from its metrics.json).
    Report(report::ReportArgs),
    /// Benchmarks that print ratios against a baseline measured in the same run.
    Bench(bench::BenchArgs),
    /// Regenerate the paper's tables from a plan (datasets x methods x seeds) with verdicts.
    Reproduce(reproduce::ReproduceArgs),
}

/// Run the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Data(a) => data::run(a),
        Command::Drr(a) => drr::run(a),
        Command::Render(a) => render::run(a),
        Command::Gradcheck(a) => gradcheck::run(a),
        Command::Train(a) => train::run(*a),
        Command::Eval(a) => eval::run(a),
        Command::Report(a) => report::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Reproduce(a) => reproduce::run(a),
    }
}
