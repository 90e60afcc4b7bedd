//! A training session: drives a [`Trainer`] iteration by iteration, reports [`Event`]s and
//! hands every file to the [`RunDir`] (the loop itself does no file I/O).
//!
//! [`run`] starts a new run (clearing the folder), [`resume`] continues a stopped one from its
//! `checkpoint.bin`. A resumed run gives the same bits as the run that never stopped:
//! parameters, Adam moments and step counts, densification statistics and the view order come
//! from the checkpoint, every other input (targets, SPWM priors, schedules, split seeds) is a
//! function of the config, the dataset and the iteration. `log.csv` is the same except its
//! wall-clock `seconds` column.
//!
//! A stop request ([`Control::stop`], set on Ctrl-C / SIGTERM by the CLI, or
//! [`Control::stop_after`]) ends the run after the current iteration with a checkpoint and a
//! `metrics.json` saying `"completed": false`.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::checkpoint::Identity;
use super::run_dir::{Checkpoint, EvalPoint, Metrics, RunDir, LOG_HEADER};
use super::{Event, IterRate, TrainConfig, Trainer};
use crate::dataset::Dataset;
use crate::error::Result;
use crate::eval;
use crate::render;

/// How a session may be stopped early.
#[derive(Clone, Copy, Debug)]
pub struct Control<'a> {
    /// Set (by a signal handler) to stop after the current iteration.
    pub stop: &'a AtomicBool,
    /// Stop once this many iterations are complete (a deterministic stand-in for a signal).
    pub stop_after: Option<usize>,
}

/// What the loop carries besides the trainer.
struct Session<'a> {
    tr: Trainer<'a>,
    log: String,
    evals: Vec<EvalPoint>,
    eval_time_s: f64,
    /// Training wall time of earlier sessions of this run.
    time_before_s: f64,
    /// The run the checkpoints belong to (computed only when there is a run folder).
    identity: Identity,
}

/// The identity of a run of `cfg` on `ds` (what its checkpoints record and `resume` checks).
pub fn identity(cfg: &TrainConfig, ds: &Dataset) -> Identity {
    Identity {
        method: cfg.method.name().to_string(),
        color: serde_json::to_value(cfg.color)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default(),
        seed: cfg.seed,
        dataset: ds.fingerprint(),
        config: crate::fingerprint::config(cfg),
    }
}

/// Train `cfg` on `ds`, writing the run folder `out` (when given; its previous run files are
/// removed first), reporting to `on_event`; `stop` ends the run cleanly after the current
/// iteration with a checkpoint.
pub fn run(
    cfg: &TrainConfig,
    ds: &Dataset,
    out: Option<&Path>,
    stop: &AtomicBool,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let ctl = Control {
        stop,
        stop_after: None,
    };
    run_with(cfg, ds, out, ctl, on_event)
}

/// [`run`] with a [`Control`].
pub fn run_with(
    cfg: &TrainConfig,
    ds: &Dataset,
    out: Option<&Path>,
    ctl: Control,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let tr = Trainer::new(cfg.clone(), ds)?;
    let dir = match out {
        Some(d) => {
            let rd = RunDir::create(d)?;
            rd.write_config(cfg)?;
            Some(rd)
        }
        None => None,
    };
    let s = Session {
        tr,
        log: LOG_HEADER.to_string(),
        evals: Vec::new(),
        eval_time_s: 0.0,
        time_before_s: 0.0,
        identity: match &dir {
            Some(_) => identity(cfg, ds),
            None => Identity::default(),
        },
    };
    if let Some(d) = &dir {
        d.write_checkpoint(&s.checkpoint(0.0))?;
    }
    drive(s, dir.as_ref(), ctl, on_event)
}

/// Continue the stopped run in `dir` (its `config.json` and `checkpoint.bin`) on `ds`.
pub fn resume(
    dir: &Path,
    ds: &Dataset,
    ctl: Control,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let rd = RunDir::open(dir)?;
    rd.check_resumable()?;
    let cfg: TrainConfig = rd.read_config()?;
    let c = rd.read_checkpoint()?;
    let id = identity(&cfg, ds);
    c.identity
        .check(&rd.path(super::run_dir::CHECKPOINT), &id)?;
    let mut tr = Trainer::new(cfg, ds)?;
    tr.restore(&c)?;
    let s = Session {
        tr,
        log: c.log,
        evals: c.evals,
        eval_time_s: c.eval_time_s,
        time_before_s: c.train_time_s,
        identity: id,
    };
    drive(s, Some(&rd), ctl, on_event)
}

