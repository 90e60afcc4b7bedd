//! FDK (TIGRE semantics) against closed forms: the filter against TIGRE's padded-DFT route and
//! a hand computation of its scale, a uniform ball reconstructed from its exact (analytic)
//! projections, and bit-identical volumes for 1, 2 and 8 threads.

use unispine::fdk;
use unispine::geometry::{ConeBeam, Mode};
use unispine::image2d::Image2d;
use unispine::Error;

/// TIGRE's filtering of one row, step by step (`filtering.py`): zero-pad to `L` with the row
/// centred, multiply the DFT by `2 |DFT(ramp_flat(L))|`, inverse DFT, real part, crop. Naive
/// O(L^2) DFTs in f64, written independently of `fdk::filter_row`.
fn tigre_filter_row(row: &[f64], l: usize) -> Vec<f64> {
    let n = row.len();
    let pad = (l - n) / 2;
    let mut x = vec![0.0; l];
    x[pad..pad + n].copy_from_slice(row);
    // ramp_flat: nn = arange(-L/2, L/2); h[L/2] = 1/4; h[odd nn] = -1/(pi nn)^2.
    let h: Vec<f64> = (0..l)
        .map(|i| {
            let nn = i as i64 - (l / 2) as i64;
            if nn == 0 {
                0.25
            } else if nn.rem_euclid(2) == 1 {
                -1.0 / (std::f64::consts::PI * nn as f64).powi(2)
            } else {
                0.0
            }
        })
        .collect();
    let dft = |v: &[f64]| -> Vec<(f64, f64)> {
        (0..l)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for (j, &a) in v.iter().enumerate() {
                    let ang = -2.0 * std::f64::consts::PI * (k * j % l) as f64 / l as f64;
                    re += a * ang.cos();
                    im += a * ang.sin();
                }
                (re, im)
            })
            .collect()
    };
    let hk = dft(&h);
    // filter(): f = 2 |fft(h)|, keep 0..=L/2, mirror (filt[1:-1][::-1]).
    let half: Vec<f64> = hk[..=l / 2]
        .iter()
        .map(|(re, im)| 2.0 * (re * re + im * im).sqrt())
        .collect();
    let mut filt = half.clone();
    filt.extend(half[1..half.len() - 1].iter().rev());
    assert_eq!(filt.len(), l);
    let xk = dft(&x);
    let prod: Vec<(f64, f64)> = xk
        .iter()
        .zip(&filt)
        .map(|(&(re, im), &f)| (re * f, im * f))
        .collect();
    // Inverse DFT, real part.
    let y: Vec<f64> = (0..l)
        .map(|j| {
            let mut re = 0.0;
            for (k, &(a, b)) in prod.iter().enumerate() {
                let ang = 2.0 * std::f64::consts::PI * (k * j % l) as f64 / l as f64;
                re += a * ang.cos() - b * ang.sin();
            }
            re / l as f64
        })
        .collect();
    y[pad..pad + n].to_vec()
}

#[test]
fn filter_matches_tigre_padded_dft() {
    for n in [7usize, 20, 33] {
        let row: Vec<f64> = (0..n)
            .map(|i| ((i * 37 + 11) % 17) as f64 / 17.0 - 0.3)
            .collect();
        let l = fdk::filter_len(n);
        let want = tigre_filter_row(&row, l);
        let kernel2: Vec<f64> = (0..n as i64).map(|k| 2.0 * fdk::ramp_kernel(k)).collect();
        let mut got = vec![0.0; n];
        fdk::filter_row(&row, &kernel2, &mut got);
        for j in 0..n {
            assert!(
                (got[j] - want[j]).abs() < 1e-12,
                "n {n} j {j}: {} vs {}",
                got[j],
                want[j]
            );
        }
    }
}

fn geo(n_det: usize, d_det: f64, n_vox: usize, d_vox: f64) -> ConeBeam {
    ConeBeam {
        dsd: 1500.0,
        dso: 1000.0,
        n_detector: [n_det, n_det],
        d_detector: [d_det, d_det],
        n_voxel: [n_vox; 3],
        d_voxel: [d_vox; 3],
        off_origin: [0.0; 3],
        off_detector: [0.0; 2],
        mode: Mode::Cone,
        accuracy: 0.5,
    }
}

