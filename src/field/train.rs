//! The field trainer (SAX-NeRF / NAF `src/trainer.py`, `src/dataset/tigre.py`):
//! - iteration `it` (1-based) uses training projection `(it - 1) mod N` (DataLoader with
//!   batch 1, no shuffle: views in angular order);
//! - `n_rays` pixels drawn without replacement among the pixels with projection > 0 (all of
//!   them when fewer), seeded per iteration; among every pixel with
//!   [`RayPixels::All`] (not an upstream setting);
//! - target: the projection in metres of the [0, 1]-normalised volume, i.e. our line integral
//!   (mm x value) / (1000 x the dataset volume's maximum value; 1 when the dataset has no
//!   volume);
//! - loss: mean over the rays of `(acc - target)^2`; Adam (PyTorch) with StepLR;
//! - a non-finite loss, gradient or parameter stops the run with [`Error::Diverged`] naming
//!   the iteration.
//!
//! Work split: blocks of [`RAYS_PER_BLOCK`] rays run in parallel (samples, encoding, MLP
//! forward and backward, per-block MLP gradient); the blocks' gradients and losses are added in
//! block order, then the encoder gradient is scattered level by level from the saved
//! per-sample encoding gradients. Bit-identical for any thread count. The per-sample buffers
//! (points, encodings, MLP caches, gradients) live in a [`Workspace`] kept by the trainer and
//! are not reallocated once grown; the batch's ray list and pixel permutation still are.

use std::sync::Mutex;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::checkpoint::FieldCheckpoint;
use super::mlp::Cache;
use super::render::{self, Ray, MM};
use super::{Field, FieldConfig, RayPixels};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::geometry::ConeBeam;
use crate::image2d::Image2d;
use crate::loss::LossValue;
use crate::optim::schedule::StepLr;
use crate::optim::FlatAdam;
use crate::real::Real;
use crate::record::{Step, Terms};
use crate::simd::Simd;
use crate::timer::ThreadClock;

/// Rays per parallel block.
pub const RAYS_PER_BLOCK: usize = 8;

/// Stream ids of the seeded generators.
const RNG_PIXELS: u64 = 1;
const RNG_TRAIN_JITTER: u64 = 2;
const RNG_EVAL_JITTER: u64 = 3;

/// How each ray of a batch is sampled: the depth range (t near, t far), the samples per ray,
/// the half-size of the cube the encoders see, and the seeded generator of ray `i`'s
/// stratified jitter.
#[derive(Clone, Copy)]
pub struct Sampling<'a> {
    pub near_far: (f64, f64),
    pub n_samples: usize,
    pub bound: f64,
    pub jitter: &'a (dyn Fn(usize) -> ChaCha8Rng + Sync),
}

impl<'a> Sampling<'a> {
    pub fn new(
        near_far: (f64, f64),
        n_samples: usize,
        bound: f64,
        jitter: &'a (dyn Fn(usize) -> ChaCha8Rng + Sync),
    ) -> Self {
        Sampling {
            near_far,
            n_samples,
            bound,
            jitter,
        }
    }
}

/// Forward + backward of a batch of rays with targets. Returns the loss (mean squared error
/// over the rays) and the gradient of every parameter (a fresh [`Workspace`]; the trainer
/// reuses one through [`Workspace::loss_and_grad`]).
pub fn loss_and_grad<R: Real>(
    field: &Field<R>,
    rays: &[Ray],
    targets: &[R],
    sampling: &Sampling<'_>,
) -> (f64, Vec<R>) {
    let mut ws = Workspace::default();
    let loss = ws.loss_and_grad(Simd::active(), field, rays, targets, sampling);
    (loss, ws.grad)
}

/// The scratch memory of one block on one thread: sample depths and weights, the encoding, the
/// density gradient and the MLP's cache.
#[derive(Debug, Default)]
struct BlockScratch<R> {
    t: Vec<f64>,
    delta: Vec<R>,
    enc: Vec<R>,
    g_mu: Vec<R>,
    mlp: Cache<R>,
}

