//! The DRR ray-marchers against closed forms, in f64.
//!
//! The rays are rebuilt here from the documented convention (source on the circle of radius DSO,
//! camera axes x = (-sin, cos, 0), y = (0, 0, -1), z = (-cos, -sin, 0), pixel centres at
//! u = (c + 0.5 - W/2) du + offU, v = (r + 0.5 - H/2) dv + offV), independently of
//! `Camera::pixel_ray`, and the chords are computed with a slab test written here.

use unispine::drr::{self, Method, Projector};
use unispine::geometry::{ConeBeam, Mode};
use unispine::volume::Volume;
use unispine::Error;

/// A ray of the documented convention: (origin, unit direction, max t or infinity).
fn ray(g: &ConeBeam, angle: f64, col: usize, row: usize) -> ([f64; 3], [f64; 3]) {
    let (s, c) = angle.sin_cos();
    let ex = [-s, c, 0.0];
    let ey = [0.0, 0.0, -1.0];
    let ez = [-c, -s, 0.0];
    let (h, w) = (g.n_detector[0] as f64, g.n_detector[1] as f64);
    let u = (col as f64 + 0.5 - w / 2.0) * g.d_detector[1] + g.off_detector[0];
    let v = (row as f64 + 0.5 - h / 2.0) * g.d_detector[0] + g.off_detector[1];
    let src = [g.dso * c, g.dso * s, 0.0];
    match g.mode {
        Mode::Cone => {
            let p: Vec<f64> = (0..3)
                .map(|a| src[a] + g.dsd * ez[a] + u * ex[a] + v * ey[a])
                .collect();
            let d = [p[0] - src[0], p[1] - src[1], p[2] - src[2]];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            (src, [d[0] / n, d[1] / n, d[2] / n])
        }
        Mode::Parallel => {
            let o = [
                src[0] + u * ex[0] + v * ey[0],
                src[1] + u * ex[1] + v * ey[1],
                src[2] + u * ex[2] + v * ey[2],
            ];
            (o, ez)
        }
    }
}

/// Length of the ray inside the box [lo, hi] (half-line t >= 0 for a cone, whole line for a
/// parallel beam).
fn chord(o: [f64; 3], d: [f64; 3], lo: [f64; 3], hi: [f64; 3], half_line: bool) -> f64 {
    let mut t0 = if half_line { 0.0 } else { f64::NEG_INFINITY };
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return 0.0;
            }
        } else {
            let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t1 - t0).max(0.0)
}

fn geo_for(vol: &Volume<f64>, n_det: [usize; 2], pitch: f64) -> ConeBeam {
    ConeBeam {
        dsd: 400.0,
        dso: 250.0,
        n_detector: n_det,
        d_detector: [pitch, pitch * 1.1],
        n_voxel: vol.dims,
        d_voxel: vol.spacing,
        off_origin: vol.offset,
        off_detector: [0.0, 0.0],
        mode: Mode::Cone,
        accuracy: 0.5,
    }
}

/// A zero volume (20 x 16 x 12, anisotropic voxels, off-centre) with a uniform box of value
/// `val` filling voxels [4, 15) x [3, 12) x [2, 9); returns the volume and the box's world corners.
fn box_volume(val: f64) -> (Volume<f64>, [f64; 3], [f64; 3]) {
    let mut v = Volume::<f64>::zeros([20, 16, 12], [1.0, 1.25, 0.8]);
    v.offset = [3.0, -2.0, 1.0];
    let (i0, i1) = ([4, 3, 2], [15, 12, 9]);
    for k in i0[2]..i1[2] {
        for j in i0[1]..i1[1] {
            for i in i0[0]..i1[0] {
                let idx = v.index(i, j, k);
                v.data[idx] = val;
            }
        }
    }
    let (lo_v, _) = v.bounds();
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for a in 0..3 {
        lo[a] = lo_v[a] + i0[a] as f64 * v.spacing[a];
        hi[a] = lo_v[a] + i1[a] as f64 * v.spacing[a];
    }
    (v, lo, hi)
}

