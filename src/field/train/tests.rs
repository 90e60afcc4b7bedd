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
    let opts = GenerateOptions {
        train_views: 2,
        test_views: 1,
        detector: 16,
        ..Default::default()
    };
    generate(&vol, &opts, &|_, _| {}).unwrap()
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
