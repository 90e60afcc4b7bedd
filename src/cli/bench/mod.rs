//! `unispine bench <kind>`: benchmarks that print ratios against a baseline measured in the same
//! run.
//!
//! Kinds:
//! - `render`: forward and forward + backward of the rasterizer in f32 on the CT-like scenes of
//!   [`unispine::bench::render`], for each Gaussian count and square detector size; prints median
//!   times, Gaussian-pixel blends per second, and the same throughput of the naive per-pixel
//!   reference measured on a smaller case in the same run, scaled per blend; the SIMD path used
//!   ([`unispine::simd::Simd::active`]) and the arithmetic limit of the work: blends x the kernels'
//!   flops per blend over the peak f32 rate measured in the same run
//!   ([`unispine::simd::peak_run`]), and the fraction of it reached; under each case, the CPU and
//!   wall time of each phase ([`unispine::bench::render::RENDER_PHASES`]) and the lanes the tile
//!   kernels evaluated against the blends.
//!
//! - `field`: the neural-field baselines ([`unispine::bench::field`]): the peak f32 rate of
//!   independent multiplies and adds on one and on all threads, the MLP forward + backward at
//!   the NAF width (rows = the preset's rays x samples) in Gflop/s and as a fraction of that
//!   peak (the widest path and the scalar path) and at the NeRF width (the widest path), each
//!   preset's per-iteration time split into stages, and the process's peak resident memory
//!   after the full NAF configuration's iterations.
//!
//! - `train`: where one training iteration of the `unispine` preset goes
//!   ([`unispine::bench::train`]): ms and % of the step per stage at each detector size,
//!   CPU time, and the share outside the rasterizer against its target (15 %).
//!
//! - `drr`: the DRR projectors ([`unispine::bench::drr`]): per projector, view (AP, lateral) and
//!   detector size, the first and the median extra view on each instruction set, the per-ray
//!   loops (`scalar`, the implementation before the vector kernels) measured in the same run as
//!   the reference of the speed-ups; rays/s, voxel steps or samples per second, peak resident
//!   memory against the volume's size, and the target (0.05 s per 256^2 view on 2 cores) with
//!   the fraction reached.
//!
//! - `loss`: the loss stage ([`unispine::bench::loss`]): per square image size, SSIM forward +
//!   backward with the fused kernels and as its definition (five whole-image blurs), measured
//!   in turns in the same run, their ratio, and the whole loss of Eq. (8) (weighted
//!   Charbonnier + SSIM); the run fails if the two SSIMs differ in any bit.

mod field;
mod train;

use anyhow::{bail, Context};

use std::time::Instant;

use unispine::bench::render::{
    process_cpu_seconds, time_naive, time_render, RenderTiming, BOX_MM, RENDER_PHASES,
};
use unispine::render::composite;

