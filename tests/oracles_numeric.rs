//! Independent oracles for the numeric code between the formulas: each expected value is
//! computed here from the documented convention (closed form or an f64 reference written
//! differently), never by the code under test, on small scenes.
//! - field rays: stratified depths (bins from a closed form, jitter replayed from the same
//!   seeded stream), sample points, `delta` and the line integral of a constant field;
//! - the trilinear DRR: the Riemann sum over the source-anchored lattice with step
//!   `L / ceil(L / h0)` of the closed-form (separable) interpolant of a box;
//! - FDK backprojection weights `DSO^2 / (DSO - x cos a - y sin a)^2` at a large cone angle;
//! - the projection's Jacobian clamp on all four sides (Sigma2D in closed form);
//! - evaluation in every colour mode and background (the [0, 1] clamp of the render).

use rand::RngExt;

use unispine::drr::{self, Method};
use unispine::field::render as fr;
use unispine::geometry::{ConeBeam, Mode};
use unispine::image2d::Image2d;
use unispine::volume::Volume;
mod common;
use common::tiny;

// ---------------------------------------------------------------------------------------------
// Field rays (NAF / SAX-NeRF sampling).

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
        d: [-1.0, 0.2, -0.05],
    };
    let norm = (1.0f64 + 0.04 + 0.0025).sqrt();
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

// ---------------------------------------------------------------------------------------------
// Trilinear DRR.

/// The zero-padded linear interpolant, along one axis, of a run of voxels of value 1 spanning
/// `[lo, hi]` (voxel size `s`): 1 between the first and last centre, ramping to 0 over the half
/// voxel each side of a face (0.5 on the face).
fn ramp(x: f64, lo: f64, hi: f64, s: f64) -> f64 {
    (((x - lo).min(hi - x) + s / 2.0) / s).clamp(0.0, 1.0)
}

#[test]
fn trilinear_step_matches_the_lattice_riemann_sum_of_the_interpolant() {
    // 14 x 12 x 10 voxels (anisotropic), a box of value 1.5 on voxels [3, 11) x [2, 9) x [2, 8).
    let mut v = Volume::<f64>::zeros([14, 12, 10], [1.0, 1.25, 0.8]);
    v.offset = [2.0, -1.0, 0.5];
    let (i0, i1) = ([3usize, 2, 2], [11usize, 9, 8]);
    let val = 1.5;
    for k in i0[2]..i1[2] {
        for j in i0[1]..i1[1] {
            for i in i0[0]..i1[0] {
                let idx = v.index(i, j, k);
                v.data[idx] = val;
            }
        }
    }
    let (vlo, _) = v.bounds();
    let lo: Vec<f64> = (0..3)
        .map(|a| vlo[a] + i0[a] as f64 * v.spacing[a])
        .collect();
    let hi: Vec<f64> = (0..3)
        .map(|a| vlo[a] + i1[a] as f64 * v.spacing[a])
        .collect();
    let g = ConeBeam {
        dsd: 400.0,
        dso: 250.0,
        n_detector: [13, 17],
        d_detector: [2.1, 2.3],
        n_voxel: v.dims,
        d_voxel: v.spacing,
        off_origin: v.offset,
        off_detector: [1.0, -0.5],
        mode: Mode::Cone,
        accuracy: 0.5,
    };
    let h0 = g.accuracy * 0.8;
    let mut v32 = Volume::<f32>::zeros(v.dims, v.spacing);
    v32.offset = v.offset;
    for (a, &b) in v32.data.iter_mut().zip(&v.data) {
        *a = b as f32;
    }
    let mut worst = (0.0f64, 0.0f64);
    let mut hits = 0;
    for &deg in &[0.0, 33.0, 100.0] {
        let a = f64::to_radians(deg);
        let img = drr::project(&v, &g, a, Method::Trilinear).unwrap();
        let img32 = drr::project(&v32, &g, a, Method::Trilinear).unwrap();
        let (s, c) = a.sin_cos();
        let src = [g.dso * c, g.dso * s, 0.0];
        let (ex, ey, ez) = ([-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]);
        for r in 0..img.height {
            for col in 0..img.width {
                let u = (col as f64 + 0.5 - img.width as f64 / 2.0) * g.d_detector[1]
                    + g.off_detector[0];
                let w = (r as f64 + 0.5 - img.height as f64 / 2.0) * g.d_detector[0]
                    + g.off_detector[1];
                let p: Vec<f64> = (0..3)
                    .map(|k| src[k] + g.dsd * ez[k] + u * ex[k] + w * ey[k])
                    .collect();
                let d: Vec<f64> = (0..3).map(|k| p[k] - src[k]).collect();
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let steps = (len / h0).ceil();
                let h = len / steps;
                let mut sum = 0.0;
                for i in 0..=steps as usize {
                    let t = i as f64 * h / len;
                    let mut f = val;
                    for k in 0..3 {
                        f *= ramp(src[k] + t * d[k], lo[k], hi[k], v.spacing[k]);
                    }
                    sum += f;
                }
                let want = h * sum;
                hits += usize::from(want > 1.0);
                let got = img.at(r, col);
                worst.0 = worst.0.max((got - want).abs());
                worst.1 = worst
                    .1
                    .max((img32.at(r, col) as f64 - want).abs() / want.max(1.0));
            }
        }
    }
    eprintln!(
        "trilinear vs lattice sum: f64 max abs {:.2e}, f32 max rel {:.2e}",
        worst.0, worst.1
    );
    assert!(hits > 50, "{hits} rays through the box");
    // The fast path's 32.32 fixed-point positions move a sample by < 1e-6 voxel.
    assert!(worst.0 < 1e-6, "f64: {}", worst.0);
    assert!(worst.1 < 1e-5, "f32: {}", worst.1);
}

