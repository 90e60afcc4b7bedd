//! Provenance: what makes two result rows comparable. The unispine version and git commit, the
//! dataset's checksum, the hash of the run's config, and the machine (CPU model, cores, SIMD
//! path) with the thread count.
//!
//! Checksums are FNV-1a 64 (an identity check between runs, not a security measure).

use std::io::Read;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The crate version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit the binary was built from (set by `build.rs` in a checkout), else "unknown".
pub fn git_commit() -> &'static str {
    option_env!("UNISPINE_GIT_COMMIT").unwrap_or("unknown")
}

pub use crate::fingerprint::fnv1a;
use crate::fingerprint::{fnv1a_continue, FNV_OFFSET};

/// Checksum of a dataset folder: FNV-1a 64 over `dataset.json`, `train.npy` and `test.npy`
/// (in that order), hex.
pub fn dataset_checksum(dir: &Path) -> Result<String> {
    let mut h = FNV_OFFSET;
    for f in ["dataset.json", "train.npy", "test.npy"] {
        let p = dir.join(f);
        // A regular file only (a link to a device or a FIFO is refused before reading), read in
        // blocks so that memory stays bounded whatever its size.
        let mut file = crate::fsio::open_regular(&p)?;
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = file.read(&mut buf).map_err(|e| Error::io(&p, e))?;
            if n == 0 {
                break;
            }
            h = fnv1a_continue(h, &buf[..n]);
        }
    }
    Ok(format!("{h:016x}"))
}

/// Hash of a run's `config.json` without its `data` field (the dataset's location is not part
/// of the config's meaning; its checksum is recorded separately), hex.
pub fn config_hash(run: &Path) -> Option<String> {
    let s = crate::fsio::read_text_bounded(&run.join("config.json"), crate::fsio::MAX_TEXT_BYTES)
        .ok()?;
    let mut v: serde_json::Value = serde_json::from_str(&s).ok()?;
    if let Some(o) = v.as_object_mut() {
        o.remove("data");
    }
    Some(format!("{:016x}", fnv1a(v.to_string().as_bytes())))
}

/// The machine a cell ran on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    pub cpu_model: String,
    pub cores: usize,
    /// The SIMD path the kernels ran on ([`crate::simd::Simd::active`]: `avx512`, `avx2` or
    /// `scalar`).
    pub simd: String,
    pub version: String,
    pub git_commit: String,
}

impl Machine {
    /// Detect the current machine.
    pub fn detect() -> Self {
        let cpu_model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|m| m.trim().to_string())
            })
            .unwrap_or_else(|| std::env::consts::ARCH.to_string());
        Machine {
            cpu_model,
            cores: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            simd: crate::simd::Simd::active().name().to_string(),
            version: VERSION.to_string(),
            git_commit: git_commit().to_string(),
        }
    }
}
