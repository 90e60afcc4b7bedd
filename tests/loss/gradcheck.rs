//! Audit of the losses of Eqs. (8)-(9) and of SSIM:
//! - every analytic gradient (SSIM, L1, Charbonnier, weighted Charbonnier, the Eq. (8) totals)
//!   against central finite differences in f64 (`math::fd`), on non-square 13x17 random images,
//!   max-abs-normalised error <= 1e-6;
//! - bit-identical loss values and gradients for 1, 2 and 3 threads (f32 and f64);
//! - SSIM(x, x) = 1, symmetry, and a closed form on a hand-checked 1x1 case;
//! - f32 against f64 for the trainer's precision.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use unispine::image2d::Image2d;
use unispine::loss::charbonnier::{charbonnier, l1, weighted_charbonnier};
use unispine::loss::spwm::{self, GateKind, SpwmConfig};
use unispine::loss::ssim::{self, ssim, ssim_forward_backward};
use unispine::loss::{forward_backward, DataTerm, LossConfig};
use unispine::math::fd::{central_diff5, rel_err_maxabs};

const W: usize = 13;
const H: usize = 17;
const TOL: f64 = 1e-6;

fn random(seed: u64, lo: f64, hi: f64) -> Image2d<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Image2d::from_vec(
        W,
        H,
        (0..W * H)
            .map(|_| lo + (hi - lo) * rng.random::<f64>())
            .collect(),
    )
}

/// A GT with structure (a bright disc and a ramp) so SPWM gates are non-trivial.
fn structured_gt(seed: u64) -> Image2d<f64> {
    let noise = random(seed, 0.0, 0.1);
    let data = (0..W * H)
        .map(|p| {
            let (r, c) = ((p / W) as f64, (p % W) as f64);
            let disc = if (r - 8.0).powi(2) + (c - 6.0).powi(2) < 16.0 {
                0.7
            } else {
                0.0
            };
            0.1 + disc + 0.02 * c + noise.data[p]
        })
        .collect();
    Image2d::from_vec(W, H, data)
}

/// Residuals whose magnitude is at least `min_abs` (for L1, away from the kink).
fn render_near(gt: &Image2d<f64>, seed: u64, min_abs: f64, max_abs: f64) -> Image2d<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let data = gt
        .data
        .iter()
        .map(|&g| {
            let m = min_abs + (max_abs - min_abs) * rng.random::<f64>();
            let s = if rng.random::<bool>() { 1.0 } else { -1.0 };
            g + s * m
        })
        .collect();
    Image2d::from_vec(W, H, data)
}

fn img(v: &[f64]) -> Image2d<f64> {
    Image2d::from_vec(W, H, v.to_vec())
}

fn check(name: &str, analytic: &[f64], f: impl FnMut(&[f64]) -> f64 + Send, x: &[f64], h: f64) {
    // Thousands of tiny evaluations: one thread avoids the cross-thread wake-ups (the values
    // do not depend on the thread count, see `loss_and_gradient_are_thread_count_invariant`).
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let num = pool.install(|| central_diff5(f, x, h));
    let err = rel_err_maxabs(analytic, &num);
    println!("{name}: max-abs-normalised error {err:.3e}");
    assert!(err <= TOL, "{name}: error {err:e} > {TOL:e}");
}

#[test]
fn ssim_gradient_matches_finite_differences() {
    for (k, (x, y)) in [
        (random(1, 0.0, 1.0), random(2, 0.0, 1.0)),
        // Correlated pair (high SSIM): the gradient is small and easy to get subtly wrong.
        (random(3, 0.0, 1.0), random(3, 0.0, 1.0)),
    ]
    .into_iter()
    .enumerate()
    {
        let y = if k == 1 {
            img(&y
                .data
                .iter()
                .zip(&random(4, -0.05, 0.05).data)
                .map(|(a, b)| a + b)
                .collect::<Vec<_>>())
        } else {
            y
        };
        let (v, g) = ssim_forward_backward(&x, &y);
        assert_eq!(v.to_bits(), ssim(&x, &y).to_bits());
        check(
            &format!("ssim pair {k}"),
            &g.data,
            |p| ssim(&img(p), &y),
            &x.data,
            1e-4,
        );
    }
}

