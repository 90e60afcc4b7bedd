//! FDK backprojection weights `DSO^2 / (DSO - x cos a - y sin a)^2` at a large cone angle.

use unispine::geometry::{ConeBeam, Mode};
use unispine::image2d::Image2d;

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
