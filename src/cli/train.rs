//! `unispine train --data DIR --method M --iters N --out RUN [--seed S] [overrides]`, and
//! `unispine train --resume RUN` to continue a stopped run with the same bits.
//!
//! Trains a method preset on a dataset folder (from `unispine data`), with a progress bar
//! (iteration, loss, PSNR, number of Gaussians, iterations per second), a clean stop on
//! SIGINT / SIGTERM that writes a checkpoint and exits 130 / 143 ([`super::signals`]), and the
//! run folder described in [`unispine::train::run_dir`].

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};

use super::progress::Progress;
use super::signals;
use unispine::baseline::{Baseline, TrainMethod};
use unispine::error::Error;
use unispine::train::{self, Control, Event, Method, Metrics, RunDir, TrainOverrides};

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
    pub baseline: unispine::baseline::BaselineFlags,
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
    if let (Some(run), TrainMethod::Gaussians(Method::Unispine)) = (&args.resume, &args.method) {
        if RunDir::open(run)?.is_field_run()? {
            return resume_field(run, &args);
        }
    }
    let method = match args.method {
        TrainMethod::Gaussians(m) => m,
        TrainMethod::Baseline(b) => return run_baseline(b, &args),
    };
    unispine::baseline::check_vm_lines(method.name(), args.baseline.vm_lines)?;
    init_threads(args.threads)?;
    if args.resume.is_some() && method != Method::Unispine {
        bail!("--method cannot be combined with --resume (the run's config.json is used)");
    }
    let (cfg, ds, out) = match &args.resume {
        Some(run) => {
            let rd = RunDir::open(run)?;
            rd.check_resumable()?;
            let cfg: train::TrainConfig = rd.read_config()?;
            let data = match (&args.data, rd.dataset_path()?) {
                (Some(d), _) => d.clone(),
                (None, Some(d)) => d,
                (None, None) => bail!("the run's config.json names no dataset: pass --data"),
            };
            let ds = unispine::dataset::store::load(&data)?;
            (cfg, ds, run.clone())
        }
        None => {
            let (Some(data), Some(out)) = (&args.data, &args.out) else {
                bail!("--data and --out are required (or --resume RUN)");
            };
            let mut cfg = args.overrides.apply(method, args.iters)?;
            // Absolute, so that `eval --run` and `--resume` work from any folder.
            let abs = data
                .canonicalize()
                .with_context(|| format!("--data {}", data.display()))?;
            cfg.data = Some(abs.display().to_string());
            let ds = unispine::dataset::store::load(data)?;
            (cfg, ds, out.clone())
        }
    };
    signals::install()?;
    eprintln!(
        "{} `{}` for {} iterations -> {}",
        if args.resume.is_some() {
            "resuming"
        } else {
            "training"
        },
        cfg.method.name(),
        cfg.total_iterations(),
        out.display()
    );
    let mut bar: Option<Progress> = None;
    let mut on_event = |e: &Event| match e {
        Event::Started {
            n_gaussians,
            train_views,
            test_views,
            extent,
            ..
        } => {
            eprintln!(
                "{n_gaussians} initial Gaussians, {train_views} training / {test_views} test views, \
                 scene extent {extent:.1} mm"
            );
        }
        Event::Progress {
            iteration,
            total,
            loss,
            psnr,
            n_gaussians,
            its_per_sec,
        } => {
            // Created at the first iteration of this session, so that a resumed run counts
            // from the iteration it resumed at.
            let b = bar.get_or_insert_with(|| {
                Progress::starting_at("train", *total as u64, (*iteration - 1) as u64)
            });
            b.inc(
                1,
                &format!("loss {loss:.4} psnr {psnr:.2} dB N {n_gaussians} {its_per_sec:.1} it/s"),
            );
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
    let ctl = Control {
        stop: &signals::STOP,
        stop_after: args.stop_after,
    };
    let m = match &args.resume {
        Some(run) => train::resume(run, &ds, ctl, &mut on_event),
        None => train::run_with(&cfg, &ds, Some(&out), ctl, &mut on_event),
    };
    if let Some(b) = bar.take() {
        b.finish("");
    }
    let ckpt = out.join(train::run_dir::CHECKPOINT);
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
    println!(
        "{}: test PSNR {:.3} dB, SSIM {:.4}, {} Gaussians, train time {:.1} s, render {:.1} fps",
        cfg.method.name(),
        m.test_psnr.unwrap_or(f64::NAN),
        m.test_ssim.unwrap_or(f64::NAN),
        m.n_gaussians,
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

/// `unispine train --method BASELINE`: the baseline's own trainer, the same run folder,
/// `--threads` as for the Gaussians.
/// Ctrl-C / SIGTERM stop a field run after the current iteration without evaluation (with a
/// checkpoint) and exit 130 / 143.
fn run_baseline(b: Baseline, args: &TrainArgs) -> anyhow::Result<()> {
    let Some(data) = args.data.as_ref() else {
        bail!("invalid `--data`: a baseline needs a dataset folder");
    };
    if args.resume.is_some() {
        bail!("--method cannot be combined with --resume (the run's config.json is used)");
    }
    let Some(out) = args.out.as_ref() else {
        bail!("invalid `--out`: a baseline needs a run folder");
    };
    if let Some(flag) = args
        .overrides
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
        seed: args.overrides.seed,
        vm_lines: args.baseline.vm_lines,
        rays: args.baseline.rays,
        stop_after: args.stop_after,
    };
    // FDK is one pass and keeps the default signal behaviour.
    let field = matches!(b, Baseline::Field(_));
    drive_baseline(
        &format!("running `{}`", b.name()),
        data,
        out,
        field,
        args.threads,
        |ds, on_event| unispine::baseline::run(b, ds, Some(out), opts, &signals::STOP, on_event),
    )
}

/// `unispine train --resume RUN` of a stopped neural-field run (`--data`: default the dataset
/// recorded in its `config.json`).
fn resume_field(run: &Path, args: &TrainArgs) -> anyhow::Result<()> {
    if args.out.is_some()
        || args.iters.is_some()
        || args.baseline.vm_lines.is_some()
        || args.baseline.rays.is_some()
        || !args.overrides.given().is_empty()
    {
        bail!(
            "--resume continues the run with its own config.json: give only --data and --threads"
        );
    }
    let rd = RunDir::open(run)?;
    let data = match (&args.data, rd.dataset_path()?) {
        (Some(d), _) => d.clone(),
        (None, Some(d)) => d,
        (None, None) => bail!(
            "invalid `--data`: {} records no dataset; give --data",
            run.display()
        ),
    };
    let v: serde_json::Value = rd.read_config()?;
    let name = v
        .get("preset")
        .and_then(|p| p.as_str())
        .unwrap_or("field")
        .to_string();
    drive_baseline(
        &format!("resuming `{name}`"),
        &data,
        run,
        true,
        args.threads,
        |ds, on_event| {
            unispine::baseline::resume(run, ds, &signals::STOP, args.stop_after, on_event)
        },
    )
}

/// Load the dataset, print `headline`, run `go` with a progress bar, report (a stopped
/// field run exits 130 / 143 after naming its checkpoint).
fn drive_baseline(
    headline: &str,
    data: &Path,
    out: &Path,
    field: bool,
    threads: Option<usize>,
    go: impl FnOnce(
        &unispine::dataset::Dataset,
        &mut dyn FnMut(&Event),
    ) -> unispine::error::Result<Metrics>,
) -> anyhow::Result<()> {
    let ds = unispine::dataset::store::load(data)?;
    init_threads(threads)?;
    if field {
        signals::install()?;
    }
    eprintln!("{headline} on {} -> {}", data.display(), out.display());
    let mut bar: Option<Progress> = None;
    let mut on_event = |e: &Event| {
        if let Event::Progress {
            iteration,
            total,
            loss,
            its_per_sec,
            ..
        } = e
        {
            let b = bar.get_or_insert_with(|| {
                Progress::starting_at("train", *total as u64, (*iteration - 1) as u64)
            });
            b.inc(1, &format!("loss {loss:.3e} {its_per_sec:.1} it/s"));
        }
    };
    let m = go(&ds, &mut on_event);
    if let Some(b) = bar.take() {
        b.finish("");
    }
    let m = m?;
    if !m.completed {
        println!(
            "stopped at iteration {}; model, metrics.json and checkpoint.bin written to {} \
             (continue with `unispine train --resume {}`)",
            m.iterations,
            out.display(),
            out.display()
        );
        if let Some(code) = signals::exit_code() {
            std::process::exit(code);
        }
        return Ok(());
    }
    println!(
        "{}: test PSNR {:.3} dB, SSIM {:.4}, train time {:.2} s, render {:.2} fps",
        m.method,
        m.test_psnr.unwrap_or(f64::NAN),
        m.test_ssim.unwrap_or(f64::NAN),
        m.train_time_s,
        m.render_fps.unwrap_or(f64::NAN)
    );
    println!("outputs: {}", out.display());
    Ok(())
}