/// Buffers of [`Workspace::loss_and_grad`], kept across iterations so that an iteration
/// allocates nothing once they have grown: scratch per worker thread, and per block (in
/// block order) its loss, MLP gradient, sample points and encoding gradient.
#[derive(Debug, Default)]
pub struct Workspace<R> {
    scratch: Vec<Mutex<BlockScratch<R>>>,
    loss: Vec<f64>,
    g_mlp: Vec<R>,
    pts: Vec<[R; 3]>,
    g_x: Vec<R>,
    /// The gradient of the last call (encoder parameters, then the MLP's).
    pub grad: Vec<R>,
}

impl<R: Real> Workspace<R> {
    /// Loss and gradient (into [`Workspace::grad`]) of a batch, the MLP products on the
    /// instruction set `simd`.
    pub fn loss_and_grad(
        &mut self,
        simd: Simd,
        field: &Field<R>,
        rays: &[Ray],
        targets: &[R],
        sampling: &Sampling<'_>,
    ) -> f64 {
        self.run(simd, field, rays, targets, sampling, None)
    }

    /// [`Workspace::loss_and_grad`], adding the seconds of each stage (per thread, summed
    /// over the blocks) to `times` when given.
    pub fn run(
        &mut self,
        simd: Simd,
        field: &Field<R>,
        rays: &[Ray],
        targets: &[R],
        sampling: &Sampling<'_>,
        times: Option<&Mutex<StageTimes>>,
    ) -> f64 {
        let Sampling {
            near_far,
            n_samples,
            bound,
            jitter,
        } = *sampling;
        let ne = field.n_encoder_params();
        let nm = field.mlp.n_params;
        let ed = field.encoder.out_dim();
        let b = R::c(rays.len() as f64);
        let want_gx = ne > 0;
        let n_blocks = rays.len().div_ceil(RAYS_PER_BLOCK);
        let n_pts = rays.len() * n_samples;
        let threads = rayon::current_num_threads().max(1);
        if self.scratch.len() < threads {
            self.scratch.resize_with(threads, Default::default);
        }
        self.loss.resize(n_blocks, 0.0);
        self.g_mlp.resize(n_blocks * nm, R::zero());
        self.pts.resize(n_pts, [R::zero(); 3]);
        self.g_x
            .resize(if want_gx { n_pts * ed } else { n_blocks }, R::zero());
        let per_block = RAYS_PER_BLOCK * n_samples;
        let scratch = &self.scratch;
        let mp = &field.params[ne..];
        // Without encoder parameters each block gets a 1-value placeholder.
        let gx_chunk = if want_gx { per_block * ed } else { 1 };
        rays.par_chunks(RAYS_PER_BLOCK)
            .zip(self.loss.par_iter_mut())
            .zip(self.g_mlp.par_chunks_mut(nm.max(1)))
            .zip(self.pts.par_chunks_mut(per_block))
            .zip(self.g_x.par_chunks_mut(gx_chunk))
            .enumerate()
            .for_each(|(bi, ((((chunk, loss), g_mlp), pts), g_x))| {
                let slot = rayon::current_thread_index().unwrap_or(0) % scratch.len();
                let mut guard = crate::par::lock(&scratch[slot]);
                let s = &mut *guard;
                let n = pts.len();
                let mut clock = ThreadClock::new(times.is_some());
                s.delta.resize(n, R::zero());
                for (j, ray) in chunk.iter().enumerate() {
                    let mut rng = jitter(bi * RAYS_PER_BLOCK + j);
                    render::stratified_into(near_far.0, near_far.1, n_samples, &mut rng, &mut s.t);
                    let r = j * n_samples..(j + 1) * n_samples;
                    render::samples_into(ray, &s.t, bound, &mut pts[r.clone()], &mut s.delta[r]);
                }
                let t_sample = clock.lap();
                s.enc.resize(n * ed, R::zero());
                field.encode_into(simd, pts, &mut s.enc);
                let t_encode = clock.lap();
                field.mlp.forward_ws(simd, mp, &s.enc, n, &mut s.mlp);
                let t_fwd = clock.lap();
                let mu = &s.mlp.out;
                s.g_mu.resize(n, R::zero());
                let mut l = 0.0;
                for j in 0..chunk.len() {
                    let r = j * n_samples..(j + 1) * n_samples;
                    let acc = render::line_integral(&mu[r.clone()], &s.delta[r.clone()]);
                    let res = acc - targets[bi * RAYS_PER_BLOCK + j];
                    l += res.f64() * res.f64();
                    let g_acc = R::c(2.0) * res / b;
                    render::line_integral_vjp(g_acc, &s.delta[r.clone()], &mut s.g_mu[r]);
                }
                *loss = l;
                let t_render = clock.lap();
                g_mlp.iter_mut().for_each(|v| *v = R::zero());
                let gx = want_gx.then_some(&mut g_x[..]);
                field
                    .mlp
                    .backward_ws(simd, mp, &mut s.mlp, &s.g_mu, n, g_mlp, gx);
                let t_bwd = clock.lap();
                if let Some(tm) = times {
                    let mut tm = crate::par::lock(tm);
                    tm.sample += t_sample;
                    tm.encode += t_encode;
                    tm.mlp_forward += t_fwd;
                    tm.render += t_render;
                    tm.mlp_backward += t_bwd;
                }
            });
        self.grad.resize(ne + nm, R::zero());
        self.grad.iter_mut().for_each(|v| *v = R::zero());
        let mut loss = 0.0;
        for (l, g) in self.loss.iter().zip(self.g_mlp.chunks(nm.max(1))) {
            loss += *l;
            for (a, &gv) in self.grad[ne..].iter_mut().zip(g) {
                *a += gv;
            }
        }
        if want_gx {
            let t0 = Instant::now();
            field.encoder.backward(
                simd,
                &field.params[..ne],
                &self.pts,
                &self.g_x,
                ed,
                0,
                &mut self.grad[..ne],
            );
            if let Some(tm) = times {
                crate::par::lock(tm).encode_backward += t0.elapsed().as_secs_f64();
            }
        }
        loss / rays.len() as f64
    }
}