#[test]
fn filter_scale_by_hand() {
    // One bright pixel at (row 3, column 4) of an 8 x 8 detector with 0.5 mm pixels, 10 views.
    let g = geo(8, 0.5, 4, 1.0);
    let mut p = Image2d::filled(8, 8, 0.0f32);
    p.data[3 * 8 + 4] = 2.0;
    let q = fdk::weight_and_filter(&g, &p, 10);
    // Pixel centre: u = (4 - 4 + 0.5) 0.5 = 0.25, v = (3 - 4 + 0.5) 0.5 = -0.25 mm.
    let cosw = 1500.0 / (1500.0f64.powi(2) + 0.0625 + 0.0625).sqrt();
    // (DSD / DSO) (2 pi / N) / (4 du) = 1.5 * 0.2 pi / 2 = 0.15 pi.
    let scale = 0.15 * std::f64::consts::PI;
    assert!((fdk::filter_scale(&g, 10) - scale).abs() < 1e-15);
    let centre = 2.0 * cosw * 2.0 * 0.25 * scale;
    let odd1 = 2.0 * cosw * 2.0 * (-1.0 / std::f64::consts::PI.powi(2)) * scale;
    let odd3 = odd1 / 9.0;
    let at = |r: usize, c: usize| q.data[r * 8 + c];
    assert!((at(3, 4) - centre).abs() < 1e-12, "{}", at(3, 4));
    assert!((at(3, 3) - odd1).abs() < 1e-12);
    assert!((at(3, 5) - odd1).abs() < 1e-12);
    assert!((at(3, 7) - odd3).abs() < 1e-12);
    assert!((at(3, 1) - odd3).abs() < 1e-12);
    assert_eq!(at(3, 2), 0.0);
    assert_eq!(at(3, 6), 0.0);
    // Other rows are untouched (filtering is along u only).
    assert!((0..8)
        .filter(|&r| r != 3)
        .all(|r| (0..8).all(|c| at(r, c) == 0.0)));
}

/// Exact projection of a ball (centre at the origin, radius `rad`, value `mu`): mu times the
/// chord of each ray. The rays are rebuilt from the documented convention (source at
/// (DSO cos a, DSO sin a, 0); detector axes u = (-sin a, cos a, 0), v = (0, 0, -1); pixel
/// centres at (c + 1/2 - W/2) du, (r + 1/2 - H/2) dv).
fn ball_projection(g: &ConeBeam, angle: f64, rad: f64, mu: f64) -> Image2d<f32> {
    let (s, c) = angle.sin_cos();
    let (h, w) = (g.n_detector[0], g.n_detector[1]);
    let src = [g.dso * c, g.dso * s, 0.0];
    let mut data = Vec::with_capacity(w * h);
    for r in 0..h {
        for col in 0..w {
            let u = (col as f64 + 0.5 - w as f64 / 2.0) * g.d_detector[1];
            let v = (r as f64 + 0.5 - h as f64 / 2.0) * g.d_detector[0];
            let det = [src[0] - g.dsd * c - u * s, src[1] - g.dsd * s + u * c, -v];
            let d: Vec<f64> = (0..3).map(|a| det[a] - src[a]).collect();
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            // Distance from the origin to the line src + t d/|d|.
            let t = -(src[0] * d[0] + src[1] * d[1] + src[2] * d[2]) / n;
            let q: Vec<f64> = (0..3).map(|a| src[a] + t * d[a] / n).collect();
            let dist2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
            let chord = 2.0 * (rad * rad - dist2).max(0.0).sqrt();
            data.push((mu * chord) as f32);
        }
    }
    Image2d::from_vec(w, h, data)
}

fn ball_scan(n_views: usize) -> (ConeBeam, Vec<f64>, Vec<Image2d<f32>>) {
    // 40 mm box of 1 mm voxels; a ball of radius 15 mm; detector 80 x 80 at 1 mm covers the
    // magnified ball (1.5 x 15 = 22.5 mm) with room.
    let g = geo(80, 1.0, 40, 1.0);
    let angles: Vec<f64> = (0..n_views)
        .map(|k| k as f64 * std::f64::consts::PI / n_views as f64)
        .collect();
    let projs = angles
        .iter()
        .map(|&a| ball_projection(&g, a, 15.0, 0.5))
        .collect();
    (g, angles, projs)
}