#[test]
fn siddon_box_chords_exact() {
    let val = 2.5;
    let (vol, lo, hi) = box_volume(val);
    for mode in [Mode::Cone, Mode::Parallel] {
        let mut g = geo_for(&vol, [23, 29], 1.3);
        g.mode = mode;
        g.off_detector = [0.37, -0.61];
        let mut hit = 0;
        for &deg in &[0.0, 17.0, 45.0, 90.0, 133.0, 251.0] {
            let a = f64::to_radians(deg);
            let img = drr::project(&vol, &g, a, Method::Siddon).unwrap();
            for r in 0..img.height {
                for c in 0..img.width {
                    let (o, d) = ray(&g, a, c, r);
                    let want = val * chord(o, d, lo, hi, mode == Mode::Cone);
                    let got = img.at(r, c);
                    if want > 0.0 {
                        hit += 1;
                    }
                    assert!(
                        (got - want).abs() <= 1e-9 * want.max(1.0),
                        "{mode:?} {deg} deg pixel ({r}, {c}): {got} vs {want}"
                    );
                }
            }
        }
        assert!(hit > 250, "{mode:?}: only {hit} rays met the box");
    }
}

#[test]
fn rays_that_miss_give_exactly_zero() {
    // A full uniform volume; the detector is shifted so that part of it sees nothing.
    let mut vol = Volume::<f64>::zeros([10, 10, 10], [1.0; 3]);
    vol.data.iter_mut().for_each(|v| *v = 1.0);
    let (lo, hi) = vol.bounds();
    for method in [Method::Siddon, Method::Trilinear] {
        let mut g = geo_for(&vol, [16, 16], 1.0);
        g.off_detector = [9.0, -5.0];
        let a = 0.3;
        let img = drr::project(&vol, &g, a, method).unwrap();
        let (mut miss, mut hit) = (0, 0);
        for r in 0..16 {
            for c in 0..16 {
                let (o, d) = ray(&g, a, c, r);
                // Trilinear reads the zero-padded interpolant, which reaches half a voxel out.
                let pad = if method == Method::Trilinear {
                    0.5
                } else {
                    0.0
                };
                let lo_p = [lo[0] - pad, lo[1] - pad, lo[2] - pad];
                let hi_p = [hi[0] + pad, hi[1] + pad, hi[2] + pad];
                if chord(o, d, lo_p, hi_p, true) == 0.0 {
                    miss += 1;
                    assert_eq!(img.at(r, c), 0.0, "{method:?} pixel ({r}, {c})");
                } else if chord(o, d, lo, hi, true) > 1.0 {
                    hit += 1;
                    assert!(img.at(r, c) > 0.0);
                }
            }
        }
        assert!(
            miss > 20 && hit > 20,
            "{method:?}: {miss} misses, {hit} hits"
        );
    }
}

/// A ball of radius `rad` (mm) centred at `c`, voxelised with 4^3 sub-samples per voxel
/// (partial volume), value 1 inside.
fn ball_volume(n: usize, s: f64, c: [f64; 3], rad: f64) -> Volume<f64> {
    let mut v = Volume::<f64>::zeros([n, n, n], [s; 3]);
    let m = 4;
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = v.voxel_to_world([i as f64, j as f64, k as f64]);
                let mut inside = 0;
                for a in 0..m {
                    for b in 0..m {
                        for e in 0..m {
                            let off = |q: usize| ((q as f64 + 0.5) / m as f64 - 0.5) * s;
                            let q = [
                                p[0] + off(a) - c[0],
                                p[1] + off(b) - c[1],
                                p[2] + off(e) - c[2],
                            ];
                            if q[0] * q[0] + q[1] * q[1] + q[2] * q[2] < rad * rad {
                                inside += 1;
                            }
                        }
                    }
                }
                let idx = v.index(i, j, k);
                v.data[idx] = inside as f64 / (m * m * m) as f64;
            }
        }
    }
    v
}

/// Chord of a line through a ball.
fn ball_chord(o: [f64; 3], d: [f64; 3], c: [f64; 3], rad: f64) -> f64 {
    let w = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
    let b = w[0] * d[0] + w[1] * d[1] + w[2] * d[2];
    let q = w[0] * w[0] + w[1] * w[1] + w[2] * w[2] - b * b; // squared distance to the line
    if q >= rad * rad {
        0.0
    } else {
        2.0 * (rad * rad - q).sqrt()
    }
}

