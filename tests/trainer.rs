//! The trainer end to end on a tiny synthetic dataset (32 x 32 detector, 8 training and 4 test
//! views, 512 ACUI Gaussians, tens of iterations). The ground truth is rendered from a hidden
//! set of 12 Gaussians, so no projector is needed.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use unispine::dataset::{Dataset, Manifest, Split};
use unispine::error::Error;
use unispine::gaussians::{ply, Gaussians};
use unispine::geometry::ConeBeam;
use unispine::image2d::Image2d;
use unispine::render::{self, ColorMode, RenderSettings};
use unispine::train::{self, Event, Method, TrainConfig, Trainer};

fn geometry() -> ConeBeam {
    // 64 mm box, magnification 1.5 -> 96 mm on a 32 px detector at 3 mm.
    ConeBeam::centred([32, 32], [3.0, 3.0], [32, 32, 32], [2.0, 2.0, 2.0])
}

fn hidden() -> Gaussians<f64> {
    let n = 12;
    let mut g = Gaussians::<f64>::zeros(n);
    for i in 0..n {
        let t = i as f64;
        g.means[i] = [
            18.0 * (1.3 * t).sin(),
            18.0 * (0.7 * t + 1.0).cos(),
            -22.0 + 4.0 * t,
        ];
        g.log_scales[i] = [(3.0 + (t % 3.0)).ln(), 4.0f64.ln(), (2.5 + (t % 2.0)).ln()];
        g.quats[i] = [1.0, 0.1 * t.sin(), 0.2, -0.1];
        g.opacity_logits[i] = 0.5 + 0.2 * (t % 4.0);
        g.features[i][0] = 0.8 + 0.3 * (t % 3.0);
    }
    g
}

fn dataset() -> Dataset {
    let geo = geometry();
    let g = hidden();
    let settings = RenderSettings {
        color: ColorMode::RirfXgaussian,
        active_features: 1,
        background: 0.0,
    };
    let split = |angles: Vec<f64>| Split {
        projections: angles
            .iter()
            .map(|&a| {
                let (img, _) = render::forward(&g, &geo.camera(a), &settings).unwrap();
                img.cast::<f32>()
            })
            .collect(),
        angles,
    };
    let pi = std::f64::consts::PI;
    Dataset {
        train: split((0..8).map(|k| k as f64 * pi / 8.0).collect()),
        test: split((0..4).map(|k| (k as f64 + 0.5) * pi / 4.0).collect()),
        geometry: geo,
        manifest: Manifest::default(),
        volume: None,
    }
}

fn tiny(method: Method, iters: usize) -> TrainConfig {
    let mut c = TrainConfig::preset(method);
    c.iterations = iters;
    c.init.interval = 4; // 8^3 = 512 Gaussians
    c.densify.from_iter = 10;
    c.densify.until_iter = iters.saturating_sub(10);
    c.densify.interval = 10;
    c.densify.opacity_reset_interval = 1000;
    c.densify.grad_threshold = 1e-4;
    c.feature_step_interval = 20;
    c.lr.position_max_steps = iters;
    c.eval_iterations = vec![1];
    c.checkpoint_every = 10;
    c.preview_views = 2;
    // The paper's learning rates are tuned for 20000 iterations; ten times larger ones let a
    // few dozen iterations show progress.
    c.lr.feature *= 10.0;
    c.lr.opacity *= 10.0;
    c.lr.scaling *= 10.0;
    c.lr.rotation *= 10.0;
    c
}

fn quiet(_: &Event) {}

#[test]
fn loss_decreases_on_a_tiny_dataset() {
    let ds = dataset();
    for method in [Method::Xgaussian, Method::Unispine, Method::Gs3d] {
        let mut c = tiny(method, 80);
        c.spwm_time_scale = 100.0; // SPWM weights active from iteration ~21 on
        let mut losses = Vec::new();
        let stop = AtomicBool::new(false);
        let m = train::run(&c, &ds, None, &stop, &mut |e: &Event| {
            if let Event::Progress { loss, .. } = e {
                losses.push(*loss);
            }
        })
        .unwrap();
        assert_eq!(losses.len(), 80);
        let first: f64 = losses[..8].iter().sum::<f64>() / 8.0;
        let last: f64 = losses[72..].iter().sum::<f64>() / 8.0;
        assert!(last < 0.7 * first, "{method:?}: loss {first} -> {last}");
        let (p0, p1) = (m.evals[0].psnr, m.evals.last().unwrap().psnr);
        assert!(p1 > p0 + 10.0, "{method:?}: test PSNR {p0} -> {p1}");
        assert!(m.evals.last().unwrap().iteration == 80);
    }
}

