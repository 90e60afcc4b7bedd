//! Densification keeps every per-Gaussian array and Adam moment aligned; clone, split, prune
//! and the opacity reset do exactly what upstream 3DGS / UniSpine-GS does.
//!
//! Each Gaussian i is marked with unique values in every parameter and moment (i + a fraction
//! per group) so that it can be followed through every operation.

use unispine::densify::{DensifyConfig, Source, TrainState};
use unispine::gaussians::Gaussians;
use unispine::math::activations::{logit, sigmoid};
use unispine::optim::AdamConfig;

const EXTENT: f64 = 100.0; // clone/split boundary 1.0, world prune 10.0

/// n Gaussians; Gaussian i has scale `scales[i]`, opacity 0.5 and markers i + 0.x elsewhere.
fn marked(scales: &[f64]) -> TrainState<f64> {
    let n = scales.len();
    let mut g = Gaussians::<f64>::zeros(n);
    for (i, &scale) in scales.iter().enumerate() {
        let x = i as f64;
        g.means[i] = [x, x + 0.1, x + 0.2];
        g.log_scales[i] = [scale.ln(); 3];
        g.quats[i] = [1.0, 0.0, 0.0, x * 1e-3];
        g.opacity_logits[i] = 0.0;
        g.features[i] = std::array::from_fn(|k| x + k as f64 * 1e-2);
    }
    let mut s = TrainState::new(g, AdamConfig::default());
    for i in 0..n {
        let x = i as f64;
        s.adam.m.means[i] = [x + 0.3; 3];
        s.adam.v.means[i] = [x + 0.4; 3];
        s.adam.m.opacity_logits[i] = x + 0.5;
        s.adam.v.opacity_logits[i] = x + 0.6;
        s.adam.m.features[i] = [x + 0.7; 16];
        s.adam.v.log_scales[i] = [x + 0.8; 3];
        s.adam.m.quats[i] = [x + 0.9; 4];
    }
    s
}

fn id_of(s: &TrainState<f64>, j: usize) -> usize {
    s.params.features[j][0].round() as usize
}

/// Every array of Gaussian j agrees with marker i (moments: `zero` = they must be 0).
fn check_aligned(s: &TrainState<f64>, j: usize, i: usize, zero: bool) {
    let x = i as f64;
    assert_eq!(s.params.features[j][3], x + 0.03, "features of {j}");
    assert_eq!(s.params.quats[j][3], x * 1e-3, "quats of {j}");
    let (m, v) = (&s.adam.m, &s.adam.v);
    if zero {
        assert_eq!(m.means[j], [0.0; 3]);
        assert_eq!(v.means[j], [0.0; 3]);
        assert_eq!(m.opacity_logits[j], 0.0);
        assert_eq!(v.opacity_logits[j], 0.0);
        assert_eq!(m.features[j], [0.0; 16]);
        assert_eq!(v.log_scales[j], [0.0; 3]);
        assert_eq!(m.quats[j], [0.0; 4]);
    } else {
        assert_eq!(m.means[j], [x + 0.3; 3], "m.means of {j}");
        assert_eq!(v.means[j], [x + 0.4; 3]);
        assert_eq!(m.opacity_logits[j], x + 0.5);
        assert_eq!(v.opacity_logits[j], x + 0.6);
        assert_eq!(m.features[j], [x + 0.7; 16]);
        assert_eq!(v.log_scales[j], [x + 0.8; 3]);
        assert_eq!(m.quats[j], [x + 0.9; 4]);
    }
    assert_eq!(s.stats.grad_accum.len(), s.len());
    assert_eq!(s.stats.denom.len(), s.len());
    assert_eq!(s.stats.max_radius.len(), s.len());
    assert_eq!(s.adam.m.len(), s.len());
    assert_eq!(s.adam.v.len(), s.len());
}

/// Give Gaussian i a mean NDC gradient `g[i]` seen in one view.
fn stats(s: &mut TrainState<f64>, g: &[f64], radius: u32) {
    let r: Vec<u32> = g
        .iter()
        .map(|&x| if x > 0.0 { radius } else { 0 })
        .collect();
    s.accumulate(g, &r);
}

#[test]
fn remap_keeps_everything_aligned() {
    let mut s = marked(&[0.5; 5]);
    s.remap(&[Source::Keep(3), Source::New(1), Source::Keep(0)]);
    assert_eq!(s.len(), 3);
    check_aligned(&s, 0, 3, false);
    check_aligned(&s, 1, 1, true);
    check_aligned(&s, 2, 0, false);
}

