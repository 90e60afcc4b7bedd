//! `unispine bench <kind>`: benchmarks that print ratios against a baseline measured in the same
//! run.
//!
//! Kinds:
//! - `render`: forward and forward + backward of the rasterizer (projection, Eq. 3, and
//!   compositing, Eqs. 4-5) in f32 on Gaussians filling a CT-like volume box ([`ct_like_scene`]),
//!   for each Gaussian count and square detector size; prints median times, Gaussian-pixel
//!   blends per second, and the same throughput of the naive per-pixel reference
//!   ([`crate::render::composite::naive_forward`], every Gaussian tested at every pixel) measured
//!   on a smaller case in the same run, scaled per blend.
//!
//! (A `train` kind, one full training iteration, belongs to the trainer.)

use std::time::Instant;

use anyhow::bail;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::gaussians::model::N_FEATURES;
use crate::gaussians::Gaussians;
use crate::geometry::{ConeBeam, Mode};
use crate::image2d::Image2d;
use crate::render::{self, composite, RenderSettings};

/// Side of the CT-like volume box, mm.
pub const BOX_MM: f64 = 256.0;

/// Cone-beam geometry of the benchmark: DSD 1500 mm, DSO 1000 mm, a `size` x `size` detector
/// whose field of view covers the 256 mm box with margin (420 mm at the detector).
pub fn bench_geometry(size: usize) -> ConeBeam {
    let pitch = 420.0 / size as f64;
    ConeBeam {
        dsd: 1500.0,
        dso: 1000.0,
        n_detector: [size, size],
        d_detector: [pitch, pitch],
        n_voxel: [128, 128, 128],
        d_voxel: [BOX_MM / 128.0; 3],
        off_origin: [0.0; 3],
        off_detector: [0.0; 2],
        mode: Mode::Cone,
        accuracy: 0.5,
    }
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
}

/// CPU time (user + system, all threads) of this process so far, s (Linux `/proc/self/stat`).
pub fn process_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    let f: Vec<&str> = s.rsplit(')').next()?.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
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
    Ok(RenderTiming {
        gaussians: n,
        size,
        forward: median(fwd),
        forward_backward: median(fb),
        blends,
        cpu_forward_backward: cpu,
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

/// Arguments of `unispine bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// What to benchmark: `render` (rasterizer forward and forward + backward).
    pub kind: String,
    /// Gaussian counts (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "10000,50000,100000")]
    pub gaussians: Vec<usize>,
    /// Square detector sizes in pixels (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "256,512")]
    pub sizes: Vec<usize>,
    /// Repetitions per case (the median is reported).
    #[arg(long, default_value_t = 7)]
    pub reps: usize,
    /// Also measure the baselines of the ratios in this run: the naive reference and the
    /// machine's peak flop rate (`false` to time the rasterizer alone, e.g. under a profiler).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub baselines: bool,
}

/// Run `unispine bench`.
pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.kind.as_str() {
        "render" => run_render(&args),
        k => bail!("unknown benchmark kind `{k}` (available: render)"),
    }
}

fn run_render(args: &BenchArgs) -> anyhow::Result<()> {
    if args.gaussians.is_empty() || args.sizes.is_empty() || args.gaussians.contains(&0) {
        bail!("--gaussians and --sizes need at least one positive value each");
    }
    if args.sizes.contains(&0) {
        bail!("--sizes must be positive");
    }
    println!(
        "render benchmark: CT-like box of {BOX_MM} mm, cone beam, f32, paper RIRF, {} threads, \
         median of {} reps",
        rayon::current_num_threads(),
        args.reps
    );
    let simd = crate::simd::Simd::active();
    let supported: Vec<&str> = crate::simd::Simd::supported_paths()
        .iter()
        .map(|p| p.name())
        .collect();
    println!(
        "SIMD path: {} (supported: {}; cap with UNISPINE_SIMD)",
        simd.name(),
        supported.join(", ")
    );
    if let Err(e) = crate::simd::Simd::from_env() {
        bail!("{e}");
    }
    // Naive per-pixel reference and the machine's peak, measured in this run.
    let (mut naive_bps, mut peak) = (f64::NAN, f64::NAN);
    if args.baselines {
        let (nn, ns) = (10_000usize, 64usize);
        let (bps, naive_blends) = time_naive(nn, ns)?;
        naive_bps = bps;
        println!(
            "naive reference (every Gaussian at every pixel, 1 thread): {nn} Gaussians at \
             {ns}x{ns}: {naive_blends} blends, {bps:.3e} blends/s"
        );
        let threads = rayon::current_num_threads();
        let cpu0 = process_cpu_seconds();
        let t0 = Instant::now();
        let flops = crate::simd::peak_run(simd, threads, 100_000_000) as f64;
        let wall = t0.elapsed().as_secs_f64();
        let cpu = match (cpu0, process_cpu_seconds()) {
            (Some(a), Some(b)) if b > a => b - a,
            _ => wall * threads as f64,
        };
        peak = flops / cpu;
        println!(
            "measured peak: {:.1} Gflop/s per busy core ({:.1} Gflop/s wall on {} threads), \
             f32 multiplies + adds, {}",
            peak * 1e-9,
            flops / wall * 1e-9,
            threads,
            simd.name()
        );
    }
    let fpb = composite::FLOPS_PER_BLEND_FORWARD + composite::FLOPS_PER_BLEND_BACKWARD;
    println!(
        "arithmetic limit = blends x {fpb} flops (forward {} + backward {}, counted from the \
         kernels) / peak per core / threads (the wall time of an idle machine); 'of limit' = \
         blends x {fpb} flops / peak per core over the forward + backward CPU time",
        composite::FLOPS_PER_BLEND_FORWARD,
        composite::FLOPS_PER_BLEND_BACKWARD
    );
    println!(
        "{:>9} {:>6} {:>11} {:>11} {:>11} {:>12} {:>10} {:>13} {:>13} {:>10} {:>9} {:>8}",
        "gaussians",
        "size",
        "forward ms",
        "fwd+bwd ms",
        "f+b cpu ms",
        "blends",
        "blends/px",
        "fwd blends/s",
        "f+b blends/s",
        "x naive",
        "limit ms",
        "of limit"
    );
    for &size in &args.sizes {
        for &n in &args.gaussians {
            let t = time_render(n, size, args.reps)?;
            let fbps = t.blends as f64 / t.forward;
            let limit_cpu = t.blends as f64 * fpb as f64 / peak;
            let limit = limit_cpu / rayon::current_num_threads() as f64;
            let frac = limit_cpu / t.cpu_forward_backward.unwrap_or(f64::NAN);
            let line = format!(
                "{:>9} {:>6} {:>11.2} {:>11.2} {:>11} {:>12} {:>10.1} {:>13.3e} {:>13.3e} {:>10.1} {:>9.2} {:>7.1}%",
                n,
                size,
                t.forward * 1e3,
                t.forward_backward * 1e3,
                t.cpu_forward_backward
                    .map_or("-".to_string(), |c| format!("{:.1}", c * 1e3)),
                t.blends,
                t.blends as f64 / (size * size) as f64,
                fbps,
                t.blends as f64 / t.forward_backward,
                fbps / naive_bps,
                limit * 1e3,
                100.0 * frac
            )
            .replace("NaN", "-");
            println!("{line}");
        }
    }
    println!(
        "x naive = forward blends/s over the naive reference's blends/s; f+b cpu ms = process CPU \
         time (all threads) per forward + backward (mean over the reps)"
    );
    Ok(())
}