fn run_in_pool(threads: usize, dir: &Path) -> train::Metrics {
    let ds = dataset();
    let c = tiny(Method::Unispine, 40);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| train::run(&c, &ds, Some(dir), &AtomicBool::new(false), &mut quiet))
        .unwrap()
}

#[test]
fn short_run_is_bit_identical_for_1_and_2_threads() {
    let d1 = tempfile::tempdir().unwrap();
    let d2 = tempfile::tempdir().unwrap();
    let m1 = run_in_pool(1, d1.path());
    let m2 = run_in_pool(2, d2.path());
    assert_eq!(m1.evals, m2.evals);
    assert_eq!(m1.n_gaussians, m2.n_gaussians);
    for f in ["model.ply", "checkpoint.ply"] {
        let a = std::fs::read(d1.path().join(f)).unwrap();
        let b = std::fs::read(d2.path().join(f)).unwrap();
        assert!(a == b, "{f} differs between 1 and 2 threads");
    }
    // log.csv without the wall-clock column
    let strip = |p: &Path| -> Vec<String> {
        std::fs::read_to_string(p.join("log.csv"))
            .unwrap()
            .lines()
            .map(|l| l.rsplit_once(',').unwrap().0.to_string())
            .collect()
    };
    assert_eq!(strip(d1.path()), strip(d2.path()));
    // The run folder is complete.
    for f in [
        "config.json",
        "metrics.json",
        "log.csv",
        "model.ply",
        "checkpoint.json",
    ] {
        assert!(d1.path().join(f).exists(), "{f} missing");
    }
    assert_eq!(
        std::fs::read_dir(d1.path().join("previews"))
            .unwrap()
            .count(),
        2
    );
    assert_eq!(strip(d1.path()).len(), 41);
}

