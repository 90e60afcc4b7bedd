//! The run folder: the one owner of every file a training run writes, and the one reader that
//! `unispine eval`, `report`, `render` and `train --resume` use.
//!
//! Files (every one written atomically: temporary name, fsync, rename; see [`crate::fsio`]):
//!
//! | file | written | content |
//! |---|---|---|
//! | `config.json` | at the start | the method's full config ([`crate::train::TrainConfig`] for Gaussians); `data` = dataset folder, absolute |
//! | `log.csv` | at checkpoints and at the end | one row per iteration (the `seconds` column is wall-clock; every other column is deterministic) |
//! | `checkpoint.bin` | at 0, every `checkpoint_every`, on stop / signal, at the end | everything a resume needs, in one file ([`Checkpoint`]); a neural-field run's ([`crate::field::checkpoint`]) every 1000 iterations and on stop / signal, removed when it completes |
//! | `model.ply` | when the run completes | the final model (3DGS PLY) with a `comment unispine-render {...}` line recording how to render it ([`crate::render::RenderSettings::to_ply_comment`]) |
//! | `previews/test_KK.png` | when the run completes | render of the final model beside its ground truth |
//! | `metrics.json` | at the end (completed, stopped or signalled) | [`Metrics`] |
//! | `eval.json` | by `unispine eval` | a re-evaluation of the saved model |
//!
//! [`RunDir::create`] removes every one of these files (and the `checkpoint.ply` /
//! `checkpoint.json` pair of the earlier layout) before a new run writes anything, so a folder
//! never shows a previous run's files as the new run's. The checkpoint is one file, so its model
//! and its training state cannot disagree.
//!
//! The top-level figures of `metrics.json` (`test_psnr`, `test_ssim`, `render_fps`,
//! `n_gaussians`) describe the saved model: for a completed run they are `model.ply`'s, exactly
//! (`unispine eval` of it gives the same PSNR and SSIM bits); a stopped run has no evaluated
//! final model, so its `test_psnr` / `test_ssim` / `render_fps` are `null` and
//! `n_gaussians` is the checkpoint's. Other methods (neural fields, FDK) write the same
//! `metrics.json` with `n_gaussians` = 0 and `model_bytes` set.

use std::path::{Path, PathBuf};

use serde::{de::DeserializeOwned, Deserialize, Serialize};

pub use super::checkpoint::Checkpoint;
use super::compact::Compaction;
use crate::error::{Error, Result};
use crate::fsio;
use crate::gaussians::{ply, Gaussians};
use crate::image2d::Image2d;
use crate::render::RenderSettings;

/// `config.json`.
pub const CONFIG: &str = "config.json";
/// `metrics.json`.
pub const METRICS: &str = "metrics.json";
/// `log.csv`.
pub const LOG: &str = "log.csv";
/// `model.ply`.
pub const MODEL: &str = "model.ply";
/// `checkpoint.bin`.
pub const CHECKPOINT: &str = "checkpoint.bin";
/// `eval.json`.
pub const EVAL: &str = "eval.json";
/// `previews/`.
pub const PREVIEWS: &str = "previews";
/// Every file and folder of a run (removed when a new run starts), earlier layouts included.
pub const RUN_FILES: [&str; 9] = [
    CONFIG,
    METRICS,
    LOG,
    MODEL,
    CHECKPOINT,
    EVAL,
    PREVIEWS,
    "checkpoint.ply",
    "checkpoint.json",
];

/// Header of `log.csv`.
pub const LOG_HEADER: &str = "iteration,view,loss,data,ssim,psnr,n_gaussians,seconds\n";

pub use crate::record::EvalPoint;

