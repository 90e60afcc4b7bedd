//! `checkpoint.bin`: everything a resumed run needs, in one file (see [`Checkpoint::to_bytes`]
//! for the layout), so its model and its training state cannot disagree.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::compact::Compaction;
use crate::densify::{Stats, TrainState};
use crate::error::{Error, Result};
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::Gaussians;
use crate::optim::{Adam, AdamConfig, N_GROUPS};
use crate::record::EvalPoint;
use crate::render::RenderSettings;

/// What a checkpoint belongs to. `train --resume` computes the same record from the run's
/// `config.json` and the dataset it is given and refuses to continue when any field differs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Identity {
    /// The preset (`unispine`, `3dgs`, ...).
    pub method: String,
    /// The intensity model (`rirf-paper`, `sh`, ...): it gives the features their meaning.
    pub color: String,
    pub seed: u64,
    /// [`crate::dataset::Dataset::fingerprint`] of the training data.
    pub dataset: String,
    /// [`crate::fingerprint::config`] of the run's config (every setting but the data path).
    pub config: String,
}

impl Identity {
    /// Error naming each field in which this (a checkpoint's) identity differs from `want`
    /// (the run being resumed); `path` is the checkpoint.
    pub fn check(&self, path: &Path, want: &Identity) -> Result<()> {
        let mut diff = Vec::new();
        let mut cmp = |field: &str, got: String, wanted: String, what: &str| {
            if got != wanted {
                diff.push(format!(
                    "{field}: the checkpoint's is {got}, {what} {wanted}"
                ));
            }
        };
        let cfg = "the run's config.json says";
        cmp("method", self.method.clone(), want.method.clone(), cfg);
        cmp("color", self.color.clone(), want.color.clone(), cfg);
        cmp("seed", self.seed.to_string(), want.seed.to_string(), cfg);
        cmp(
            "dataset",
            self.dataset.clone(),
            want.dataset.clone(),
            "the dataset given has",
        );
        if diff.is_empty() && self.config != want.config {
            diff.push(format!(
                "config: config.json changed since the checkpoint was written (fingerprint {} \
                 then, {} now)",
                self.config, want.config
            ));
        }
        if diff.is_empty() {
            return Ok(());
        }
        Err(Error::format(
            path,
            "identity",
            format!(
                "belongs to another run, refused: {} (start a new run instead of --resume)",
                diff.join("; ")
            ),
        ))
    }
}

/// Everything a resumed run needs to continue with the same bits: parameters, Adam moments and
/// step counts, densification statistics, the view order (random generator position and the
/// views left in the stack), the evaluations, times and log so far, and the run it belongs to.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    /// The run it belongs to.
    pub identity: Identity,
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
const CKPT_VERSION: u32 = 2;
/// f32 values per Gaussian in one parameter-shaped array.
const PER_G: usize = 3 + 3 + 4 + 1 + N_FEATURES;

#[derive(Serialize, Deserialize)]
struct CkptHeader {
    format_version: u32,
    identity: Identity,
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
    /// gradient sums (f64), visibility counts and max radii (u32); then the checksum of
    /// everything before it ([`crate::fsio::seal`]). The header records the run's [`Identity`].
    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.state.len();
        let h = CkptHeader {
            format_version: CKPT_VERSION,
            identity: self.identity.clone(),
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
        let mut buf = crate::fsio::frame_header(CKPT_MAGIC, &h);
        buf.reserve(self.log.len() + n * 340);
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
        crate::fsio::seal(&mut buf);
        buf
    }

    /// Parse [`Checkpoint::to_bytes`]; sizes are checked against the length of `bytes` before
    /// anything is allocated. Errors name `path` and the field.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self> {
        let bad = |field: &str, msg: String| Error::format(path, field, msg);
        let (h, rest): (CkptHeader, _) =
            crate::fsio::read_frame(path, bytes, CKPT_MAGIC, "a unispine checkpoint")?;
        if h.format_version != CKPT_VERSION {
            return Err(bad(
                "format_version",
                format!("{} (this build reads {CKPT_VERSION})", h.format_version),
            ));
        }
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
            identity: h.identity,
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
