//! Adam against a hand computation (torch.optim.Adam, betas (0.9, 0.999), eps 1e-15).
//!
//! One parameter p0 = 1, gradients g1 = 0.5 then g2 = -0.25, lr = 0.1:
//! - step 1: m = 0.05, v = 0.00025, bias corrections 0.1 and 0.001, so
//!   p1 = 1 - (0.1 / 0.1) * 0.05 / (sqrt(0.00025) / sqrt(0.001)) = 1 - 0.05 / 0.5 = 0.9
//!   (Adam's first step moves every element by exactly lr * sign(g));
//! - step 2: m = 0.9 * 0.05 + 0.1 * (-0.25) = 0.02,
//!   v = 0.999 * 0.00025 + 0.001 * 0.0625 = 0.00031225, bias corrections 0.19 and 0.001999, so
//!   p2 = 0.9 - (0.1 / 0.19) * 0.02 / sqrt(0.00031225 / 0.001999) = 0.87336629603396.

use unispine::gaussians::Gaussians;
use unispine::optim::{Adam, AdamConfig, Group, N_GROUPS};

fn one(v: f64) -> Gaussians<f64> {
    let mut g = Gaussians::<f64>::zeros(1);
    g.means[0] = [v; 3];
    g.log_scales[0] = [v; 3];
    g.quats[0] = [v; 4];
    g.opacity_logits[0] = v;
    g.features[0] = [v; 16];
    g
}

fn all_values(g: &Gaussians<f64>) -> Vec<f64> {
    let mut out = Vec::new();
    out.extend(g.means[0]);
    out.extend(g.log_scales[0]);
    out.extend(g.quats[0]);
    out.push(g.opacity_logits[0]);
    out.extend(g.features[0]);
    out
}

#[test]
fn one_and_two_steps_match_the_hand_computation() {
    let mut p = one(1.0);
    let mut adam = Adam::<f64>::new(AdamConfig::default(), 1);
    let lr = [0.1; N_GROUPS];
    adam.step(&mut p, &one(0.5), &lr, &[true; N_GROUPS]);
    for x in all_values(&p) {
        assert!((x - 0.9).abs() < 1e-15, "step 1: {x}");
    }
    for x in all_values(&adam.m) {
        assert!((x - 0.05).abs() < 1e-16);
    }
    for x in all_values(&adam.v) {
        assert!((x - 0.00025).abs() < 1e-18 * 10.0);
    }
    adam.step(&mut p, &one(-0.25), &lr, &[true; N_GROUPS]);
    for x in all_values(&p) {
        assert!((x - 0.87336629603396).abs() < 1e-13, "step 2: {x}");
    }
    for x in all_values(&adam.m) {
        assert!((x - 0.02).abs() < 1e-16 * 2.0);
    }
    for x in all_values(&adam.v) {
        assert!((x - 0.00031225).abs() < 1e-18 * 10.0);
    }
    assert_eq!(adam.steps, [2; N_GROUPS]);
}

#[test]
fn f32_follows_f64() {
    let mut p64 = one(1.0);
    let mut p32 = p64.cast::<f32>();
    let mut a64 = Adam::<f64>::new(AdamConfig::default(), 1);
    let mut a32 = Adam::<f32>::new(AdamConfig::default(), 1);
    let lr = [0.1; N_GROUPS];
    for g in [0.5, -0.25, 0.125] {
        a64.step(&mut p64, &one(g), &lr, &[true; N_GROUPS]);
        a32.step(&mut p32, &one(g).cast(), &lr, &[true; N_GROUPS]);
    }
    for (a, b) in all_values(&p64).iter().zip(all_values(&p32.cast())) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
}

