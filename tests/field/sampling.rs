//! Field rays (NAF / SAX-NeRF sampling) against the documented convention: stratified depths
//! (bins from a closed form, jitter replayed from the same seeded stream), sample points,
//! `delta` and the line integral of a constant field, NAF's constant near / far, and the
//! trainer's batch loss from those per-ray functions.

use rand::RngExt;
use unispine::field::render as fr;
use unispine::geometry::ConeBeam;

/// `linspace(near, far, n)` and its bins bounded by the midpoints (first and last bins half
/// width), written from the formula.
fn bins(near: f64, far: f64, n: usize) -> Vec<(f64, f64)> {
    if n == 1 {
        return vec![(near, near)];
    }
    let step = (far - near) / (n - 1) as f64;
    (0..n)
        .map(|i| {
            let c = near + step * i as f64;
            let lo = if i == 0 { near } else { c - step / 2.0 };
            let hi = if i + 1 == n { far } else { c + step / 2.0 };
            (lo, hi)
        })
        .collect()
}

#[test]
fn stratified_depths_fill_their_bins_from_near_to_far() {
    for &(near, far, n) in &[(0.7, 1.3, 2usize), (0.5, 1.5, 7), (0.2, 2.0, 64)] {
        let want_bins = bins(near, far, n);
        for ray in 0..20u64 {
            let mut rng = fr::ray_rng(11, 3, 5, ray);
            let mut replay = rng.clone();
            let t = fr::stratified(near, far, n, &mut rng);
            assert_eq!(t.len(), n);
            for (i, (&ti, &(lo, hi))) in t.iter().zip(&want_bins).enumerate() {
                let u: f64 = replay.random();
                let want = lo + (hi - lo) * u;
                assert!(
                    (ti - want).abs() <= 1e-14 * far,
                    "n {n} ray {ray} sample {i}: {ti} vs {want} (bin [{lo}, {hi}])"
                );
            }
        }
        // The first and last bins touch near and far: over 2000 rays the extreme samples come
        // within 0.5 % of a bin of the ends (a draw misses that with probability 0.995^2000).
        let (mut lo_min, mut hi_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for ray in 0..2000u64 {
            let t = fr::stratified(near, far, n, &mut fr::ray_rng(1, 2, 3, ray));
            lo_min = lo_min.min(t[0]);
            hi_max = hi_max.max(t[n - 1]);
        }
        let half_bin = (far - near) / (n - 1) as f64 / 2.0;
        assert!(
            lo_min >= near && lo_min < near + 0.005 * half_bin,
            "{lo_min}"
        );
        assert!(hi_max <= far && hi_max > far - 0.005 * half_bin, "{hi_max}");
    }
}

#[test]
#[allow(clippy::needless_range_loop)] // points, axes and depths indexed together
fn samples_and_line_integral_of_a_constant_field() {
    let ray = fr::Ray {
        o: [0.8, -0.1, 0.05],
        // No component of magnitude 1 (d_x^2 and d_x / d_x would agree).
        d: [-0.9, 0.2, -0.05],
    };
    let norm = (0.81f64 + 0.04 + 0.0025).sqrt();
    let bound = 0.3;
    let (near, far, n) = (0.4, 1.2, 33);
    let t = fr::stratified(near, far, n, &mut fr::ray_rng(7, 1, 2, 3));
    let (mut pts, mut delta) = (Vec::<[f64; 3]>::new(), Vec::<f64>::new());
    fr::samples(&ray, &t, bound, &mut pts, &mut delta);
    assert_eq!((pts.len(), delta.len()), (n, n));
    let b = bound - 1e-6;
    let mut clamped = 0;
    for i in 0..n {
        for a in 0..3 {
            let free = ray.o[a] + ray.d[a] * t[i];
            let want = if free < -b {
                -b
            } else if free > b {
                b
            } else {
                free
            };
            clamped += usize::from(want != free);
            assert!((pts[i][a] - want).abs() < 1e-15, "point {i} axis {a}");
        }
    }
    assert!(clamped > 0, "the ray must leave the cube somewhere");
    // A constant field mu: the left Riemann sum telescopes to mu |d| (t_last - t_first) plus the
    // last sample's 1e-10 |d|.
    let mu = 2.5;
    let acc = fr::line_integral(&vec![mu; n], &delta);
    let want = mu * norm * (t[n - 1] - t[0] + 1e-10);
    assert!((acc - want).abs() < 1e-12, "{acc} vs {want}");
    // ... which is the integral over [near, far] up to the two half bins at the ends.
    let half_bin = (far - near) / (n - 1) as f64 / 2.0;
    assert!((acc - mu * norm * (far - near)).abs() <= mu * norm * 2.0 * half_bin);
    // Backward: d acc / d mu_i = delta_i = (t_{i+1} - t_i) |d|, the last 1e-10 |d|.
    let mut g = vec![0.0; n];
    fr::line_integral_vjp(1.5, &delta, &mut g);
    for i in 0..n {
        let dt = if i + 1 < n { t[i + 1] - t[i] } else { 1e-10 };
        assert!((g[i] - 1.5 * dt * norm).abs() < 1e-14, "{i}");
    }
}

#[test]
fn near_far_is_naf_s_constant_interval() {
    let mut g = ConeBeam::centred([16, 16], [2.0, 2.0], [20, 10, 8], [2.0, 3.0, 1.0]);
    g.off_origin = [5.0, -4.0, 3.0];
    // Corners' largest xy distance from the axis: (5 + 20, -4 - 15) -> sqrt(25^2 + 19^2).
    let dmax = (25.0f64 * 25.0 + 19.0 * 19.0).sqrt();
    let (near, far) = fr::near_far(&g);
    assert!((near - (g.dso - dmax - 5.0) / 1000.0).abs() < 1e-15);
    assert!((far - (g.dso + dmax + 5.0) / 1000.0).abs() < 1e-15);
}

/// The trainer's batch loss is the mean over the rays of (line integral - target)^2, where ray
/// k of the batch is sampled from the jitter stream `jitter(k)` into samples of its own: each
/// integral is written here from the per-ray functions checked above, over several blocks of
/// rays (the last one partial), so a sample stored in another ray's place or another ray's
/// stream shows. `render_rays` is held to the same integrals.
#[test]
fn the_batch_loss_samples_ray_k_from_stream_k() {
    use unispine::field::train::{loss_and_grad, render_rays, Sampling, RAYS_PER_BLOCK};
    use unispine::field::{EncoderConfig, Field};
    let mut cfg = crate::small_cfg(EncoderConfig::Frequency { bands: 2 });
    cfg.n_samples = 5;
    let field = Field::<f64>::new(&cfg).unwrap();
    let n_rays = 2 * RAYS_PER_BLOCK + 3;
    let rays: Vec<fr::Ray> = (0..n_rays)
        .map(|i| fr::Ray {
            o: [1.0, 0.0, 0.0],
            d: [-1.0, -0.2 + 0.02 * i as f64, 0.01 * i as f64 - 0.1],
        })
        .collect();
    let targets: Vec<f64> = (0..n_rays).map(|i| 0.01 * i as f64).collect();
    let jitter = |i: usize| fr::ray_rng(5, 2, 0, i as u64);
    let (near, far, bound) = (0.6, 1.4, 0.3);
    let sampling = Sampling::new((near, far), cfg.n_samples, bound, &jitter);
    let mut want_loss = 0.0;
    let mut want = Vec::new();
    for (k, ray) in rays.iter().enumerate() {
        let t = fr::stratified(near, far, cfg.n_samples, &mut jitter(k));
        let (mut pts, mut delta) = (Vec::new(), Vec::new());
        fr::samples(ray, &t, bound, &mut pts, &mut delta);
        let mu = field.density(&pts);
        let acc: f64 = mu.iter().zip(&delta).map(|(m, d)| m * d).sum();
        want.push(acc);
        want_loss += (acc - targets[k]).powi(2);
    }
    want_loss /= n_rays as f64;
    assert!(
        want.iter().all(|&a| a > 1e-3),
        "integrals too small to see: {want:?}"
    );
    let (loss, _) = loss_and_grad(&field, &rays, &targets, &sampling);
    assert!(
        (loss - want_loss).abs() <= 1e-12 * want_loss,
        "loss {loss} against {want_loss}"
    );
    let got = render_rays(&field, &rays, &sampling);
    assert_eq!(got.len(), n_rays);
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!((g - w).abs() <= 1e-12 * w, "ray {k}: {g} against {w}");
    }
}
