//! `checkpoint.bin` of a neural-field run: the parameters, Adam's moments and step count, the
//! iterations done, the training time and `log.csv` so far, in one file. Nothing else is
//! needed to continue with the same bits: iteration `it`'s rays, targets and sample jitter
//! are drawn from generators seeded by the config's seed and `it` alone (see
//! [`super::train::FieldTrainer::batch`]).
//!
//! Layout: the magic line `unispine-field-checkpoint`, a little-endian u64 header length, the
//! header as JSON (`Header`: the run it belongs to, with the dataset's and the config's
//! fingerprints, and the sizes), the log (UTF-8), then the parameters, `m` and `v` as
//! little-endian f32 arrays of `n_params` values each, and the checksum of everything before
//! it ([`crate::fsio::seal`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::FieldConfig;
use crate::error::{Error, Result};
use crate::fsio;

const MAGIC: &[u8] = b"unispine-field-checkpoint\n";
const VERSION: u32 = 2;

/// Everything a resumed field run needs.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldCheckpoint {
    /// Iterations completed.
    pub iteration: usize,
    /// Training wall time so far (summed over sessions), seconds.
    pub train_time_s: f64,
    /// `log.csv` up to `iteration`.
    pub log: String,
    pub params: Vec<f32>,
    pub adam_m: Vec<f32>,
    pub adam_v: Vec<f32>,
    pub adam_step: u64,
}

/// The JSON header: the run it belongs to and the sizes of what follows.
#[derive(Serialize, Deserialize)]
struct Header {
    format_version: u32,
    preset: String,
    seed: u64,
    /// [`crate::dataset::Dataset::fingerprint`] of the training data.
    dataset: String,
    /// [`crate::fingerprint::config`] of the run's config.
    config: String,
    iterations_total: usize,
    iteration: usize,
    n_params: usize,
    adam_step: u64,
    train_time_s: f64,
    log_bytes: usize,
}

/// Whether `bytes` start as a field checkpoint (as opposed to a Gaussian run's).
pub fn is_field_checkpoint(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
}

/// Whether the file at `path` is a field checkpoint (reads only its first line).
pub fn file_is_field_checkpoint(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; MAGIC.len()];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && is_field_checkpoint(&head)
}

