//! Evaluation as the UniSpine-GS code does it (`train.py` `training_report`,
//! `scene/cameras.py`, `utils/image_utils.py`, `utils/loss_utils.py`):
//! - ground truth: each projection min-max normalised to [0, 1] on its own
//!   ([`crate::dataset::targets`]);
//! - render clamped to [0, 1];
//! - PSNR = 20 log10(1 / sqrt(MSE)) (data range 1), SSIM with the 11x11 Gaussian window
//!   (sigma 1.5, zero padding, C1 = 0.01^2, C2 = 0.03^2) of [`crate::loss::ssim`], each averaged
//!   over the test views.
//!
//! Speed figures:
//! - render fps ([`render_fps`]): one warm-up render of the first test view, then three timed
//!   passes that each render every test view once (forward only: projection, tile binning and
//!   sorting, compositing; no metrics, no I/O, no copies to disk); fps = views / seconds of the
//!   median pass. Upstream's "testing speed" also timed its metric computation.
//! - peak memory ([`peak_memory_bytes`]): `VmHWM` of `/proc/self/status` (Linux), the
//!   process's resident-set high-water mark.
//!
//! [`render_fps`]: crate::eval::render_fps
//! [`peak_memory_bytes`]: crate::eval::peak_memory_bytes

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::gaussians::Gaussians;
use crate::image2d::Image2d;
use crate::render::{self, RenderSettings};

/// The image clamped to [0, 1].
pub fn clamp01(img: &Image2d<f32>) -> Image2d<f32> {
    Image2d {
        width: img.width,
        height: img.height,
        data: img.data.iter().map(|&v| v.clamp(0.0, 1.0)).collect(),
    }
}

/// PSNR with data range 1 of `a` against `b` (no clamping here). MSE summed in f64.
pub fn psnr(a: &Image2d<f32>, b: &Image2d<f32>) -> f64 {
    assert_eq!(a.data.len(), b.data.len(), "psnr: image sizes differ");
    let n = a.data.len();
    let mse =
        crate::par::det_sum_by(n, |i| (a.data[i] as f64 - b.data[i] as f64).powi(2)) / n as f64;
    20.0 * (1.0 / mse.sqrt()).log10()
}

/// Metrics of one test view.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewMetrics {
    pub psnr: f64,
    pub ssim: f64,
}

/// Metrics over the test views.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalResult {
    /// Mean PSNR over the test views (dB).
    pub psnr: f64,
    /// Mean SSIM over the test views.
    pub ssim: f64,
    /// Per view, in test order.
    pub views: Vec<ViewMetrics>,
}

/// Render `g` at every test view and compare with the normalised ground truth.
pub fn evaluate(
    g: &Gaussians<f32>,
    ds: &Dataset,
    targets: &[Image2d<f32>],
    settings: &RenderSettings,
) -> Result<EvalResult> {
    if ds.test.angles.is_empty() {
        return Err(Error::invalid("test", "the dataset has no test view"));
    }
    let mut views = Vec::with_capacity(targets.len());
    for (k, gt) in targets.iter().enumerate() {
        let (img, _) = render::forward(g, &ds.test_camera(k), settings)?;
        let img = clamp01(&img);
        views.push(ViewMetrics {
            psnr: psnr(&img, gt),
            ssim: crate::loss::ssim::ssim(&img, gt),
        });
    }
    let n = views.len() as f64;
    Ok(EvalResult {
        psnr: views.iter().map(|v| v.psnr).sum::<f64>() / n,
        ssim: views.iter().map(|v| v.ssim).sum::<f64>() / n,
        views,
    })
}

/// Render speed in frames per second over the test views (see the module doc for the
/// protocol) and the seconds of the median pass.
pub fn render_fps(
    g: &Gaussians<f32>,
    ds: &Dataset,
    settings: &RenderSettings,
) -> Result<(f64, f64)> {
    let n = ds.test.angles.len();
    if n == 0 {
        return Err(Error::invalid("test", "the dataset has no test view"));
    }
    let cams: Vec<_> = (0..n).map(|k| ds.test_camera(k)).collect();
    std::hint::black_box(render::forward(g, &cams[0], settings)?);
    let mut times = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        for c in &cams {
            std::hint::black_box(render::forward(g, c, settings)?);
        }
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let s = times[1];
    Ok((n as f64 / s.max(1e-12), s))
}

/// Peak resident memory of this process in bytes (`VmHWM`), when the OS tells.
pub fn peak_memory_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_and_clamp() {
        let n = Image2d::from_vec(2, 2, vec![0.0f32, 0.5, 0.25, 1.0]);
        // MSE = (0.1^2 * 4) / 4 = 0.01 -> 20 dB
        let a = Image2d::from_vec(2, 2, vec![0.1f32, 0.6, 0.35, 1.1]);
        let p = psnr(&a, &n);
        assert!((p - 20.0).abs() < 1e-5, "{p}");
        assert_eq!(clamp01(&a).data[3], 1.0);
    }

    #[test]
    fn peak_memory_is_reported_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(peak_memory_bytes().unwrap() > 1 << 20);
        }
    }
}
