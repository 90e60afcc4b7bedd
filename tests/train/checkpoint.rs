//! Checkpoint round trips with every field non-zero and random (seeded), through the public API:
//! `Checkpoint::to_bytes` / `from_bytes` and `RunDir::write_checkpoint` / `read_checkpoint`.
//! Each field is compared on its own, bit for bit, so a field that is dropped, zeroed, swapped
//! with another or written in the wrong precision fails here.

use std::path::Path;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use unispine::densify::{Stats, TrainState};
use unispine::gaussians::Gaussians;
use unispine::optim::{Adam, AdamConfig, N_GROUPS};
use unispine::render::{ColorMode, RenderSettings};
use unispine::train::checkpoint::Identity;
use unispine::train::compact::Compaction;
use unispine::train::{Checkpoint, EvalPoint, RunDir};

/// Random non-zero f32 in (-3, -0.01] U [0.01, 3), different for every call.
fn val(r: &mut ChaCha8Rng) -> f32 {
    let m: f32 = r.random_range(0.01..3.0);
    if r.random::<bool>() {
        m
    } else {
        -m
    }
}

fn gaussians(r: &mut ChaCha8Rng, n: usize) -> Gaussians<f32> {
    let mut g = Gaussians::<f32>::zeros(n);
    for i in 0..n {
        g.means[i] = [val(r), val(r), val(r)];
        g.log_scales[i] = [val(r), val(r), val(r)];
        g.quats[i] = [val(r), val(r), val(r), val(r)];
        g.opacity_logits[i] = val(r);
        for f in g.features[i].iter_mut() {
            *f = val(r);
        }
    }
    g
}

fn random_checkpoint(seed: u64, n: usize) -> Checkpoint {
    let r = &mut ChaCha8Rng::seed_from_u64(seed);
    let colors = [
        ColorMode::RirfPaper,
        ColorMode::RirfXgaussian,
        ColorMode::Sh,
    ];
    let mut steps = [0u64; N_GROUPS];
    for s in steps.iter_mut() {
        *s = r.random_range(1..1_000_000);
    }
    let state = TrainState {
        params: gaussians(r, n),
        adam: Adam {
            cfg: AdamConfig {
                beta1: r.random_range(0.5..0.99),
                beta2: r.random_range(0.9..0.9999),
                eps: r.random_range(1e-16..1e-6),
            },
            m: gaussians(r, n),
            v: gaussians(r, n),
            steps,
        },
        stats: Stats {
            grad_accum: (0..n).map(|_| r.random_range(1e-9..1e3)).collect(),
            denom: (0..n).map(|_| r.random_range(1..u32::MAX)).collect(),
            max_radius: (0..n).map(|_| r.random_range(1..u32::MAX)).collect(),
        },
    };
    Checkpoint {
        identity: Identity {
            method: format!("method-{}", r.random::<u32>()),
            color: format!("color-{}", r.random::<u32>()),
            seed: r.random::<u64>() | 1,
            dataset: format!("{:032x}", r.random::<u128>()),
            config: format!("{:032x}", r.random::<u128>()),
        },
        iteration: r.random_range(1..1_000_000),
        render: RenderSettings {
            color: colors[r.random_range(0..3)],
            active_features: [1, 4, 9, 16][r.random_range(0..4)],
            background: r.random_range(-2.0..2.0),
            ..Default::default()
        },
        state,
        rng_word_pos: r.random::<u128>() | 1,
        view_stack: (0..r.random_range(3..9))
            .map(|_| r.random_range(1..50))
            .collect(),
        evals: (0..3)
            .map(|_| EvalPoint {
                iteration: r.random_range(1..20_000),
                psnr: r.random_range(5.0..60.0),
                ssim: r.random_range(0.01..1.0),
                n_gaussians: r.random_range(1..100_000),
            })
            .collect(),
        train_time_s: r.random_range(0.001..1e5),
        eval_time_s: r.random_range(0.001..1e5),
        log: format!(
            "iteration,loss\n1,{}\n2,{} µ ≠ ascii\n",
            r.random::<f64>(),
            r.random::<f64>()
        ),
        compaction: Some(Compaction {
            iteration: r.random_range(1..20_000),
            n_before: r.random_range(2..100_000),
            n_after: r.random_range(1..1000),
            psnr_before: r.random_range(5.0..60.0),
            ssim_before: r.random_range(0.01..1.0),
            psnr_pruned: r.random_range(5.0..60.0),
            ssim_pruned: r.random_range(0.01..1.0),
            score: format!("score {}", r.random::<u32>()),
        }),
    }
}