#[test]
fn uniform_ball_interior() {
    let (g, angles, projs) = ball_scan(50);
    let vol = fdk::reconstruct(&g, &angles, &projs).unwrap();
    assert_eq!(vol.dims, [40; 3]);
    let (mut sum, mut n, mut worst) = (0.0, 0usize, 0.0f64);
    let mut outside = 0.0f64;
    for k in 0..40 {
        for j in 0..40 {
            for i in 0..40 {
                let p = vol.voxel_to_world([i as f64, j as f64, k as f64]);
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                let v = vol.get(i, j, k) as f64;
                if r < 10.0 {
                    sum += v;
                    n += 1;
                    worst = worst.max((v - 0.5).abs());
                } else if r > 19.0 && r < 20.0 * 1.0 {
                    outside = outside.max(v.abs());
                }
            }
        }
    }
    let mean = sum / n as f64;
    eprintln!("interior mean {mean}, worst {worst}, outside max {outside}");
    assert!((mean - 0.5).abs() < 0.005, "interior mean {mean}");
    assert!(worst < 0.025, "interior worst deviation {worst}");
    assert!(outside < 0.05, "outside {outside}");
}

#[test]
fn bit_identical_for_1_2_8_threads() {
    let (g, angles, projs) = ball_scan(12);
    let mut vols = Vec::new();
    for t in [1, 2, 8] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        vols.push(pool.install(|| fdk::reconstruct(&g, &angles, &projs).unwrap()));
    }
    let bits = |v: &unispine::volume::Volume<f32>| -> Vec<u32> {
        v.data.iter().map(|x| x.to_bits()).collect()
    };
    assert_eq!(bits(&vols[0]), bits(&vols[1]));
    assert_eq!(bits(&vols[0]), bits(&vols[2]));
}

#[test]
fn bad_input_names_the_field() {
    let (mut g, angles, projs) = ball_scan(3);
    let e = fdk::reconstruct(&g, &angles[..2], &projs).unwrap_err();
    assert!(e.to_string().contains("projections"), "{e}");
    let mut bad = projs.clone();
    bad[1].data[5] = f32::NAN;
    let e = fdk::reconstruct(&g, &angles, &bad).unwrap_err();
    assert!(matches!(e, Error::NonFinite { .. }), "{e}");
    assert!(e.to_string().contains("projection 1"), "{e}");
    // Each of the three size checks on its own: a projection whose width alone, height alone,
    // or pixel buffer alone disagrees with the detector (the fields of an image are public, so
    // a caller can build one whose buffer does not match its size).
    let (w, h) = (g.n_detector[1], g.n_detector[0]);
    let n = w * h;
    for (k, (pw, ph, len)) in [(w + 1, h, n), (w, h + 1, n), (w, h, n - 1)]
        .into_iter()
        .enumerate()
    {
        let mut bad = projs.clone();
        bad[2] = Image2d {
            width: pw,
            height: ph,
            data: vec![0.0; len],
        };
        let e = fdk::reconstruct(&g, &angles, &bad).unwrap_err();
        assert!(e.to_string().contains("projections[2]"), "case {k}: {e}");
    }
    g.mode = Mode::Parallel;
    let e = fdk::reconstruct(&g, &angles, &projs).unwrap_err();
    assert!(e.to_string().contains("mode"), "{e}");
}