/// Seconds spent in each stage of [`Workspace::run`] (summed over blocks and threads, so
/// CPU seconds; the encoder backward is wall time of its level-parallel scatter).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StageTimes {
    pub sample: f64,
    pub encode: f64,
    pub mlp_forward: f64,
    pub render: f64,
    pub mlp_backward: f64,
    pub encode_backward: f64,
}

/// Line integrals (metres x normalised value) along `rays`, sampled as `sampling` says.
pub fn render_rays<R: Real>(field: &Field<R>, rays: &[Ray], sampling: &Sampling<'_>) -> Vec<R> {
    let (n_samples, (near, far)) = (sampling.n_samples, sampling.near_far);
    rays.par_chunks(RAYS_PER_BLOCK)
        .enumerate()
        .flat_map_iter(|(bi, chunk)| {
            let mut pts = Vec::with_capacity(chunk.len() * n_samples);
            let mut delta = Vec::with_capacity(chunk.len() * n_samples);
            for (j, ray) in chunk.iter().enumerate() {
                let mut rng = (sampling.jitter)(bi * RAYS_PER_BLOCK + j);
                let t = render::stratified(near, far, n_samples, &mut rng);
                render::samples(ray, &t, sampling.bound, &mut pts, &mut delta);
            }
            let mu = field.density(&pts);
            (0..chunk.len())
                .map(|j| {
                    let s = j * n_samples..(j + 1) * n_samples;
                    render::line_integral(&mu[s.clone()], &delta[s])
                })
                .collect::<Vec<R>>()
        })
        .collect()
}