#[test]
fn data_term_gradients_match_finite_differences() {
    let gt = random(10, 0.0, 1.0);
    // L1 with every |residual| >= 0.01 (the stencil spans 4e-4 and never crosses the kink).
    let r = render_near(&gt, 11, 0.01, 0.3);
    let (_, g) = l1(&r, &gt);
    check("l1", &g.data, |p| l1(&img(p), &gt).0, &r.data, 1e-4);
    // L1 subgradient is 0 at a zero residual.
    let (v0, g0) = l1(&gt, &gt);
    assert_eq!(v0, 0.0);
    assert!(g0.data.iter().all(|&v| v == 0.0));

    // Charbonnier with residuals from ~eps (the curved part) to 0.3; step well below eps.
    let r = render_near(&gt, 12, 2e-4, 0.3);
    let eps = 1e-3;
    let (_, g) = charbonnier(&r, &gt, eps);
    check(
        "charbonnier",
        &g.data,
        |p| charbonnier(&img(p), &gt, eps).0,
        &r.data,
        1e-6,
    );

    // Weighted Charbonnier, Eq. (9), with SPWM weights at full strength and with w = 1.
    let cfg = SpwmConfig::default();
    let gts = structured_gt(13);
    let r = render_near(&gts, 14, 2e-4, 0.3);
    let w = spwm::weights(&spwm::view_prior(&gts, &cfg), 9000, &cfg);
    assert!(
        w.data.iter().any(|&v| v > 1.1),
        "weights are all ~1: the test would be weak"
    );
    for (name, wo) in [
        ("weighted charbonnier", Some(&w)),
        ("weighted charbonnier w=1", None),
    ] {
        let (_, g) = weighted_charbonnier(&r, &gts, wo, eps, 1e-6);
        check(
            name,
            &g.data,
            |p| weighted_charbonnier(&img(p), &gts, wo, eps, 1e-6).0,
            &r.data,
            1e-6,
        );
    }
}

#[test]
fn hybrid_loss_gradients_match_finite_differences() {
    let gt = structured_gt(20);
    let r = render_near(&gt, 21, 2e-4, 0.25);
    let cfg = SpwmConfig::default();
    let w = spwm::weights(&spwm::view_prior(&gt, &cfg), 4500, &cfg);
    let r_l1 = render_near(&gt, 22, 0.01, 0.25);
    for (name, lc, render, wo) in [
        (
            "eq8 weighted charbonnier",
            LossConfig::weighted_charbonnier_dssim(),
            &r,
            Some(&w),
        ),
        ("eq8 charbonnier", LossConfig::charbonnier_dssim(), &r, None),
        ("eq8 l1", LossConfig::l1_dssim(), &r_l1, None),
    ] {
        let (v, g) = forward_backward(render, &gt, wo, &lc);
        let want = 0.8 * v.data + 0.2 * (1.0 - v.ssim);
        assert!((v.total - want).abs() < 1e-15, "{name}: total");
        assert_eq!(v.ssim.to_bits(), ssim(render, &gt).to_bits());
        let h = if lc.data_term == DataTerm::L1 {
            1e-4
        } else {
            1e-6
        };
        check(
            name,
            &g.data,
            |p| forward_backward(&img(p), &gt, wo, &lc).0.total,
            &render.data,
            h,
        );
    }
}

#[test]
fn ssim_identity_symmetry_and_closed_form() {
    let x = random(30, 0.0, 1.0);
    let y = random(31, 0.0, 1.0);
    let s = ssim(&x, &x);
    assert!((s - 1.0).abs() < 1e-14, "SSIM(x, x) = {s}");
    // At x = y the gradient of SSIM vanishes (a maximum).
    let (_, g) = ssim_forward_backward(&x, &x);
    assert!(g.data.iter().all(|v| v.abs() < 1e-13));
    assert_eq!(ssim(&x, &y).to_bits(), ssim(&y, &x).to_bits());
    assert!(ssim(&x, &y) < 0.5);

    // 1x1 images a, b: only the window centre w0 = g5^2 sees the image (zero padding), so
    // mu = w0 a, E[x^2] = w0 a^2, sigma_x^2 = w0 (1 - w0) a^2, sigma_xy = w0 (1 - w0) a b.
    let g: Vec<f64> = (0..11)
        .map(|k| (-((k as f64 - 5.0).powi(2)) / 4.5).exp())
        .collect();
    let g5 = g[5] / g.iter().sum::<f64>();
    let w0 = g5 * g5;
    let (a, b) = (0.7, 0.3);
    let (c1, c2) = (1e-4, 9e-4);
    let v = w0 * (1.0 - w0);
    let want = (2.0 * w0 * w0 * a * b + c1) * (2.0 * v * a * b + c2)
        / ((w0 * w0 * (a * a + b * b) + c1) * (v * (a * a + b * b) + c2));
    let got = ssim(
        &Image2d::from_vec(1, 1, vec![a]),
        &Image2d::from_vec(1, 1, vec![b]),
    );
    assert!((got - want).abs() < 1e-15, "{got} vs {want}");
    // Hand value: g5 = 1 / sum_k exp(-(k-5)^2/4.5) = 0.266011724..., w0 = 0.070762237...,
    // SSIM = 0.53568892...
    assert!((g5 - 0.266_011_724_9).abs() < 1e-9, "{g5}");
    assert!((want - 0.535_688_93).abs() < 1e-8, "{want}");
    assert_eq!(ssim::WINDOW, 11);
}

