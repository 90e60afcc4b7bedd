//! `unispine bench field`: prints the figures of [`unispine::bench::field`] and their ratios.

use anyhow::bail;

use super::BenchArgs;
use unispine::bench::field::{peak, time_iteration, time_mlp};
use unispine::field::{FieldConfig, PRESETS};
use unispine::simd::Simd;

/// Training views assumed for the presets' schedules (only the iteration count depends on it).
const VIEWS: usize = 50;

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    if let Err(e) = Simd::from_env() {
        bail!("{e}");
    }
    for p in &args.presets {
        if !PRESETS.contains(&p.as_str()) {
            bail!(
                "--presets: unknown preset `{p}` (one of: {})",
                PRESETS.join(", ")
            );
        }
    }
    let iters_per_preset = args.iters.unwrap_or(5);
    if args.reps == 0 || iters_per_preset == 0 {
        bail!("--reps and --iters must be positive");
    }
    let simd = Simd::active();
    let threads = rayon::current_num_threads();
    println!(
        "field benchmark: f32, {threads} threads, SIMD path {} (cap with UNISPINE_SIMD)",
        simd.name()
    );
    // Peak: independent multiplies and adds (not fused, as the kernels), 1 and all threads.
    let iters = 100_000_000u64;
    let (f1, w1, _) = peak(simd, 1, iters / 2);
    let (fa, wa, ca) = peak(simd, threads, iters / 2);
    let peak1 = f1 / w1;
    let peak_all = fa / wa;
    let peak_core = if ca.is_finite() && ca > 0.0 {
        fa / ca
    } else {
        peak1
    };
    println!(
        "peak f32 (multiply + add, {}): 1 thread {:.1} Gflop/s; {threads} threads {:.1} Gflop/s \
         wall, {:.1} Gflop/s per busy core (flops / process CPU time)",
        simd.name(),
        peak1 * 1e-9,
        peak_all * 1e-9,
        peak_core * 1e-9
    );
    // The MLP at the NAF width (widest path and scalar) and at the NeRF width (widest path).
    let mut mlp_frac = None;
    for (label, preset) in [("NAF", "naf"), ("NeRF", "nerf")] {
        let cfg = FieldConfig::preset(preset, VIEWS)?;
        let paths: Vec<Simd> = if simd == Simd::Scalar || preset == "nerf" {
            vec![simd]
        } else {
            vec![simd, Simd::Scalar]
        };
        for p in paths {
            let m = time_mlp(&cfg, p, args.reps)?;
            if p == simd && preset == "naf" {
                mlp_frac = Some((m.flops / m.wall / peak_all, m.flops / m.cpu / peak_core));
            }
            let g = m.flops / m.wall;
            let gc = m.flops / m.cpu;
            println!(
                "MLP forward + backward, {label} width ({} x {} x {} layers, skip {:?}), {} rows, \
                 {} path: {:.1} Mflop in {:.2} ms = {:.1} Gflop/s wall ({:.0}% of the \
                 {threads}-thread peak), {:.1} Gflop/s per busy core ({:.0}% of the per-core peak)",
                cfg.hidden_dim,
                cfg.hidden_dim,
                cfg.num_layers,
                cfg.skips,
                m.rows,
                p.name(),
                m.flops * 1e-6,
                m.wall * 1e3,
                g * 1e-9,
                100.0 * g / peak_all,
                gc * 1e-9,
                100.0 * gc / peak_core
            );
        }
    }
    println!(
        "per iteration (ms): stage columns are CPU time summed over the threads (sample = \
         stratified points; render = line integrals and their gradient; enc bwd = hash-grid \
         scatter, wall); wall = one whole iteration (loss, gradient, Adam)"
    );
    println!(
        "{:>15} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9}",
        "preset",
        "samples",
        "sample",
        "encode",
        "mlp fwd",
        "render",
        "mlp bwd",
        "enc bwd",
        "adam",
        "wall",
        "cpu"
    );
    let mut hwm_naf_full = None;
    let mut iter_s = Vec::new();
    for name in &args.presets {
        let cfg = FieldConfig::preset(name, VIEWS)?;
        let n = if cfg.reduced { iters_per_preset } else { 1 };
        let t = time_iteration(&cfg, simd, n)?;
        let s = &t.stages;
        println!(
            "{:>15} {:>8} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>9.1} {:>9.1}",
            cfg.label(),
            t.samples,
            s.sample * 1e3,
            s.encode * 1e3,
            s.mlp_forward * 1e3,
            s.render * 1e3,
            s.mlp_backward * 1e3,
            s.encode_backward * 1e3,
            t.adam * 1e3,
            t.wall * 1e3,
            t.cpu * 1e3
        );
        iter_s.push((name.clone(), cfg.label(), t.wall, t.cpu));
        if name == "naf-full" {
            hwm_naf_full = unispine::eval::peak_memory_bytes();
        }
    }
    if let Some(b) = hwm_naf_full {
        println!(
            "peak resident memory (VmHWM) after the naf-full iterations: {:.0} MiB ({:.2} of the \
             2 GiB target; includes every preset timed before it)",
            b as f64 / (1 << 20) as f64,
            b as f64 / (2u64 << 30) as f64
        );
    }
    print_targets(threads, mlp_frac, &iter_s, hwm_naf_full);
    Ok(())
}

