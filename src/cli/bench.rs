//! `unispine bench <kind>`: benchmarks that print ratios against a baseline measured in the same
//! run.
//!
//! Kinds:
//! - `render`: forward and forward + backward of the rasterizer in f32 on the CT-like scenes of
//!   [`crate::audit::bench`], for each Gaussian count and square detector size; prints median
//!   times, Gaussian-pixel blends per second, and the same throughput of the naive per-pixel
//!   reference measured on a smaller case in the same run, scaled per blend.
//!
//! (A `train` kind, one full training iteration, belongs to the trainer.)

use anyhow::bail;

use crate::audit::bench::{time_naive, time_render, BOX_MM};

/// Arguments of `unispine bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// What to benchmark: `render` (rasterizer forward and forward + backward).
    pub kind: String,
    /// Gaussian counts (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "10000,50000,100000")]
    pub gaussians: Vec<usize>,
    /// Square detector sizes in pixels (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "256,512")]
    pub sizes: Vec<usize>,
    /// Repetitions per case (the median is reported).
    #[arg(long, default_value_t = 7)]
    pub reps: usize,
}

/// Run `unispine bench`.
pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.kind.as_str() {
        "render" => run_render(&args),
        k => bail!("unknown benchmark kind `{k}` (available: render)"),
    }
}

fn run_render(args: &BenchArgs) -> anyhow::Result<()> {
    if args.gaussians.is_empty() || args.sizes.is_empty() || args.gaussians.contains(&0) {
        bail!("--gaussians and --sizes need at least one positive value each");
    }
    if args.sizes.contains(&0) {
        bail!("--sizes must be positive");
    }
    println!(
        "render benchmark: CT-like box of {BOX_MM} mm, cone beam, f32, paper RIRF, {} threads, \
         median of {} reps",
        rayon::current_num_threads(),
        args.reps
    );
    // Naive per-pixel reference, measured in this run on a smaller case and scaled per blend.
    let (nn, ns) = (10_000usize, 64usize);
    let (naive_bps, naive_blends) = time_naive(nn, ns)?;
    println!(
        "naive reference (every Gaussian at every pixel, 1 thread): {nn} Gaussians at {ns}x{ns}: \
         {naive_blends} blends, {:.3e} blends/s",
        naive_bps
    );
    println!(
        "{:>9} {:>6} {:>11} {:>11} {:>11} {:>12} {:>10} {:>13} {:>13} {:>10}",
        "gaussians",
        "size",
        "forward ms",
        "fwd+bwd ms",
        "f+b cpu ms",
        "blends",
        "blends/px",
        "fwd blends/s",
        "f+b blends/s",
        "x naive"
    );
    for &size in &args.sizes {
        for &n in &args.gaussians {
            let t = time_render(n, size, args.reps)?;
            let fbps = t.blends as f64 / t.forward;
            println!(
                "{:>9} {:>6} {:>11.2} {:>11.2} {:>11} {:>12} {:>10.1} {:>13.3e} {:>13.3e} {:>10.1}",
                n,
                size,
                t.forward * 1e3,
                t.forward_backward * 1e3,
                t.cpu_forward_backward
                    .map_or("-".to_string(), |c| format!("{:.1}", c * 1e3)),
                t.blends,
                t.blends as f64 / (size * size) as f64,
                fbps,
                t.blends as f64 / t.forward_backward,
                fbps / naive_bps
            );
        }
    }
    println!(
        "x naive = forward blends/s over the naive reference's blends/s; f+b cpu ms = process CPU \
         time (all threads) per forward + backward (mean over the reps)"
    );
    Ok(())
}