#[test]
fn loss_and_gradient_are_thread_count_invariant() {
    // Big enough (several CHUNKs of pixels) for the reductions to split.
    let (w, h) = (131, 97);
    let mut rng = ChaCha8Rng::seed_from_u64(40);
    let gt = Image2d::from_vec(w, h, (0..w * h).map(|_| rng.random::<f64>()).collect());
    let r = Image2d::from_vec(
        w,
        h,
        gt.data
            .iter()
            .map(|v| v + 0.1 * (rng.random::<f64>() - 0.5))
            .collect(),
    );
    let cfg = SpwmConfig::default();
    fn run<R: unispine::Real>(r: &Image2d<R>, gt: &Image2d<R>, cfg: &SpwmConfig) -> Vec<u64> {
        let mut bits = Vec::new();
        let prior = spwm::view_prior(gt, cfg);
        let wgt = spwm::weights(&prior, 5000, cfg);
        bits.extend(prior.data.iter().map(|v| v.f64().to_bits()));
        for lc in [
            LossConfig::weighted_charbonnier_dssim(),
            LossConfig::l1_dssim(),
        ] {
            let (v, g) = forward_backward(r, gt, Some(&wgt), &lc);
            bits.extend([v.total.to_bits(), v.data.to_bits(), v.ssim.to_bits()]);
            bits.extend(g.data.iter().map(|v| v.f64().to_bits()));
        }
        bits
    }
    let (r32, gt32) = (r.cast::<f32>(), gt.cast::<f32>());
    let mut all = Vec::new();
    for t in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        all.push(pool.install(|| (run(&r, &gt, &cfg), run(&r32, &gt32, &cfg))));
    }
    for o in &all[1..] {
        assert!(o.0 == all[0].0, "f64 bits differ with the thread count");
        assert!(o.1 == all[0].1, "f32 bits differ with the thread count");
    }
}

#[test]
fn f32_path_agrees_with_f64() {
    let gt = structured_gt(50);
    let r = render_near(&gt, 51, 1e-3, 0.2);
    let cfg = SpwmConfig::default();
    let w = spwm::weights(&spwm::view_prior(&gt, &cfg), 9000, &cfg);
    let lc = LossConfig::default();
    let (v64, g64) = forward_backward(&r, &gt, Some(&w), &lc);
    let (v32, g32) = forward_backward(
        &r.cast::<f32>(),
        &gt.cast::<f32>(),
        Some(&w.cast::<f32>()),
        &lc,
    );
    assert!(
        (v32.total - v64.total).abs() < 1e-6 * v64.total.abs(),
        "{v32:?} vs {v64:?}"
    );
    let g32: Vec<f64> = g32.data.iter().map(|&v| v as f64).collect();
    let err = rel_err_maxabs(&g32, &g64.data);
    assert!(err < 1e-4, "f32 gradient error {err:e}");
}

#[test]
fn spwm_weights_properties() {
    let gt = structured_gt(60);
    let cfg = SpwmConfig::default();
    let at = spwm::attention(&gt, &cfg);
    let prior = spwm::view_prior(&gt, &cfg);
    // A in [0, 1] with both ends reached (min exactly 0; max 1 - ~1e-6 / range).
    let amin = at
        .attention
        .data
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    let amax = at.attention.data.iter().cloned().fold(0.0, f64::max);
    assert_eq!(amin, 0.0);
    assert!(amax > 1.0 - 1e-5 && amax <= 1.0);
    // 15 % of the pixels (up to interpolation) are above tau; the gate is 0 below tau.
    let above = at.attention.data.iter().filter(|&&a| a > at.tau).count();
    assert!(
        (above as f64 - 0.15 * (W * H) as f64).abs() <= 1.0,
        "{above}"
    );
    for (&a, &g) in at.attention.data.iter().zip(&at.gate.data) {
        assert!((a <= at.tau) == (g == 0.0) && (0.0..=1.0).contains(&g));
    }
    // w = 1 up to t = 2000; w in [1, 1 + alpha]; w at 4500 is halfway to w at 7000.
    for t in [0, 2000] {
        assert!(spwm::weights(&prior, t, &cfg)
            .data
            .iter()
            .all(|&v| v == 1.0));
    }
    let (w45, w70, w90) = (
        spwm::weights(&prior, 4500, &cfg),
        spwm::weights(&prior, 7000, &cfg),
        spwm::weights(&prior, 9000, &cfg),
    );
    assert_eq!(w70, w90);
    for p in 0..W * H {
        assert!((1.0..=1.8).contains(&w70.data[p]));
        assert!(((w45.data[p] - 1.0) - 0.5 * (w70.data[p] - 1.0)).abs() < 1e-15);
    }
    assert!(w70.data.iter().any(|&v| v > 1.3));
    // The sigmoid gate is smooth: positive everywhere, 1/2 at tau.
    let sig = spwm::attention(
        &gt,
        &SpwmConfig {
            gate: GateKind::Sigmoid,
            ..cfg.clone()
        },
    );
    assert_eq!(sig.tau, at.tau);
    assert!(sig.gate.data.iter().all(|&g| g > 0.0 && g < 1.0));
}