impl Session<'_> {
    fn checkpoint(&self, train_time_s: f64) -> Checkpoint {
        let (rng_word_pos, view_stack) = self.tr.view_order();
        Checkpoint {
            identity: self.identity.clone(),
            iteration: self.tr.iteration,
            render: self.tr.settings(self.tr.iteration.max(1)),
            state: self.tr.state.clone(),
            rng_word_pos,
            view_stack,
            evals: self.evals.clone(),
            train_time_s,
            eval_time_s: self.eval_time_s,
            log: self.log.clone(),
            compaction: self.tr.compaction.clone(),
        }
    }
}

fn drive(
    mut s: Session,
    dir: Option<&RunDir>,
    ctl: Control,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let cfg = s.tr.cfg.clone();
    let ds = s.tr.ds;
    on_event(&Event::Started {
        total: cfg.total_iterations(),
        n_gaussians: s.tr.state.len(),
        train_views: s.tr.targets.len(),
        test_views: s.tr.test_targets.len(),
        extent: s.tr.extent,
    });
    let t0 = Instant::now();
    let before = s.time_before_s;
    let elapsed = || before + t0.elapsed().as_secs_f64();
    let mut rate = IterRate::default();
    let mut completed = true;
    let total = cfg.total_iterations();
    while s.tr.iteration < total {
        let asked = ctl.stop.load(Ordering::SeqCst);
        if asked || ctl.stop_after.is_some_and(|k| s.tr.iteration >= k) {
            completed = false;
            on_event(&Event::Stopped {
                iteration: s.tr.iteration,
            });
            break;
        }
        let info = match s.tr.step() {
            Ok(i) => i,
            Err(e) => {
                if let Some(d) = dir {
                    d.write_log(&s.log)?;
                }
                return Err(e);
            }
        };
        let it = info.iteration;
        if let Some(e) = &info.eval {
            s.eval_time_s += e.seconds;
            s.evals.push(EvalPoint {
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
        if let Some(r) = info.densified {
            on_event(&Event::Densified {
                iteration: it,
                report: r,
            });
        }
        let _ = writeln!(
            s.log,
            "{it},{},{:.9e},{:.9e},{:.9e},{:.6},{},{:.3}",
            info.view,
            info.loss.total,
            info.loss.data,
            info.loss.ssim,
            info.psnr,
            info.n_gaussians,
            elapsed()
        );
        let its_per_sec = rate.tick();
        on_event(&Event::Progress {
            iteration: it,
            total,
            loss: info.loss.total,
            psnr: info.psnr,
            n_gaussians: info.n_gaussians,
            its_per_sec,
        });
        if let Some(d) = dir {
            if cfg.checkpoint_every > 0 && it.is_multiple_of(cfg.checkpoint_every) && it < total {
                d.write_checkpoint(&s.checkpoint(elapsed()))?;
                d.write_log(&s.log)?;
                on_event(&Event::Checkpoint { iteration: it });
            }
        }
    }
    let train_time = elapsed();
    let settings = s.tr.settings(s.tr.iteration.max(1));
    let g = &s.tr.state.params;
    // A completed run's last evaluation is of the final model (the last iteration is always
    // evaluated and nothing changes the model after it).
    let last = s
        .evals
        .last()
        .filter(|e| completed && e.iteration == s.tr.iteration);
    let render_fps = if completed {
        Some(eval::render_fps(g, ds, &settings)?.0)
    } else {
        None
    };
    if let Some(d) = dir {
        d.write_checkpoint(&s.checkpoint(train_time))?;
        on_event(&Event::Checkpoint {
            iteration: s.tr.iteration,
        });
        d.write_log(&s.log)?;
        if completed {
            d.write_model(g, &settings)?;
            let n = s.tr.test_targets.len();
            let k = cfg.preview_views.min(n);
            for j in 0..k {
                let v = j * n / k.max(1);
                let (img, _) = render::forward(g, &ds.test_camera(v), &settings)?;
                d.write_preview(&format!("test_{v:02}.png"), &img, &s.tr.test_targets[v])?;
            }
        }
    }
    let metrics = Metrics {
        method: cfg.method.name().to_string(),
        iterations: s.tr.iteration,
        completed,
        test_psnr: last.map(|e| e.psnr),
        test_ssim: last.map(|e| e.ssim),
        evals: s.evals.clone(),
        train_time_s: train_time,
        eval_time_s: s.eval_time_s,
        render_fps,
        render_fps_protocol: "test views, forward only (project + tiles + composite), f32, one warm-up render, median of 3 timed passes".into(),
        n_gaussians: g.len(),
        model_bytes: None,
        peak_memory_bytes: eval::peak_memory_bytes(),
        extent: s.tr.extent,
        render: settings,
        threads: rayon::current_num_threads(),
        compaction: s.tr.compaction.clone(),
    };
    if let Some(d) = dir {
        d.write_metrics(&metrics)?;
    }
    Ok(metrics)
}
