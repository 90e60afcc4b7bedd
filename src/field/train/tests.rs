//! The field trainer's batches, units and views.

use super::*;
use crate::dataset::generate::{generate, GenerateOptions};

/// A small cube in the middle of an empty volume: views with background pixels.
fn dataset() -> Dataset {
    let mut vol = crate::volume::Volume::<f32>::zeros([16, 16, 16], [4.0; 3]);
    for z in 6..10 {
        for y in 6..10 {
            for x in 6..10 {
                vol.data[(z * 16 + y) * 16 + x] = 0.02;
            }
        }
    }
    views_of(&vol, 2)
}

/// `train_views` training views and one test view of `vol` on a 16 x 16 detector.
fn views_of(vol: &crate::volume::Volume<f32>, train_views: usize) -> Dataset {
    let opts = GenerateOptions {
        train_views,
        test_views: 1,
        detector: 16,
        ..Default::default()
    };
    generate(vol, &opts, &|_, _| {}).unwrap()
}

/// The dataset's units per (metre x normalised value): 1000 mm per metre times the volume's
/// largest value, or 1000 when there is no volume or its largest value is not a positive
/// finite number.
#[test]
fn unit_scale_is_a_thousand_times_the_volume_s_maximum() {
    let mut ds = dataset();
    let with_max = |ds: &mut Dataset, vals: &[f32]| {
        let v = ds.volume.as_mut().unwrap();
        v.data.iter_mut().for_each(|x| *x = 0.0);
        v.data[..vals.len()].copy_from_slice(vals);
        unit_scale(ds)
    };
    assert_eq!(with_max(&mut ds, &[0.25, -3.0, 0.5]), 500.0);
    assert_eq!(with_max(&mut ds, &[-0.5]), 1000.0); // the maximum is 0
    ds.volume
        .as_mut()
        .unwrap()
        .data
        .iter_mut()
        .for_each(|x| *x = -0.5);
    assert_eq!(unit_scale(&ds), 1000.0);
    assert_eq!(with_max(&mut ds, &[f32::INFINITY]), 1000.0);
    ds.volume = None;
    assert_eq!(unit_scale(&ds), 1000.0);
}

/// A rendered view is the line integrals of its pixel rays, each times the dataset's
/// scale: the same view at two scales differs by their ratio, pixel by pixel.
#[test]
fn render_view_scales_every_pixel() {
    let ds = dataset();
    let mut cfg = FieldConfig::preset("naf", 2).unwrap();
    cfg.hidden_dim = 8;
    cfg.num_layers = 3;
    cfg.skips = vec![];
    cfg.n_samples = 8;
    let field = Field::<f32>::new(&cfg).unwrap();
    let at = |scale| render_view(&field, &cfg, &ds.geometry, 0.3, 1, scale);
    let (one, big) = (at(1.0), at(1000.0));
    assert_eq!((one.width, one.height), (16, 16));
    assert!(
        one.data.iter().any(|&v| v > 1e-4),
        "an empty view tells nothing"
    );
    for (i, (a, b)) in one.data.iter().zip(&big.data).enumerate() {
        assert!(
            (b - 1000.0 * a).abs() <= 1e-6 * b.abs().max(1e-30),
            "pixel {i}: {b} against 1000 x {a}"
        );
    }
}

#[test]
fn rays_come_from_positive_pixels_or_from_all() {
    let ds = dataset();
    let proj = &ds.train.projections[0];
    let n_pix = proj.data.len();
    let n_pos = proj.data.iter().filter(|&&v| v > 0.0).count();
    assert!(0 < n_pos && n_pos < n_pix / 2, "{n_pos} of {n_pix}");
    let mut cfg = FieldConfig::preset("intratomo", 2).unwrap();
    // More rays than pixels: a batch is every pixel it may draw from.
    cfg.n_rays = 10 * n_pix;
    let tr = FieldTrainer::new(cfg.clone(), &ds).unwrap();
    let (view, rays, targets) = tr.batch(1);
    assert_eq!((view, rays.len()), (0, n_pos));
    assert!(targets.iter().all(|&t| t > 0.0));
    cfg.ray_pixels = RayPixels::All;
    let tr = FieldTrainer::new(cfg.clone(), &ds).unwrap();
    let (_, rays, targets) = tr.batch(1);
    assert_eq!(rays.len(), n_pix);
    assert_eq!(targets.iter().filter(|&&t| t > 0.0).count(), n_pos);
    // The upstream default is not written to config.json (older configurations read and
    // hash the same); `all` is, and reads back.
    let mut up = cfg.clone();
    up.ray_pixels = RayPixels::Positive;
    let json = serde_json::to_string(&up).unwrap();
    assert!(!json.contains("ray_pixels"), "{json}");
    let json = serde_json::to_string(&cfg).unwrap();
    assert!(json.contains("\"ray_pixels\":\"all\""), "{json}");
    let back: FieldConfig = serde_json::from_str(&json).unwrap();
    assert_eq!(back, cfg);
    assert_eq!(cfg.label(), "intratomo (reduced, all pixels)");
}