/// Arguments of `unispine bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// What to benchmark: `render` (rasterizer forward and forward + backward), `field`
    /// (neural-field baselines: MLP products, per-iteration stages, memory), `train` (one
    /// training iteration of the `unispine` preset split into stages), `drr` (the DRR
    /// projectors per view and SIMD path) or `loss` (SSIM's fused kernels against its
    /// definition, and the whole loss of Eq. 8).
    pub kind: String,
    /// Gaussian counts (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "10000,50000,100000")]
    pub gaussians: Vec<usize>,
    /// Square detector sizes in pixels (comma-separated; default `render` 256,512, `train`
    /// 256,1024, `drr` 256).
    #[arg(long, value_delimiter = ',')]
    pub sizes: Vec<usize>,
    /// Repetitions per case (the median is reported).
    #[arg(long, default_value_t = 7)]
    pub reps: usize,
    /// Also measure the baselines of the ratios in this run: the naive reference and the
    /// machine's peak flop rate (`false` to time the rasterizer alone, e.g. under a profiler).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub baselines: bool,
    /// `field`: presets to time (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "naf,intratomo,tensorf,nerf,naf-full,intratomo-full,tensorf-full,nerf-full"
    )]
    pub presets: Vec<String>,
    /// Timed iterations (`field`: per reduced preset, full presets 1; default 5. `train`:
    /// default 30).
    #[arg(long)]
    pub iters: Option<usize>,
    /// `train`: a dataset folder written by `unispine data` (its detector size is the only
    /// size; do not pass `--sizes`). Default: the CT crop built from `--volume` and `--mask`,
    /// or the built-in phantom when those files are absent.
    #[arg(long)]
    pub data: Option<std::path::PathBuf>,
    /// `train`: the CT volume of the default dataset (default `data/cxr.nii.gz`). `drr`: the
    /// volume to project (NIfTI, MetaImage or .npy; default `data/cxr.nii.gz` when present, else
    /// the built-in phantom of `--phantom` voxels per side).
    #[arg(long)]
    pub volume: Option<std::path::PathBuf>,
    /// `train`: its label volume (vertebrae 25-50 are kept, plus 10 mm).
    #[arg(long, default_value = "data/mask.nii.gz")]
    pub mask: std::path::PathBuf,
    /// `train`: training views of the built dataset (one test view).
    #[arg(long, default_value_t = 50)]
    pub views: usize,
    /// `train`: warm-up iterations before timing; with `--model`, the schedule position the
    /// model starts at instead (then one untimed iteration runs before the timed ones).
    #[arg(long, default_value_t = 1000)]
    pub warmup: usize,
    /// `train`: start from this model (`model.ply` of a run, or its run folder) instead of
    /// training a warm-up.
    #[arg(long)]
    pub model: Option<std::path::PathBuf>,
    /// `drr`: voxels per side of the built-in phantom used when there is no volume (1.0 mm
    /// voxels), in [2, 1024].
    #[arg(long, default_value_t = 256)]
    pub phantom: usize,
}

/// Run `unispine bench`.
pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.kind.as_str() {
        "render" => run_render(&args),
        "field" => field::run(&args),
        "train" => train::run(&args),
        "drr" => run_drr(&args),
        "loss" => run_loss(&args),
        k => bail!("unknown benchmark kind `{k}` (available: render, field, train, drr, loss)"),
    }
}

fn run_render(args: &BenchArgs) -> anyhow::Result<()> {
    let sizes = if args.sizes.is_empty() {
        vec![256, 512]
    } else {
        args.sizes.clone()
    };
    unispine::bench::render::check_render_cases(&args.gaussians, &sizes, args.reps)?;
    println!(
        "render benchmark: CT-like box of {BOX_MM} mm, cone beam, f32, paper RIRF, {} threads, \
         median of {} reps",
        rayon::current_num_threads(),
        args.reps
    );
    let simd = unispine::simd::Simd::active();
    let supported: Vec<&str> = unispine::simd::Simd::supported_paths()
        .iter()
        .map(|p| p.name())
        .collect();
    println!(
        "SIMD path: {} (supported: {}; cap with UNISPINE_SIMD)",
        simd.name(),
        supported.join(", ")
    );
    if let Err(e) = unispine::simd::Simd::from_env() {
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
        let flops = unispine::simd::peak_run(simd, threads, 100_000_000) as f64;
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
        "arithmetic limit = blends x {fpb} operations (forward {} + backward {}, counted from the \
         kernels; a fused multiply-add counts as one) / peak per core / threads (the wall time \
         of an idle machine); 'of limit' = blends x {fpb} operations / peak per core over the \
         forward + backward CPU time",
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
    for &size in &sizes {
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
            print_phases(&t);
        }
    }
    println!(
        "x naive = forward blends/s over the naive reference's blends/s; f+b cpu ms = process CPU \
         time (all threads) per forward + backward (mean over the reps)"
    );
    Ok(())
}

