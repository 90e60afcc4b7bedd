//! `unispine train --data DIR --method M --iters N --out RUN [--seed S] [overrides]`, and
//! `unispine train --resume RUN` to continue a stopped run with the same bits.
//!
//! Trains a method preset on a dataset folder (from `unispine data`), with a progress bar
//! (iteration, loss, PSNR, number of Gaussians, iterations per second), a clean stop on
//! SIGINT / SIGTERM that writes a checkpoint and exits 130 / 143 ([`super::signals`]), and the
//! run folder described in [`unispine::train::run_dir`].

use std::path::PathBuf;

use anyhow::{bail, Context};

use super::flags::Flags;
use super::progress::Progress;
use super::signals;
use unispine::error::Error;
use unispine::method::{Config, TrainMethod};
use unispine::session::{self, Control};
use unispine::train::{run_dir, Event, Method, RunDir, TrainOverrides};

/// Arguments of `unispine train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Dataset folder written by `unispine data` (with `--resume`: default the run's own).
    #[arg(long, required_unless_present = "resume")]
    pub data: Option<PathBuf>,
    /// Method: a Gaussian preset (unispine, xgaussian, 3dgs, spwm-only, 3dgs-vanilla) or a
    /// baseline (fdk, naf, intratomo, tensorf, nerf, naf-full, intratomo-full, tensorf-full,
    /// nerf-full).
    #[arg(long, default_value = "unispine", value_parser = MethodParser)]
    pub method: TrainMethod,
    /// Training iterations (paper: 20000).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Run folder (created; the files of an earlier run in it are removed first).
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Continue the stopped run in this folder from its checkpoint, with its config.
    #[arg(long, conflicts_with_all = ["iters", "TrainOverrides"])]
    pub resume: Option<PathBuf>,
    /// Stop (as on a signal, with a checkpoint) once this many iterations are complete.
    #[arg(long, hide = true)]
    pub stop_after: Option<usize>,
    #[command(flatten)]
    pub baseline: Flags<unispine::baseline::BaselineFlags>,
    /// rayon threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub overrides: Flags<TrainOverrides>,
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

/// Run `unispine train`: flags -> a [`Config`] (or the run to resume), then
/// [`unispine::session`] with events -> progress output.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    init_threads(args.threads)?;
    let (cfg, data, out) = match &args.resume {
        Some(run) => {
            if args.method != TrainMethod::Gaussians(Method::Unispine)
                || args.baseline.0.vm_lines.is_some()
                || args.baseline.0.rays.is_some()
            {
                bail!("--resume continues the run with its own config.json: give only --data and --threads");
            }
            session::check_resumable(run)?;
            let data = match (&args.data, RunDir::open(run)?.dataset_path()?) {
                (Some(d), _) => d.clone(),
                (None, Some(d)) => d,
                (None, None) => bail!(
                    "invalid `--data`: {} records no dataset; give --data",
                    run.display()
                ),
            };
            (None, data, run.clone())
        }
        None => {
            let (Some(data), Some(out)) = (&args.data, &args.out) else {
                bail!("--data and --out are required (or --resume RUN)");
            };
            (Some(config(&args, data)?), data.clone(), out.clone())
        }
    };
    let ds = unispine::dataset::store::load(&data)?;
    let cfg = match cfg {
        Some(Pending::Ready(c)) => Some(*c),
        Some(Pending::Baseline(b, opts)) => {
            Some(Config::baseline(b, ds.train.angles.len(), &opts)?)
        }
        None => None,
    };
    // FDK is one pass and keeps the default signal behaviour.
    if cfg != Some(Config::Fdk) {
        signals::install()?;
    }
    eprintln!(
        "{} `{}` on {} -> {}",
        if cfg.is_some() { "running" } else { "resuming" },
        match &cfg {
            Some(c) => c.name().to_string(),
            None => Config::read(&RunDir::open(&out)?)?.name().to_string(),
        },
        data.display(),
        out.display()
    );
    let mut bar: Option<Progress> = None;
    let mut on_event = |e: &Event| show(e, &mut bar);
    let ctl = Control {
        stop: &signals::STOP,
        stop_after: args.stop_after,
    };
    let m = match &cfg {
        Some(c) => session::run(c, &ds, Some(&out), ctl, &mut on_event),
        None => session::resume(&out, &ds, ctl, &mut on_event),
    };
    if let Some(b) = bar.take() {
        b.finish("");
    }
    let ckpt = out.join(run_dir::CHECKPOINT);
    let m = match m {
        Ok(m) => m,
        // Only a divergence has a last good state worth naming, and only when it was written.
        Err(e @ Error::Diverged { .. }) if ckpt.is_file() => {
            return Err(e).with_context(|| {
                format!(
                    "the last good state is in {} (continue with `unispine train --resume {}` \
                     after changing what diverged, or evaluate it with `unispine eval --run {}`)",
                    ckpt.display(),
                    out.display(),
                    out.display()
                )
            })
        }
        Err(e) => return Err(e.into()),
    };
    if !m.completed {
        println!(
            "stopped at iteration {}; checkpoint: {} (continue with `unispine train --resume {}`)",
            m.iterations,
            ckpt.display(),
            out.display()
        );
        if let Some(code) = signals::exit_code() {
            std::process::exit(code);
        }
        return Ok(());
    }
    let gaussians = if m.n_gaussians > 0 {
        format!("{} Gaussians, ", m.n_gaussians)
    } else {
        String::new()
    };
    println!(
        "{}: test PSNR {:.3} dB, SSIM {:.4}, {gaussians}train time {:.2} s, render {:.2} fps",
        m.method,
        m.test_psnr.unwrap_or(f64::NAN),
        m.test_ssim.unwrap_or(f64::NAN),
        m.train_time_s,
        m.render_fps.unwrap_or(f64::NAN)
    );
    if let Some(c) = &m.compaction {
        println!(
            "compaction at iteration {}: {} -> {} Gaussians, test PSNR {:.3} dB before, {:.3} dB \
             after pruning, {:.3} dB after fine-tuning",
            c.iteration,
            c.n_before,
            c.n_after,
            c.psnr_before,
            c.psnr_pruned,
            m.test_psnr.unwrap_or(f64::NAN)
        );
    }
    println!("outputs: {}", out.display());
    Ok(())
}

