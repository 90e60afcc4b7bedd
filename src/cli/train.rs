//! `unispine train --data DIR --method M --iters N --out RUN [--seed S] [overrides]`.
//!
//! Trains a method preset on a dataset folder (from `unispine data`), with a progress bar
//! (iteration, loss, PSNR, number of Gaussians, iterations per second), a clean stop on Ctrl-C
//! that still writes a checkpoint, and the run folder described in [`crate::train`].

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::Context;

use super::progress::Progress;
use crate::train::{self, Event, Method, TrainOverrides};

/// Arguments of `unispine train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Dataset folder written by `unispine data`.
    #[arg(long)]
    pub data: PathBuf,
    /// Method preset.
    #[arg(long, value_enum, default_value = "unispine")]
    pub method: Method,
    /// Training iterations (paper: 20000).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Run folder (created; files in it are replaced).
    #[arg(long)]
    pub out: PathBuf,
    /// rayon threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub overrides: TrainOverrides,
}

/// Set up rayon's global pool with `threads` threads (no-op when `None`).
pub fn init_threads(threads: Option<usize>) -> anyhow::Result<()> {
    if let Some(t) = threads {
        // Results do not depend on the thread count; more threads than 8 x the cores only
        // costs memory (each has a stack) and time.
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        if t == 0 || t > 8 * cores {
            anyhow::bail!(
                "invalid `--threads`: {t} is outside the allowed range [1, {}] (8 x the {cores} \
                 cores)",
                8 * cores
            );
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .context("setting up the thread pool")?;
    }
    Ok(())
}

/// Run `unispine train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    init_threads(args.threads)?;
    let mut cfg = args.overrides.apply(args.method, args.iters)?;
    cfg.data = Some(args.data.display().to_string());
    let ds = crate::dataset::store::load(&args.data)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                eprintln!("second Ctrl-C: exiting without a checkpoint");
                std::process::exit(130);
            }
            eprintln!("\nCtrl-C: stopping after this iteration and writing a checkpoint ...");
        })
        .context("installing the Ctrl-C handler")?;
    }
    eprintln!(
        "training `{}` on {} for {} iterations -> {}",
        cfg.method.name(),
        args.data.display(),
        cfg.iterations,
        args.out.display()
    );
    let mut bar: Option<Progress> = None;
    let mut on_event = |e: &Event| match e {
        Event::Started {
            total,
            n_gaussians,
            train_views,
            test_views,
            extent,
        } => {
            eprintln!(
                "{n_gaussians} initial Gaussians, {train_views} training / {test_views} test views, \
                 scene extent {extent:.1} mm"
            );
            bar = Some(Progress::new("train", *total as u64));
        }
        Event::Progress {
            loss,
            psnr,
            n_gaussians,
            its_per_sec,
            ..
        } => {
            if let Some(b) = bar.as_mut() {
                b.inc(
                    1,
                    &format!(
                        "loss {loss:.4} psnr {psnr:.2} dB N {n_gaussians} {its_per_sec:.1} it/s"
                    ),
                );
            }
        }
        Event::Eval {
            iteration,
            psnr,
            ssim,
            n_gaussians,
        } => eprintln!(
            "\n[test @ {iteration}] PSNR {psnr:.3} dB  SSIM {ssim:.4}  ({n_gaussians} Gaussians)"
        ),
        Event::Stopped { iteration } => eprintln!("\nstopped after iteration {iteration}"),
        _ => {}
    };
    let m = train::run(&cfg, &ds, Some(&args.out), &stop, &mut on_event);
    if let Some(b) = bar.take() {
        b.finish("");
    }
    let m = m.with_context(|| {
        format!(
            "the last good state is in {}",
            args.out.join("checkpoint.ply").display()
        )
    })?;
    if !m.completed {
        println!(
            "stopped at iteration {}; checkpoint: {}",
            m.iterations,
            args.out.join("checkpoint.ply").display()
        );
        return Ok(());
    }
    println!(
        "{}: test PSNR {:.3} dB, SSIM {:.4}, {} Gaussians, train time {:.1} s, render {:.1} fps",
        cfg.method.name(),
        m.test_psnr.unwrap_or(f64::NAN),
        m.test_ssim.unwrap_or(f64::NAN),
        m.n_gaussians,
        m.train_time_s,
        m.render_fps.unwrap_or(f64::NAN)
    );
    println!("outputs: {}", args.out.display());
    Ok(())
}