/// The scale from a line integral in metres of the normalised volume to the dataset's units:
/// `1000 x` the volume's maximum (1000 when the dataset has no volume or its maximum is not
/// positive).
pub fn unit_scale(ds: &Dataset) -> f64 {
    let vmax = ds
        .volume
        .as_ref()
        .map(|v| v.data.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64)
        .filter(|m| m.is_finite() && *m > 0.0)
        .unwrap_or(1.0);
    MM * vmax
}

/// Render a whole view in the dataset's units.
pub fn render_view(
    field: &Field<f32>,
    cfg: &FieldConfig,
    geo: &ConeBeam,
    angle: f64,
    view_id: u64,
    scale: f64,
) -> Image2d<f32> {
    let cam = geo.camera(angle);
    let (w, h) = (cam.width, cam.height);
    let rays: Vec<Ray> = (0..h)
        .flat_map(|r| (0..w).map(move |c| (c, r)))
        .map(|(c, r)| render::pixel_ray(&cam, c, r))
        .collect();
    let seed = cfg.seed;
    let acc = render_rays(
        field,
        &rays,
        &Sampling::new(render::near_far(geo), cfg.n_samples, cfg.bound, &|i| {
            render::ray_rng(seed, RNG_EVAL_JITTER, view_id, i as u64)
        }),
    );
    Image2d::from_vec(
        w,
        h,
        acc.iter().map(|&a| (a as f64 * scale) as f32).collect(),
    )
}

/// The training state.
pub struct FieldTrainer<'a> {
    pub cfg: FieldConfig,
    pub ds: &'a Dataset,
    pub field: Field<f32>,
    pub adam: FlatAdam<f32>,
    pub sched: StepLr,
    pub iteration: usize,
    /// Per training view: indices of the pixels rays are drawn from (projection > 0, or all).
    valid: Vec<Vec<u32>>,
    scale: f64,
    near_far: (f64, f64),
    /// Buffers reused by every iteration.
    pub work: Workspace<f32>,
}

impl<'a> FieldTrainer<'a> {
    /// Set up a run (validates the settings and the dataset).
    pub fn new(cfg: FieldConfig, ds: &'a Dataset) -> Result<Self> {
        cfg.validate()?;
        crate::dataset::store::check(ds)?;
        if ds.geometry.mode != crate::geometry::Mode::Cone {
            return Err(Error::invalid(
                "mode",
                "the field trainer needs a cone-beam geometry (NAF rays)",
            ));
        }
        let field = Field::<f32>::new(&cfg)?;
        let valid: Vec<Vec<u32>> = ds
            .train
            .projections
            .iter()
            .map(|p| {
                (0..p.data.len() as u32)
                    .filter(|&i| cfg.ray_pixels == RayPixels::All || p.data[i as usize] > 0.0)
                    .collect()
            })
            .collect();
        if let Some(k) = valid.iter().position(|v| v.is_empty()) {
            return Err(Error::invalid(
                format!("train projection {k}"),
                "no pixel with a positive value: nothing to sample rays from",
            ));
        }
        Ok(FieldTrainer {
            adam: FlatAdam::new(field.params.len()),
            sched: StepLr {
                lr0: cfg.lr,
                step: cfg.lr_step,
                gamma: cfg.lr_gamma,
            },
            scale: unit_scale(ds),
            near_far: render::near_far(&ds.geometry),
            cfg,
            ds,
            field,
            iteration: 0,
            valid,
            work: Workspace::default(),
        })
    }