/// The per-phase times of one case and the lane use of the tile kernels.
fn print_phases(t: &RenderTiming) {
    let p = &t.phases;
    let (cpu, wall): (f64, f64) = (p.cpu.iter().sum(), p.wall.iter().sum());
    let cells: Vec<String> = RENDER_PHASES
        .iter()
        .zip(p.cpu.iter().zip(&p.wall))
        .map(|(n, (c, w))| format!("{n} {:.1}/{:.1}", c * 1e3, w * 1e3))
        .collect();
    println!(
        "  phases, cpu/wall ms per forward + backward (total {:.1}/{:.1}): {}",
        cpu * 1e3,
        wall * 1e3,
        cells.join(", ")
    );
    for (name, w) in [("forward", p.forward_work), ("backward", p.backward_work)] {
        println!(
            "  {name} tiles: {} entries, {} entry rows, {} lanes evaluated, {:.1}% of them blends",
            w.entries,
            w.rows,
            w.lanes,
            100.0 * t.blends as f64 / w.lanes as f64
        );
    }
}

fn run_drr(args: &BenchArgs) -> anyhow::Result<()> {
    use unispine::bench::drr::{time_case, BENCH_REPS, BENCH_SIZES, TARGET_S};
    use unispine::drr::{MarchLanes, Method};
    use unispine::simd::Simd;
    let check = |flag: &str, v: usize, (lo, hi): (usize, usize)| {
        if v < lo || v > hi {
            bail!("{flag}: {v} is outside the allowed range [{lo}, {hi}]");
        }
        Ok(())
    };
    // Default: the target's size.
    let sizes = if args.sizes.is_empty() {
        vec![256]
    } else {
        args.sizes.clone()
    };
    for &s in &sizes {
        check("--sizes", s, BENCH_SIZES)?;
    }
    check("--reps", args.reps, BENCH_REPS)?;
    check("--phantom", args.phantom, (2, 1024))?;
    if let Err(e) = Simd::from_env() {
        bail!("{e}");
    }
    let default_ct = std::path::Path::new("data/cxr.nii.gz");
    let path = match &args.volume {
        Some(p) => Some(p.clone()),
        None => default_ct.exists().then(|| default_ct.to_path_buf()),
    };
    let vol = match &path {
        Some(p) => unispine::volume::load(p)
            .with_context(|| format!("reading --volume {}", p.display()))?,
        None => {
            let n = args.phantom;
            let spec = unispine::volume::phantom::PhantomSpec {
                dims: [n, n, n],
                ..Default::default()
            };
            unispine::volume::phantom::generate(&spec)?.0
        }
    };
    let vol_bytes = (vol.len() * 4) as f64;
    println!(
        "DRR benchmark: {} ({:?} voxels of {:?} mm, f32 {:.0} MiB), cone beam DSD 1500 mm, DSO \
         1000 mm, square detector as wide as the volume's shadow, {} threads, median of {} \
         extra views",
        path.as_ref()
            .map_or("built-in phantom".to_string(), |p| p.display().to_string()),
        vol.dims,
        vol.spacing,
        vol_bytes / (1024.0 * 1024.0),
        rayon::current_num_threads(),
        args.reps
    );
    let active = Simd::active();
    let mut paths = vec![Simd::Scalar];
    paths.extend(
        Simd::supported_paths()
            .into_iter()
            .filter(|&p| p != Simd::Scalar && p <= active),
    );
    println!(
        "paths: {} (scalar = the per-ray loops, the reference of the ratios; cap with \
         UNISPINE_SIMD); every path's image is checked bit-identical to the scalar one",
        paths
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
            .join(", ")
    );
    // The trilinear march on AVX-512 runs 8 or 16 lanes (`MarchLanes`): both are timed, the
    // default for this CPU first.
    let default_lanes = MarchLanes::for_this_cpu();
    let other_lanes = match default_lanes {
        MarchLanes::Eight => MarchLanes::Sixteen,
        MarchLanes::Sixteen => MarchLanes::Eight,
    };
    println!(
        "trilinear on avx512: {} lanes by default on this CPU (avx512/N = N lanes; 512-bit \
         operations {}), the other width timed too",
        default_lanes.count(),
        if unispine::simd::splits_512_bit() {
            "split in two halves"
        } else {
            "full width"
        }
    );
    println!(
        "{:>9} {:>5} {:>5} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11} {:>11} {:>8} {:>9}",
        "method",
        "view",
        "size",
        "path",
        "first s",
        "extra s",
        "cpu s",
        "cpu/thr s",
        "x scalar",
        "rays/cpu s",
        "steps/cpu s",
        "peak/vol",
        "of target"
    );
    for &size in &sizes {
        for method in [Method::Siddon, Method::Trilinear] {
            for (view, deg) in [("AP", 90.0), ("lat", 0.0)] {
                let mut case_paths: Vec<_> = paths.iter().map(|&p| (p, default_lanes)).collect();
                if method == Method::Trilinear && paths.contains(&Simd::Avx512) {
                    case_paths.push((Simd::Avx512, other_lanes));
                }
                let t = time_case(&vol, method, deg, size, args.reps, &case_paths)?;
                let base_cpu = t.paths[0].extra_cpu;
                let threads = rayon::current_num_threads() as f64;
                for p in &t.paths {
                    // The target is per 256^2 view: scale by the pixel count.
                    let target = TARGET_S * (size * size) as f64 / (256.0 * 256.0);
                    let line = format!(
                        "{:>9} {:>5} {:>5} {:>9} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>9.2} {:>11.3e} {:>11.3e} {:>8} {:>8.0}%",
                        format!("{method:?}").to_lowercase(),
                        view,
                        size,
                        if method == Method::Trilinear && p.simd == Simd::Avx512 {
                            format!("avx512/{}", p.march_lanes)
                        } else {
                            p.simd.name().to_string()
                        },
                        p.first_wall,
                        p.extra_wall,
                        p.extra_cpu,
                        p.extra_cpu / threads,
                        base_cpu / p.extra_cpu,
                        t.rays as f64 / p.extra_cpu,
                        t.steps as f64 / p.extra_cpu,
                        t.peak_rss
                            .map_or("-".to_string(), |b| format!("{:.2}", b as f64 / vol_bytes)),
                        100.0 * target / (p.extra_cpu / threads)
                    );
                    println!("{line}");
                }
            }
        }
    }
    println!(
        "first = projector checks + one view (wall); extra = median extra view (wall), cpu = its \
         process CPU time (all threads), cpu/thr = cpu over the threads (the wall time of a machine \
         with nothing else running); x scalar = the scalar path's cpu over this path's (same \
         run); rays/cpu s and steps/cpu s = rays and steps per second of process CPU time (per busy \
         core); steps = voxels crossed (siddon) or samples (trilinear); peak/vol = the process's \
         peak resident memory during the first projection over the volume's f32 size; of target \
         = {TARGET_S} s per 256^2 view (scaled by pixels) over cpu/thr"
    );
    Ok(())
}

fn run_loss(args: &BenchArgs) -> anyhow::Result<()> {
    use unispine::bench::loss::{check_loss_case, time_loss};
    let sizes = if args.sizes.is_empty() {
        vec![256, 1024]
    } else {
        args.sizes.clone()
    };
    for &size in &sizes {
        check_loss_case(size, args.reps)?;
    }
    println!(
        "loss stage, f32, {} threads, {} path, median of {} reps (wall ms / process CPU ms)",
        rayon::current_num_threads(),
        unispine::simd::Simd::active().name(),
        args.reps
    );
    println!(
        "{:>6} {:>17} {:>17} {:>13} {:>17}",
        "size", "ssim fused", "ssim definition", "ratio (CPU)", "whole loss"
    );
    for &size in &sizes {
        let t = time_loss(size, args.reps)?;
        let ms = |(w, c): (f64, f64)| format!("{w:.2} / {c:.2}");
        println!(
            "{:>6} {:>17} {:>17} {:>12.2}x {:>17}",
            size,
            ms(t.ssim_fused),
            ms(t.ssim_reference),
            t.ssim_reference.1 / t.ssim_fused.1,
            ms(t.loss)
        );
    }
    Ok(())
}
