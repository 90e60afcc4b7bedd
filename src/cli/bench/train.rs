//! `unispine bench train`: prints [`unispine::bench::train`]'s stage breakdown of one
//! training iteration per detector size and the share outside the rasterizer.

use anyhow::{bail, Context};

use super::BenchArgs;
use unispine::bench::train::{self, Clock, TrainBench};
use unispine::dataset::{store, Dataset};

/// Default detector sizes.
const SIZES: [usize; 2] = [256, 1024];

/// Builds (or hands over) the dataset of one detector size.
type MakeDataset = Box<dyn FnOnce() -> anyhow::Result<Dataset>>;

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let iters = args.iters.unwrap_or(30);
    let volume = args
        .volume
        .clone()
        .unwrap_or_else(|| std::path::PathBuf::from("data/cxr.nii.gz"));
    let sizes = if args.sizes.is_empty() {
        SIZES.to_vec()
    } else {
        args.sizes.clone()
    };
    if args.data.is_some() && !args.sizes.is_empty() {
        bail!("--sizes cannot be used with --data (the dataset's detector is the size)");
    }
    train::check_train_cases(&sizes, iters, args.warmup, args.views)?;
    if let Err(e) = unispine::simd::Simd::from_env() {
        bail!("{e}");
    }
    let model = match &args.model {
        Some(p) => {
            let ply = if p.is_dir() {
                p.join("model.ply")
            } else {
                p.clone()
            };
            let g = unispine::gaussians::ply::read_ply::<f32>(&ply)
                .with_context(|| format!("reading --model {}", ply.display()))?;
            Some(g)
        }
        None => None,
    };
    println!(
        "train benchmark: `unispine` preset (20k schedule), f32, {} threads, SIMD path {}, {} \
         timed iterations after {}",
        rayon::current_num_threads(),
        unispine::simd::Simd::active().name(),
        iters,
        match &args.model {
            Some(p) => format!(
                "loading {} at iteration {} and one untimed iteration",
                p.display(),
                args.warmup
            ),
            None => format!("a warm-up of {} iterations", args.warmup),
        }
    );
    let datasets: Vec<(usize, MakeDataset)> = match &args.data {
        Some(d) => {
            let ds = store::load(d).with_context(|| format!("reading --data {}", d.display()))?;
            let n = ds.geometry.n_detector;
            if n[0] != n[1] {
                bail!(
                    "--data {}: the detector is {}x{}, not square",
                    d.display(),
                    n[0],
                    n[1]
                );
            }
            train::check_train_cases(&[n[0]], iters, args.warmup, args.views)
                .with_context(|| format!("--data {}", d.display()))?;
            println!(
                "dataset: {} ({} training views)",
                d.display(),
                ds.train.angles.len()
            );
            vec![(n[0], Box::new(move || Ok(ds)))]
        }
        None => {
            let ct = volume.is_file() && args.mask.is_file();
            if ct {
                println!(
                    "dataset: CT crop of {} with {} (vertebrae 25-50 + 10 mm, 128^3 at most, \
                     naf-mu, min-max), {} training views, 1 test view",
                    volume.display(),
                    args.mask.display(),
                    args.views
                );
            } else {
                println!(
                    "dataset: built-in phantom (128^3 voxels of 1 mm), {} training views: {} or \
                     {} not found (bash scripts/fetch-example-ct.sh fetches the CT)",
                    args.views,
                    volume.display(),
                    args.mask.display()
                );
            }
            sizes
                .iter()
                .map(|&s| {
                    let (vol, mask, views) = (volume.clone(), args.mask.clone(), args.views);
                    let f: MakeDataset = Box::new(move || {
                        Ok(if ct {
                            train::ct_crop_dataset(&vol, &mask, s, views)?
                        } else {
                            train::phantom_dataset(s, views)?
                        })
                    });
                    (s, f)
                })
                .collect()
        }
    };
    for (size, make) in datasets {
        let ds = make().with_context(|| format!("building the dataset at {size}x{size}"))?;
        let b = train::time_train(&ds, args.warmup, iters, model.clone())?;
        print_case(&b);
    }
    Ok(())
}

fn print_case(b: &TrainBench) {
    let (step, cstep) = (b.step(Clock::Wall), b.step(Clock::Cpu));
    println!(
        "\n{0}x{0}: {1} -> {2} Gaussians over iterations {3}..={4}",
        b.size,
        b.gaussians.0,
        b.gaussians.1,
        b.first_iteration,
        b.first_iteration + b.stages.steps - 1
    );
    println!(
        "{:>22} {:>12} {:>8} {:>12} {:>8}",
        "stage", "wall ms/it", "% step", "CPU ms/it", "% step"
    );
    for (name, w, c) in b.rows() {
        println!(
            "{name:>22} {:>12.3} {:>7.1}% {:>12.3} {:>7.1}%",
            w * 1e3,
            100.0 * w / step,
            c * 1e3,
            100.0 * c / cstep
        );
    }
    println!(
        "{:>22} {:>12.3} {:>7.1}% {:>12.3} {:>7.1}%",
        "step",
        step * 1e3,
        100.0,
        cstep * 1e3,
        100.0
    );
    let amort = if b.densify_phase {
        format!(
            "one clone / split / prune event {:.1} ms wall, {:.1} ms CPU every {} iterations ({} \
             in the window)",
            b.densify_event.0 * 1e3,
            b.densify_event.1 * 1e3,
            b.densify_interval,
            b.stages.n_densify_events
        )
    } else {
        "outside the densification phase (iterations 501-7999): no events".to_string()
    };
    println!("densification: statistics every iteration, {amort}");
    if let Some(c) = b.cpu_per_iteration {
        println!(
            "CPU time {:.1} ms per iteration (all threads, from /proc, over the timed loop)",
            c * 1e3
        );
    }
    if let Some(m) = unispine::eval::peak_memory_bytes() {
        println!(
            "peak resident memory of the process so far: {:.0} MiB",
            m as f64 / 1048576.0
        );
    }
    println!(
        "non-rasterizer share {:.1}% (target <= {:.0}%), by CPU time ({:.1}% by wall time)",
        100.0 * b.non_rasterizer_share(Clock::Cpu),
        100.0 * train::NON_RASTERIZER_TARGET,
        100.0 * b.non_rasterizer_share(Clock::Wall)
    );
}