/// A new run's settings from the flags: complete for the Gaussians, the options of a baseline
/// (completed once the dataset is loaded: a field preset's schedule is in epochs of its
/// training views).
enum Pending {
    Ready(Box<Config>),
    Baseline(
        unispine::method::Baseline,
        unispine::baseline::BaselineOptions,
    ),
}

fn config(args: &TrainArgs, data: &std::path::Path) -> anyhow::Result<Pending> {
    match args.method {
        TrainMethod::Gaussians(method) => {
            unispine::baseline::check_vm_lines(method.name(), args.baseline.0.vm_lines)?;
            if args.baseline.0.rays.is_some() {
                bail!(
                    "invalid `--rays`: only for the neural-field baselines, not `{}`",
                    method.name()
                );
            }
            let mut cfg = args.overrides.0.apply(method, args.iters)?;
            // Absolute, so that `eval --run` and `--resume` work from any folder.
            let abs = data
                .canonicalize()
                .with_context(|| format!("--data {}", data.display()))?;
            cfg.data = Some(abs.display().to_string());
            Ok(Pending::Ready(Box::new(Config::Gaussians(cfg))))
        }
        TrainMethod::Baseline(b) => {
            if let Some(flag) = args
                .overrides
                .0
                .given()
                .into_iter()
                .find(|f| !unispine::baseline::FLAGS.contains(&&f[2..]))
            {
                bail!(
                    "invalid `{flag}`: a setting of the Gaussian trainer; `{}` takes only --{}",
                    b.name(),
                    unispine::baseline::FLAGS.join(", --")
                );
            }
            let opts = unispine::baseline::BaselineOptions {
                iters: args.iters,
                seed: args.overrides.0.seed,
                vm_lines: args.baseline.0.vm_lines,
                rays: args.baseline.0.rays,
            };
            Ok(Pending::Baseline(b, opts))
        }
    }
}

/// The terminal output of a training event: a line at the start and at each evaluation, a
/// progress bar over the iterations (created at the first iteration of this session, so that
/// a resumed run counts from the iteration it resumed at).
fn show(e: &Event, bar: &mut Option<Progress>) {
    match e {
        Event::Started {
            n_gaussians,
            train_views,
            test_views,
            extent,
            ..
        } => eprintln!(
            "{n_gaussians} initial Gaussians, {train_views} training / {test_views} test views, \
             scene extent {extent:.1} mm"
        ),
        Event::Progress {
            iteration,
            total,
            loss,
            psnr,
            n_gaussians,
            its_per_sec,
        } => {
            let b = bar.get_or_insert_with(|| {
                Progress::starting_at("train", *total as u64, (*iteration - 1) as u64)
            });
            let msg = if *n_gaussians > 0 {
                format!("loss {loss:.4} psnr {psnr:.2} dB N {n_gaussians} {its_per_sec:.1} it/s")
            } else {
                format!("loss {loss:.3e} {its_per_sec:.1} it/s")
            };
            b.inc(1, &msg);
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
    }
}

/// The `--method` parser over the library's list of methods ([`TrainMethod`]): its error
/// message for an unknown name, and every preset and baseline as clap's possible values (shown
/// by `--help`).
#[derive(Clone, Copy, Debug)]
struct MethodParser;

impl clap::builder::TypedValueParser for MethodParser {
    type Value = TrainMethod;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        _arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<TrainMethod, clap::Error> {
        let s = value.to_str().unwrap_or("");
        TrainMethod::parse(s).map_err(|e| {
            clap::Error::raw(clap::error::ErrorKind::InvalidValue, e + "\n").with_cmd(cmd)
        })
    }

    fn possible_values(
        &self,
    ) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        Some(Box::new(TrainMethod::all().into_iter().map(
            |(name, help)| {
                let v = clap::builder::PossibleValue::new(name);
                if help.is_empty() {
                    v
                } else {
                    v.help(help)
                }
            },
        )))
    }
}
