//! Pose error as a dataset condition: the projections are computed with the scanner's exact
//! cameras, the *recorded* training cameras are perturbed; test cameras stay exact.
//!
//! Per training view k, in view order from one seeded stream: a rotation axis uniform on the
//! unit sphere (z = 2 u1 - 1, phi = 2 pi u2), an angle of N(0, S^2) degrees about that axis
//! through the isocentre (the world origin, on the rotation axis of the orbit), and a
//! translation of N(0, T^2) mm per axis applied to the source and the detector together. With
//! R the rotation (Rodrigues) and t the translation, the recorded camera is
//! `centre' = R centre + t`, `rot' = rot R^T` (its axes rotated with it). S = T = 0 records
//! nothing: the dataset is today's, bit for bit. The perturbations are stored in the manifest
//! (`manifest.pose_noise`), and [`crate::dataset::Dataset::train_camera`] applies them.

#![allow(clippy::needless_range_loop)] // small fixed-size matrix loops read best indexed

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::{Camera, ConeBeam};

/// One training view's perturbation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewPose {
    /// Unit rotation axis through the isocentre (world coordinates).
    pub axis: [f64; 3],
    /// Rotation angle about `axis`, degrees (right-handed).
    pub angle_deg: f64,
    /// Translation of the source and detector, mm (world coordinates).
    pub translation_mm: [f64; 3],
}

/// The recorded pose error of a dataset's training cameras.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseNoise {
    /// S: standard deviation of the rotation angle, degrees.
    pub rotation_sd_deg: f64,
    /// T: standard deviation of the translation per axis, mm.
    pub translation_sd_mm: f64,
    /// Seed of the stream the perturbations were drawn from.
    pub seed: u64,
    /// One perturbation per training view, in view order.
    pub views: Vec<ViewPose>,
}

/// The rotation matrix of `angle` radians about the unit `axis` (Rodrigues:
/// R = cos a I + sin a K + (1 - cos a) k k^T, K the cross-product matrix of k).
pub fn rotation(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let v = 1.0 - c;
    [
        [c + x * x * v, x * y * v - z * s, x * z * v + y * s],
        [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
        [z * x * v - y * s, z * y * v + x * s, c + z * z * v],
    ]
}

impl ViewPose {
    /// The recorded camera: `cam` rotated about the isocentre and translated.
    pub fn apply(&self, cam: &Camera) -> Camera {
        let r = rotation(self.axis, self.angle_deg.to_radians());
        let c = cam.centre;
        let mut out = cam.clone();
        for i in 0..3 {
            out.centre[i] =
                r[i][0] * c[0] + r[i][1] * c[1] + r[i][2] * c[2] + self.translation_mm[i];
            // Row i of rot R^T: (R a_i)^T, a_i the camera axis i in world coordinates.
            for j in 0..3 {
                out.rot[i][j] = (0..3).map(|k| cam.rot[i][k] * r[j][k]).sum();
            }
        }
        out
    }
}

/// A standard normal variate (Box-Muller, one of the pair).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Check a flag value: finite and >= 0.
pub fn check_sd(flag: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            flag,
            format!("must be a finite number >= 0, got {v}"),
        ))
    }
}

/// Draw the perturbations of `views` training views; `None` when both deviations are 0 (the
/// exact cameras, nothing recorded).
pub fn draw(deg: f64, mm: f64, seed: u64, views: usize) -> Result<Option<PoseNoise>> {
    check_sd("--pose-noise-deg", deg)?;
    check_sd("--pose-noise-mm", mm)?;
    if deg == 0.0 && mm == 0.0 {
        return Ok(None);
    }
    // Purpose-specific stream: the seed mixed with a constant naming "pose".
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x706f_7365_0000_0001);
    let views = (0..views)
        .map(|_| {
            let z = 2.0 * rng.random::<f64>() - 1.0;
            let phi = 2.0 * std::f64::consts::PI * rng.random::<f64>();
            let rxy = (1.0 - z * z).max(0.0).sqrt();
            let axis = [rxy * phi.cos(), rxy * phi.sin(), z];
            let angle_deg = deg * normal(&mut rng);
            let translation_mm = [0; 3].map(|_| mm * normal(&mut rng));
            ViewPose {
                axis,
                angle_deg,
                translation_mm,
            }
        })
        .collect();
    Ok(Some(PoseNoise {
        rotation_sd_deg: deg,
        translation_sd_mm: mm,
        seed,
        views,
    }))
}

/// Is `p` inside the volume's box (offOrigin-centred, nVoxel x dVoxel)?
fn inside_box(geo: &ConeBeam, p: [f64; 3]) -> bool {
    (0..3).all(|i| {
        let half = 0.5 * geo.n_voxel[i] as f64 * geo.d_voxel[i];
        (p[i] - geo.off_origin[i]).abs() <= half
    })
}