#[test]
fn per_group_learning_rates_and_skipped_groups() {
    // Groups: xyz, f_dc, f_rest, opacity, scaling, rotation. First step moves by exactly lr.
    let lr = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let mut p = one(0.0);
    let mut adam = Adam::<f64>::new(AdamConfig::default(), 1);
    let mut active = [true; N_GROUPS];
    active[Group::Opacity as usize] = false;
    adam.step(&mut p, &one(1.0), &lr, &active);
    // (1 - b1 rounds 0.1 to 0.09999999999999998 in f64: a few ulps.)
    let close = |x: f64, y: f64| (x - y).abs() < 1e-14 * y.abs();
    assert!(p.means[0].iter().all(|&x| close(x, -1.0)));
    assert!(close(p.features[0][0], -2.0));
    assert!(p.features[0][1..].iter().all(|&x| close(x, -3.0)));
    assert_eq!(p.opacity_logits[0], 0.0, "skipped group must not move");
    assert_eq!(
        adam.m.opacity_logits[0], 0.0,
        "skipped group keeps its moments"
    );
    assert!(p.log_scales[0].iter().all(|&x| close(x, -5.0)));
    assert!(p.quats[0].iter().all(|&x| close(x, -6.0)));
    assert_eq!(adam.steps, [1, 1, 1, 0, 1, 1]);
    // Second step of the opacity group is its first: it moves by exactly lr again.
    adam.step(&mut p, &one(1.0), &lr, &[true; N_GROUPS]);
    assert!(close(p.opacity_logits[0], -4.0));
    // The opacity reset zeroes its moments only.
    adam.zero_opacity_moments();
    assert_eq!(adam.m.opacity_logits[0], 0.0);
    assert_eq!(adam.v.opacity_logits[0], 0.0);
    assert!(adam.m.means[0][0] != 0.0);
}

#[test]
fn thread_count_does_not_change_bits() {
    let n = 10_007;
    let mk = |s: f64| {
        let mut g = Gaussians::<f32>::zeros(n);
        for i in 0..n {
            let x = ((i as f64 * 0.37 + s).sin()) as f32;
            g.means[i] = [x, -x, 0.5 * x];
            g.log_scales[i] = [x; 3];
            g.quats[i] = [1.0, x, 0.0, -x];
            g.opacity_logits[i] = x;
            g.features[i] = [x; 16];
        }
        g
    };
    let run = |t: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        pool.install(|| {
            let mut p = mk(0.0);
            let mut a = Adam::<f32>::new(AdamConfig::default(), n);
            for s in 1..4 {
                a.step(&mut p, &mk(s as f64), &[1e-3; N_GROUPS], &[true; N_GROUPS]);
            }
            p
        })
    };
    assert_eq!(run(1), run(2));
}

/// Every SIMD path gives the same bits (each element does the same operations), for every
/// group on and for a partial set (features split into their two groups, opacity off), over a
/// length that leaves remainders for every lane count.
#[test]
fn every_simd_path_gives_the_same_bits() {
    use rand::{RngExt, SeedableRng};
    use unispine::simd::Simd;
    let n = 1037;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut rand_g = |scale: f64| {
        let mut g = Gaussians::<f64>::zeros(n);
        for i in 0..n {
            g.means[i] = std::array::from_fn(|_| scale * (rng.random::<f64>() - 0.5));
            g.log_scales[i] = std::array::from_fn(|_| scale * (rng.random::<f64>() - 0.5));
            g.quats[i] = std::array::from_fn(|_| scale * (rng.random::<f64>() - 0.5));
            g.opacity_logits[i] = scale * (rng.random::<f64>() - 0.5);
            g.features[i] = std::array::from_fn(|_| scale * (rng.random::<f64>() - 0.5));
        }
        g.cast::<f32>()
    };
    let p0 = rand_g(2.0);
    let grads: Vec<Gaussians<f32>> = (0..3).map(|_| rand_g(1e-3)).collect();
    let lr = [1.6e-4, 0.025, 0.00125, 0.05, 0.005, 0.001];
    let mut partial = [true; N_GROUPS];
    partial[Group::Opacity as usize] = false;
    let run = |simd: Simd| {
        let mut p = p0.clone();
        let mut adam = Adam::<f32>::new(AdamConfig::default(), n);
        for (k, g) in grads.iter().enumerate() {
            let active = if k == 1 { partial } else { [true; N_GROUPS] };
            adam.step_with(simd, &mut p, g, &lr, &active);
        }
        (p, adam)
    };
    let want = run(Simd::Scalar);
    assert_ne!(want.0, p0);
    for s in Simd::ALL {
        let got = run(s);
        // Gaussians<f32> equality is exact (no NaN here), so this compares bits.
        assert_eq!(got.0, want.0, "{s:?}");
        assert_eq!(got.1, want.1, "{s:?}");
    }
}

