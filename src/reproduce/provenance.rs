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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A dataset folder `parent/ds` as a plan's `path` may name it (the three files whose bytes
    /// the checksum reads; their content is not a dataset's), for the harness modules' tests.
    pub(crate) fn ready_folder(parent: &Path) -> std::path::PathBuf {
        let ds = parent.join("ds");
        std::fs::create_dir_all(&ds).unwrap();
        for f in ["dataset.json", "train.npy", "test.npy"] {
            std::fs::write(ds.join(f), f).unwrap();
        }
        ds
    }

    /// FNV-1a 64 written from its definition (offset basis 0xcbf29ce484222325, prime
    /// 0x100000001b3: xor the byte, then multiply).
    fn fnv(bytes: &[u8]) -> u64 {
        bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
            (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
        })
    }

    #[test]
    fn a_dataset_s_checksum_runs_over_its_three_files_in_order() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        // train.npy longer than the 1 MiB read block, so that blocks are continued.
        let train: Vec<u8> = (0..(1u32 << 20) + 77)
            .map(|i| (i * 7 + i / 251) as u8)
            .collect();
        std::fs::write(d.join("dataset.json"), b"{\"n\": 1}").unwrap();
        std::fs::write(d.join("train.npy"), &train).unwrap();
        std::fs::write(d.join("test.npy"), b"test").unwrap();
        let mut all = b"{\"n\": 1}".to_vec();
        all.extend(&train);
        all.extend(b"test");
        assert_eq!(dataset_checksum(d).unwrap(), format!("{:016x}", fnv(&all)));
        // The files' order counts.
        std::fs::write(d.join("dataset.json"), b"test").unwrap();
        std::fs::write(d.join("test.npy"), b"{\"n\": 1}").unwrap();
        assert_ne!(dataset_checksum(d).unwrap(), format!("{:016x}", fnv(&all)));
        // A missing file is named.
        std::fs::remove_file(d.join("test.npy")).unwrap();
        let e = dataset_checksum(d).unwrap_err().to_string();
        assert!(e.contains("test.npy"), "{e}");
    }

    #[test]
    fn a_config_s_hash_leaves_out_where_its_data_lies() {
        let tmp = tempfile::tempdir().unwrap();
        let r = tmp.path();
        assert_eq!(config_hash(r), None);
        let put = |t: &str| std::fs::write(r.join("config.json"), t).unwrap();
        put(r#"{"data": "/a/ds", "iters": 10}"#);
        let h = config_hash(r).unwrap();
        assert_eq!(h, format!("{:016x}", fnv(br#"{"iters":10}"#)));
        put(r#"{"iters": 10, "data": "/b/elsewhere"}"#);
        assert_eq!(config_hash(r).unwrap(), h);
        put(r#"{"data": "/a/ds", "iters": 11}"#);
        assert_ne!(config_hash(r).unwrap(), h);
        put("not json");
        assert_eq!(config_hash(r), None);
    }

    /// In a checkout the build records the commit (hex, `-dirty` when the sources differ);
    /// outside one, `unknown`.
    #[test]
    fn the_commit_is_hex_or_unknown() {
        let c = git_commit();
        let hex = c.strip_suffix("-dirty").unwrap_or(c);
        assert!(
            c == "unknown" || (hex.len() >= 7 && hex.chars().all(|ch| ch.is_ascii_hexdigit())),
            "{c:?}"
        );
    }
}
