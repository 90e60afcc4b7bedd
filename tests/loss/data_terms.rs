//! The data terms of Eq. (8) (`loss::charbonnier`: L1, Charbonnier, Eq. (9)'s weighted
//! Charbonnier) on an image of several of the loss stage's parallel chunks, each gradient
//! against its per-pixel definition written out here; and every term refusing images of
//! different sizes.

use crate::common::panic_text;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use unispine::image2d::Image2d;
use unispine::loss::charbonnier::{charbonnier, l1, weighted_charbonnier};

/// 131 x 97 = 12,707 pixels: three chunks of 4096 and a partial fourth.
const W: usize = 131;
const H: usize = 97;

fn image(seed: u64, lo: f64, hi: f64) -> Image2d<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Image2d::from_vec(W, H, (0..W * H).map(|_| rng.random_range(lo..hi)).collect())
}

fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 1e-14 * want.abs().max(1e-300)
}

#[test]
fn each_pixel_s_gradient_is_its_own_definition_across_chunks() {
    let (r, mut gt) = (image(1, 0.0, 1.0), image(2, 0.0, 1.0));
    // Some pixels with no error: the L1 subgradient 0 there.
    for p in (0..W * H).step_by(97) {
        gt.data[p] = r.data[p];
    }
    let w = image(3, 0.5, 2.0);
    let (eps, delta) = (1e-3, 1e-6);
    let n = (W * H) as f64;
    let e: Vec<f64> = r.data.iter().zip(&gt.data).map(|(a, b)| a - b).collect();
    let rho: Vec<f64> = e.iter().map(|d| (d * d + eps * eps).sqrt()).collect();

    let (v, g) = l1(&r, &gt);
    let want: f64 = e.iter().map(|d| d.abs()).sum::<f64>() / n;
    assert!((v - want).abs() <= 1e-12 * want, "L1 {v} vs {want}");
    for (p, (&got, &d)) in g.data.iter().zip(&e).enumerate() {
        let s = if d > 0.0 {
            1.0
        } else if d < 0.0 {
            -1.0
        } else {
            0.0
        };
        assert_eq!(got, s / n, "L1 pixel {p}");
    }

    let (v, g) = charbonnier(&r, &gt, eps);
    let want: f64 = rho.iter().sum::<f64>() / n;
    assert!(
        (v - want).abs() <= 1e-12 * want,
        "Charbonnier {v} vs {want}"
    );
    for p in 0..W * H {
        assert!(close(g.data[p], e[p] / rho[p] / n), "Charbonnier pixel {p}");
    }

    for weights in [None, Some(&w)] {
        let wp = |p: usize| weights.map_or(1.0, |w| w.data[p]);
        let (v, g) = weighted_charbonnier(&r, &gt, weights, eps, delta);
        let den = (0..W * H).map(wp).sum::<f64>() + delta;
        let want = (0..W * H).map(|p| wp(p) * rho[p]).sum::<f64>() / den;
        assert!((v - want).abs() <= 1e-12 * want, "weighted {v} vs {want}");
        for p in 0..W * H {
            let want = wp(p) * e[p] / rho[p] / den;
            assert!(
                close(g.data[p], want),
                "weighted pixel {p}: {} vs {want}",
                g.data[p]
            );
        }
    }
}

#[test]
fn every_data_term_refuses_images_of_different_sizes() {
    let r = image(4, 0.0, 1.0);
    // Larger than the render: read past the render's pixels, it would not fail by itself.
    let big = Image2d::filled(W + 1, H, 0.5);
    let tall = Image2d::filled(W, H + 1, 0.5);
    type Case = Box<dyn FnOnce() + std::panic::UnwindSafe>;
    let cases: Vec<(&str, Case)> = vec![
        (
            "L1",
            Box::new({
                let (r, b) = (r.clone(), big.clone());
                move || drop(l1(&r, &b))
            }),
        ),
        (
            "Charbonnier",
            Box::new({
                let (r, b) = (r.clone(), tall.clone());
                move || drop(charbonnier(&r, &b, 1e-3))
            }),
        ),
        (
            "weighted Charbonnier",
            Box::new({
                let (r, b) = (r.clone(), big.clone());
                move || drop(weighted_charbonnier(&r, &b, None, 1e-3, 1e-6))
            }),
        ),
        (
            "weighted Charbonnier weights",
            Box::new({
                let (r, g, w) = (r.clone(), r.clone(), tall.clone());
                move || drop(weighted_charbonnier(&r, &g, Some(&w), 1e-3, 1e-6))
            }),
        ),
    ];
    for (what, f) in cases {
        let msg = panic_text(f).unwrap_or_else(|| panic!("{what}: accepted"));
        assert!(
            msg.starts_with(&format!("{what}: images of different or empty size")),
            "{what}: {msg}"
        );
    }
}