/// `metrics.json` of a run (any method).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    pub method: String,
    /// Iterations completed.
    pub iterations: usize,
    /// False when stopped early (Ctrl-C, SIGTERM, `--stop-after`); `train --resume` continues.
    pub completed: bool,
    /// Test PSNR / SSIM at the evaluation iterations.
    pub evals: Vec<EvalPoint>,
    /// Test PSNR / SSIM of the saved final model (`null` for a stopped run).
    pub test_psnr: Option<f64>,
    pub test_ssim: Option<f64>,
    /// Wall time of the training loop (everything from the first to the last iteration,
    /// evaluation passes and checkpoints included, summed over resumed sessions), seconds.
    pub train_time_s: f64,
    /// Part of `train_time_s` spent in the test evaluations (rendering and scoring the test
    /// views only).
    pub eval_time_s: f64,
    /// Test-view render speed of the final model (see `eval::render_fps`).
    pub render_fps: Option<f64>,
    #[serde(default)]
    pub render_fps_protocol: String,
    /// Gaussians of the saved model (0 for methods without Gaussians).
    #[serde(default)]
    pub n_gaussians: usize,
    /// Size of the saved model in bytes, for methods whose size is not a Gaussian count.
    #[serde(default)]
    pub model_bytes: Option<u64>,
    /// Peak resident memory (VmHWM), bytes.
    pub peak_memory_bytes: Option<u64>,
    /// Scene extent (mm).
    #[serde(default)]
    pub extent: f64,
    /// Render settings of the saved model (also recorded in `model.ply`).
    #[serde(default)]
    pub render: RenderSettings,
    /// rayon threads of the run.
    pub threads: usize,
    /// The compaction (Gaussians and test PSNR before and after pruning), when the run
    /// compacted; `n_gaussians` and `test_psnr` are then those of the compacted, fine-tuned,
    /// saved model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compaction: Option<Compaction>,
}

/// Which file a loaded model came from.
#[derive(Clone, Debug, PartialEq)]
pub struct SavedModel {
    pub gaussians: Gaussians<f32>,
    pub render: RenderSettings,
    /// `model.ply` or `checkpoint.bin`.
    pub path: PathBuf,
    /// Iterations behind the model.
    pub iteration: usize,
}

