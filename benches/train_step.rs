//! One full training iteration of the `unispine` method (render, loss with SPWM weights,
//! backward, Adam) at a 256 x 256 detector with about 50k Gaussians (ACUI grid 37^3 = 50,653).
//!
//! The targets are smooth synthetic images (no projector needed); densification is off so every
//! iteration does the same work, and the iteration counter starts at 5000 so the SPWM weights
//! are in their warm-up (alpha_eff = 0.48). Run with
//! `cargo bench --bench train_step -- --measurement-time 20`.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use unispine::dataset::{Dataset, Manifest, Split};
use unispine::geometry::ConeBeam;
use unispine::image2d::Image2d;
use unispine::train::{Method, TrainConfig, Trainer};

fn dataset() -> Dataset {
    let n = 256;
    let geo = ConeBeam::centred([n, n], [0.85, 0.85], [296, 296, 296], [120.0 / 296.0; 3]);
    let img = |k: usize| {
        let mut d = vec![0.0f32; n * n];
        for r in 0..n {
            for c in 0..n {
                let (x, y) = (c as f32 / n as f32 - 0.5, r as f32 / n as f32 - 0.5);
                d[r * n + c] = (1.0 - 4.0 * (x * x + y * y)).max(0.0)
                    * (1.0 + 0.3 * (20.0 * y + k as f32).sin());
            }
        }
        Image2d::from_vec(n, n, d)
    };
    let pi = std::f64::consts::PI;
    let split = |m: usize, off: f64| Split {
        angles: (0..m).map(|k| (k as f64 + off) * pi / m as f64).collect(),
        projections: (0..m).map(img).collect(),
    };
    Dataset {
        geometry: geo,
        train: split(8, 0.0),
        test: split(2, 0.5),
        manifest: Manifest::default(),
        volume: None,
    }
}

fn bench(c: &mut Criterion) {
    let ds = dataset();
    let mut cfg = TrainConfig::preset(Method::Unispine);
    cfg.iterations = 1_000_000;
    cfg.densify.until_iter = 0;
    cfg.eval_iterations = vec![];
    let mut tr = Trainer::new(cfg, &ds).unwrap();
    tr.iteration = 5000;
    eprintln!("{} Gaussians, 256 x 256", tr.state.len());
    let mut g = c.benchmark_group("train_step");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    g.bench_function("unispine_256px_50k", |b| b.iter(|| tr.step().unwrap()));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
