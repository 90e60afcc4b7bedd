//! The projection's Jacobian clamp (Eq. 3) on all four sides, Sigma2D in closed form.

use unispine::geometry::ConeBeam;

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