/// A run folder.
#[derive(Clone, Debug)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// Start a new run in `root`: create the folder and remove every file of an earlier run
    /// ([`RUN_FILES`] and leftover temporary files) before anything new is written.
    pub fn create(root: &Path) -> Result<Self> {
        std::fs::create_dir_all(root).map_err(|e| Error::io(root, e))?;
        for f in RUN_FILES {
            fsio::remove_if_exists(&root.join(f))?;
        }
        fsio::remove_matching(root, ".", ".tmp")?;
        Ok(RunDir {
            root: root.to_path_buf(),
        })
    }

    /// An existing run folder (each read names the file it misses).
    pub fn open(root: &Path) -> Result<Self> {
        if !root.is_dir() {
            return Err(Error::io(
                root,
                std::io::Error::new(std::io::ErrorKind::NotFound, "no such run folder"),
            ));
        }
        Ok(RunDir {
            root: root.to_path_buf(),
        })
    }

    /// The folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// A file of the folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }

    fn read_json<T: DeserializeOwned>(&self, name: &str, what: &str) -> Result<T> {
        let p = self.path(name);
        let s = std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))?;
        serde_json::from_str(&s).map_err(|e| Error::format(&p, what, e.to_string()))
    }

    /// Write `config.json`.
    pub fn write_config<T: Serialize>(&self, cfg: &T) -> Result<()> {
        fsio::write_json_atomic(&self.path(CONFIG), cfg)
    }

    /// Read `config.json` as `T`.
    pub fn read_config<T: DeserializeOwned>(&self) -> Result<T> {
        self.read_json(CONFIG, "config")
    }

    /// The dataset folder recorded in `config.json` (`data`): absolute as written by `train`;
    /// a relative path (older runs) is taken relative to the run folder, else to the current
    /// folder. `None` when the config names none.
    pub fn dataset_path(&self) -> Result<Option<PathBuf>> {
        let v: serde_json::Value = self.read_json(CONFIG, "config")?;
        let Some(d) = v.get("data").and_then(|d| d.as_str()) else {
            return Ok(None);
        };
        let p = PathBuf::from(d);
        if p.is_absolute() {
            return Ok(Some(p));
        }
        let beside = self.root.join(&p);
        Ok(Some(if beside.join("dataset.json").exists() {
            beside
        } else {
            p
        }))
    }

    /// Write `metrics.json`.
    pub fn write_metrics(&self, m: &Metrics) -> Result<()> {
        fsio::write_json_atomic(&self.path(METRICS), m)
    }

    /// Read `metrics.json`.
    pub fn read_metrics(&self) -> Result<Metrics> {
        self.read_json(METRICS, "metrics")
    }

    /// Write `log.csv`.
    pub fn write_log(&self, log: &str) -> Result<()> {
        fsio::write_atomic(&self.path(LOG), log.as_bytes())
    }

    /// Write `model.ply` with its render settings in the header.
    pub fn write_model(&self, g: &Gaussians<f32>, render: &RenderSettings) -> Result<()> {
        ply::write_ply_with_comments(&self.path(MODEL), g, &[render.to_ply_comment()])
    }

    /// Write `checkpoint.bin` (one file: model and training state cannot disagree).
    pub fn write_checkpoint(&self, c: &Checkpoint) -> Result<()> {
        fsio::write_atomic(&self.path(CHECKPOINT), &c.to_bytes())
    }

    /// Whether `checkpoint.bin` exists.
    pub fn has_checkpoint(&self) -> bool {
        self.path(CHECKPOINT).is_file()
    }

    /// Read `checkpoint.bin`.
    pub fn read_checkpoint(&self) -> Result<Checkpoint> {
        let p = self.path(CHECKPOINT);
        let b = fsio::read_bounded(&p, fsio::MAX_CHECKPOINT_BYTES)?;
        Checkpoint::from_bytes(&p, &b)
    }

    /// The saved model: `model.ply` of a completed run (its render settings from its header),
    /// else the checkpoint's model.
    pub fn read_model(&self) -> Result<SavedModel> {
        let metrics = self.read_metrics().ok();
        let model = self.path(MODEL);
        if model.is_file() && metrics.as_ref().is_some_and(|m| m.completed) {
            let (g, comments) = ply::read_ply_with_comments::<f32>(&model)?;
            let render = match RenderSettings::from_ply_comments(&model, &comments)? {
                Some(r) => r,
                None => metrics
                    .as_ref()
                    .map(|m| m.render.clone())
                    .unwrap_or_default(),
            };
            let iteration = metrics.map(|m| m.iterations).unwrap_or(0);
            return Ok(SavedModel {
                gaussians: g,
                render,
                path: model,
                iteration,
            });
        }
        if !self.has_checkpoint() {
            return Err(Error::io(
                self.path(CHECKPOINT),
                std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "the run has neither a completed model.ply (with metrics.json) nor a checkpoint",
                ),
            ));
        }
        let c = self.read_checkpoint()?;
        Ok(SavedModel {
            gaussians: c.state.params,
            render: c.render,
            path: self.path(CHECKPOINT),
            iteration: c.iteration,
        })
    }

    /// Write `previews/NAME`: `render | ground truth` side by side, values clamped to [0, 1].
    pub fn write_preview(
        &self,
        name: &str,
        render: &Image2d<f32>,
        gt: &Image2d<f32>,
    ) -> Result<()> {
        let pdir = self.path(PREVIEWS);
        std::fs::create_dir_all(&pdir).map_err(|e| Error::io(&pdir, e))?;
        let (w, h) = (render.width, render.height);
        let gap = 4;
        let mut buf = image::GrayImage::new((2 * w + gap) as u32, h as u32);
        let u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        for r in 0..h {
            for c in 0..w {
                buf.put_pixel(
                    c as u32,
                    r as u32,
                    image::Luma([u8(render.data[r * w + c])]),
                );
                buf.put_pixel(
                    (w + gap + c) as u32,
                    r as u32,
                    image::Luma([u8(gt.data[r * w + c])]),
                );
            }
        }
        fsio::write_png_atomic(&pdir.join(name), &buf)
    }

    /// Write `eval.json`.
    pub fn write_eval<T: Serialize>(&self, v: &T) -> Result<()> {
        fsio::write_json_atomic(&self.path(EVAL), v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::densify::TrainState;
    use crate::optim::AdamConfig;

    fn state(n: usize) -> TrainState<f32> {
        let mut g = Gaussians::<f32>::zeros(n);
        for i in 0..n {
            g.means[i] = [i as f32, 0.5, -1.0];
            g.quats[i] = [1.0, 0.0, 0.1, 0.0];
            g.features[i][15] = 0.25 * i as f32;
        }
        let mut s = TrainState::new(g, AdamConfig::default());
        s.adam.steps = [1, 2, 3, 4, 5, 6];
        s.adam.m.opacity_logits.iter_mut().for_each(|v| *v = 1e-3);
        s.stats.grad_accum.iter_mut().for_each(|v| *v = 0.1);
        s.stats.denom.iter_mut().for_each(|v| *v = 7);
        s
    }

    #[test]
    fn a_preview_is_render_gap_truth_clamped_to_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let rd = RunDir::create(dir.path()).unwrap();
        let img = |v: [f32; 6]| Image2d {
            width: 3,
            height: 2,
            data: v.to_vec(),
        };
        let render = img([0.0, 0.5, 1.0, -1.0, 2.0, 0.2]);
        let gt = img([1.0, 0.25, 0.0, 0.75, 0.1, 0.6]);
        rd.write_preview("p.png", &render, &gt).unwrap();
        let png = image::open(rd.path(PREVIEWS).join("p.png"))
            .unwrap()
            .to_luma8();
        // 3 + 4 + 3 columns, 2 rows; v -> round(255 clamp(v, 0, 1)).
        assert_eq!(png.dimensions(), (10, 2));
        let row = |r: u32| -> Vec<u8> { (0..10).map(|c| png.get_pixel(c, r)[0]).collect() };
        assert_eq!(row(0), [0, 128, 255, 0, 0, 0, 0, 255, 64, 0]);
        assert_eq!(row(1), [0, 255, 51, 0, 0, 0, 0, 191, 26, 153]);
    }

    #[test]
    fn checkpoint_round_trips_and_refuses_truncation_corruption_and_other_runs() {
        use crate::train::checkpoint::Identity;
        let c = Checkpoint {
            identity: crate::train::checkpoint::Identity {
                method: "unispine".into(),
                color: "rirf-paper".into(),
                seed: 3,
                dataset: "0123456789abcdef".into(),
                config: "fedcba9876543210".into(),
            },
            iteration: 12,
            render: RenderSettings::default(),
            state: state(3),
            rng_word_pos: u128::MAX - 5,
            view_stack: vec![4, 1],
            evals: vec![],
            train_time_s: 1.5,
            eval_time_s: 0.25,
            log: format!("{LOG_HEADER}1,0,1,1,1,1,3,0.1\n"),
            compaction: None,
        };
        let p = Path::new("c.bin");
        let b = c.to_bytes();
        let back = Checkpoint::from_bytes(p, &b).unwrap();
        assert_eq!(back.to_bytes(), b);
        assert_eq!(back.state.params, c.state.params);
        assert_eq!(back.state.adam, c.state.adam);
        assert_eq!(back.state.stats, c.state.stats);
        assert_eq!(back.rng_word_pos, c.rng_word_pos);
        assert_eq!(back.identity, c.identity);
        let e = Checkpoint::from_bytes(p, &b[..b.len() - 1]).unwrap_err();
        assert!(e.to_string().contains("checksum"), "{e}");
        // A flipped bit anywhere after the magic line (header, log, any array, the checksum).
        for i in (20..b.len()).step_by(7) {
            let mut f = b.clone();
            f[i] ^= 0x04;
            let e = Checkpoint::from_bytes(p, &f).unwrap_err();
            assert!(e.to_string().contains("checksum"), "byte {i}: {e}");
        }
        // Another run: each field of the identity is named when it differs.
        let mut other = c.identity.clone();
        assert!(back.identity.check(p, &other).is_ok());
        for (field, edit) in [
            (
                "method",
                (|o: &mut Identity| o.method = "3dgs".into()) as fn(&mut Identity),
            ),
            ("color", |o| o.color = "sh".into()),
            ("seed", |o| o.seed = 4),
            ("dataset", |o| o.dataset = "ffffffffffffffff".into()),
            ("config.json changed", |o| {
                o.config = "0000000000000000".into()
            }),
        ] {
            let mut o = c.identity.clone();
            edit(&mut o);
            let e = back.identity.check(p, &o).unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("c.bin"), "{field}: {e}");
        }
        other.seed = 9;
        other.method = "xgaussian".into();
        let e = back.identity.check(p, &other).unwrap_err().to_string();
        assert!(e.contains("seed") && e.contains("method"), "{e}");
        let e = Checkpoint::from_bytes(p, b"nope").unwrap_err();
        assert!(e.to_string().contains("magic"), "{e}");
    }

    #[test]
    fn create_clears_a_previous_run() {
        let d = tempfile::tempdir().unwrap();
        for f in [
            METRICS,
            MODEL,
            EVAL,
            "checkpoint.ply",
            ".log.csv.tmp",
            "notes.txt",
        ] {
            std::fs::write(d.path().join(f), b"old").unwrap();
        }
        std::fs::create_dir(d.path().join(PREVIEWS)).unwrap();
        std::fs::write(d.path().join(PREVIEWS).join("test_03.png"), b"old").unwrap();
        RunDir::create(d.path()).unwrap();
        let left: Vec<String> = std::fs::read_dir(d.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        assert_eq!(left, vec!["notes.txt".to_string()]);
    }
}
