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
use crate::baseline::Baseline;
use crate::train::{self, Event, Method, TrainOverrides};

/// Arguments of `unispine train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Dataset folder written by `unispine data`.
    #[arg(long)]
    pub data: PathBuf,
    /// Method: a Gaussian preset (unispine, xgaussian, 3dgs, spwm-only) or a baseline (fdk).
    #[arg(long, default_value = "unispine", value_parser = parse_method)]
    pub method: MethodArg,
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
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .context("setting up the thread pool")?;
    }
    Ok(())
}

/// `--method`: a Gaussian preset or a baseline of [`crate::baseline`].
#[derive(Clone, Copy, Debug)]
pub enum MethodArg {
    Gaussians(Method),
    Baseline(Baseline),
}

impl MethodArg {
    /// The Gaussian preset, when `--method` names one.
    pub fn gaussians(self) -> Option<Method> {
        match self {
            MethodArg::Gaussians(m) => Some(m),
            MethodArg::Baseline(_) => None,
        }
    }
}

fn parse_method(s: &str) -> Result<MethodArg, String> {
    if let Some(b) = Baseline::parse(s) {
        return Ok(MethodArg::Baseline(b));
    }
    <Method as clap::ValueEnum>::from_str(s, false)
        .map(MethodArg::Gaussians)
        .map_err(|_| {
            let mut names: Vec<&str> = <Method as clap::ValueEnum>::value_variants()
                .iter()
                .map(|m| m.name())
                .collect();
            names.extend(Baseline::names());
            format!("unknown method `{s}` (one of: {})", names.join(", "))
        })
}

/// Run `unispine train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    init_threads(args.threads)?;
    let method = match args.method {
        MethodArg::Gaussians(m) => m,
        MethodArg::Baseline(b) => return run_baseline(b, &args),
    };
    let mut cfg = args.overrides.apply(method, args.iters)?;
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

/// `unispine train --method BASELINE`: the baseline's own trainer, the same run folder.
fn run_baseline(b: Baseline, args: &TrainArgs) -> anyhow::Result<()> {
    let ds = crate::dataset::store::load(&args.data)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\nCtrl-C: stopping after this iteration ...");
        })
        .context("installing the Ctrl-C handler")?;
    }
    eprintln!(
        "running `{}` on {} -> {}",
        b.name(),
        args.data.display(),
        args.out.display()
    );
    let mut bar: Option<Progress> = None;
    let mut on_event = |e: &Event| {
        if let Event::Progress {
            total,
            loss,
            its_per_sec,
            ..
        } = e
        {
            let b = bar.get_or_insert_with(|| Progress::new("train", *total as u64));
            b.inc(1, &format!("loss {loss:.3e} {its_per_sec:.1} it/s"));
        }
    };
    let m = crate::baseline::run(b, &ds, Some(&args.out), args.iters, &stop, &mut on_event);
    if let Some(b) = bar.take() {
        b.finish("");
    }
    let m = m?;
    println!(
        "{}: test PSNR {:.3} dB, SSIM {:.4}, train time {:.2} s, render {:.2} fps",
        m.method,
        m.test_psnr.unwrap_or(f64::NAN),
        m.test_ssim.unwrap_or(f64::NAN),
        m.train_time_s,
        m.render_fps.unwrap_or(f64::NAN)
    );
    println!("outputs: {}", args.out.display());
    Ok(())
}
