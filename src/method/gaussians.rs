//! The Gaussian presets as a [`Method`]: [`crate::train::Trainer`] one iteration at a time,
//! `checkpoint.bin` ([`crate::train::checkpoint`]) with the run's [`Identity`], and the final
//! `model.ply`, previews and render speed.
//!
//! A resumed run gives the same bits as the run that never stopped: parameters, Adam moments
//! and step counts, densification statistics and the view order come from the checkpoint,
//! every other input (targets, SPWM priors, schedules, split seeds) is a function of the
//! config, the dataset and the iteration. `log.csv` is the same except its wall-clock
//! `seconds` column.

use std::path::Path;

use super::{Description, Method, Record};
use crate::dataset::Dataset;
use crate::error::Result;
use crate::eval;
use crate::record::Step;
use crate::render;
use crate::train::checkpoint::Identity;
use crate::train::{Checkpoint, Event, Metrics, RunDir, TrainConfig, Trainer};

/// The identity of a run of `cfg` on `ds` (what its checkpoints record and a resume checks).
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

/// A Gaussian run.
pub struct Gaussians<'a> {
    pub tr: Trainer<'a>,
    /// The run's identity, computed at the first checkpoint (it hashes the dataset).
    identity: Option<Identity>,
}

impl<'a> Gaussians<'a> {
    /// Set up a run of `cfg` on `ds` (initialises the Gaussians).
    pub fn new(cfg: TrainConfig, ds: &'a Dataset) -> Result<Self> {
        Ok(Gaussians {
            tr: Trainer::new(cfg, ds)?,
            identity: None,
        })
    }

    fn identity(&mut self) -> Identity {
        let (cfg, ds) = (&self.tr.cfg, self.tr.ds);
        self.identity
            .get_or_insert_with(|| identity(cfg, ds))
            .clone()
    }
}

impl Method for Gaussians<'_> {
    fn describe(&self) -> Description {
        let tr = &self.tr;
        Description {
            name: tr.cfg.method.name().to_string(),
            total: tr.cfg.total_iterations(),
            checkpoint_every: tr.cfg.checkpoint_every,
            resumable: true,
            checkpoint_at_start: true,
            keep_checkpoint: true,
            started: Some(Event::Started {
                total: tr.cfg.total_iterations(),
                n_gaussians: tr.state.len(),
                train_views: tr.targets.len(),
                test_views: tr.test_targets.len(),
                extent: tr.extent,
            }),
        }
    }

    fn iteration(&self) -> usize {
        self.tr.iteration
    }

    fn step(&mut self) -> Result<Step> {
        self.tr.step()
    }

    fn checkpoint(&mut self, rec: &Record) -> Result<Vec<u8>> {
        let identity = self.identity();
        let tr = &self.tr;
        let (rng_word_pos, view_stack) = tr.view_order();
        let c = Checkpoint {
            identity,
            iteration: tr.iteration,
            render: tr.settings(tr.iteration.max(1)),
            state: tr.state.clone(),
            rng_word_pos,
            view_stack,
            evals: rec.evals.clone(),
            train_time_s: rec.train_time_s,
            eval_time_s: rec.eval_time_s,
            log: rec.log.clone(),
            compaction: tr.compaction.clone(),
        };
        Ok(c.to_bytes())
    }

    fn restore(&mut self, path: &Path, bytes: &[u8]) -> Result<Record> {
        let c = Checkpoint::from_bytes(path, bytes)?;
        c.identity.check(path, &self.identity())?;
        self.tr.restore(&c)?;
        Ok(Record {
            log: c.log,
            evals: c.evals,
            train_time_s: c.train_time_s,
            eval_time_s: c.eval_time_s,
        })
    }

    fn evaluate(&mut self, rec: &Record, completed: bool, dir: Option<&RunDir>) -> Result<Metrics> {
        let tr = &self.tr;
        let (cfg, ds) = (&tr.cfg, tr.ds);
        let settings = tr.settings(tr.iteration.max(1));
        let g = &tr.state.params;
        // A completed run's last evaluation is of the final model (the last iteration is always
        // evaluated and nothing changes the model after it).
        let last = rec
            .evals
            .last()
            .filter(|e| completed && e.iteration == tr.iteration);
        let render_fps = if completed {
            Some(eval::render_fps(g, ds, &settings)?.0)
        } else {
            None
        };
        if let (Some(d), true) = (dir, completed) {
            d.write_model(g, &settings)?;
            let n = tr.test_targets.len();
            let k = cfg.preview_views.min(n);
            for j in 0..k {
                let v = j * n / k.max(1);
                let (img, _) = render::forward(g, &ds.test_camera(v), &settings)?;
                d.write_preview(&format!("test_{v:02}.png"), &img, &tr.test_targets[v])?;
            }
        }
        let metrics = Metrics {
            method: cfg.method.name().to_string(),
            iterations: tr.iteration,
            completed,
            test_psnr: last.map(|e| e.psnr),
            test_ssim: last.map(|e| e.ssim),
            evals: rec.evals.clone(),
            train_time_s: rec.train_time_s,
            eval_time_s: rec.eval_time_s,
            render_fps,
            render_fps_protocol: "test views, forward only (project + tiles + composite), f32, one warm-up render, median of 3 timed passes".into(),
            n_gaussians: g.len(),
            model_bytes: None,
            peak_memory_bytes: eval::peak_memory_bytes(),
            extent: tr.extent,
            render: settings,
            threads: rayon::current_num_threads(),
            compaction: tr.compaction.clone(),
        };
        if let Some(d) = dir {
            d.write_metrics(&metrics)?;
        }
        Ok(metrics)
    }
}
