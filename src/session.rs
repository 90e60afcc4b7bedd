//! The one driver of every method ([`crate::method::Method`]): iterations, stop requests,
//! progress [`Event`]s, `log.csv`, checkpoints and the run folder ([`RunDir`]). The method
//! computes; the session does the file I/O of the loop.
//!
//! [`run`] starts a new run (clearing the folder and writing `config.json`), [`resume`]
//! continues a stopped one from its `checkpoint.bin`, whatever the method (the run's
//! `config.json` says which, [`Config::read`]); a resumed run gives the same bits as the run
//! that never stopped (`log.csv` the same except its wall-clock `seconds` column).
//!
//! A stop request ([`Control::stop`], set on Ctrl-C / SIGTERM by the CLI, or
//! [`Control::stop_after`]) ends a resumable run after the current iteration with a checkpoint,
//! `log.csv` and a `metrics.json` saying `"completed": false`. With a run folder, a
//! checkpoint is also written every [`Description::checkpoint_every`] iterations (and before
//! the first when the method asks); a completed run keeps its last one when the method says
//! so, else it is removed. A failed step leaves `log.csv` up to the last iteration done.
//!
//! [`Description::checkpoint_every`]: crate::method::Description::checkpoint_every

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::dataset::Dataset;
use crate::error::Result;
use crate::fsio;
use crate::method::{Config, Method, Record};
use crate::train::run_dir::{CHECKPOINT, LOG_HEADER};
use crate::train::{EvalPoint, Event, IterRate, Metrics, RunDir};

/// How a session may be stopped early.
#[derive(Clone, Copy, Debug)]
pub struct Control<'a> {
    /// Set (by a signal handler) to stop after the current iteration.
    pub stop: &'a AtomicBool,
    /// Stop once this many iterations are complete (a deterministic stand-in for a signal).
    pub stop_after: Option<usize>,
}

impl<'a> Control<'a> {
    /// Stopped by `stop` alone.
    pub fn new(stop: &'a AtomicBool) -> Self {
        Control {
            stop,
            stop_after: None,
        }
    }
}

/// Train `cfg` on `ds`, writing the run folder `out` (when given; its previous run files are
/// removed first), reporting to `on_event`.
pub fn run(
    cfg: &Config,
    ds: &Dataset,
    out: Option<&Path>,
    ctl: Control,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let mut m = cfg.build(ds)?;
    let dir = match out {
        Some(d) => {
            let rd = RunDir::create(d)?;
            cfg.write(&rd)?;
            Some(rd)
        }
        None => None,
    };
    let rec = Record {
        log: LOG_HEADER.to_string(),
        ..Record::default()
    };
    let desc = m.describe();
    if let (Some(d), true) = (&dir, desc.resumable && desc.checkpoint_at_start) {
        fsio::write_atomic(&d.path(CHECKPOINT), &m.checkpoint(&rec)?)?;
    }
    drive(m.as_mut(), rec, dir.as_ref(), ctl, on_event)
}

/// An error when the run in `dir` cannot be resumed (an FDK run is one pass), from its
/// `config.json` alone: checked before a dataset is looked for.
pub fn check_resumable(dir: &Path) -> Result<()> {
    match Config::read(&RunDir::open(dir)?)? {
        Config::Fdk => Err(crate::method::fdk::Fdk::not_resumable()),
        _ => Ok(()),
    }
}

/// Continue the stopped run in `dir` (its `config.json` and `checkpoint.bin`) on `ds`.
pub fn resume(
    dir: &Path,
    ds: &Dataset,
    ctl: Control,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let rd = RunDir::open(dir)?;
    let cfg = Config::read(&rd)?;
    let mut m = cfg.build(ds)?;
    let path = rd.path(CHECKPOINT);
    let rec = {
        let bytes = fsio::read_bounded(&path, fsio::MAX_CHECKPOINT_BYTES)?;
        m.restore(&path, &bytes)?
    };
    drive(m.as_mut(), rec, Some(&rd), ctl, on_event)
}

/// The loop (see the module doc).
fn drive(
    m: &mut dyn Method,
    mut rec: Record,
    dir: Option<&RunDir>,
    ctl: Control,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let desc = m.describe();
    if let Some(e) = &desc.started {
        on_event(e);
    }
    let total = desc.total;
    let t0 = Instant::now();
    let before = rec.train_time_s;
    let elapsed = || before + t0.elapsed().as_secs_f64();
    let mut rate = IterRate::default();
    let mut completed = true;
    while m.iteration() < total {
        let asked = ctl.stop.load(Ordering::SeqCst);
        let it = m.iteration();
        if desc.resumable && (asked || ctl.stop_after.is_some_and(|k| it >= k)) {
            completed = false;
            on_event(&Event::Stopped { iteration: it });
            break;
        }
        let s = match m.step() {
            Ok(s) => s,
            Err(e) => {
                if let Some(d) = dir {
                    d.write_log(&rec.log)?;
                }
                return Err(e);
            }
        };
        let it = s.iteration;
        if let Some(e) = &s.eval {
            rec.eval_time_s += e.seconds;
            rec.evals.push(EvalPoint {
                iteration: it,
                psnr: e.result.psnr,
                ssim: e.result.ssim,
                n_gaussians: e.n_gaussians,
            });
            on_event(&Event::Eval {
                iteration: it,
                psnr: e.result.psnr,
                ssim: e.result.ssim,
                n_gaussians: e.n_gaussians,
            });
        }
        if let Some(r) = s.densified {
            on_event(&Event::Densified {
                iteration: it,
                report: r,
            });
        }
        rec.log.push_str(&s.log_row(elapsed()));
        let its_per_sec = rate.tick();
        on_event(&Event::Progress {
            iteration: it,
            total,
            loss: s.loss.total,
            psnr: s.psnr,
            n_gaussians: s.n_gaussians,
            its_per_sec,
        });
        let every = desc.checkpoint_every;
        if let (Some(d), true) = (dir, desc.resumable && every > 0) {
            if it.is_multiple_of(every) && it < total {
                rec.train_time_s = elapsed();
                fsio::write_atomic(&d.path(CHECKPOINT), &m.checkpoint(&rec)?)?;
                d.write_log(&rec.log)?;
                on_event(&Event::Checkpoint { iteration: it });
            }
        }
    }
    rec.train_time_s = elapsed();
    if let Some(d) = dir {
        if desc.resumable && (!completed || desc.keep_checkpoint) {
            fsio::write_atomic(&d.path(CHECKPOINT), &m.checkpoint(&rec)?)?;
            on_event(&Event::Checkpoint {
                iteration: m.iteration(),
            });
        } else {
            fsio::remove_if_exists(&d.path(CHECKPOINT))?;
        }
        d.write_log(&rec.log)?;
    }
    m.evaluate(&rec, completed, dir)
}