#[test]
fn clone_appends_exact_copies_with_zero_moments() {
    // Small Gaussians (scale 0.5 <= 1.0): 1 and 3 pass the threshold.
    let mut s = marked(&[0.5; 5]);
    let cfg = DensifyConfig {
        grad_threshold: 1e-3,
        ..Default::default()
    };
    stats(&mut s, &[0.0, 2e-3, 1e-4, 1e-3, 0.0], 4);
    // A second view where 1 is seen with a small gradient: mean (2e-3 + 0) / 2 = 1e-3 >= thr.
    s.accumulate(&[0.0, 0.0, 0.0, 0.0, 0.0], &[0, 3, 0, 0, 0]);
    let rep = s.densify_and_prune(&cfg, EXTENT, false, 1);
    assert_eq!((rep.cloned, rep.split, rep.pruned, rep.after), (2, 0, 0, 7));
    for i in 0..5 {
        check_aligned(&s, i, i, false);
    }
    check_aligned(&s, 5, 1, true);
    check_aligned(&s, 6, 3, true);
    assert_eq!(s.params.means[5], s.params.means[1]);
    assert_eq!(s.params.log_scales[6], s.params.log_scales[3]);
    assert!(s.stats.grad_accum.iter().all(|&x| x == 0.0));
    assert!(s.stats.denom.iter().all(|&x| x == 0));
}

#[test]
fn split_replaces_big_gaussians_by_two_smaller_ones() {
    // Gaussian 0 small (clone), 1 and 3 big (split), 2 big but below threshold.
    let mut s = marked(&[0.5, 2.0, 2.0, 3.0]);
    let cfg = DensifyConfig {
        grad_threshold: 1e-3,
        ..Default::default()
    };
    stats(&mut s, &[5e-3, 5e-3, 1e-4, 5e-3], 4);
    let rep = s.densify_and_prune(&cfg, EXTENT, false, 9);
    assert_eq!((rep.cloned, rep.split, rep.pruned), (1, 2, 0));
    // Order: survivors 0, 2; clone of 0; then sample 1 of (1, 3), sample 2 of (1, 3).
    let ids: Vec<usize> = (0..s.len()).map(|j| id_of(&s, j)).collect();
    assert_eq!(ids, vec![0, 2, 0, 1, 3, 1, 3]);
    check_aligned(&s, 0, 0, false);
    check_aligned(&s, 1, 2, false);
    for (j, &i) in ids.iter().enumerate().skip(2) {
        check_aligned(&s, j, i, true);
    }
    for (j, &i) in ids.iter().enumerate().take(7).skip(3) {
        let want = (if i == 1 { 2.0f64 } else { 3.0 } / 1.6).ln();
        assert!(s.params.log_scales[j]
            .iter()
            .all(|&l| (l - want).abs() < 1e-12));
        assert_eq!(s.params.opacity_logits[j], 0.0);
        // The sample moved away from the original mean.
        assert_ne!(
            s.params.means[j],
            [i as f64, i as f64 + 0.1, i as f64 + 0.2]
        );
    }
    // Same seed, same samples; another seed, other samples.
    let mut a = marked(&[0.5, 2.0, 2.0, 3.0]);
    stats(&mut a, &[5e-3, 5e-3, 1e-4, 5e-3], 4);
    let mut b = a.clone();
    a.densify_and_prune(&cfg, EXTENT, false, 9);
    b.densify_and_prune(&cfg, EXTENT, false, 10);
    assert_eq!(a.params, s.params);
    assert_ne!(b.params.means, s.params.means);
}

