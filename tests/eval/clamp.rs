//! Evaluation in every colour mode and background: the [0, 1] clamp of the render.

use crate::common;
use common::tiny;
use unispine::image2d::Image2d;

#[test]
#[allow(clippy::manual_clamp)] // written differently from the code's f32::clamp on purpose
fn evaluation_clamps_the_render_in_every_colour_mode_and_background() {
    use unispine::eval;
    use unispine::render::{self, ColorMode, RenderSettings};
    let ds = tiny::dataset();
    let targets = unispine::dataset::targets::test_targets(&ds).unwrap();
    let mut g = tiny::hidden().cast::<f32>();
    // Non-zero higher features so that the SH and X-Gaussian modes differ from the DC term.
    for (i, f) in g.features.iter_mut().enumerate() {
        for (k, v) in f.iter_mut().enumerate().skip(1) {
            *v = 0.3 * ((i * 7 + k * 3) % 5) as f32 / 5.0 - 0.1;
        }
    }
    for color in [
        ColorMode::RirfPaper,
        ColorMode::RirfXgaussian,
        ColorMode::Sh,
    ] {
        for background in [-0.5, 0.0, 0.4, 1.0, 2.0] {
            let settings = RenderSettings {
                color,
                active_features: 16,
                background,
                ..Default::default()
            };
            let got = eval::evaluate(&g, &ds, &targets, &settings).unwrap();
            let (mut psnr_sum, mut ssim_sum, mut outside) = (0.0, 0.0, 0usize);
            for (k, gt) in targets.iter().enumerate() {
                let (img, _) = render::forward(&g, &ds.test_camera(k), &settings).unwrap();
                outside += img
                    .data
                    .iter()
                    .filter(|v| !(0.0..=1.0).contains(*v))
                    .count();
                let clamped = Image2d::from_vec(
                    img.width,
                    img.height,
                    img.data
                        .iter()
                        .map(|&v| {
                            if v < 0.0 {
                                0.0
                            } else if v > 1.0 {
                                1.0
                            } else {
                                v
                            }
                        })
                        .collect(),
                );
                let mse = clamped
                    .data
                    .iter()
                    .zip(&gt.data)
                    .map(|(&a, &b)| (a as f64 - b as f64).powi(2))
                    .sum::<f64>()
                    / gt.data.len() as f64;
                let psnr = -10.0 * mse.log10();
                let ssim = unispine::loss::ssim::ssim(&clamped, gt);
                let v = got.views[k];
                assert!(
                    (v.psnr - psnr).abs() < 1e-9 * psnr.abs().max(1.0),
                    "{color:?} bg {background} view {k}: psnr {} vs {psnr}",
                    v.psnr
                );
                assert!(
                    (v.ssim - ssim).abs() < 1e-12,
                    "{color:?} bg {background} view {k}"
                );
                psnr_sum += psnr;
                ssim_sum += ssim;
            }
            let n = targets.len() as f64;
            assert!((got.psnr - psnr_sum / n).abs() < 1e-9 * got.psnr.abs().max(1.0));
            assert!((got.ssim - ssim_sum / n).abs() < 1e-12);
            if !(0.0..=1.0).contains(&background) {
                assert!(
                    outside > 0,
                    "{color:?} bg {background}: the clamp is not exercised"
                );
            }
        }
    }
}
