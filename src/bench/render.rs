//! Benchmark scenes and timings, printed by `unispine bench` and used by the criterion benches
//! and the determinism tests.
//!
//! - [`ct_like_scene`] on [`bench_geometry`]: Gaussians filling a CT-like volume box;
//! - [`time_render`]: forward and forward + backward of the rasterizer (projection, Eq. 3, and
//!   compositing, Eqs. 4-5) in f32, median times and Gaussian-pixel blends, and the CPU and
//!   wall time of each phase ([`RenderPhases`]) with the lanes the tile kernels evaluated;
//! - [`time_naive`]: the same throughput of the naive per-pixel reference
//!   ([`crate::render::composite::naive_forward`], every Gaussian tested at every pixel).

use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::median;
use crate::gaussians::model::N_FEATURES;
use crate::gaussians::Gaussians;
use crate::geometry::ConeBeam;
use crate::image2d::Image2d;
use crate::render::composite::{KernelWork, Phase};
use crate::render::{self, composite, RenderSettings};

/// Side of the CT-like volume box, mm.
pub const BOX_MM: f64 = 256.0;

/// Allowed ranges of the render benchmark's cases: Gaussian counts, square detector sizes
/// (pixels per side) and repetitions. A case beyond them needs more memory than a workstation
/// has (a Gaussian with its gradient and render state takes about 1 KiB) or never ends.
pub const BENCH_GAUSSIANS: (usize, usize) = (1, 2_000_000);
pub const BENCH_SIZES: (usize, usize) = (1, 4096);
pub const BENCH_REPS: (usize, usize) = (1, 1000);

/// Check the render benchmark's cases against [`BENCH_GAUSSIANS`], [`BENCH_SIZES`] and
/// [`BENCH_REPS`]; the error names the flag, the value and the allowed range.
pub fn check_render_cases(gaussians: &[usize], sizes: &[usize], reps: usize) -> crate::Result<()> {
    let check = |flag: &str, values: &[usize], (lo, hi): (usize, usize)| {
        if values.is_empty() {
            return Err(crate::Error::invalid(flag, "needs at least one value"));
        }
        match values.iter().find(|&&v| v < lo || v > hi) {
            Some(v) => Err(crate::Error::invalid(
                flag,
                format!("{v} is outside the allowed range [{lo}, {hi}]"),
            )),
            None => Ok(()),
        }
    };
    check("--gaussians", gaussians, BENCH_GAUSSIANS)?;
    check("--sizes", sizes, BENCH_SIZES)?;
    check("--reps", &[reps], BENCH_REPS)
}

/// Cone-beam geometry of the benchmark: DSD 1500 mm, DSO 1000 mm, a `size` x `size` detector
/// whose field of view covers the 256 mm box with margin (420 mm at the detector).
pub fn bench_geometry(size: usize) -> ConeBeam {
    let pitch = 420.0 / size as f64;
    ConeBeam::centred(
        [size, size],
        [pitch, pitch],
        [128, 128, 128],
        [BOX_MM / 128.0; 3],
    )
}

/// `n` Gaussians filling the 256 mm box around the isocentre like a model of a CT volume
/// (seeded): positions uniform in the box, scales log-uniform in [0.3, 0.8] x the mean spacing
/// (box / n^(1/3)) per axis, random rotations, opacities sigmoid(U(-3, 0)) (0.05-0.5), features
/// giving intensities around 0.5.
pub fn ct_like_scene(n: usize, seed: u64) -> Gaussians<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let spacing = BOX_MM / (n.max(1) as f64).cbrt();
    let mut g = Gaussians::<f64>::zeros(n);
    for i in 0..n {
        g.means[i] = std::array::from_fn(|_| rng.random_range(-0.5..0.5) * BOX_MM);
        g.log_scales[i] = std::array::from_fn(|_| (spacing * rng.random_range(0.3f64..0.8)).ln());
        g.quats[i] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        g.quats[i][0] += 0.5;
        g.opacity_logits[i] = rng.random_range(-3.0..0.0);
        g.features[i] = std::array::from_fn(|k| {
            if k == 0 {
                rng.random_range(-0.5..0.5)
            } else {
                rng.random_range(-0.05..0.05)
            }
        });
    }
    debug_assert_eq!(g.features[0].len(), N_FEATURES);
    g.cast()
}

/// Timings of one render benchmark case.
#[derive(Clone, Copy, Debug)]
pub struct RenderTiming {
    pub gaussians: usize,
    pub size: usize,
    /// Median forward time (projection + compositing), s.
    pub forward: f64,
    /// Median forward + backward time, s.
    pub forward_backward: f64,
    /// Blends (pixel, Gaussian pairs composited) of one forward pass.
    pub blends: u64,
    /// Process CPU time (all threads) per forward + backward, s (Linux; None elsewhere). On a
    /// shared machine this is less sensitive to other load than the wall time.
    pub cpu_forward_backward: Option<f64>,
    /// Per-phase times and kernel work, measured in separate reps after the timed ones.
    pub phases: RenderPhases,
}

