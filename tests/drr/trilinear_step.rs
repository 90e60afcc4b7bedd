//! The trilinear DRR's step: the Riemann sum over the source-anchored lattice with step
//! `L / ceil(L / h0)` of the closed-form (separable) interpolant of a box.

use unispine::drr::{self, Method};
use unispine::geometry::{ConeBeam, Mode};
use unispine::volume::Volume;

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
