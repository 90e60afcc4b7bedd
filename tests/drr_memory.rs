//! The DRR's memory bound: a projection allocates little beside the volume (issue 11: peak
//! memory at most 1.1 x the volume). Alone in its test binary so that no other test's
//! allocations move the process's peak. Linux only (reads `/proc/self/status`).

use unispine::drr::{Method, Projector};
use unispine::geometry::ConeBeam;
use unispine::simd::Simd;
use unispine::volume::Volume;
mod common;
use common::skip;

fn status_kib(key: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[test]
fn projection_peak_memory_is_within_a_tenth_of_the_volume() {
    let n = 256;
    let mut vol = Volume::<f32>::zeros([n, n, n], [1.0; 3]);
    for (i, v) in vol.data.iter_mut().enumerate() {
        *v = (i % 97) as f32 * 0.01;
    }
    let vol_kib = (vol.len() * 4 / 1024) as u64;
    let geo = ConeBeam::centred([256, 256], [2.0, 2.0], [n, n, n], [1.0; 3]);
    // Warm up (thread pool, allocator arenas).
    Projector::new(&vol, &geo, Method::Siddon)
        .unwrap()
        .view(0.3)
        .unwrap();
    if std::fs::write("/proc/self/clear_refs", "5").is_err() {
        skip::skipped(
            "the DRR memory test",
            "cannot reset the peak resident memory here (/proc/self/clear_refs)",
        );
        return;
    }
    let before = status_kib("VmRSS:").expect("VmRSS");
    for method in [Method::Siddon, Method::Trilinear] {
        for simd in Simd::supported_paths() {
            let img = Projector::new(&vol, &geo, method)
                .unwrap()
                .with_simd(simd)
                .view(0.3)
                .unwrap();
            assert!(img.data.iter().any(|&v| v > 0.0));
        }
    }
    let peak = status_kib("VmHWM:").expect("VmHWM");
    let extra = peak.saturating_sub(before);
    assert!(
        extra * 10 <= vol_kib,
        "projections raised the peak by {extra} KiB over {before} KiB, more than a tenth of the \
         volume's {vol_kib} KiB"
    );
}