#[test]
fn split_positions_are_drawn_from_the_gaussian() {
    // 4000 copies of one anisotropic, rotated Gaussian; the 8000 offsets must have covariance
    // R diag(s^2) R^T and mean 0 (sampling error ~ 1/sqrt(8000) ~ 1.1 %).
    let n = 4000;
    let mut g = Gaussians::<f64>::zeros(n);
    let sc = [2.0, 5.0, 9.0];
    let q = [0.8, 0.2, -0.4, 0.3];
    let mu = [10.0, -20.0, 30.0];
    for i in 0..n {
        g.means[i] = mu;
        g.log_scales[i] = sc.map(f64::ln);
        g.quats[i] = q;
    }
    let mut s = TrainState::new(g, AdamConfig::default());
    s.accumulate(&vec![1.0; n], &vec![1; n]);
    let rep = s.densify_and_prune(&DensifyConfig::default(), EXTENT, false, 3);
    assert_eq!((rep.split, s.len()), (n, 2 * n));
    let (_, qn) = unispine::math::quat::normalize(q).unwrap();
    let r = unispine::math::quat::rotmat_unit(qn);
    let mut want = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            want[a][b] = (0..3).map(|k| r[a][k] * sc[k] * sc[k] * r[b][k]).sum();
        }
    }
    let m = s.len() as f64;
    let mut mean = [0.0; 3];
    let mut cov = [[0.0; 3]; 3];
    for p in &s.params.means {
        let d = [p[0] - mu[0], p[1] - mu[1], p[2] - mu[2]];
        for a in 0..3 {
            mean[a] += d[a] / m;
            for b in 0..3 {
                cov[a][b] += d[a] * d[b] / m;
            }
        }
    }
    for a in 0..3 {
        assert!(mean[a].abs() < 4.0 * 9.0 / m.sqrt(), "mean {mean:?}");
        for b in 0..3 {
            let tol = 0.05 * want[a][a].max(want[b][b]);
            assert!(
                (cov[a][b] - want[a][b]).abs() < tol,
                "cov {cov:?} want {want:?}"
            );
        }
    }
}

#[test]
fn prune_removes_exactly_the_right_ones() {
    // 0: fine; 1: opacity 0.004 (pruned); 2: opacity 0.006 (kept); 3: world scale 11 > 10;
    // 4: screen radius 25 px (pruned only with upstream_radii_reset = false).
    let mut s = marked(&[0.5, 0.5, 0.5, 11.0, 0.5]);
    s.params.opacity_logits[1] = logit(0.004);
    s.params.opacity_logits[2] = logit(0.006);
    s.accumulate(&[0.0; 5], &[3, 3, 3, 3, 25]);
    let cfg = DensifyConfig::default();
    // Early (no big-prune): only the low opacity one.
    let mut a = s.clone();
    let rep = a.densify_and_prune(&cfg, EXTENT, false, 0);
    assert_eq!((rep.pruned, rep.after), (1, 4));
    let ids: Vec<usize> = (0..a.len()).map(|j| id_of(&a, j)).collect();
    assert_eq!(ids, vec![0, 2, 3, 4]);
    for (j, &i) in ids.iter().enumerate() {
        check_aligned(&a, j, i, false);
    }
    // Late, upstream: the screen radii were reset before the prune, so 4 survives.
    let mut b = s.clone();
    b.densify_and_prune(&cfg, EXTENT, true, 0);
    let ids: Vec<usize> = (0..b.len()).map(|j| id_of(&b, j)).collect();
    assert_eq!(ids, vec![0, 2, 4]);
    // Late, with the radii kept: 4 goes too.
    let mut c = s.clone();
    let cfg2 = DensifyConfig {
        upstream_radii_reset: false,
        ..Default::default()
    };
    c.densify_and_prune(&cfg2, EXTENT, true, 0);
    let ids: Vec<usize> = (0..c.len()).map(|j| id_of(&c, j)).collect();
    assert_eq!(ids, vec![0, 2]);
    check_aligned(&c, 1, 2, false);
}

#[test]
fn budget_keeps_the_largest_gradients() {
    let mut s = marked(&[0.5; 6]);
    stats(&mut s, &[1e-3, 5e-3, 2e-3, 4e-3, 0.0, 3e-3], 2);
    let cfg = DensifyConfig {
        grad_threshold: 1e-3,
        max_gaussians: Some(8),
        ..Default::default()
    };
    let rep = s.densify_and_prune(&cfg, EXTENT, false, 0);
    assert_eq!((rep.cloned, s.len()), (2, 8));
    assert_eq!((id_of(&s, 6), id_of(&s, 7)), (1, 3));
}

#[test]
fn opacity_reset_caps_and_zeroes_the_moments() {
    let mut s = marked(&[0.5; 3]);
    s.params.opacity_logits = vec![logit(0.5), logit(0.004), logit(0.0101)];
    s.reset_opacity(0.01);
    let o: Vec<f64> = s
        .params
        .opacity_logits
        .iter()
        .map(|&x| sigmoid(x))
        .collect();
    assert!((o[0] - 0.01).abs() < 1e-15 && (o[2] - 0.01).abs() < 1e-15);
    assert!((o[1] - 0.004).abs() < 1e-15);
    assert!(s.adam.m.opacity_logits.iter().all(|&x| x == 0.0));
    assert!(s.adam.v.opacity_logits.iter().all(|&x| x == 0.0));
    // Other moments untouched.
    assert_eq!(s.adam.m.means[2], [2.3; 3]);
    assert_eq!(s.adam.v.means[2], [2.4; 3]);
    assert_eq!(s.adam.m.features[1], [1.7; 16]);
}