// ---------------------------------------------------------------------------------------------
// FDK backprojection weights.

#[test]
fn fdk_backprojection_weights_at_a_large_cone_angle() {
    // DSO 60 mm with a 40 mm box: U = (DSO - x cos a - y sin a) / DSO runs from about 0.6 to
    // 1.4, so 1/U^2 from 0.5 to 2.6.
    let g = ConeBeam {
        dsd: 90.0,
        dso: 60.0,
        n_detector: [160, 160],
        d_detector: [1.0, 1.0],
        n_voxel: [5, 5, 3],
        d_voxel: [8.0, 8.0, 4.0],
        off_origin: [0.0, 0.0, 0.0],
        off_detector: [0.0, 0.0],
        mode: Mode::Cone,
        accuracy: 0.5,
    };
    let angles = [0.0, 0.9, 2.0, 4.4];
    let ones: Vec<Image2d<f64>> = angles
        .iter()
        .map(|_| Image2d::from_vec(160, 160, vec![1.0; 160 * 160]))
        .collect();
    let vol = unispine::fdk::backproject(&g, &angles, &ones);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for k in 0..3 {
        for j in 0..5 {
            for i in 0..5 {
                let x = (i as f64 - 2.0) * 8.0;
                let y = (j as f64 - 2.0) * 8.0;
                let want: f64 = angles
                    .iter()
                    .map(|&a| {
                        let u = (g.dso - x * a.cos() - y * a.sin()) / g.dso;
                        lo = lo.min(u);
                        hi = hi.max(u);
                        1.0 / (u * u)
                    })
                    .sum();
                let got = vol.get(i, j, k) as f64;
                assert!(
                    (got - want).abs() < 1e-6 * want,
                    "voxel ({i}, {j}, {k}): {got} vs {want}"
                );
            }
        }
    }
    assert!(lo < 0.65 && hi > 1.35, "U in [{lo}, {hi}]");
}

// ---------------------------------------------------------------------------------------------
// Jacobian clamp of the projection (Eq. 3).

#[test]
fn jacobian_clamp_on_all_four_sides() {
    use unispine::render::project::{project_geom, CamConsts, CLAMP, DILATION};
    let geo = ConeBeam::centred([24, 32], [2.0, 1.5], [16, 16, 16], [4.0, 4.0, 4.0]);
    let cam = geo.camera(0.7);
    let cc = CamConsts::<f64>::new(&cam);
    let tan_x = cam.width as f64 / (2.0 * cam.fx);
    let tan_y = cam.height as f64 / (2.0 * cam.fy);
    let (lim_x, lim_y) = (CLAMP * tan_x, CLAMP * tan_y);
    let z = 900.0;
    let s: f64 = 60.0; // isotropic: Sigma = s^2 I, so Sigma2D = s^2 J J^T + 0.3 I
    let mut seen = [[false; 2]; 2];
    for &fx_ in &[-1.8, -0.97, 0.0, 0.6, 1.8] {
        for &fy_ in &[-1.8, -0.4, 0.0, 0.98, 1.8] {
            let (rx, ry) = (fx_ * lim_x, fy_ * lim_y);
            let tc = [rx * z, ry * z, z];
            let dw = cam.cam_dir_to_world(tc);
            let mean = [
                cam.centre[0] + dw[0],
                cam.centre[1] + dw[1],
                cam.centre[2] + dw[2],
            ];
            let (r, _) = project_geom(&cc, mean, [s.ln(); 3], [1.0, 0.0, 0.0, 0.0]);
            let geom = r.unwrap_or_else(|c| panic!("({fx_}, {fy_}) culled: {c:?}"));
            let (xc, yc) = (rx.clamp(-lim_x, lim_x), ry.clamp(-lim_y, lim_y));
            let want_clamped = [rx.abs() > lim_x, ry.abs() > lim_y];
            assert_eq!(geom.clamped, want_clamped, "({fx_}, {fy_})");
            for (a, &on) in want_clamped.iter().enumerate() {
                if on {
                    let side = if [rx, ry][a] > 0.0 { 1 } else { 0 };
                    seen[a][side] = true;
                }
            }
            let (fx, fy) = (cam.fx, cam.fy);
            let want = [
                s * s * fx * fx * (1.0 + xc * xc) / (z * z) + DILATION,
                s * s * fx * fy * xc * yc / (z * z),
                s * s * fy * fy * (1.0 + yc * yc) / (z * z) + DILATION,
            ];
            for k in 0..3 {
                assert!(
                    (geom.cov2d[k] - want[k]).abs() < 1e-9 * want[0].max(want[2]),
                    "({fx_}, {fy_}) cov2d[{k}]: {} vs {}",
                    geom.cov2d[k],
                    want[k]
                );
            }
            // The mean is projected without the clamp.
            let m = [fx * rx + cam.cx, fy * ry + cam.cy];
            assert!((geom.mean2d[0] - m[0]).abs() < 1e-9 && (geom.mean2d[1] - m[1]).abs() < 1e-9);
        }
    }
    assert_eq!(seen, [[true; 2]; 2], "every side clamped somewhere");
}