/// Whether `ok`, as printed.
fn verdict(ok: bool) -> &'static str {
    if ok {
        "reached"
    } else {
        "NOT reached"
    }
}

/// The targets of the speed and memory requirements next to the figures of this run: the
/// MLP's fraction of the peak (wall against the all-thread peak, and CPU time against the
/// per-core peak), seconds per iteration of the reduced NAF and NeRF (wall, and process CPU
/// time / threads: what the iteration costs on otherwise idle cores), the full presets' cost,
/// and the peak memory of naf-full.
fn print_targets(
    threads: usize,
    mlp_frac: Option<(f64, f64)>,
    iter_s: &[(String, String, f64, f64)],
    hwm_naf_full: Option<u64>,
) {
    println!("targets (fraction reached = target / figure for times and memory, figure / target for the rate):");
    if let Some((wall, core)) = mlp_frac {
        println!(
            "  MLP forward + backward at the NAF width: {:.0}% of the {threads}-thread peak \
             (wall), {:.0}% of the per-core peak (CPU time); target >= 50%: {:.2} ({})",
            100.0 * wall,
            100.0 * core,
            wall.max(core) / 0.5,
            verdict(wall.max(core) >= 0.5)
        );
    }
    for (name, limit) in [("naf", 0.05), ("nerf", 0.5)] {
        if let Some((_, label, wall, cpu)) = iter_s.iter().find(|r| r.0 == name) {
            let busy = cpu / threads as f64;
            println!(
                "  {label}: {wall:.3} s per iteration wall, {busy:.3} s CPU / {threads} threads; \
                 target <= {limit} s: {:.2} ({})",
                limit / wall.min(busy),
                verdict(wall.min(busy) <= limit)
            );
        }
    }
    for (name, label, wall, cpu) in iter_s.iter().filter(|r| r.0.ends_with("-full")) {
        let cfg = FieldConfig::preset(name, VIEWS).ok();
        let iters = cfg.map_or(0, |c| c.iterations);
        let busy = cpu / threads as f64;
        println!(
            "  {label}: {wall:.2} s per iteration wall, {busy:.2} s CPU / {threads} threads; \
             {iters} iterations ({VIEWS} views) = {:.1} h at the CPU figure",
            busy * iters as f64 / 3600.0
        );
    }
    if let Some(b) = hwm_naf_full {
        println!(
            "  naf-full peak resident memory: {:.0} MiB; target <= 2048 MiB: {:.2} ({})",
            b as f64 / (1 << 20) as f64,
            (2u64 << 30) as f64 / b as f64,
            verdict(b <= 2u64 << 30)
        );
    }
}