/// Ball chords, cone and parallel beam, both projectors. The partial-volume voxelisation is 1
/// in every voxel entirely inside the ball and 0 in every voxel entirely outside. A ray point at
/// distance r from the centre lies in a voxel all of whose points are within r +- sqrt(3) s, so
/// Siddon's integrand is 1 where r < R - delta and 0 where r > R + delta with delta = sqrt(3) s
/// (one voxel diagonal); the trilinear interpolant mixes voxels whose centres are within a
/// diagonal of the sample: delta = 1.5 sqrt(3) s.
/// Each ray's integral therefore lies between the chords of those two balls (trilinear: minus /
/// plus one step h for the Riemann sum). Over all rays the errors average out: the summed error
/// is below 1 % of the summed chord.
#[test]
fn ball_chords_within_voxelisation_error() {
    let (n, s, rad) = (48, 0.5, 9.0);
    let c = [0.6, -0.4, 0.3];
    let vol = ball_volume(n, s, c, rad);
    for mode in [Mode::Cone, Mode::Parallel] {
        for method in [Method::Siddon, Method::Trilinear] {
            let mut g = geo_for(&vol, [32, 32], 0.9);
            g.mode = mode;
            g.off_detector = [0.3, 0.2];
            let (delta, h) = match method {
                Method::Siddon => (3f64.sqrt() * s, 0.0),
                Method::Trilinear => (1.5 * 3f64.sqrt() * s, g.accuracy * s),
            };
            let a = 0.7;
            let img = drr::project(&vol, &g, a, method).unwrap();
            let (mut sum_err, mut sum_want, mut cnt) = (0.0, 0.0, 0);
            for r in 0..32 {
                for col in 0..32 {
                    let (o, d) = ray(&g, a, col, r);
                    let want = ball_chord(o, d, c, rad);
                    let (lo, hi) = (
                        ball_chord(o, d, c, rad - delta),
                        ball_chord(o, d, c, rad + delta),
                    );
                    let got = img.at(r, col);
                    assert!(
                        got >= lo - h - 1e-9 && got <= hi + h + 1e-9,
                        "{mode:?} {method:?} ({r}, {col}): {got} not in [{lo}, {hi}]"
                    );
                    sum_err += got - want;
                    sum_want += want;
                    if want > 0.0 {
                        cnt += 1;
                    }
                }
            }
            eprintln!(
                "ball {mode:?} {method:?}: summed error {:.2e} of the summed chord, {cnt} rays",
                sum_err / sum_want
            );
            assert!(cnt > 250);
            assert!(
                (sum_err / sum_want).abs() < 1e-2,
                "{mode:?} {method:?}: {sum_err} / {sum_want}"
            );
        }
    }
}

#[test]
fn detector_offset_shifts_the_image() {
    let (vol, _, _) = box_volume(1.0);
    for method in [Method::Siddon, Method::Trilinear] {
        for mode in [Mode::Cone, Mode::Parallel] {
            let mut g = geo_for(&vol, [24, 30], 1.2);
            g.mode = mode;
            let base = drr::project(&vol, &g, 0.4, method).unwrap();
            // Shift by (k, m) = (3, -2) pixels: offU = 3 du, offV = -2 dv.
            let (k, m) = (3i64, -2i64);
            g.off_detector = [k as f64 * g.d_detector[1], m as f64 * g.d_detector[0]];
            let shifted = drr::project(&vol, &g, 0.4, method).unwrap();
            let mut compared = 0;
            for r in 0..24i64 {
                for c in 0..30i64 {
                    let (r2, c2) = (r + m, c + k);
                    if (0..24).contains(&r2) && (0..30).contains(&c2) {
                        let (a, b) = (
                            shifted.at(r as usize, c as usize),
                            base.at(r2 as usize, c2 as usize),
                        );
                        assert!(
                            (a - b).abs() <= 1e-9 * b.abs().max(1.0),
                            "{method:?} {mode:?} ({r}, {c}): {a} vs {b}"
                        );
                        compared += 1;
                    }
                }
            }
            assert!(compared > 400);
            // And the image really moved (the box is not symmetric in the detector).
            assert_ne!(shifted.data, base.data);
        }
    }
}

/// A smooth volume: a 3-D Gaussian blob, whose line integrals are known in closed form:
/// int A exp(-|p(t) - c|^2 / (2 sigma^2)) dt = A sqrt(2 pi) sigma exp(-d^2 / (2 sigma^2)), d the
/// distance from c to the line.
fn blob(n: usize, s: f64, c: [f64; 3], sigma: f64) -> Volume<f64> {
    let mut v = Volume::<f64>::zeros([n, n, n], [s; 3]);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = v.voxel_to_world([i as f64, j as f64, k as f64]);
                let r2 = (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f64>();
                let idx = v.index(i, j, k);
                v.data[idx] = (-r2 / (2.0 * sigma * sigma)).exp();
            }
        }
    }
    v
}

