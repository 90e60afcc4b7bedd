//! The trainer end to end on a tiny synthetic dataset (32 x 32 detector, 8 training and 4 test
//! views, 512 ACUI Gaussians, tens of iterations). The ground truth is rendered from a hidden
//! set of 12 Gaussians, so no projector is needed.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use unispine::error::Error;
use unispine::gaussians::ply;
use unispine::image2d::Image2d;
use unispine::render::{self, ColorMode};
use unispine::session::{self, Control};
use unispine::train::{self, Event, Method, Metrics, RunDir, TrainConfig, TrainOverrides, Trainer};

/// A Gaussian run through the session driver, stopped by `stop`.
fn run_gaussians(
    c: &TrainConfig,
    ds: &unispine::dataset::Dataset,
    out: Option<&std::path::Path>,
    stop: &AtomicBool,
    on_event: &mut dyn FnMut(&Event),
) -> unispine::Result<Metrics> {
    session::run(&c.clone().into(), ds, out, Control::new(stop), on_event)
}

use crate::common;
use common::tiny;
use tiny::{dataset, tiny};

fn quiet(_: &Event) {}

#[test]
fn loss_decreases_on_a_tiny_dataset() {
    let ds = dataset();
    for method in [Method::Xgaussian, Method::Unispine, Method::Gs3d] {
        let mut c = tiny(method, 80);
        c.spwm_time_scale = 100.0; // SPWM weights active from iteration ~21 on
        let mut losses = Vec::new();
        let stop = AtomicBool::new(false);
        let m = run_gaussians(&c, &ds, None, &stop, &mut |e: &Event| {
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
    pool.install(|| run_gaussians(&c, &ds, Some(dir), &AtomicBool::new(false), &mut quiet))
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
    let a = std::fs::read(d1.path().join("model.ply")).unwrap();
    let b = std::fs::read(d2.path().join("model.ply")).unwrap();
    assert!(a == b, "model.ply differs between 1 and 2 threads");
    let (c1, c2) = (
        RunDir::open(d1.path()).unwrap().read_checkpoint().unwrap(),
        RunDir::open(d2.path()).unwrap().read_checkpoint().unwrap(),
    );
    assert_eq!(c1.state.params, c2.state.params);
    assert_eq!(c1.state.adam, c2.state.adam);
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
        "checkpoint.bin",
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
    // Every Gaussian moved far out of the scene: nothing is rendered any more.
    let mut t = Trainer::new(tiny(Method::Xgaussian, 30), &ds).unwrap();
    t.step().unwrap();
    t.state.params.means.iter_mut().for_each(|m| m[0] += 1e7);
    match t.step() {
        Err(Error::Diverged { iteration, what }) => {
            assert_eq!(iteration, 2);
            assert!(what.contains("nothing is rendered"), "{what}");
        }
        other => panic!("expected Diverged, got {other:?}"),
    }
    // The largest position learning rate allowed moves the means by a scene extent per step:
    // the run stops as diverged, and the last good checkpoint stays.
    let dir = tempfile::tempdir().unwrap();
    let mut c = tiny(Method::Xgaussian, 30);
    c.lr.position_init = 1.0;
    c.lr.position_final = 1.0;
    c.checkpoint_every = 1;
    let e = run_gaussians(
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
    assert!(
        what.contains("nothing is rendered") || what.contains("left the scene"),
        "{what}"
    );
    let c = RunDir::open(dir.path()).unwrap().read_checkpoint().unwrap();
    assert_eq!(c.iteration, iteration - 1);
    c.state.params.check_finite().unwrap();
    assert!(!dir.path().join("model.ply").exists());
    assert!(!dir.path().join("metrics.json").exists());
}

#[test]
fn stop_request_writes_a_checkpoint() {
    let ds = dataset();
    let dir = tempfile::tempdir().unwrap();
    let c = tiny(Method::Xgaussian, 30);
    let stop = AtomicBool::new(false);
    let m = run_gaussians(&c, &ds, Some(dir.path()), &stop, &mut |e: &Event| {
        if let Event::Progress { iteration: 5, .. } = e {
            stop.store(true, Ordering::SeqCst);
        }
    })
    .unwrap();
    assert!(!m.completed);
    assert_eq!(m.iterations, 5);
    let c = RunDir::open(dir.path()).unwrap().read_checkpoint().unwrap();
    assert_eq!(c.iteration, 5);
    let saved = RunDir::open(dir.path()).unwrap().read_metrics().unwrap();
    assert!(!saved.completed && saved.test_psnr.is_none());
    assert_eq!(saved.n_gaussians, c.state.len());
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
    // Command line: preset + flag-by-flag overrides, parsed by the library's settings table.
    let method = unispine::method::TrainMethod::parse("3dgs").unwrap();
    let argv: Vec<String> = [
        "--color",
        "rirf-paper",
        "--spwm",
        "true",
        "--max-gaussians",
        "1000",
        "--eval-iterations",
        "10,20",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let c = unispine::flags::parse_set::<TrainOverrides>(&argv)
        .unwrap()
        .apply(method.gaussians().unwrap(), Some(50))
        .unwrap();
    assert_eq!(c.method, Method::Gs3d);
    assert_eq!(c.iterations, 50);
    assert_eq!(c.color, ColorMode::RirfPaper);
    assert!(c.spwm.is_some());
    assert_eq!(c.densify.max_gaussians, Some(1000));
    assert_eq!(c.eval_points(), vec![10, 20, 50]);
    assert!(
        unispine::flags::parse_set::<TrainOverrides>(&["--color".into(), "rgb".into()]).is_err()
    );
    assert!(unispine::method::TrainMethod::parse("rgb").is_err());
    assert!(unispine::method::TrainMethod::parse("fdk")
        .unwrap()
        .gaussians()
        .is_none());
}

#[test]
fn eval_matches_a_direct_computation() {
    let ds = dataset();
    let dir = tempfile::tempdir().unwrap();
    let c = tiny(Method::Unispine, 20);
    let m = run_gaussians(
        &c,
        &ds,
        Some(dir.path()),
        &AtomicBool::new(false),
        &mut quiet,
    )
    .unwrap();
    let g = ply::read_ply::<f32>(&dir.path().join("model.ply")).unwrap();
    let targets = unispine::dataset::targets::test_targets(&ds).unwrap();
    let r = unispine::eval::evaluate(&g, &ds, &targets, &m.render).unwrap();
    // Same model (via PLY) and protocol as the final in-loop evaluation: the same bits.
    assert_eq!(Some(r.psnr), m.test_psnr);
    assert_eq!(Some(r.ssim), m.test_ssim);
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
