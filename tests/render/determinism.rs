//! Bit-identical image and gradients for 1, 2 and 8 threads: the whole render (projection,
//! tile binning and sort, compositing, backward with the per-tile gradient records reduced in
//! tile order) on a CT-like scene of 3000 Gaussians at 96 x 96, in f32 (the training path) and
//! f64 (the audit path).

use unispine::bench::render::{bench_geometry, ct_like_scene};
use unispine::image2d::Image2d;
use unispine::real::Real;
use unispine::render::{self, ColorMode, RenderSettings};

/// Every output bit of one forward + backward, as u64 words.
fn run<R: Real>(threads: usize, color: ColorMode) -> Vec<u64> {
    let g = ct_like_scene(3000, 3).cast::<R>();
    let size = 96;
    let cam = bench_geometry(size).camera(1.1);
    let st = RenderSettings {
        color,
        active_features: 16,
        background: 0.1,
        ..Default::default()
    };
    let d = Image2d::from_vec(
        size,
        size,
        (0..size * size)
            .map(|k| R::c(((k * 37) % 101) as f64 / 101.0 - 0.4))
            .collect(),
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (img, saved) = render::forward(&g, &cam, &st).unwrap();
        let gr = render::backward(&g, &cam, &st, &saved, &d);
        let p = &gr.params;
        let mut bits: Vec<f64> = img.data.iter().map(|x| x.f64()).collect();
        bits.extend(p.means.iter().flatten().map(|x| x.f64()));
        bits.extend(p.log_scales.iter().flatten().map(|x| x.f64()));
        bits.extend(p.quats.iter().flatten().map(|x| x.f64()));
        bits.extend(p.opacity_logits.iter().map(|x| x.f64()));
        bits.extend(p.features.iter().flatten().map(|x| x.f64()));
        bits.extend(gr.mean2d_ndc_norm.iter().map(|x| x.f64()));
        let mut out: Vec<u64> = bits.iter().map(|x| x.to_bits()).collect();
        out.push(saved.composite.blends);
        out
    })
}

#[test]
fn one_two_and_eight_threads_give_identical_bits() {
    for color in [ColorMode::RirfPaper, ColorMode::Sh] {
        let a32 = run::<f32>(1, color);
        assert!(
            a32[..96 * 96].iter().any(|&b| f64::from_bits(b) > 0.2),
            "scene visible"
        );
        assert!(*a32.last().unwrap() > 100_000, "enough blends to matter");
        for t in [2, 8] {
            assert!(
                a32 == run::<f32>(t, color),
                "f32 {color:?}: {t} threads differ"
            );
        }
        let a64 = run::<f64>(1, color);
        for t in [2, 8] {
            assert!(
                a64 == run::<f64>(t, color),
                "f64 {color:?}: {t} threads differ"
            );
        }
        println!(
            "{color:?}: {} values (image, every gradient, NDC norms, blend count) identical for \
             1, 2, 8 threads in f32 and f64",
            a32.len()
        );
    }
}
