//! The measurements of `unispine bench field`: the machine's peak f32 rate, the MLP's matrix
//! products at the NAF and NeRF widths against it, the per-iteration time of each field preset
//! split into stages, and the peak memory of the full NAF configuration.
//!
//! Inputs are synthetic but shaped like a training iteration: the rays of random pixels of a
//! 128 x 128 cone-beam view of the 256 mm benchmark box ([`crate::bench::render::bench_geometry`]),
//! random targets, a freshly initialised field. Every figure is a time measured in the calling
//! process; the ratios are formed by the caller from figures of the same run.

use std::sync::Mutex;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::timed;
use crate::bench::render::bench_geometry;
use crate::error::Result;
use crate::field::mlp::Cache;
use crate::field::render::{self, Ray};
use crate::field::train::{Sampling, StageTimes, Workspace, RAYS_PER_BLOCK};
use crate::field::{Field, FieldConfig};
use crate::optim::FlatAdam;
use crate::simd::Simd;

/// The peak of [`crate::simd::peak_run`] on `threads` threads: `(flops, wall s, cpu s)`.
pub fn peak(simd: Simd, threads: usize, iters: u64) -> (f64, f64, f64) {
    let (f, w, c) = timed(|| crate::simd::peak_run(simd, threads, iters));
    (f as f64, w, c)
}

/// One MLP measurement: floating-point operations and the best wall / CPU seconds of `reps`.
#[derive(Clone, Debug)]
pub struct MlpTiming {
    pub rows: usize,
    pub flops: f64,
    pub wall: f64,
    pub cpu: f64,
}

/// Forward + backward (dW, db and dX of every layer, as in training) of the MLP of `cfg` over
/// `rays x samples` rows, in blocks of [`RAYS_PER_BLOCK`] rays run in parallel as the trainer
/// does, with the instruction set `simd`; the best of `reps`.
pub fn time_mlp(cfg: &FieldConfig, simd: Simd, reps: usize) -> Result<MlpTiming> {
    let field = Field::<f32>::new(cfg)?;
    let mlp = &field.mlp;
    let mp = &field.params[field.n_encoder_params()..];
    let rows = cfg.n_rays * cfg.n_samples;
    let block = RAYS_PER_BLOCK * cfg.n_samples;
    let ed = mlp.in_dim;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let x: Vec<f32> = (0..rows * ed)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let gy: Vec<f32> = (0..rows).map(|_| rng.random_range(-1e-3..1e-3)).collect();
    let n_blocks = rows.div_ceil(block);
    let mut grads = vec![0.0f32; n_blocks * mlp.n_params];
    let mut gx = vec![0.0f32; rows * ed];
    let ws: Vec<Mutex<Cache<f32>>> = (0..rayon::current_num_threads())
        .map(|_| Mutex::default())
        .collect();
    let mut best = (f64::INFINITY, f64::NAN);
    for _ in 0..reps.max(1) + 1 {
        let (_, wall, cpu) = timed(|| {
            x.par_chunks(block * ed)
                .zip(gy.par_chunks(block))
                .zip(grads.par_chunks_mut(mlp.n_params))
                .zip(gx.par_chunks_mut(block * ed))
                .for_each(|(((xb, gb), g), gxb)| {
                    let slot = rayon::current_thread_index().unwrap_or(0) % ws.len();
                    let mut c = crate::par::lock(&ws[slot]);
                    let n = gb.len();
                    mlp.forward_ws(simd, mp, xb, n, &mut c);
                    g.iter_mut().for_each(|v| *v = 0.0);
                    mlp.backward_ws(simd, mp, &mut c, gb, n, g, Some(gxb));
                })
        });
        // The first pass grows the buffers; it is not counted.
        if best.0.is_infinite() {
            best = (f64::MAX, f64::NAN);
        } else if wall < best.0 {
            best = (wall, cpu);
        }
    }
    let flops: f64 = mlp
        .shape
        .iter()
        .map(|&(i, o, _)| 3 * crate::field::gemm::flops(rows, i, o))
        .sum::<u64>() as f64;
    Ok(MlpTiming {
        rows,
        flops,
        wall: best.0,
        cpu: best.1,
    })
}

/// Per-iteration stage times of one preset (seconds): the [`StageTimes`] of the loss and
/// gradient (CPU seconds summed over the threads), Adam, and the wall time of whole
/// iterations (the mean over `iters`, after one iteration that grows the buffers).
#[derive(Clone, Debug)]
pub struct IterTiming {
    pub stages: StageTimes,
    pub adam: f64,
    pub wall: f64,
    pub cpu: f64,
    pub samples: usize,
}

/// Time `iters` training iterations (loss, gradient, Adam) of `cfg`.
pub fn time_iteration(cfg: &FieldConfig, simd: Simd, iters: usize) -> Result<IterTiming> {
    let mut field = Field::<f32>::new(cfg)?;
    let geo = bench_geometry(128);
    let nf = render::near_far(&geo);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let cams: Vec<_> = (0..4).map(|k| geo.camera(k as f64 * 0.7)).collect();
    let batch = |it: usize, rng: &mut ChaCha8Rng| -> (Vec<Ray>, Vec<f32>) {
        let cam = &cams[it % cams.len()];
        let rays = (0..cfg.n_rays)
            .map(|_| {
                let (c, r) = (rng.random_range(0..128), rng.random_range(0..128));
                render::pixel_ray(cam, c, r)
            })
            .collect();
        let t = (0..cfg.n_rays)
            .map(|_| rng.random_range(0.0..0.05))
            .collect();
        (rays, t)
    };
    let mut adam = FlatAdam::<f32>::new(field.params.len());
    let mut ws = Workspace::<f32>::default();
    let times = Mutex::new(StageTimes::default());
    let (mut adam_s, mut wall, mut cpu) = (0.0, 0.0, 0.0);
    for it in 0..iters.max(1) + 1 {
        let (rays, targets) = batch(it, &mut rng);
        let seed = cfg.seed;
        let jitter = |i: usize| render::ray_rng(seed, 2, it as u64, i as u64);
        let warm = it == 0;
        let ((), w, c) = timed(|| {
            ws.run(
                simd,
                &field,
                &rays,
                &targets,
                &Sampling::new(nf, cfg.n_samples, cfg.bound, &jitter),
                (!warm).then_some(&times),
            );
        });
        let ((), wa, ca) = timed(|| adam.update(&mut field.params, &ws.grad, 1e-3));
        if !warm {
            adam_s += wa;
            wall += w + wa;
            cpu += c + ca;
        }
    }
    let k = iters.max(1) as f64;
    let s = times.into_inner().unwrap_or_else(|e| e.into_inner());
    Ok(IterTiming {
        stages: StageTimes {
            sample: s.sample / k,
            encode: s.encode / k,
            mlp_forward: s.mlp_forward / k,
            render: s.render / k,
            mlp_backward: s.mlp_backward / k,
            encode_backward: s.encode_backward / k,
        },
        adam: adam_s / k,
        wall: wall / k,
        cpu: cpu / k,
        samples: cfg.n_rays * cfg.n_samples,
    })
}
