//! Provenance: what makes two result rows comparable. The unispine version and git commit, the
//! dataset's checksum, the hash of the run's config, and the machine (CPU model, cores, SIMD
//! path) with the thread count.
//!
//! Checksums are FNV-1a 64 (an identity check between runs, not a security measure).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The crate version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit the binary was built from (set by `build.rs` in a checkout), else "unknown".
pub fn git_commit() -> &'static str {
    option_env!("UNISPINE_GIT_COMMIT").unwrap_or("unknown")
}

/// FNV-1a, 64 bit.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_continue(0xcbf2_9ce4_8422_2325, bytes)
}

fn fnv1a_continue(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Checksum of a dataset folder: FNV-1a 64 over `dataset.json`, `train.npy` and `test.npy`
/// (in that order), hex.
pub fn dataset_checksum(dir: &Path) -> Result<String> {
    let mut h = 0xcbf2_9ce4_8422_2325;
    for f in ["dataset.json", "train.npy", "test.npy"] {
        let p = dir.join(f);
        let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        h = fnv1a_continue(h, &b);
    }
    Ok(format!("{h:016x}"))
}

/// Hash of a run's `config.json` without its `data` field (the dataset's location is not part
/// of the config's meaning; its checksum is recorded separately), hex.
pub fn config_hash(run: &Path) -> Option<String> {
    let s = std::fs::read_to_string(run.join("config.json")).ok()?;
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
    /// The rasterizer's SIMD path on this CPU (`avx2` or `scalar`).
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
            simd: simd_path().to_string(),
            version: VERSION.to_string(),
            git_commit: git_commit().to_string(),
        }
    }
}

/// The SIMD path the compositing kernels take on this CPU (see `render::composite`).
pub fn simd_path() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") {
            return "avx2";
        }
    }
    "scalar"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_matches_the_reference_vectors() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(fnv1a(b""), 0xcbf29ce484222325);
        assert_eq!(fnv1a(b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(fnv1a(b"foobar"), 0x85944171f73967e8);
    }
}
