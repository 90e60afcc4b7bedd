//! The neural-field presets as a [`Method`]: [`FieldTrainer`] one iteration at a time,
//! `checkpoint.bin` ([`crate::field::checkpoint`]) every [`FIELD_CHECKPOINT_EVERY`] iterations
//! and on stop (removed when the run completes), then the test views rendered and scored
//! ([`crate::baseline::score_line_integrals`]), `model.npz`, previews, and `config.json` again
//! with the evaluated views. A resumed run gives the same bits as one that never stopped.

use std::path::Path;
use std::time::Instant;

use super::{BaselineOptions, Description, Method, Record};
use crate::baseline::{baseline_metrics, score_line_integrals, views_fps, write_previews};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::field::checkpoint::FieldCheckpoint;
use crate::field::encode::VmLines;
use crate::field::train::FieldTrainer;
use crate::field::{EncoderConfig, FieldConfig};
use crate::image2d::Image2d;
use crate::record::Step;
use crate::train::run_dir::CONFIG;
use crate::train::{Metrics, RunDir};

/// Iterations between the checkpoints of a field run with a run folder (and one when it
/// stops early).
pub const FIELD_CHECKPOINT_EVERY: usize = 1000;

/// Test views timed for a field's fps (rendering a full view is slow on a CPU).
pub const FIELD_FPS_VIEWS: usize = 5;

/// The settings of the field preset `name` on `train_views` training views with `opts`.
pub fn configure(name: &str, train_views: usize, opts: &BaselineOptions) -> Result<FieldConfig> {
    let mut cfg = FieldConfig::preset(name, train_views)?;
    if let Some(n) = opts.iters {
        if n == 0 || n > crate::field::MAX_ITERATIONS {
            return Err(Error::invalid(
                "--iters",
                format!(
                    "{n} is outside the allowed range [1, {}]",
                    crate::field::MAX_ITERATIONS
                ),
            ));
        }
        cfg.set_iterations(n);
    }
    if let Some(seed) = opts.seed {
        cfg.seed = seed;
    }
    if let Some(r) = opts.rays {
        cfg.ray_pixels = r;
    }
    if let (Some(l), EncoderConfig::TensorVm { lines, .. }) = (opts.vm_lines, &mut cfg.encoder) {
        *lines = l;
    }
    let _: Option<VmLines> = opts.vm_lines;
    cfg.validate()?;
    Ok(cfg)
}

/// `config.json` of a field run (written when it starts, so that a stopped run can be
/// resumed, and again at the end with the evaluated views).
pub fn config_json(cfg: &FieldConfig, views: &[usize]) -> serde_json::Value {
    let mut config = serde_json::to_value(cfg).expect("config serialises");
    config["method"] = serde_json::Value::String(cfg.label());
    config["evaluated_test_views"] = serde_json::json!(views);
    config
}

/// A neural-field run.
pub struct Field<'a> {
    pub tr: FieldTrainer<'a>,
    /// [`Dataset::fingerprint`] of the training data, computed at the first checkpoint.
    fingerprint: Option<String>,
}

impl<'a> Field<'a> {
    /// Set up a run of `cfg` on `ds`.
    pub fn new(cfg: FieldConfig, ds: &'a Dataset) -> Result<Self> {
        Ok(Field {
            tr: FieldTrainer::new(cfg, ds)?,
            fingerprint: None,
        })
    }

    fn fingerprint(&mut self) -> String {
        let ds = self.tr.ds;
        self.fingerprint
            .get_or_insert_with(|| ds.fingerprint())
            .clone()
    }
}

impl Method for Field<'_> {
    fn describe(&self) -> Description {
        Description {
            name: self.tr.cfg.label(),
            total: self.tr.cfg.iterations,
            checkpoint_every: FIELD_CHECKPOINT_EVERY,
            resumable: true,
            checkpoint_at_start: false,
            keep_checkpoint: false,
            started: None,
        }
    }

    fn iteration(&self) -> usize {
        self.tr.iteration
    }

    fn step(&mut self) -> Result<Step> {
        self.tr.step()
    }

    fn checkpoint(&mut self, rec: &Record) -> Result<Vec<u8>> {
        let fp = self.fingerprint();
        let c = self.tr.checkpoint(rec.train_time_s, &rec.log);
        Ok(c.to_bytes(&self.tr.cfg, &fp))
    }

    fn restore(&mut self, path: &Path, bytes: &[u8]) -> Result<Record> {
        let fp = self.fingerprint();
        let n_params = self.tr.field.params.len();
        let c = FieldCheckpoint::from_bytes(path, bytes, &self.tr.cfg, n_params, &fp)?;
        self.tr.restore(&c);
        Ok(Record {
            log: c.log,
            evals: Vec::new(),
            train_time_s: c.train_time_s,
            eval_time_s: 0.0,
        })
    }

    fn evaluate(&mut self, rec: &Record, completed: bool, dir: Option<&RunDir>) -> Result<Metrics> {
        let tr = &self.tr;
        let ds = tr.ds;
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
        let cfg = &tr.cfg;
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
            (rec.train_time_s, eval_time),
            (fps, protocol),
            tr.field.params.len(),
        );
        if let Some(rd) = dir {
            crate::baseline::write_metrics(rd, &metrics)?;
            crate::field::model::save(&rd.path("model.npz"), &tr.field)?;
            crate::fsio::write_json_atomic(&rd.path(CONFIG), &config_json(cfg, &views))?;
            write_previews(rd, ds, &renders, 4)?;
        }
        Ok(metrics)
    }
}
