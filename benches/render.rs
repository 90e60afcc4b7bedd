//! Criterion benchmark of the rasterizer: forward and forward + backward (projection, tile
//! binning, compositing) in f32 on the CT-like scenes of `unispine bench render`
//! (`unispine::bench::render::ct_like_scene`), 10k / 50k / 100k Gaussians at 256 x 256 and 512 x 512.
//! Short measurement time; run with `cargo bench --bench render`. The naive reference and the
//! blend throughput are printed by `unispine bench render`.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use unispine::bench::render::{bench_geometry, ct_like_scene};
use unispine::image2d::Image2d;
use unispine::render::{self, RenderSettings};

fn render_bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("render");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    let st = RenderSettings::default();
    for size in [256usize, 512] {
        for n in [10_000usize, 50_000, 100_000] {
            let g = ct_like_scene(n, 7);
            let cam = bench_geometry(size).camera(0.3);
            let d = Image2d::filled(size, size, 1.0 / (size * size) as f32);
            let id = format!("{n}g-{size}px");
            group.bench_function(BenchmarkId::new("forward", &id), |b| {
                b.iter(|| render::forward(&g, &cam, &st).unwrap())
            });
            group.bench_function(BenchmarkId::new("forward_backward", &id), |b| {
                b.iter(|| {
                    let (img, saved) = render::forward(&g, &cam, &st).unwrap();
                    let gr = render::backward(&g, &cam, &st, &saved, &d);
                    (img, gr)
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, render_bench);
criterion_main!(benches);