fn bits(g: &Gaussians<f32>) -> Vec<u32> {
    let mut v = Vec::new();
    for i in 0..g.len() {
        v.extend(g.means[i].iter().map(|x| x.to_bits()));
        v.extend(g.log_scales[i].iter().map(|x| x.to_bits()));
        v.extend(g.quats[i].iter().map(|x| x.to_bits()));
        v.push(g.opacity_logits[i].to_bits());
        v.extend(g.features[i].iter().map(|x| x.to_bits()));
    }
    v
}

/// Every field of `b` equals `a`'s, bit for bit.
fn assert_same(a: &Checkpoint, b: &Checkpoint) {
    assert_eq!(a.identity, b.identity, "identity");
    assert_eq!(a.iteration, b.iteration, "iteration");
    assert_eq!(a.render, b.render, "render");
    assert_eq!(a.render.background.to_bits(), b.render.background.to_bits());
    assert_eq!(bits(&a.state.params), bits(&b.state.params), "params");
    assert_eq!(bits(&a.state.adam.m), bits(&b.state.adam.m), "adam.m");
    assert_eq!(bits(&a.state.adam.v), bits(&b.state.adam.v), "adam.v");
    let cfg = |c: &AdamConfig| [c.beta1, c.beta2, c.eps].map(f64::to_bits);
    assert_eq!(cfg(&a.state.adam.cfg), cfg(&b.state.adam.cfg), "adam.cfg");
    assert_eq!(a.state.adam.steps, b.state.adam.steps, "adam.steps");
    let f64bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        f64bits(&a.state.stats.grad_accum),
        f64bits(&b.state.stats.grad_accum),
        "stats.grad_accum"
    );
    assert_eq!(a.state.stats.denom, b.state.stats.denom, "stats.denom");
    assert_eq!(
        a.state.stats.max_radius, b.state.stats.max_radius,
        "stats.max_radius"
    );
    assert_eq!(a.rng_word_pos, b.rng_word_pos, "rng_word_pos");
    assert_eq!(a.view_stack, b.view_stack, "view_stack");
    assert_eq!(a.evals, b.evals, "evals");
    assert_eq!(
        a.train_time_s.to_bits(),
        b.train_time_s.to_bits(),
        "train_time_s"
    );
    assert_eq!(
        a.eval_time_s.to_bits(),
        b.eval_time_s.to_bits(),
        "eval_time_s"
    );
    assert_eq!(a.log, b.log, "log");
    assert_eq!(a.compaction, b.compaction, "compaction");
}

#[test]
fn every_field_survives_to_bytes_and_from_bytes() {
    for (seed, n) in [(1u64, 1usize), (2, 7), (3, 33)] {
        let c = random_checkpoint(seed, n);
        // The generator gave every field a non-zero value (so a zeroed field cannot pass).
        assert!(c.state.stats.max_radius.iter().all(|&x| x > 0));
        assert!(c.state.stats.denom.iter().all(|&x| x > 0));
        assert!(c.state.adam.steps.iter().all(|&x| x > 0));
        let back = Checkpoint::from_bytes(Path::new("ckpt.bin"), &c.to_bytes()).unwrap();
        assert_same(&c, &back);
        // Two checkpoints that differ only in one Gaussian's statistics give different bytes.
        let mut d = c.clone();
        d.state.stats.max_radius[n - 1] ^= 1;
        assert_ne!(c.to_bytes(), d.to_bytes());
    }
    // No compaction record round-trips as none.
    let mut c = random_checkpoint(4, 3);
    c.compaction = None;
    let back = Checkpoint::from_bytes(Path::new("ckpt.bin"), &c.to_bytes()).unwrap();
    assert_same(&c, &back);
}

#[test]
fn every_field_survives_the_run_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let rd = RunDir::create(&tmp.path().join("run")).unwrap();
    assert!(!rd.has_checkpoint());
    let c = random_checkpoint(5, 11);
    rd.write_checkpoint(&c).unwrap();
    assert!(rd.has_checkpoint());
    let back = RunDir::open(&tmp.path().join("run"))
        .unwrap()
        .read_checkpoint()
        .unwrap();
    assert_same(&c, &back);
    // A newer checkpoint replaces the older one completely.
    let c2 = random_checkpoint(6, 2);
    rd.write_checkpoint(&c2).unwrap();
    assert_same(&c2, &rd.read_checkpoint().unwrap());
}