/// Siddon and trilinear agree on a smooth volume, and both match the closed form. Tolerances, as
/// fractions of the peak projection P0 = sqrt(2 pi) sigma, for a Gaussian of sigma = 5 voxels:
/// - trilinear integrates the trilinear interpolant, a second-order approximation:
///   error ~ s^2 / 8 |f''| ~ (s / sigma)^2 / 8 = 5e-3; we require 1e-2.
/// - Siddon integrates the nearest-voxel (piecewise-constant) volume. A ray that stays inside
///   one voxel layer (here the rays run almost parallel to the z layers) sees the layer's
///   centre value instead of f at its own z: a first-order error up to s/2 |dP/dz| =
///   s / (2 sigma) e^(-1/2) P0 = 0.061 P0; we require 0.061 (measured 0.035).
/// - between the two: the sum of both, 0.071.
#[test]
fn siddon_and_trilinear_agree_on_a_smooth_volume() {
    let (n, s, sigma) = (40, 1.0, 5.0);
    let c = [0.7, -0.3, 0.4];
    let vol = blob(n, s, c, sigma);
    let g = geo_for(&vol, [24, 24], 1.5);
    let peak = (2.0 * std::f64::consts::PI).sqrt() * sigma;
    for &deg in &[0.0, 30.0, 77.0] {
        let a = f64::to_radians(deg);
        let sid = drr::project(&vol, &g, a, Method::Siddon).unwrap();
        let tri = drr::project(&vol, &g, a, Method::Trilinear).unwrap();
        let (mut e_s, mut e_t, mut e_st) = (0.0f64, 0.0f64, 0.0f64);
        for r in 0..24 {
            for col in 0..24 {
                let (o, d) = ray(&g, a, col, r);
                let w = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
                let b = w[0] * d[0] + w[1] * d[1] + w[2] * d[2];
                let d2 = w.iter().map(|x| x * x).sum::<f64>() - b * b;
                let want = peak * (-d2 / (2.0 * sigma * sigma)).exp();
                e_s = e_s.max((sid.at(r, col) - want).abs());
                e_t = e_t.max((tri.at(r, col) - want).abs());
                e_st = e_st.max((sid.at(r, col) - tri.at(r, col)).abs());
            }
        }
        eprintln!(
            "blob {deg} deg: max |siddon - exact| {:.2e}, |trilinear - exact| {:.2e}, |siddon - trilinear| {:.2e} (x peak)",
            e_s / peak,
            e_t / peak,
            e_st / peak
        );
        let first_order = s / (2.0 * sigma) * (-0.5f64).exp();
        assert!(e_t < 1e-2 * peak, "trilinear: {e_t}");
        assert!(e_s < first_order * peak, "siddon: {e_s}");
        assert!(
            e_st < (first_order + 1e-2) * peak,
            "siddon vs trilinear: {e_st}"
        );
    }
}

/// Trilinear on a uniform box: the zero-padded interpolant is the box value inside the box
/// shrunk by half a voxel and 0 outside the box grown by half a voxel, so each integral lies
/// between the value times those two chords (minus / plus one step h for the Riemann sum). For
/// rays that cross the faces steeply (the shrunk and grown chords within 4 mm of each other,
/// the voxels being 0.8-1.25 mm) the ramps integrate to the sharp edge: |error| <= 2 h x value.
#[test]
fn trilinear_box_chords() {
    let val = 1.5;
    let (vol, lo, hi) = box_volume(val);
    let g = geo_for(&vol, [23, 29], 1.3);
    let h = g.accuracy * 0.8;
    let half = [0.5, 0.625, 0.4];
    let (mut tight, mut all) = (0, 0);
    for &deg in &[0.0, 45.0, 120.0] {
        let a = f64::to_radians(deg);
        let img = drr::project(&vol, &g, a, Method::Trilinear).unwrap();
        for r in 0..img.height {
            for c in 0..img.width {
                let (o, d) = ray(&g, a, c, r);
                let want = val * chord(o, d, lo, hi, true);
                let shr = val * chord(o, d, sub(lo, half, -1.0), sub(hi, half, 1.0), true);
                let gro = val * chord(o, d, sub(lo, half, 1.0), sub(hi, half, -1.0), true);
                let got = img.at(r, c);
                all += 1;
                assert!(
                    got >= shr - h * val - 1e-9 && got <= gro + h * val + 1e-9,
                    "{deg} deg ({r}, {c}): {got} not in [{shr}, {gro}]"
                );
                if shr > 0.0 && gro - shr < 4.0 * val {
                    tight += 1;
                    assert!(
                        (got - want).abs() <= 2.0 * h * val,
                        "{deg} deg ({r}, {c}): {got} vs {want}"
                    );
                }
            }
        }
    }
    assert!(tight > 200, "{tight} of {all}");
}

