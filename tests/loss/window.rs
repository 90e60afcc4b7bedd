//! The Gaussian windows of the SSIM and SPWM blurs (`loss::filters::gaussian_kernel`) against
//! their closed form, at several widths: `w_k = exp(-(k - r)^2 / (2 sigma^2)) / (sum_j
//! exp(-(j - r)^2 / (2 sigma^2)) + eps)`, `r = size / 2` (integer division).

use unispine::loss::filters::gaussian_kernel;

#[test]
fn gaussian_windows_follow_their_closed_form_at_every_width() {
    for (size, sigma, eps) in [
        (11usize, 1.5f64, 0.0f64),
        (7, 0.7, 0.0),
        (9, 2.0, 1e-12),
        (5, 3.3, 0.25),
    ] {
        let r = (size / 2) as f64;
        let g: Vec<f64> = (0..size)
            .map(|k| (-((k as f64 - r).powi(2)) / (2.0 * sigma.powi(2))).exp())
            .collect();
        let s: f64 = g.iter().sum::<f64>() + eps;
        let got = gaussian_kernel(size, sigma, eps);
        assert_eq!(got.len(), size);
        for (k, (a, b)) in got.iter().zip(&g).enumerate() {
            assert!(
                (a - b / s).abs() <= 1e-15,
                "size {size} sigma {sigma} tap {k}: {a} vs {}",
                b / s
            );
        }
    }
}