/// The flat (neural-field) Adam by hand: p = 1, g = 0.5 then g = -1, lr 0.1, eps 1e-8.
#[test]
fn flat_adam_two_steps_by_hand() {
    use unispine::optim::FlatAdam;
    let mut a = FlatAdam::<f64>::new(1);
    let mut p = vec![1.0];
    a.update(&mut p, &[0.5], 0.1);
    // t = 1: m = 0.05, v = 0.00025; m / bc1 = 0.5, sqrt(v / bc2) = 0.5 -> step 0.1 * 1.
    assert!((p[0] - (1.0 - 0.1 * 0.5 / (0.5 + 1e-8))).abs() < 1e-15);
    a.update(&mut p, &[-1.0], 0.1);
    let m: f64 = 0.9 * 0.05 - 0.1;
    let v: f64 = 0.999 * 0.00025 + 0.001;
    let want = 1.0
        - 0.1 * 0.5 / (0.5 + 1e-8)
        - (0.1 / (1.0 - 0.81)) * m / (v.sqrt() / (1.0 - 0.999f64.powi(2)).sqrt() + 1e-8);
    assert!((p[0] - want).abs() < 1e-14, "{} {want}", p[0]);
    assert_eq!(a.step, 2);
}

/// The flat Adam runs the shared kernel in the order `(step_size * m) / denom`: bit for bit
/// the scalar loop written out here (an independent copy of the update the neural fields were
/// trained with), over a length that leaves remainders for every lane count, and not the same
/// bits as the other order (so the test can tell the two apart).
#[test]
fn flat_adam_gives_the_bits_of_its_scalar_loop() {
    use rand::{RngExt, SeedableRng};
    use unispine::optim::FlatAdam;
    let n = 5003;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let p0: Vec<f32> = (0..n).map(|_| rng.random::<f32>() - 0.5).collect();
    let grads: Vec<Vec<f32>> = (0..4)
        .map(|_| (0..n).map(|_| 1e-2 * (rng.random::<f32>() - 0.5)).collect())
        .collect();
    let lrs = [1e-3, 5e-4, 5e-4, 1e-4];
    let (mut p, mut a) = (p0.clone(), FlatAdam::<f32>::new(n));
    for (g, &lr) in grads.iter().zip(&lrs) {
        a.update(&mut p, g, lr);
    }
    let reference = |scaled_first: bool| {
        let (mut q, mut m, mut v) = (p0.clone(), vec![0f32; n], vec![0f32; n]);
        for (k, (g, &lr)) in grads.iter().zip(&lrs).enumerate() {
            let t = k as i32 + 1;
            let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
            let step_size = (lr / (1.0 - b1.powi(t))) as f32;
            let bc2s = (1.0 - b2.powi(t)).sqrt() as f32;
            for i in 0..n {
                m[i] = b1 as f32 * m[i] + (1.0 - b1) as f32 * g[i];
                v[i] = b2 as f32 * v[i] + (1.0 - b2) as f32 * g[i] * g[i];
                let denom = v[i].sqrt() / bc2s + eps as f32;
                if scaled_first {
                    q[i] -= step_size * m[i] / denom;
                } else {
                    q[i] -= step_size * (m[i] / denom);
                }
            }
        }
        (q, m, v)
    };
    let (q, m, v) = reference(true);
    let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&p), bits(&q));
    assert_eq!(bits(&a.m), bits(&m));
    assert_eq!(bits(&a.v), bits(&v));
    assert_ne!(bits(&p), bits(&reference(false).0));
}