/// Validate a record against a dataset's geometry and training angles: one finite perturbation
/// per view, unit axes, and no recorded source inside the volume. Errors name
/// `manifest.pose_noise` (a stored dataset is untrusted input).
pub fn check(p: &PoseNoise, geo: &ConeBeam, train_angles: &[f64]) -> Result<()> {
    let field = "manifest.pose_noise";
    if p.views.len() != train_angles.len() {
        return Err(Error::invalid(
            field,
            format!(
                "{} perturbations for {} training views",
                p.views.len(),
                train_angles.len()
            ),
        ));
    }
    for (k, (v, &a)) in p.views.iter().zip(train_angles).enumerate() {
        let finite = v
            .axis
            .iter()
            .chain(&v.translation_mm)
            .all(|x| x.is_finite())
            && v.angle_deg.is_finite();
        let norm = v.axis.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !finite || (norm - 1.0).abs() > 1e-9 {
            return Err(Error::invalid(
                format!("{field}.views[{k}]"),
                "not a finite perturbation about a unit axis",
            ));
        }
        let c = v.apply(&Camera::new(geo, a)).centre;
        if inside_box(geo, c) {
            return Err(Error::invalid(
                format!("{field}.views[{k}]"),
                format!(
                    "moves the source to ({:.1}, {:.1}, {:.1}) mm, inside the volume",
                    c[0], c[1], c[2]
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geo() -> ConeBeam {
        ConeBeam::centred([32, 32], [2.0, 2.0], [32, 32, 32], [1.0; 3])
    }

    /// Rotate `v` by the unit quaternion of (axis, angle): q v q* (independent of Rodrigues).
    fn quat_rotate(axis: [f64; 3], angle: f64, v: [f64; 3]) -> [f64; 3] {
        let (s, c) = (angle / 2.0).sin_cos();
        let q = [c, axis[0] * s, axis[1] * s, axis[2] * s];
        let mul = |a: [f64; 4], b: [f64; 4]| {
            [
                a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
                a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
                a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
                a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
            ]
        };
        let r = mul(mul(q, [0.0, v[0], v[1], v[2]]), [q[0], -q[1], -q[2], -q[3]]);
        [r[1], r[2], r[3]]
    }

    #[test]
    fn a_perturbed_camera_matches_a_hand_computed_rotation() {
        let g = geo();
        // 90 deg about z: the source at (DSO, 0, 0) goes to (0, DSO, 0), then + t.
        let v = ViewPose {
            axis: [0.0, 0.0, 1.0],
            angle_deg: 90.0,
            translation_mm: [1.0, -2.0, 3.0],
        };
        let cam = Camera::new(&g, 0.0);
        let p = v.apply(&cam);
        let want = [1.0, g.dso - 2.0, 3.0];
        for i in 0..3 {
            assert!((p.centre[i] - want[i]).abs() < 1e-9, "{:?}", p.centre);
        }
        // Rotated by 90 deg about z the exact camera at angle 0 is the exact camera at 90 deg.
        let c90 = Camera::new(&g, std::f64::consts::FRAC_PI_2);
        for i in 0..3 {
            for j in 0..3 {
                assert!((p.rot[i][j] - c90.rot[i][j]).abs() < 1e-12);
            }
        }
        // A fixed seed: the drawn perturbation of view 3, applied, equals the quaternion
        // rotation of the exact camera's centre and axes.
        let rec = draw(0.2, 0.5, 7, 10).unwrap().unwrap();
        assert_eq!(rec, draw(0.2, 0.5, 7, 10).unwrap().unwrap());
        assert_ne!(rec, draw(0.2, 0.5, 8, 10).unwrap().unwrap());
        let v = &rec.views[3];
        assert!((v.axis.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(v.angle_deg != 0.0 && v.angle_deg.abs() < 5.0 * 0.2);
        let cam = Camera::new(&g, 0.7);
        let p = v.apply(&cam);
        let a = v.angle_deg.to_radians();
        let c = quat_rotate(v.axis, a, cam.centre);
        for i in 0..3 {
            assert!((p.centre[i] - (c[i] + v.translation_mm[i])).abs() < 1e-9);
            let axis_i = quat_rotate(v.axis, a, cam.rot[i]);
            for j in 0..3 {
                assert!((p.rot[i][j] - axis_i[j]).abs() < 1e-12);
            }
        }
        // A world point moved with the camera projects to the same pixel.
        let x = [3.0, -4.0, 5.0];
        let xr = quat_rotate(v.axis, a, x);
        let xr = [0, 1, 2].map(|i| xr[i] + v.translation_mm[i]);
        let (u0, u1) = (
            cam.project_cam(cam.world_to_cam(x)),
            p.project_cam(p.world_to_cam(xr)),
        );
        assert!((u0[0] - u1[0]).abs() < 1e-9 && (u0[1] - u1[1]).abs() < 1e-9);
        check(
            &rec,
            &g,
            &(0..10).map(|k| k as f64 * 0.3).collect::<Vec<_>>(),
        )
        .unwrap();
    }

    #[test]
    fn bad_noise_is_an_error_naming_the_flag_and_value() {
        assert_eq!(draw(0.0, 0.0, 1, 5).unwrap(), None);
        for (d, m, flag, val) in [
            (-1.0, 0.0, "--pose-noise-deg", "-1"),
            (f64::NAN, 0.0, "--pose-noise-deg", "NaN"),
            (0.1, f64::INFINITY, "--pose-noise-mm", "inf"),
            (0.1, -0.5, "--pose-noise-mm", "-0.5"),
        ] {
            let e = draw(d, m, 0, 3).unwrap_err().to_string();
            assert!(e.contains(flag) && e.contains(val), "{e}");
        }
        // A recorded source moved onto the isocentre is refused.
        let g = geo();
        let mut rec = draw(0.0, 1.0, 0, 2).unwrap().unwrap();
        rec.views[1].translation_mm = [-g.dso, 0.0, 0.0];
        let e = check(&rec, &g, &[0.0, 0.0]).unwrap_err().to_string();
        assert!(
            e.contains("views[1]") && e.contains("inside the volume"),
            "{e}"
        );
        rec.views.pop();
        assert!(check(&rec, &g, &[0.0, 0.0]).is_err());
    }
}
