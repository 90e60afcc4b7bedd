//! `unispine bench field`: prints the figures of [`crate::field::bench`] and their ratios.

use anyhow::bail;

use super::bench::BenchArgs;
use crate::field::bench::{peak, time_iteration, time_mlp};
use crate::field::{FieldConfig, PRESETS};
use crate::simd::Simd;

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
    // MLP at the NAF width.
    let naf = FieldConfig::preset("naf", VIEWS)?;
    let paths: Vec<Simd> = if simd == Simd::Scalar {
        vec![simd]
    } else {
        vec![simd, Simd::Scalar]
    };
    for p in paths {
        let m = time_mlp(&naf, p, args.reps)?;
        let g = m.flops / m.wall;
        let gc = m.flops / m.cpu;
        println!(
            "MLP forward + backward, NAF width ({} x {} x {} layers, skip {:?}), {} rows, {} \
             path: {:.1} Mflop in {:.2} ms = {:.1} Gflop/s wall ({:.0}% of the {threads}-thread \
             peak), {:.1} Gflop/s per busy core ({:.0}% of the per-core peak)",
            naf.hidden_dim,
            naf.hidden_dim,
            naf.num_layers,
            naf.skips,
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
        if name == "naf-full" {
            hwm_naf_full = crate::eval::peak_memory_bytes();
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
    Ok(())
}