/// Iteration `it` draws from training view `(it - 1) mod views` the first `n_rays` of a
/// permutation of that view's positive pixels, shuffled by a partial Fisher-Yates with the
/// ChaCha8 generator of seed `seed ^ 0x0a1f << 48` on stream `2^40 ^ it` (pixel-stream number 1
/// times 2^40): written out here from that description.
#[test]
fn a_batch_is_a_seeded_partial_permutation_of_its_view_s_positive_pixels() {
    let mut vol = crate::volume::Volume::<f32>::zeros([16, 16, 16], [4.0; 3]);
    for (i, v) in vol.data.iter_mut().enumerate() {
        // An uneven blob, so that the three views differ.
        let (x, y, z) = (i % 16, i / 16 % 16, i / 256);
        if (5..11).contains(&x) && (6..10).contains(&y) && (4..12).contains(&z) {
            *v = 0.01 + (x * y) as f32 * 1e-4;
        }
    }
    let ds = views_of(&vol, 3);
    let mut cfg = FieldConfig::preset("intratomo", 3).unwrap();
    cfg.n_rays = 7;
    // Bits shared with the stream constant, so that `^` differs from `|` and `&`.
    cfg.seed = 0x0a00_0000_0000_0007;
    let tr = FieldTrainer::new(cfg.clone(), &ds).unwrap();
    let scale = unit_scale(&ds);
    let mut drawn = Vec::new();
    for it in 1..=5usize {
        let (view, rays, targets) = tr.batch(it);
        assert_eq!(view, (it - 1) % 3, "iteration {it}");
        let proj = &ds.train.projections[view];
        let mut idx: Vec<usize> = (0..proj.data.len())
            .filter(|&p| proj.data[p] > 0.0)
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(0x0a00_0000_0000_0007 ^ 0x0a1f_0000_0000_0000);
        rng.set_stream((1u64 << 40) ^ it as u64);
        for i in 0..7 {
            let j = rng.random_range(i..idx.len());
            idx.swap(i, j);
        }
        let cam = ds.train_camera(view);
        let w = proj.width;
        let want_rays: Vec<Ray> = idx[..7]
            .iter()
            .map(|&p| render::pixel_ray(&cam, p % w, p / w))
            .collect();
        let want_targets: Vec<f32> = idx[..7]
            .iter()
            .map(|&p| (proj.data[p] as f64 / scale) as f32)
            .collect();
        assert_eq!(rays, want_rays, "iteration {it}");
        assert_eq!(targets, want_targets, "iteration {it}");
        drawn.push(idx[..7].to_vec());
    }
    // Iterations 1 and 4 use the same view and draw other pixels.
    assert_ne!(drawn[0], drawn[3]);
}

/// A trainer restored from another's checkpoint continues with the same bits; each step reports
/// PSNR = -10 log10(loss); the evaluated test views are every `eval_stride`-th.
#[test]
fn a_restored_trainer_continues_with_the_same_bits() {
    let ds = dataset();
    let mut cfg = FieldConfig::preset("naf", 2).unwrap();
    cfg.hidden_dim = 8;
    cfg.n_rays = 16;
    cfg.n_samples = 8;
    let mut a = FieldTrainer::new(cfg.clone(), &ds).unwrap();
    for _ in 0..3 {
        let s = a.step().unwrap();
        assert_eq!(s.psnr, -10.0 * s.loss.total.log10(), "{s:?}");
        assert!(s.loss.total > 0.0);
    }
    let c = a.checkpoint(1.5, "log");
    let mut b = FieldTrainer::new(cfg.clone(), &ds).unwrap();
    assert_ne!(b.field.params, a.field.params);
    b.restore(&c);
    assert_eq!(b.iteration, 3);
    let (sa, sb) = (a.step().unwrap(), b.step().unwrap());
    assert_eq!(sa.iteration, 4);
    assert_eq!(sa.loss.total.to_bits(), sb.loss.total.to_bits());
    let bits = |t: &FieldTrainer| {
        t.field
            .params
            .iter()
            .map(|p| p.to_bits())
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(a.adam.step, b.adam.step);
    assert_eq!(a.eval_views(), [0]);
    let mut five = cfg;
    five.eval_stride = 5;
    let mut ds12 = dataset();
    let t = ds12.test.clone();
    ds12.test.angles = (0..12).map(|i| i as f64 * 0.1).collect();
    ds12.test.projections = vec![t.projections[0].clone(); 12];
    let t12 = FieldTrainer::new(five, &ds12).unwrap();
    assert_eq!(t12.eval_views(), [0, 5, 10]);
}