/// Figures for docs/measurements.md (not a timed assertion):
/// `cargo test --release --test loss gradcheck::timing -- --ignored --nocapture`
/// (add `RAYON_NUM_THREADS=1` for one thread).
#[test]
#[ignore]
fn timing_at_256() {
    let (w, h) = (256, 256);
    let mut rng = ChaCha8Rng::seed_from_u64(70);
    let gt = Image2d::from_vec(w, h, (0..w * h).map(|_| rng.random::<f64>()).collect());
    let r = Image2d::from_vec(
        w,
        h,
        gt.data
            .iter()
            .map(|v| v + 0.05 * (rng.random::<f64>() - 0.5))
            .collect(),
    );
    let cfg = SpwmConfig::default();
    let (gt32, r32) = (gt.cast::<f32>(), r.cast::<f32>());
    let reps = 60;
    // The minimum over repetitions (the machine may be shared; the minimum is the least noisy).
    let time = |name: &str, f: &mut dyn FnMut()| {
        f();
        let mut best = f64::INFINITY;
        for _ in 0..reps {
            let t = std::time::Instant::now();
            f();
            best = best.min(t.elapsed().as_secs_f64() * 1e3);
        }
        println!(
            "{name}: {best:.3} ms ({} threads)",
            rayon::current_num_threads()
        );
    };
    let prior32 = spwm::view_prior(&gt32, &cfg);
    let w32 = spwm::weights(&prior32, 9000, &cfg);
    let lc = LossConfig::default();
    time("spwm::view_prior f32 256x256", &mut || {
        std::hint::black_box(spwm::view_prior(&gt32, &cfg));
    });
    time("spwm::weights f32 256x256", &mut || {
        std::hint::black_box(spwm::weights(&prior32, 9000, &cfg));
    });
    time(
        "forward_backward (w-charb + D-SSIM) f32 256x256",
        &mut || {
            std::hint::black_box(forward_backward(&r32, &gt32, Some(&w32), &lc));
        },
    );
    time("forward_backward (L1 + D-SSIM) f32 256x256", &mut || {
        std::hint::black_box(forward_backward(&r32, &gt32, None, &LossConfig::l1_dssim()));
    });
    let k11 = unispine::loss::filters::gaussian_kernel(11, 1.5, 0.0);
    time("blur 11 taps f32 256x256", &mut || {
        std::hint::black_box(unispine::loss::filters::blur(&r32, &k11));
    });
    time("ssim_forward_backward f32 256x256", &mut || {
        std::hint::black_box(ssim_forward_backward(&r32, &gt32));
    });
    time("weighted_charbonnier f32 256x256", &mut || {
        std::hint::black_box(weighted_charbonnier(&r32, &gt32, Some(&w32), 1e-3, 1e-6));
    });
    time("l1 f32 256x256", &mut || {
        std::hint::black_box(l1(&r32, &gt32));
    });
    time("det_sum_by |e| f32 256x256", &mut || {
        std::hint::black_box(unispine::par::det_sum_by(r32.data.len(), |p| {
            (r32.data[p] as f64 - gt32.data[p] as f64).abs()
        }));
    });
    time("ssim f32 256x256", &mut || {
        std::hint::black_box(ssim(&r32, &gt32));
    });
    let w64 = spwm::weights(&spwm::view_prior(&gt, &cfg), 9000, &cfg);
    time(
        "forward_backward (w-charb + D-SSIM) f64 256x256",
        &mut || {
            std::hint::black_box(forward_backward(&r, &gt, Some(&w64), &lc));
        },
    );
    let (v64, g64) = forward_backward(&r, &gt, Some(&w64), &lc);
    let (v32, g32) = forward_backward(&r32, &gt32, Some(&w32), &lc);
    let g32: Vec<f64> = g32.data.iter().map(|&v| v as f64).collect();
    println!(
        "f32 vs f64 at 256x256: total rel {:.2e}, gradient max-abs-normalised {:.2e}",
        ((v32.total - v64.total) / v64.total).abs(),
        rel_err_maxabs(&g32, &g64.data)
    );
}
