//! A neural-field baseline's run: train (from a checkpoint when resuming), checkpoint every
//! [`FIELD_CHECKPOINT_EVERY`] iterations and on stop, then render and score the test views.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::{baseline_metrics, score_line_integrals, views_fps, write_run, Outcome};
use crate::dataset::Dataset;
use crate::error::Result;
use crate::field::checkpoint::FieldCheckpoint;
use crate::field::train::FieldTrainer;
use crate::field::{Field, FieldConfig};
use crate::fsio;
use crate::image2d::Image2d;
use crate::train::run_dir::CHECKPOINT;
use crate::train::{Event, IterRate, Metrics, RunDir};

/// Continue the stopped field run in `dir` (its `config.json` and `checkpoint.bin`) on `ds`,
/// with the same bits as a run that never stopped; writes the run folder as
/// [`run`](crate::baseline::run) does.
pub fn resume(
    dir: &Path,
    ds: &Dataset,
    stop: &AtomicBool,
    stop_after: Option<usize>,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Metrics> {
    let rd = RunDir::open(dir)?;
    let cfg: FieldConfig = rd.read_config()?;
    cfg.validate()?;
    let n_params = Field::<f32>::new(&cfg)?.params.len();
    let path = rd.path(CHECKPOINT);
    let bytes = fsio::read_bounded(&path, fsio::MAX_CHECKPOINT_BYTES)?;
    let c = FieldCheckpoint::from_bytes(&path, &bytes, &cfg, n_params, &ds.fingerprint())?;
    drop(bytes);
    let (o, field) = run_field(cfg, ds, (stop, stop_after), on_event, Some(&rd), Some(&c))?;
    crate::field::model::save(&rd.path("model.npz"), &field)?;
    write_run(rd.root(), &rd, ds, &o, 4)?;
    Ok(o.metrics)
}

/// Iterations between the checkpoints of a field run with a run folder (and one when it
/// stops early).
pub const FIELD_CHECKPOINT_EVERY: usize = 1000;

/// `config.json` of a field run (written when it starts, so that a stopped run can be
/// resumed, and again at the end with the evaluated views).
pub(super) fn field_config_json(cfg: &FieldConfig, views: &[usize]) -> serde_json::Value {
    let mut config = serde_json::to_value(cfg).expect("config serialises");
    config["method"] = serde_json::Value::String(cfg.label());
    config["evaluated_test_views"] = serde_json::json!(views);
    config
}

/// Train a field preset (from `resume` when given), then render and score the test views
/// (every `eval_stride`-th). With `store`, `checkpoint.bin` is written every
/// [`FIELD_CHECKPOINT_EVERY`] iterations and when `stop` ends the run, and removed when it
/// completes.
pub fn run_field(
    cfg: FieldConfig,
    ds: &Dataset,
    (stop, stop_after): (&AtomicBool, Option<usize>),
    on_event: &mut dyn FnMut(&Event),
    store: Option<&RunDir>,
    resume: Option<&FieldCheckpoint>,
) -> Result<(Outcome, Field<f32>)> {
    let total = cfg.iterations;
    let mut tr = FieldTrainer::new(cfg, ds)?;
    let (mut log, before) = match resume {
        Some(c) => {
            tr.restore(c);
            (c.log.clone(), c.train_time_s)
        }
        None => (
            String::from("iteration,view,loss,data,ssim,psnr,n_gaussians,seconds\n"),
            0.0,
        ),
    };
    let fingerprint = store.map(|_| ds.fingerprint()).unwrap_or_default();
    let save = |tr: &FieldTrainer, t: f64, log: &str| -> Result<()> {
        match store {
            Some(rd) => fsio::write_atomic(
                &rd.path(CHECKPOINT),
                &tr.checkpoint(t, log).to_bytes(&tr.cfg, &fingerprint),
            ),
            None => Ok(()),
        }
    };
    let t0 = Instant::now();
    let elapsed = || before + t0.elapsed().as_secs_f64();
    let mut rate = IterRate::default();
    let mut completed = true;
    while tr.iteration < total {
        if stop.load(Ordering::SeqCst) || stop_after.is_some_and(|k| tr.iteration >= k) {
            completed = false;
            break;
        }
        let s = tr.step()?;
        let t = elapsed();
        // psnr column: 10 log10(1 / loss), the loss in (metres x normalised value)^2.
        let psnr = -10.0 * s.loss.max(1e-30).log10();
        let _ = writeln!(
            log,
            "{},{},{:.9e},{:.9e},0,{:.6},0,{:.3}",
            s.iteration, s.view, s.loss, s.loss, psnr, t
        );
        let its = rate.tick();
        on_event(&Event::Progress {
            iteration: s.iteration,
            total,
            loss: s.loss,
            psnr,
            n_gaussians: 0,
            its_per_sec: its,
        });
        if s.iteration.is_multiple_of(FIELD_CHECKPOINT_EVERY) && s.iteration < total {
            save(&tr, t, &log)?;
        }
    }
    let train_time = elapsed();
    match (completed, store) {
        (false, _) => save(&tr, train_time, &log)?,
        (true, Some(rd)) => fsio::remove_if_exists(&rd.path(CHECKPOINT))?,
        (true, None) => {}
    }
    let views = tr.eval_views();
    let (mut ev, mut renders, mut fps, mut eval_time) = (None, Vec::new(), None, 0.0);
    if completed {
        let te = Instant::now();
        renders = views.iter().map(|&k| (k, tr.render_test(k))).collect();
        let preds: Vec<Image2d<f32>> = renders.iter().map(|r| r.1.clone()).collect();
        let gts: Vec<Image2d<f32>> = views
            .iter()
            .map(|&k| ds.test.projections[k].clone())
            .collect();
        ev = Some(score_line_integrals(&preds, &gts)?);
        eval_time = te.elapsed().as_secs_f64();
        let nf = views.len().min(FIELD_FPS_VIEWS);
        fps = Some(
            views_fps(nf, &|j| {
                std::hint::black_box(tr.render_test(views[j]));
                Ok(())
            })?
            .0,
        );
    }
    let cfg = tr.cfg.clone();
    let protocol = format!(
        "the first {} evaluated test views rendered in full ({} samples per ray), f32, one \
         warm-up render, median of 3 timed passes",
        views.len().min(FIELD_FPS_VIEWS),
        cfg.n_samples
    );
    let metrics = baseline_metrics(
        cfg.label(),
        tr.iteration,
        ev.as_ref(),
        (train_time, eval_time),
        (fps, protocol),
        tr.field.params.len(),
    );
    let config = field_config_json(&cfg, &views);
    let field = tr.field;
    Ok((
        Outcome {
            metrics,
            config,
            log,
            test_renders: renders,
        },
        field,
    ))
}

/// Test views timed for a field's fps (rendering a full view is slow on a CPU).
pub const FIELD_FPS_VIEWS: usize = 5;
