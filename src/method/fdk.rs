//! FDK as a [`Method`]: one step (the reconstruction from the training views, with the fit to
//! them as the step's PSNR and SSIM), then the re-projection at the test views with the
//! dataset's projector, scored as every baseline ([`crate::baseline`]). Nothing to checkpoint:
//! an FDK run is not resumable and a stop request does not interrupt it.

use std::path::Path;
use std::time::Instant;

use super::{Baseline, Description, Method, Record};
use crate::baseline::{
    baseline_metrics, dataset_projector, project_views, score_line_integrals, views_fps,
    write_previews, write_volume_npy,
};
use crate::dataset::Dataset;
use crate::drr::Projector;
use crate::error::{Error, Result};
use crate::loss::LossValue;
use crate::record::{Step, Terms};
use crate::train::run_dir::CONFIG;
use crate::train::{Metrics, RunDir};
use crate::volume::Volume;

/// An FDK run.
pub struct Fdk<'a> {
    ds: &'a Dataset,
    /// The reconstruction, after the step.
    vol: Option<Volume<f32>>,
    /// Seconds of the reconstruction alone.
    recon_s: f64,
}

impl<'a> Fdk<'a> {
    /// Check `ds` (FDK needs the circular orbit: no pose noise).
    pub fn new(ds: &'a Dataset) -> Result<Self> {
        crate::dataset::store::check(ds)?;
        if ds.manifest.pose_noise.is_some() {
            // FDK filters and back-projects along the circular orbit; perturbed recorded
            // cameras leave it, so running it on the nominal angles would ignore the condition.
            return Err(Error::invalid(
                "manifest.pose_noise",
                "FDK needs the circular orbit: this dataset's recorded training cameras carry \
                 pose noise (make it with --pose-noise-deg 0 --pose-noise-mm 0 for FDK)",
            ));
        }
        Ok(Fdk {
            ds,
            vol: None,
            recon_s: 0.0,
        })
    }

    /// The error of `--resume` on an FDK run.
    pub fn not_resumable() -> Error {
        Error::invalid(
            "--resume",
            "an FDK run: FDK runs in one pass, nothing to resume (train it again with \
             `unispine train --method fdk`)",
        )
    }
}

impl Method for Fdk<'_> {
    fn describe(&self) -> Description {
        Description {
            name: Baseline::Fdk.name().into(),
            total: 1,
            checkpoint_every: 0,
            resumable: false,
            checkpoint_at_start: false,
            keep_checkpoint: false,
            started: None,
        }
    }

    fn iteration(&self) -> usize {
        usize::from(self.vol.is_some())
    }

    fn step(&mut self) -> Result<Step> {
        let ds = self.ds;
        let t0 = Instant::now();
        let vol = crate::fdk::reconstruct(&ds.geometry, &ds.train.angles, &ds.train.projections)?;
        self.recon_s = t0.elapsed().as_secs_f64();
        let proj = Projector::new(&vol, &ds.geometry, dataset_projector(ds))?;
        let train_renders = project_views(&proj, &ds.train.angles)?;
        let fit = score_line_integrals(&train_renders, &ds.train.projections)?;
        self.vol = Some(vol);
        Ok(Step {
            iteration: 1,
            view: 0,
            loss: LossValue {
                total: 0.0,
                data: 0.0,
                ssim: fit.ssim,
            },
            terms: Terms::Fit,
            psnr: fit.psnr,
            lr: 0.0,
            n_gaussians: 0,
            eval: None,
            densified: None,
        })
    }

    fn checkpoint(&mut self, _rec: &Record) -> Result<Vec<u8>> {
        Err(Fdk::not_resumable())
    }

    fn restore(&mut self, _path: &Path, _bytes: &[u8]) -> Result<Record> {
        Err(Fdk::not_resumable())
    }

    fn evaluate(
        &mut self,
        _rec: &Record,
        completed: bool,
        dir: Option<&RunDir>,
    ) -> Result<Metrics> {
        let ds = self.ds;
        let Some(vol) = self.vol.as_ref().filter(|_| completed) else {
            return Err(Error::invalid("fdk", "stopped before the reconstruction"));
        };
        let proj = Projector::new(vol, &ds.geometry, dataset_projector(ds))?;
        let te = Instant::now();
        let test_renders = project_views(&proj, &ds.test.angles)?;
        let ev = score_line_integrals(&test_renders, &ds.test.projections)?;
        let eval_time = te.elapsed().as_secs_f64();
        let (fps, _) = views_fps(ds.test.angles.len(), &|k| {
            std::hint::black_box(proj.view(ds.test.angles[k])?);
            Ok(())
        })?;
        let protocol = format!(
            "test views, forward only ({} DRR of the reconstructed volume), f32, one warm-up \
             render, median of 3 timed passes",
            ds.manifest.projector
        );
        let metrics = baseline_metrics(
            Baseline::Fdk.name().into(),
            1,
            Some(&ev),
            (self.recon_s, eval_time),
            (Some(fps), protocol),
            vol.data.len(),
        );
        if let Some(rd) = dir {
            crate::baseline::write_metrics(rd, &metrics)?;
            let config = serde_json::json!({
                "method": "fdk",
                "algorithm": "FDK, TIGRE Python semantics: cosine weighting, Ram-Lak (ramp_flat, scale (DSD/DSO)(2 pi/N)/(4 du)), voxel-driven backprojection weighted by 1/U^2, no Parker",
                "train_views": ds.train.angles.len(),
                "test_views": ds.test.angles.len(),
                "grid": { "nVoxel": ds.geometry.n_voxel, "dVoxel": ds.geometry.d_voxel, "offOrigin": ds.geometry.off_origin },
                "reprojection": ds.manifest.projector,
            });
            let p = rd.path(CONFIG);
            let text = serde_json::to_string_pretty(&config).expect("config serialises") + "\n";
            std::fs::write(&p, text).map_err(|e| Error::io(&p, e))?;
            write_volume_npy(&rd.path("model.npy"), vol)?;
            let renders: Vec<_> = test_renders.into_iter().enumerate().collect();
            write_previews(rd, ds, &renders, 4)?;
        }
        Ok(metrics)
    }
}