impl FieldCheckpoint {
    /// The file's bytes for the run configured by `cfg` on the dataset of fingerprint
    /// `dataset`.
    pub fn to_bytes(&self, cfg: &FieldConfig, dataset: &str) -> Vec<u8> {
        let h = Header {
            format_version: VERSION,
            preset: cfg.preset.clone(),
            seed: cfg.seed,
            dataset: dataset.to_string(),
            config: crate::fingerprint::config(cfg),
            iterations_total: cfg.iterations,
            iteration: self.iteration,
            n_params: self.params.len(),
            adam_step: self.adam_step,
            train_time_s: self.train_time_s,
            log_bytes: self.log.len(),
        };
        let mut b = fsio::frame_header(MAGIC, &h);
        b.reserve(self.log.len() + 12 * h.n_params);
        b.extend_from_slice(self.log.as_bytes());
        for a in [&self.params, &self.adam_m, &self.adam_v] {
            for v in a.iter() {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        fsio::seal(&mut b);
        b
    }

    /// Parse the file `path` (its bytes `bytes`) as a checkpoint of the run configured by
    /// `cfg` with `n_params` parameters on the dataset of fingerprint `dataset`; every mismatch
    /// (another run's checkpoint, an edited config, another dataset, a changed byte) is an
    /// error naming the file and field.
    pub fn from_bytes(
        path: &Path,
        bytes: &[u8],
        cfg: &FieldConfig,
        n_params: usize,
        dataset: &str,
    ) -> Result<Self> {
        let bad = |field: &str, msg: String| Error::format(path, field, msg);
        let (h, rest): (Header, _) =
            fsio::read_frame(path, bytes, MAGIC, "a neural-field checkpoint")?;
        if h.format_version != VERSION {
            return Err(bad(
                "format_version",
                format!("{} (this build reads {VERSION})", h.format_version),
            ));
        }
        let want = |field: &str, got: String, cfg_v: String| -> Result<()> {
            if got == cfg_v {
                Ok(())
            } else {
                Err(bad(
                    field,
                    format!(
                        "{got}, but the run's config.json says {cfg_v} (not this run's checkpoint)"
                    ),
                ))
            }
        };
        want("preset", h.preset.clone(), cfg.preset.clone())?;
        want("seed", h.seed.to_string(), cfg.seed.to_string())?;
        want(
            "iterations_total",
            h.iterations_total.to_string(),
            cfg.iterations.to_string(),
        )?;
        want("n_params", h.n_params.to_string(), n_params.to_string())?;
        if h.dataset != dataset {
            return Err(bad(
                "dataset",
                format!(
                    "fingerprint {}, but the dataset given has {dataset} (not this run's data)",
                    h.dataset
                ),
            ));
        }
        let now = crate::fingerprint::config(cfg);
        if h.config != now {
            return Err(bad(
                "config",
                format!(
                    "config.json changed since the checkpoint was written (fingerprint {} then, \
                     {now} now): refused",
                    h.config
                ),
            ));
        }
        if h.iteration > cfg.iterations {
            return Err(bad(
                "iteration",
                format!(
                    "{} is past the run's {} iterations",
                    h.iteration, cfg.iterations
                ),
            ));
        }
        if !(h.train_time_s.is_finite() && h.train_time_s >= 0.0) {
            return Err(bad(
                "train_time_s",
                format!("{} is not a time", h.train_time_s),
            ));
        }
        let need = n_params
            .checked_mul(12)
            .and_then(|b| b.checked_add(h.log_bytes))
            .ok_or_else(|| bad("log_bytes", format!("{} is too large", h.log_bytes)))?;
        if rest.len() != need {
            return Err(bad(
                "n_params",
                format!(
                    "{n_params} parameters and a {}-byte log need {need} bytes after the header, \
                     the file has {} (truncated or corrupt)",
                    h.log_bytes,
                    rest.len()
                ),
            ));
        }
        let log = std::str::from_utf8(&rest[..h.log_bytes])
            .map_err(|_| bad("log", "not UTF-8".into()))?
            .to_string();
        // Array k (parameters, m, v) of n_params little-endian f32 after the log.
        let array = |k: usize| -> Vec<f32> {
            rest[h.log_bytes + 4 * n_params * k..h.log_bytes + 4 * n_params * (k + 1)]
                .chunks_exact(4)
                .map(|v| f32::from_le_bytes(v.try_into().expect("4 bytes")))
                .collect()
        };
        let c = FieldCheckpoint {
            iteration: h.iteration,
            train_time_s: h.train_time_s,
            log,
            params: array(0),
            adam_m: array(1),
            adam_v: array(2),
            adam_step: h.adam_step,
        };
        for (name, a) in [
            ("params", &c.params),
            ("adam_m", &c.adam_m),
            ("adam_v", &c.adam_v),
        ] {
            if let Some(i) = a.iter().position(|v| !v.is_finite()) {
                return Err(bad(name, format!("value {i} is {} (not finite)", a[i])));
            }
        }
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> FieldConfig {
        FieldConfig::preset("intratomo", 4).unwrap()
    }

    fn ckpt(n: usize) -> FieldCheckpoint {
        FieldCheckpoint {
            iteration: 7,
            train_time_s: 1.5,
            log: "iteration,view\n1,0\n".into(),
            params: (0..n).map(|i| i as f32 * 0.5).collect(),
            adam_m: (0..n).map(|i| -(i as f32)).collect(),
            adam_v: (0..n).map(|i| i as f32 * 1e-3).collect(),
            adam_step: 7,
        }
    }

    #[test]
    fn round_trips_and_names_what_is_wrong() {
        let (c, p) = (ckpt(10), Path::new("run/checkpoint.bin"));
        let b = c.to_bytes(&cfg(), DS);
        assert!(is_field_checkpoint(&b));
        assert_eq!(
            FieldCheckpoint::from_bytes(p, &b, &cfg(), 10, DS).unwrap(),
            c
        );
        let err = |bytes: &[u8], cfg: &FieldConfig, n: usize| {
            FieldCheckpoint::from_bytes(p, bytes, cfg, n, DS)
                .unwrap_err()
                .to_string()
        };
        // Truncated, another run's parameter count, seed or preset, a Gaussian checkpoint.
        assert!(err(&b[..b.len() - 3], &cfg(), 10).contains("checksum"));
        assert!(err(&b, &cfg(), 11).contains("n_params"));
        let mut other = cfg();
        other.seed = 3;
        assert!(err(&b, &other, 10).contains("seed"));
        let naf = FieldConfig::preset("naf", 4).unwrap();
        assert!(err(&b, &naf, 10).contains("preset"));
        assert!(err(b"unispine-checkpoint\n....", &cfg(), 10).contains("magic"));
        let mut nan = ckpt(10);
        nan.adam_v[4] = f32::NAN;
        assert!(err(&nan.to_bytes(&cfg(), DS), &cfg(), 10).contains("adam_v"));
        assert!(err(&b, &cfg(), 11).contains("run/checkpoint.bin"));
    }

    const DS: &str = "00112233aabbccdd";

    #[test]
    fn a_flipped_bit_another_dataset_or_an_edited_config_is_refused() {
        let (c, p) = (ckpt(10), Path::new("run/checkpoint.bin"));
        let b = c.to_bytes(&cfg(), DS);
        // Every bit of the payload and of the header's values.
        for i in MAGIC.len()..b.len() {
            let mut f = b.clone();
            f[i] ^= 0x10;
            let e = FieldCheckpoint::from_bytes(p, &f, &cfg(), 10, DS).unwrap_err();
            assert!(e.to_string().contains("checksum"), "byte {i}: {e}");
        }
        let e = FieldCheckpoint::from_bytes(p, &b, &cfg(), 10, "ffffffffffffffff").unwrap_err();
        assert!(e.to_string().contains("dataset"), "{e}");
        let mut edited = cfg();
        edited.lr *= 2.0;
        let e = FieldCheckpoint::from_bytes(p, &b, &edited, 10, DS).unwrap_err();
        assert!(e.to_string().contains("config.json changed"), "{e}");
    }

    #[test]
    fn the_iteration_may_reach_the_schedule_s_end_and_the_time_must_be_a_time() {
        let p = Path::new("run/checkpoint.bin");
        let iters = cfg().iterations;
        let at = |iteration: usize, t: f64| {
            let mut c = ckpt(10);
            c.iteration = iteration;
            c.train_time_s = t;
            FieldCheckpoint::from_bytes(p, &c.to_bytes(&cfg(), DS), &cfg(), 10, DS)
        };
        assert!(at(iters, 0.0).is_ok());
        let e = at(iters + 1, 1.0).unwrap_err().to_string();
        assert!(e.contains("iteration") && e.contains("past the run"), "{e}");
        let e = at(1, -1.0).unwrap_err().to_string();
        assert!(e.contains("train_time_s"), "{e}");
        // Not finite: written as JSON null, refused when the header is read.
        for t in [f64::NAN, f64::INFINITY] {
            assert!(at(1, t).is_err(), "{t}");
        }
    }

    #[test]
    fn a_field_checkpoint_is_told_from_a_gaussian_one_by_its_first_line() {
        let b = ckpt(3).to_bytes(&cfg(), DS);
        assert!(is_field_checkpoint(&b));
        assert!(!is_field_checkpoint(b"unispine-checkpoint\n...."));
        assert!(!is_field_checkpoint(&b[..MAGIC.len() - 1]));
        let dir = tempfile::tempdir().unwrap();
        let (field, short, other) = (
            dir.path().join("f.bin"),
            dir.path().join("s.bin"),
            dir.path().join("g.bin"),
        );
        std::fs::write(&field, &b).unwrap();
        std::fs::write(&short, &b[..3]).unwrap();
        std::fs::write(&other, b"unispine-checkpoint\n0123456789abcdef0123456789").unwrap();
        assert!(file_is_field_checkpoint(&field));
        assert!(!file_is_field_checkpoint(&short));
        assert!(!file_is_field_checkpoint(&other));
        assert!(!file_is_field_checkpoint(&dir.path().join("missing.bin")));
    }
}