/// Names of the rasterizer's phases in [`RenderPhases::cpu`] and [`RenderPhases::wall`], in
/// the order they run: projection, tile binning and depth sort side by side with the per-splat
/// packing, forward tile kernels, image assembly, backward tile kernels, what is left of the
/// gradient reduction after them, projection backward to the Gaussian parameters.
pub const RENDER_PHASES: [&str; 7] = [
    "project",
    "bin + pack",
    "forward tiles",
    "assemble",
    "backward tiles",
    "reduce",
    "project bwd",
];

/// Mean time per forward + backward of each of [`RENDER_PHASES`], and the work of the tile
/// kernels.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderPhases {
    /// Process CPU time (all threads), s.
    pub cpu: [f64; 7],
    /// Wall time, s.
    pub wall: [f64; 7],
    /// Work of the forward and of the backward tile kernels in one pass.
    pub forward_work: KernelWork,
    pub backward_work: KernelWork,
}

/// Mean per-phase CPU and wall times of `reps` forward + backward passes ([`RenderPhases`]).
fn time_phases(
    g: &Gaussians<f32>,
    cam: &crate::geometry::Camera,
    st: &RenderSettings,
    d: &Image2d<f32>,
    reps: usize,
) -> crate::Result<RenderPhases> {
    use crate::timer::cpu_seconds;
    let now = || (cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID), Instant::now());
    let mut ph = RenderPhases::default();
    for _ in 0..reps.max(1) {
        // Times at the start and at the end of each phase, in order.
        let mut marks = vec![now()];
        let (splats, ps) = render::project::forward(g, cam, st)?;
        marks.push(now());
        let mut probe = |_: Phase| marks.push(now());
        let bg = st.background as f32;
        let (img, cs) = composite::forward_probed(&splats, cam.width, cam.height, bg, &mut probe);
        let (ds, bw) = composite::backward_probed(&splats, &cs, d, &mut probe);
        let params = render::project::backward(g, cam, st, &splats, &ps, &ds);
        marks.push(now());
        std::hint::black_box((&img, &params));
        assert_eq!(marks.len(), RENDER_PHASES.len() + 1, "one mark per phase");
        for (k, m) in marks.windows(2).enumerate() {
            ph.cpu[k] += m[1].0 - m[0].0;
            ph.wall[k] += (m[1].1 - m[0].1).as_secs_f64();
        }
        ph.forward_work = cs.forward_work;
        ph.backward_work = bw;
    }
    let n = reps.max(1) as f64;
    ph.cpu
        .iter_mut()
        .chain(ph.wall.iter_mut())
        .for_each(|x| *x /= n);
    Ok(ph)
}

/// CPU time (user + system, all threads) of this process so far, s (Linux `/proc/self/stat`).
pub fn process_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    let f: Vec<&str> = s.rsplit(')').next()?.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// Time `reps` forward and forward + backward passes of the CT-like scene (f32, paper RIRF,
/// upstream gradient 1/pixels everywhere).
pub fn time_render(n: usize, size: usize, reps: usize) -> crate::Result<RenderTiming> {
    let g = ct_like_scene(n, 7);
    let cam = bench_geometry(size).camera(0.3);
    let st = RenderSettings::default();
    let d = Image2d::filled(size, size, 1.0 / (size * size) as f32);
    let (_, saved) = render::forward(&g, &cam, &st)?; // warm-up
    let blends = saved.composite.blends;
    let mut fwd = Vec::new();
    let mut fb = Vec::new();
    let cpu0 = process_cpu_seconds();
    for _ in 0..reps.max(1) {
        let t0 = Instant::now();
        let (img, saved) = render::forward(&g, &cam, &st)?;
        let t1 = Instant::now();
        let grads = render::backward(&g, &cam, &st, &saved, &d);
        let t2 = Instant::now();
        std::hint::black_box((&img, &grads));
        fwd.push((t1 - t0).as_secs_f64());
        fb.push((t2 - t0).as_secs_f64());
    }
    let cpu = match (cpu0, process_cpu_seconds()) {
        (Some(a), Some(b)) => Some((b - a) / reps.max(1) as f64),
        _ => None,
    };
    let phases = time_phases(&g, &cam, &st, &d, reps)?;
    Ok(RenderTiming {
        gaussians: n,
        size,
        forward: median(fwd),
        forward_backward: median(fb),
        blends,
        cpu_forward_backward: cpu,
        phases,
    })
}

/// Blends per second of the naive per-pixel reference on `n` Gaussians at `size` x `size`
/// (one run, single-threaded), and its blend count.
pub fn time_naive(n: usize, size: usize) -> crate::Result<(f64, u64)> {
    let g = ct_like_scene(n, 7);
    let cam = bench_geometry(size).camera(0.3);
    let st = RenderSettings::default();
    let (splats, _) = render::project::forward(&g, &cam, &st)?;
    let (_, saved) = composite::forward(&splats, size, size, 0.0);
    let t0 = Instant::now();
    let img = composite::naive_forward(&splats, size, size, 0.0);
    let dt = t0.elapsed().as_secs_f64();
    std::hint::black_box(&img);
    Ok((saved.blends as f64 / dt, saved.blends))
}