    /// The rays and targets of iteration `it`.
    pub fn batch(&self, it: usize) -> (usize, Vec<Ray>, Vec<f32>) {
        let nv = self.ds.train.angles.len();
        let view = (it - 1) % nv;
        let valid = &self.valid[view];
        let k = self.cfg.n_rays.min(valid.len());
        let mut rng = ChaCha8Rng::seed_from_u64(self.cfg.seed ^ 0x0a1f_0000_0000_0000);
        rng.set_stream(RNG_PIXELS.wrapping_mul(1 << 40) ^ it as u64);
        // Partial Fisher-Yates: the first k of a seeded permutation.
        let mut idx = valid.clone();
        for i in 0..k {
            let j = rng.random_range(i..idx.len());
            idx.swap(i, j);
        }
        let cam = self.ds.train_camera(view);
        let proj = &self.ds.train.projections[view];
        let w = proj.width;
        let rays = idx[..k]
            .iter()
            .map(|&p| render::pixel_ray(&cam, p as usize % w, p as usize / w))
            .collect();
        let targets = idx[..k]
            .iter()
            .map(|&p| (proj.data[p as usize] as f64 / self.scale) as f32)
            .collect();
        (view, rays, targets)
    }

    /// Run iteration `self.iteration + 1`.
    pub fn step(&mut self) -> Result<Step> {
        let it = self.iteration + 1;
        let (view, rays, targets) = self.batch(it);
        let seed = self.cfg.seed;
        let loss = self.work.loss_and_grad(
            Simd::active(),
            &self.field,
            &rays,
            &targets,
            &Sampling::new(self.near_far, self.cfg.n_samples, self.cfg.bound, &|i| {
                render::ray_rng(seed, RNG_TRAIN_JITTER, it as u64, i as u64)
            }),
        );
        let grad = &self.work.grad;
        let diverged = |what: String| Error::Diverged {
            iteration: it,
            what,
        };
        if !loss.is_finite() {
            return Err(diverged(format!("loss is {loss} on training view {view}")));
        }
        if let Some(i) = grad.iter().position(|g| !g.is_finite()) {
            return Err(diverged(format!(
                "gradient of parameter {i} is {} on training view {view}",
                grad[i]
            )));
        }
        let lr = self.sched.at(it);
        self.adam.update(&mut self.field.params, grad, lr);
        if let Some(i) = self.field.params.iter().position(|p| !p.is_finite()) {
            return Err(diverged(format!("parameter {i} became non-finite")));
        }
        self.iteration = it;
        Ok(Step {
            iteration: it,
            view,
            loss: LossValue {
                total: loss,
                data: loss,
                ssim: 0.0,
            },
            terms: Terms::Loss,
            // 10 log10(1 / loss), the loss in (metres x normalised value)^2.
            psnr: -10.0 * loss.max(1e-30).log10(),
            lr,
            n_gaussians: 0,
            eval: None,
            densified: None,
        })
    }

    /// The state after the iterations done, with the training time and log so far.
    pub fn checkpoint(&self, train_time_s: f64, log: &str) -> FieldCheckpoint {
        FieldCheckpoint {
            iteration: self.iteration,
            train_time_s,
            log: log.to_string(),
            params: self.field.params.clone(),
            adam_m: self.adam.m.clone(),
            adam_v: self.adam.v.clone(),
            adam_step: self.adam.step,
        }
    }

    /// Continue from `c` (read for this run's config: [`FieldCheckpoint::from_bytes`] checked
    /// its sizes).
    pub fn restore(&mut self, c: &FieldCheckpoint) {
        self.iteration = c.iteration;
        self.field.params.clone_from(&c.params);
        self.adam.m.clone_from(&c.adam_m);
        self.adam.v.clone_from(&c.adam_v);
        self.adam.step = c.adam_step;
    }

    /// Render test view `k` in the dataset's units.
    pub fn render_test(&self, k: usize) -> Image2d<f32> {
        render_view(
            &self.field,
            &self.cfg,
            &self.ds.geometry,
            self.ds.test.angles[k],
            k as u64,
            self.scale,
        )
    }

    /// The test views evaluated (every `eval_stride`-th).
    pub fn eval_views(&self) -> Vec<usize> {
        (0..self.ds.test.angles.len())
            .step_by(self.cfg.eval_stride)
            .collect()
    }
}

#[cfg(test)]
mod tests;
