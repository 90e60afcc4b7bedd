//! The run folder: the one owner of every file a training run writes, and the one reader that
//! `unispine eval`, `report`, `render` and `train --resume` use.
//!
//! Files (every one written atomically: temporary name, fsync, rename; see [`crate::fsio`]):
//!
//! | file | written | content |
//! |---|---|---|
//! | `config.json` | at the start | the method's full config ([`crate::train::TrainConfig`] for Gaussians); `data` = dataset folder, absolute |
//! | `log.csv` | at checkpoints and at the end | one row per iteration (the `seconds` column is wall-clock; every other column is deterministic) |
//! | `checkpoint.bin` | at 0, every `checkpoint_every`, on stop / signal, at the end | everything a resume needs, in one file ([`Checkpoint`]) |
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

use super::compact::Compaction;
use crate::densify::{Stats, TrainState};
use crate::error::{Error, Result};
use crate::fsio;
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::{ply, Gaussians};
use crate::image2d::Image2d;
use crate::optim::{Adam, AdamConfig, N_GROUPS};
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

/// One evaluation point of `metrics.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalPoint {
    pub iteration: usize,
    pub psnr: f64,
    pub ssim: f64,
    /// Gaussians of the evaluated model (before that iteration's densification).
    pub n_gaussians: usize,
}

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

/// Everything a resumed run needs to continue with the same bits: parameters, Adam moments and
/// step counts, densification statistics, the view order (random generator position and the
/// views left in the stack), the evaluations, times and log so far.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    /// Iterations completed.
    pub iteration: usize,
    /// Render settings of the model at this point.
    pub render: RenderSettings,
    pub state: TrainState<f32>,
    /// Word position of the view-order generator (ChaCha8, seeded from the config's seed).
    pub rng_word_pos: u128,
    /// Views not yet drawn in the current pass.
    pub view_stack: Vec<usize>,
    pub evals: Vec<EvalPoint>,
    pub train_time_s: f64,
    pub eval_time_s: f64,
    /// `log.csv` up to `iteration`.
    pub log: String,
    /// What the compaction did, once it has run.
    pub compaction: Option<Compaction>,
}

const CKPT_MAGIC: &[u8] = b"unispine-checkpoint\n";
const CKPT_VERSION: u32 = 1;
/// f32 values per Gaussian in one parameter-shaped array.
const PER_G: usize = 3 + 3 + 4 + 1 + N_FEATURES;

#[derive(Serialize, Deserialize)]
struct CkptHeader {
    format_version: u32,
    iteration: usize,
    n_gaussians: usize,
    render: RenderSettings,
    adam: AdamConfig,
    adam_steps: [u64; N_GROUPS],
    /// Decimal (a u128 does not fit a JSON number).
    rng_word_pos: String,
    view_stack: Vec<usize>,
    evals: Vec<EvalPoint>,
    train_time_s: f64,
    eval_time_s: f64,
    log_bytes: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    compaction: Option<Compaction>,
}

fn put_g(buf: &mut Vec<u8>, g: &Gaussians<f32>) {
    let mut put = |v: f32| buf.extend_from_slice(&v.to_le_bytes());
    for i in 0..g.len() {
        g.means[i].iter().for_each(|&v| put(v));
        g.log_scales[i].iter().for_each(|&v| put(v));
        g.quats[i].iter().for_each(|&v| put(v));
        put(g.opacity_logits[i]);
        g.features[i].iter().for_each(|&v| put(v));
    }
}

fn get_g(b: &[u8], n: usize) -> Gaussians<f32> {
    let mut g = Gaussians::<f32>::zeros(n);
    let mut k = 0;
    let mut get = || {
        let v = f32::from_le_bytes(b[k..k + 4].try_into().unwrap());
        k += 4;
        v
    };
    for i in 0..n {
        g.means[i].iter_mut().for_each(|v| *v = get());
        g.log_scales[i].iter_mut().for_each(|v| *v = get());
        g.quats[i].iter_mut().for_each(|v| *v = get());
        g.opacity_logits[i] = get();
        g.features[i].iter_mut().for_each(|v| *v = get());
    }
    g
}