// ---------------------------------------------------------------------------------------------
// Evaluation.

#[test]
#[allow(clippy::manual_clamp)] // written differently from the code's f32::clamp on purpose
fn evaluation_clamps_the_render_in_every_colour_mode_and_background() {
    use unispine::eval;
    use unispine::render::{self, ColorMode, RenderSettings};
    let ds = tiny::dataset();
    let targets = unispine::dataset::targets::test_targets(&ds).unwrap();
    let mut g = tiny::hidden().cast::<f32>();
    // Non-zero higher features so that the SH and X-Gaussian modes differ from the DC term.
    for (i, f) in g.features.iter_mut().enumerate() {
        for (k, v) in f.iter_mut().enumerate().skip(1) {
            *v = 0.3 * ((i * 7 + k * 3) % 5) as f32 / 5.0 - 0.1;
        }
    }
    for color in [
        ColorMode::RirfPaper,
        ColorMode::RirfXgaussian,
        ColorMode::Sh,
    ] {
        for background in [-0.5, 0.0, 0.4, 1.0, 2.0] {
            let settings = RenderSettings {
                color,
                active_features: 16,
                background,
                ..Default::default()
            };
            let got = eval::evaluate(&g, &ds, &targets, &settings).unwrap();
            let (mut psnr_sum, mut ssim_sum, mut outside) = (0.0, 0.0, 0usize);
            for (k, gt) in targets.iter().enumerate() {
                let (img, _) = render::forward(&g, &ds.test_camera(k), &settings).unwrap();
                outside += img
                    .data
                    .iter()
                    .filter(|v| !(0.0..=1.0).contains(*v))
                    .count();
                let clamped = Image2d::from_vec(
                    img.width,
                    img.height,
                    img.data
                        .iter()
                        .map(|&v| {
                            if v < 0.0 {
                                0.0
                            } else if v > 1.0 {
                                1.0
                            } else {
                                v
                            }
                        })
                        .collect(),
                );
                let mse = clamped
                    .data
                    .iter()
                    .zip(&gt.data)
                    .map(|(&a, &b)| (a as f64 - b as f64).powi(2))
                    .sum::<f64>()
                    / gt.data.len() as f64;
                let psnr = -10.0 * mse.log10();
                let ssim = unispine::loss::ssim::ssim(&clamped, gt);
                let v = got.views[k];
                assert!(
                    (v.psnr - psnr).abs() < 1e-9 * psnr.abs().max(1.0),
                    "{color:?} bg {background} view {k}: psnr {} vs {psnr}",
                    v.psnr
                );
                assert!(
                    (v.ssim - ssim).abs() < 1e-12,
                    "{color:?} bg {background} view {k}"
                );
                psnr_sum += psnr;
                ssim_sum += ssim;
            }
            let n = targets.len() as f64;
            assert!((got.psnr - psnr_sum / n).abs() < 1e-9 * got.psnr.abs().max(1.0));
            assert!((got.ssim - ssim_sum / n).abs() < 1e-12);
            if !(0.0..=1.0).contains(&background) {
                assert!(
                    outside > 0,
                    "{color:?} bg {background}: the clamp is not exercised"
                );
            }
        }
    }
}