/// `p - sign * d` per axis.
fn sub(p: [f64; 3], d: [f64; 3], sign: f64) -> [f64; 3] {
    [p[0] - sign * d[0], p[1] - sign * d[1], p[2] - sign * d[2]]
}

#[test]
fn f32_matches_f64() {
    let vol = blob(32, 1.0, [0.5, 0.2, -0.3], 4.0);
    let vol32: Volume<f32> = vol.cast();
    let g = geo_for(&vol, [20, 20], 1.5);
    for method in [Method::Siddon, Method::Trilinear] {
        let a = drr::project(&vol, &g, 0.9, method).unwrap();
        let b = drr::project(&vol32, &g, 0.9, method).unwrap();
        let peak = a.data.iter().cloned().fold(0.0, f64::max);
        let err = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - *y as f64).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "f32 vs f64 {method:?}: max abs diff {:.2e} x peak",
            err / peak
        );
        assert!(
            peak > 1.0 && err <= 1e-5 * peak,
            "{method:?}: {err} vs peak {peak}"
        );
    }
}

#[test]
fn bit_identical_for_1_2_8_threads() {
    let vol = blob(32, 1.0, [0.5, 0.2, -0.3], 4.0).cast::<f32>();
    let g = ConeBeam {
        n_detector: [37, 41],
        ..geo_for(&vol.cast(), [37, 41], 1.5)
    };
    for method in [Method::Siddon, Method::Trilinear] {
        let mut images = Vec::new();
        for t in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            let img = pool
                .install(|| drr::project_views(&vol, &g, &[0.1, 1.3], method, &|_| {}))
                .unwrap();
            images.push(
                img.iter()
                    .flat_map(|i| i.data.iter().map(|v| v.to_bits()))
                    .collect::<Vec<_>>(),
            );
        }
        assert_eq!(images[0], images[1], "{method:?} 1 vs 2 threads");
        assert_eq!(images[0], images[2], "{method:?} 1 vs 8 threads");
    }
}

#[test]
fn grid_mismatch_is_named() {
    let (vol, _, _) = box_volume(1.0);
    let g0 = geo_for(&vol, [8, 8], 1.0);
    type Change = Box<dyn Fn(&mut ConeBeam)>;
    let cases: [(&str, Change); 3] = [
        ("nVoxel", Box::new(|g| g.n_voxel[1] += 1)),
        ("dVoxel[2]", Box::new(|g| g.d_voxel[2] *= 1.01)),
        ("offOrigin[0]", Box::new(|g| g.off_origin[0] += 0.5)),
    ];
    for (field, change) in cases {
        let mut g = g0.clone();
        change(&mut g);
        let e = drr::project(&vol, &g, 0.0, Method::Siddon)
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
}

#[test]
fn nan_voxel_is_named() {
    let (mut vol, _, _) = box_volume(1.0);
    let idx = vol.index(7, 5, 3);
    vol.data[idx] = f64::NAN;
    let g = geo_for(&vol, [8, 8], 1.0);
    for method in [Method::Siddon, Method::Trilinear] {
        let e = drr::project(&vol, &g, 0.0, method).unwrap_err();
        assert!(matches!(e, Error::NonFinite { .. }), "{e}");
        assert!(e.to_string().contains("(7, 5, 3)"), "{e}");
    }
}

#[test]
fn geometry_that_misses_the_volume_is_an_error() {
    let (vol, _, _) = box_volume(1.0);
    let mut g = geo_for(&vol, [8, 8], 1.0);
    g.off_detector = [500.0, 0.0];
    for method in [Method::Siddon, Method::Trilinear] {
        let e = drr::project(&vol, &g, 0.0, method).unwrap_err();
        assert!(matches!(e, Error::Geometry(_)), "{e}");
        assert!(e.to_string().contains("no ray"), "{e}");
    }
}

#[test]
fn source_inside_the_volume_is_an_error() {
    let (vol, _, _) = box_volume(1.0);
    let mut g = geo_for(&vol, [8, 8], 1.0);
    g.dso = 5.0;
    g.dsd = 400.0;
    let e = drr::project(&vol, &g, 0.0, Method::Siddon).unwrap_err();
    assert!(matches!(e, Error::Geometry(_)), "{e}");
    assert!(e.to_string().contains("inside the volume"), "{e}");
    // The projector checks once and then per view.
    let p = Projector::new(&vol, &g, Method::Trilinear).unwrap();
    assert!(p
        .view(0.0)
        .unwrap_err()
        .to_string()
        .contains("inside the volume"));
}