impl Checkpoint {
    /// The checkpoint as bytes: magic line, header length (u64 LE), header JSON, the log, then
    /// little-endian arrays: parameters, first and second Adam moments (each per Gaussian:
    /// mean 3, log-scale 3, quaternion 4, opacity logit 1, features 16, f32), the statistics'
    /// gradient sums (f64), visibility counts and max radii (u32).
    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.state.len();
        let h = CkptHeader {
            format_version: CKPT_VERSION,
            iteration: self.iteration,
            n_gaussians: n,
            render: self.render.clone(),
            adam: self.state.adam.cfg,
            adam_steps: self.state.adam.steps,
            rng_word_pos: self.rng_word_pos.to_string(),
            view_stack: self.view_stack.clone(),
            evals: self.evals.clone(),
            train_time_s: self.train_time_s,
            eval_time_s: self.eval_time_s,
            log_bytes: self.log.len(),
            compaction: self.compaction.clone(),
        };
        let hj = serde_json::to_vec(&h).expect("checkpoint header serialises");
        let mut buf =
            Vec::with_capacity(CKPT_MAGIC.len() + 8 + hj.len() + self.log.len() + n * 340);
        buf.extend_from_slice(CKPT_MAGIC);
        buf.extend_from_slice(&(hj.len() as u64).to_le_bytes());
        buf.extend_from_slice(&hj);
        buf.extend_from_slice(self.log.as_bytes());
        put_g(&mut buf, &self.state.params);
        put_g(&mut buf, &self.state.adam.m);
        put_g(&mut buf, &self.state.adam.v);
        let st = &self.state.stats;
        st.grad_accum
            .iter()
            .for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
        st.denom
            .iter()
            .for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
        st.max_radius
            .iter()
            .for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
        buf
    }

    /// Parse [`Checkpoint::to_bytes`]; sizes are checked against the length of `bytes` before
    /// anything is allocated. Errors name `path` and the field.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self> {
        let bad = |field: &str, msg: String| Error::format(path, field, msg);
        let rest = bytes
            .strip_prefix(CKPT_MAGIC)
            .ok_or_else(|| bad("magic", "not a unispine checkpoint".into()))?;
        if rest.len() < 8 {
            return Err(bad("header", "file ends inside the header length".into()));
        }
        let hl = u64::from_le_bytes(rest[..8].try_into().unwrap());
        let rest = &rest[8..];
        let hl = usize::try_from(hl)
            .ok()
            .filter(|&l| l <= rest.len())
            .ok_or_else(|| bad("header", format!("length {hl} exceeds the file")))?;
        let h: CkptHeader = serde_json::from_slice(&rest[..hl])
            .map_err(|e| bad("header", format!("not valid JSON: {e}")))?;
        if h.format_version != CKPT_VERSION {
            return Err(bad(
                "format_version",
                format!("{} (this build reads {CKPT_VERSION})", h.format_version),
            ));
        }
        let rest = &rest[hl..];
        let n = h.n_gaussians;
        let need = n
            .checked_mul(3 * PER_G * 4 + 8 + 4 + 4)
            .and_then(|b| b.checked_add(h.log_bytes))
            .ok_or_else(|| bad("n_gaussians", format!("{n} is too large")))?;
        if rest.len() != need {
            return Err(bad(
                "n_gaussians",
                format!(
                    "{n} Gaussians and a {}-byte log need {need} bytes after the header, the file \
                     has {} (truncated or corrupt)",
                    h.log_bytes,
                    rest.len()
                ),
            ));
        }
        let log = std::str::from_utf8(&rest[..h.log_bytes])
            .map_err(|_| bad("log", "not UTF-8".into()))?
            .to_string();
        let mut b = &rest[h.log_bytes..];
        let gb = n * PER_G * 4;
        let params = get_g(&b[..gb], n);
        let m = get_g(&b[gb..2 * gb], n);
        let v = get_g(&b[2 * gb..3 * gb], n);
        b = &b[3 * gb..];
        let grad_accum = b[..8 * n]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        let u32s = |c: &[u8]| -> Vec<u32> {
            c.chunks_exact(4)
                .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
                .collect()
        };
        let denom = u32s(&b[8 * n..12 * n]);
        let max_radius = u32s(&b[12 * n..16 * n]);
        let rng_word_pos = h.rng_word_pos.parse().map_err(|_| {
            bad(
                "rng_word_pos",
                format!("`{}` is not a u128", h.rng_word_pos),
            )
        })?;
        h.render
            .validate()
            .map_err(|e| bad("render", e.to_string()))?;
        params
            .check_finite()
            .map_err(|e| bad("parameters", e.to_string()))?;
        Ok(Checkpoint {
            iteration: h.iteration,
            render: h.render,
            state: TrainState {
                params,
                adam: Adam {
                    cfg: h.adam,
                    m,
                    v,
                    steps: h.adam_steps,
                },
                stats: Stats {
                    grad_accum,
                    denom,
                    max_radius,
                },
            },
            rng_word_pos,
            view_stack: h.view_stack,
            compaction: h.compaction,
            evals: h.evals,
            train_time_s: h.train_time_s,
            eval_time_s: h.eval_time_s,
            log,
        })
    }
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

    /// An error when the folder holds a baseline run (`unispine train --method fdk | naf | ...`,
    /// recognised by its `config.json`): only Gaussian runs have a checkpoint to resume from.
    pub fn check_resumable(&self) -> Result<()> {
        let v: serde_json::Value = self.read_json(CONFIG, "config")?;
        let baseline = match (v.get("preset"), v.get("method")) {
            (Some(p), _) => p.as_str().map(str::to_string),
            (None, Some(m)) if m == "fdk" => Some("fdk".to_string()),
            _ => None,
        };
        match baseline {
            Some(name) => Err(Error::invalid(
                "--resume",
                format!(
                    "{} holds a `{name}` baseline run: baseline runs cannot be resumed (train \
                     it again with `unispine train --method {name}`)",
                    self.root.display()
                ),
            )),
            None => Ok(()),
        }
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

    /// Read `log.csv`.
    pub fn read_log(&self) -> Result<String> {
        let p = self.path(LOG);
        std::fs::read_to_string(&p).map_err(|e| Error::io(&p, e))
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
        let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
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
    fn checkpoint_round_trips_and_refuses_truncation() {
        let c = Checkpoint {
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
        let e = Checkpoint::from_bytes(p, &b[..b.len() - 1]).unwrap_err();
        assert!(e.to_string().contains("n_gaussians"), "{e}");
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