/// Cosine weights off the detector's centre: one bright pixel in each corner of a non-square
/// detector with large, non-square pixels (cone angles near 20 degrees), so that each weight
/// depends on the pixel-centre convention and on which axis is u and which v. The weight is
/// rebuilt here from the convention: `DSD / sqrt(DSD^2 + u^2 + v^2)` at the pixel centre
/// `u = (c + 1/2 - W/2) du`, `v = (r + 1/2 - H/2) dv`; filtering puts `2 h(0) = 1/2` of it on the
/// pixel itself.
#[test]
fn cosine_weights_at_the_corners_of_a_non_square_detector() {
    let mut g = geo(8, 1.0, 4, 1.0);
    let (w, h) = (9usize, 6usize);
    g.n_detector = [h, w];
    g.d_detector = [70.0, 50.0];
    for (r, c) in [(0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (2, 5)] {
        let mut p = Image2d::filled(w, h, 0.0f32);
        p.data[r * w + c] = 3.0;
        let q = fdk::weight_and_filter(&g, &p, 7);
        let u = (c as f64 + 0.5 - w as f64 / 2.0) * 50.0;
        let v = (r as f64 + 0.5 - h as f64 / 2.0) * 70.0;
        let cosw = g.dsd / (g.dsd * g.dsd + u * u + v * v).sqrt();
        let want = 0.5 * 3.0 * cosw * fdk::filter_scale(&g, 7);
        let got = q.data[r * w + c];
        assert!(
            (got - want).abs() < 1e-12 * want.abs(),
            "pixel ({r}, {c}): {got} vs {want} (cos {cosw})"
        );
    }
}

/// Backprojection against a voxel-driven backprojection written from the convention alone:
/// each voxel centre is projected from the source onto the detector plane, read bilinearly
/// (zero outside) at the continuous pixel index `u / du + W/2 - 1/2` (columns) and
/// `v / dv + H/2 - 1/2` (rows), and weighted by `1 / U^2`, `U` its depth along the central ray
/// over DSO. Random filtered images, three views at arbitrary angles, a non-square detector and
/// an anisotropic, off-centre voxel grid, so every axis and offset of the convention shows.
#[test]
fn backprojection_matches_an_independent_voxel_driven_sum() {
    let mut g = geo(8, 1.0, 4, 1.0);
    let (w, h) = (11usize, 7usize);
    g.n_detector = [h, w];
    g.d_detector = [9.0, 6.0];
    g.n_voxel = [5, 4, 3];
    g.d_voxel = [7.0, 9.0, 11.0];
    g.off_origin = [3.0, -4.0, 5.0];
    let angles = [0.3, 2.1, 4.0];
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let filtered: Vec<Image2d<f64>> = angles
        .iter()
        .map(|_| Image2d::from_vec(w, h, (0..w * h).map(|_| rnd()).collect()))
        .collect();
    let vol = fdk::backproject(&g, &angles, &filtered);
    let read = |img: &Image2d<f64>, x: f64, y: f64| -> f64 {
        // Bilinear with zero outside, written as a sum over the four neighbours.
        let mut s = 0.0;
        for (c, r) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (ci, ri) = (x.floor() as i64 + c, y.floor() as i64 + r);
            let wx = 1.0 - (x - ci as f64).abs();
            let wy = 1.0 - (y - ri as f64).abs();
            if ci >= 0 && ri >= 0 && (ci as usize) < w && (ri as usize) < h {
                s += wx * wy * img.data[ri as usize * w + ci as usize];
            }
        }
        s
    };
    let mut inside = 0usize;
    for k in 0..3 {
        for j in 0..4 {
            for i in 0..5 {
                let idx = [i, j, k];
                let p: Vec<f64> = (0..3)
                    .map(|a| {
                        (idx[a] as f64 + 0.5 - g.n_voxel[a] as f64 / 2.0) * g.d_voxel[a]
                            + g.off_origin[a]
                    })
                    .collect();
                let mut want = 0.0;
                for (a, img) in angles.iter().zip(&filtered) {
                    let (s, c) = a.sin_cos();
                    let src = [g.dso * c, g.dso * s, 0.0];
                    let d = [p[0] - src[0], p[1] - src[1], p[2] - src[2]];
                    let depth = -(d[0] * c + d[1] * s);
                    let u = (-d[0] * s + d[1] * c) * g.dsd / depth;
                    let v = -d[2] * g.dsd / depth;
                    let x = u / g.d_detector[1] + w as f64 / 2.0 - 0.5;
                    let y = v / g.d_detector[0] + h as f64 / 2.0 - 0.5;
                    if x > 0.0 && y > 0.0 && x < (w - 1) as f64 && y < (h - 1) as f64 {
                        inside += 1;
                    }
                    let big_u = depth / g.dso;
                    want += read(img, x, y) / (big_u * big_u);
                }
                let got = vol.get(i, j, k) as f64;
                assert!(
                    (got - want).abs() < 1e-6 * (1.0 + want.abs()),
                    "voxel {idx:?}: {got} vs {want}"
                );
            }
        }
    }
    // Most reads fall inside the detector (the check is not a comparison of zeros).
    assert!(inside > 120, "{inside} of 180 reads inside");
}