#[test]
fn divergence_stops_with_iteration_and_view() {
    let ds = dataset();
    // Injected NaN in a parameter.
    let mut t = Trainer::new(tiny(Method::Xgaussian, 30), &ds).unwrap();
    for _ in 0..3 {
        t.step().unwrap();
    }
    t.state.params.opacity_logits[7] = f32::NAN;
    match t.step() {
        Err(Error::Diverged { iteration, what }) => {
            assert_eq!(iteration, 4);
            assert!(what.contains("training view"), "{what}");
            assert!(what.contains("Gaussian 7"), "{what}");
        }
        other => panic!("expected Diverged, got {other:?}"),
    }
    // A learning rate that blows the means up: the run stops, the last good checkpoint stays.
    let dir = tempfile::tempdir().unwrap();
    let mut c = tiny(Method::Xgaussian, 30);
    c.lr.position_init = 1e38;
    c.lr.position_final = 1e38;
    c.checkpoint_every = 1;
    let e = train::run(
        &c,
        &ds,
        Some(dir.path()),
        &AtomicBool::new(false),
        &mut quiet,
    )
    .unwrap_err();
    let Error::Diverged { iteration, what } = e else {
        panic!("expected Diverged, got {e:?}")
    };
    assert_eq!(iteration, 1, "{what}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(j["iteration"], 0);
    let g = ply::read_ply::<f32>(&dir.path().join("checkpoint.ply")).unwrap();
    g.check_finite().unwrap();
    assert!(!dir.path().join("model.ply").exists());
}

#[test]
fn stop_request_writes_a_checkpoint() {
    let ds = dataset();
    let dir = tempfile::tempdir().unwrap();
    let c = tiny(Method::Xgaussian, 30);
    let stop = AtomicBool::new(false);
    let m = train::run(&c, &ds, Some(dir.path()), &stop, &mut |e: &Event| {
        if let Event::Progress { iteration: 5, .. } = e {
            stop.store(true, Ordering::SeqCst);
        }
    })
    .unwrap();
    assert!(!m.completed);
    assert_eq!(m.iterations, 5);
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(j["iteration"], 5);
    assert!(dir.path().join("metrics.json").exists());
}

#[test]
fn presets_parse_and_round_trip() {
    for m in [
        Method::Gs3d,
        Method::Xgaussian,
        Method::Unispine,
        Method::SpwmOnly,
    ] {
        let c = TrainConfig::preset(m);
        let s = serde_json::to_string(&c).unwrap();
        let back: TrainConfig = serde_json::from_str(&s).unwrap();
        assert_eq!(back, c);
        assert_eq!(c.iterations, 20_000);
        assert_eq!(c.densify.grad_threshold, 1.5e-4);
    }
    let u = TrainConfig::preset(Method::Unispine);
    assert!(u.spwm.is_some() && u.color == ColorMode::RirfXgaussian);
    let s = TrainConfig::preset(Method::SpwmOnly);
    assert!(s.spwm.is_some() && s.color == ColorMode::Sh);
    assert_eq!(s.init.kind, unispine::gaussians::init::InitKind::Random);
    let x = TrainConfig::preset(Method::Xgaussian);
    assert!(x.spwm.is_none() && x.loss.data_term == unispine::loss::DataTerm::L1);
    // Command line: preset + flag-by-flag overrides.
    let cli = unispine::cli::Cli::try_parse_from([
        "unispine",
        "train",
        "--data",
        "d",
        "--method",
        "3dgs",
        "--out",
        "o",
        "--iters",
        "50",
        "--color",
        "rirf-paper",
        "--spwm",
        "true",
        "--max-gaussians",
        "1000",
        "--eval-iterations",
        "10,20",
    ])
    .unwrap();
    let unispine::cli::Command::Train(a) = cli.command else {
        panic!()
    };
    let c = a
        .overrides
        .apply(a.method.gaussians().unwrap(), a.iters)
        .unwrap();
    assert_eq!(c.method, Method::Gs3d);
    assert_eq!(c.iterations, 50);
    assert_eq!(c.color, ColorMode::RirfPaper);
    assert!(c.spwm.is_some());
    assert_eq!(c.densify.max_gaussians, Some(1000));
    assert_eq!(c.eval_points(), vec![10, 20, 50]);
    assert!(unispine::cli::Cli::try_parse_from([
        "unispine", "train", "--data", "d", "--out", "o", "--color", "rgb"
    ])
    .is_err());
}

#[test]
fn eval_matches_a_direct_computation() {
    let ds = dataset();
    let dir = tempfile::tempdir().unwrap();
    let c = tiny(Method::Unispine, 20);
    let m = train::run(
        &c,
        &ds,
        Some(dir.path()),
        &AtomicBool::new(false),
        &mut quiet,
    )
    .unwrap();
    let g = ply::read_ply::<f32>(&dir.path().join("model.ply")).unwrap();
    let targets = unispine::eval::test_targets(&ds).unwrap();
    let r = unispine::eval::evaluate(&g, &ds, &targets, &m.render).unwrap();
    // Same model (via PLY) and protocol as the final in-loop evaluation.
    assert!(
        (r.psnr - m.test_psnr.unwrap()).abs() < 1e-3,
        "{} vs {:?}",
        r.psnr,
        m.test_psnr
    );
    // Direct: normalise GT, render, clamp, MSE, PSNR, by hand.
    let mut psnr = 0.0;
    for k in 0..ds.test.angles.len() {
        let p = &ds.test.projections[k];
        let lo = p.data.iter().cloned().fold(f32::INFINITY, f32::min) as f64;
        let hi = p.data.iter().cloned().fold(f32::NEG_INFINITY, f32::max) as f64;
        let (img, _) = render::forward(&g, &ds.test_camera(k), &m.render).unwrap();
        let mut se = 0.0;
        for i in 0..p.data.len() {
            let gt = (p.data[i] as f64 - lo) / (hi - lo);
            let x = (img.data[i] as f64).clamp(0.0, 1.0);
            se += (x - gt).powi(2);
        }
        let mse = se / p.data.len() as f64;
        psnr += -10.0 * mse.log10() / ds.test.angles.len() as f64;
    }
    assert!((psnr - r.psnr).abs() < 1e-4, "{psnr} vs {}", r.psnr);
    let ssim0 = unispine::loss::ssim::ssim(
        &unispine::eval::clamp01(
            &render::forward(&g, &ds.test_camera(0), &m.render)
                .unwrap()
                .0,
        ),
        &targets[0],
    );
    assert_eq!(ssim0, r.views[0].ssim);
    let _ = Image2d::<f32>::filled(1, 1, 0.0);
}