#[test]
fn schedule_matches_train_py() {
    let c = DensifyConfig::default();
    assert!(!c.densifies(500) && c.densifies(600) && c.densifies(7800) && !c.densifies(8000));
    assert!(c.resets(4000) && !c.resets(8000) && !c.resets(3999));
    assert!(c.collects(7999) && !c.collects(8000));
    assert!(!c.prunes_big(4000) && c.prunes_big(4200));
}

/// The densification statistic |dL/dmean2d| in NDC (3DGS `viewspace_point_tensor.grad`) has a
/// fixed scale and axis order: the rasterizer's pixel coordinate is ndc2Pix(x, S) =
/// ((x + 1) S - 1) / 2 (3DGS `auxiliary.h`), so dL/dndc_u = (W / 2) dL/du and dL/dndc_v =
/// (H / 2) dL/dv. The pixel-space gradient is taken here by central differences of the
/// compositor's forward pass alone, on a non-square detector (W = 40, H = 24) with a weight
/// image that pulls differently along u and v, so doubling the statistic or swapping W and H
/// fails.
#[test]
fn ndc_mean_gradient_has_the_3dgs_scale_and_axis_order() {
    use unispine::geometry::ConeBeam;
    use unispine::image2d::Image2d;
    use unispine::render::{self, composite, ColorMode, RenderSettings};
    let geo = ConeBeam::centred([24, 40], [3.0, 3.0], [32, 32, 32], [2.0, 2.0, 2.0]);
    let cam = geo.camera(0.3);
    let (w, h) = (cam.width, cam.height);
    assert_eq!((w, h), (40, 24));
    let mut g = Gaussians::<f64>::zeros(1);
    g.means[0] = [5.0, -3.0, 4.0];
    g.log_scales[0] = [3.0f64.ln(), 4.0f64.ln(), 3.5f64.ln()];
    g.quats[0] = [1.0, 0.1, -0.2, 0.05];
    g.opacity_logits[0] = 0.5;
    g.features[0][0] = 0.8;
    let settings = RenderSettings {
        color: ColorMode::RirfXgaussian,
        active_features: 1,
        background: 0.0,
        ..Default::default()
    };
    let (img, saved) = render::forward(&g, &cam, &settings).unwrap();
    // Weights linear in (u, v) with different slopes, zero where the splat is faint (so no
    // pixel crosses the compositor's 1/255 alpha cut-off under the perturbation).
    let peak = img.data.iter().cloned().fold(0.0, f64::max);
    let wimg = Image2d::from_vec(
        w,
        h,
        (0..w * h)
            .map(|i| {
                let (u, v) = ((i % w) as f64, (i / w) as f64);
                if img.data[i] > 0.05 * peak {
                    0.3 + 0.07 * u - 0.11 * v
                } else {
                    0.0
                }
            })
            .collect(),
    );
    let grads = render::backward(&g, &cam, &settings, &saved, &wimg);
    let loss = |s: &unispine::render::Splats<f64>| -> f64 {
        let (im, _) = composite::forward(s, w, h, 0.0);
        im.data.iter().zip(&wimg.data).map(|(a, b)| a * b).sum()
    };
    let step = 1e-5;
    let mut d_pix = [0.0; 2];
    for (a, d) in d_pix.iter_mut().enumerate() {
        let (mut p, mut m) = (saved.splats.clone(), saved.splats.clone());
        p.mean2d[0][a] += step;
        m.mean2d[0][a] -= step;
        *d = (loss(&p) - loss(&m)) / (2.0 * step);
    }
    assert!(d_pix[0].abs() > 1e-3 && d_pix[1].abs() > 1e-3, "{d_pix:?}");
    let expect = ((d_pix[0] * w as f64 / 2.0).powi(2) + (d_pix[1] * h as f64 / 2.0).powi(2)).sqrt();
    let swapped =
        ((d_pix[0] * h as f64 / 2.0).powi(2) + (d_pix[1] * w as f64 / 2.0).powi(2)).sqrt();
    assert!(
        (expect - swapped).abs() > 0.05 * expect,
        "{expect} vs {swapped}"
    );
    let got = grads.mean2d_ndc_norm[0];
    assert!(
        (got - expect).abs() <= 1e-6 * expect,
        "NDC statistic {got}, closed form from the pixel gradient {expect}"
    );
}
