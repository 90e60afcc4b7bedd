//! Quaternion (w, x, y, z) -> rotation matrix, with the normalisation q / |q| done inside and
//! differentiated (Eq. 1).
//!
//! 3DGS's CUDA kernel does not normalise (the division is commented out) and relies on PyTorch
//! autograd through `F.normalize`; gsplat and brush normalise in the kernel and apply
//! (I - q^ q^^T) / |q|. We do the latter: [`normalize_vjp`] returns the gradient with respect to
//! the *unnormalised* q.

#![allow(clippy::needless_range_loop)] // small fixed-size matrix loops read best indexed

use crate::math::Mat3;
use crate::real::Real;

/// Quaternions with |q| below this are treated as degenerate (the Gaussian is culled; see
/// `render::project`). Squared norm threshold, so no square root is needed to test it.
pub const MIN_QUAT_NORM2: f64 = 1e-24;

/// |q| and q / |q|, or `None` if |q|^2 < [`MIN_QUAT_NORM2`] or is NaN.
#[inline(always)]
pub fn normalize<R: Real>(q: [R; 4]) -> Option<(R, [R; 4])> {
    let (ok, n, qn) = normalize_unchecked(q);
    ok.then_some((n, qn))
}

/// [`normalize`] without a branch (so that loops over Gaussians vectorise): whether q is valid,
/// |q| and q / |q| (meaningless when it is not valid). The same operations as [`normalize`].
#[inline(always)]
pub fn normalize_unchecked<R: Real>(q: [R; 4]) -> (bool, R, [R; 4]) {
    let n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    let ok = (n2 >= R::c(MIN_QUAT_NORM2)) & n2.is_finite();
    let n = n2.sqrt();
    let inv = R::one() / n;
    (ok, n, [q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv])
}

/// Rotation matrix of a *unit* quaternion (w, x, y, z) (3DGS `computeCov3D`, gsplat
/// `quat_to_rotmat`).
#[inline(always)]
pub fn rotmat_unit<R: Real>(q: [R; 4]) -> Mat3<R> {
    let [w, x, y, z] = q;
    let one = R::one();
    let two = R::c(2.0);
    [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ]
}

/// VJP of [`rotmat_unit`]: d L / d q^ given G = d L / d R (row-major, every entry independent).
#[inline(always)]
pub fn rotmat_unit_vjp<R: Real>(q: [R; 4], g: &Mat3<R>) -> [R; 4] {
    let [w, x, y, z] = q;
    let two = R::c(2.0);
    let dw = -z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1];
    let dx = y * g[0][1] + z * g[0][2] + y * g[1][0] - two * x * g[1][1] - w * g[1][2]
        + z * g[2][0]
        + w * g[2][1]
        - two * x * g[2][2];
    let dy = -two * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2]
        - w * g[2][0]
        + z * g[2][1]
        - two * y * g[2][2];
    let dz = -two * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - two * z * g[1][1]
        + y * g[1][2]
        + x * g[2][0]
        + y * g[2][1];
    [two * dw, two * dx, two * dy, two * dz]
}

/// VJP of q -> q / |q|: (I - q^ q^^T) g / |q|.
#[inline(always)]
pub fn normalize_vjp<R: Real>(norm: R, qn: [R; 4], g: [R; 4]) -> [R; 4] {
    let dot = qn[0] * g[0] + qn[1] * g[1] + qn[2] * g[2] + qn[3] * g[3];
    let inv = R::one() / norm;
    [
        (g[0] - qn[0] * dot) * inv,
        (g[1] - qn[1] * dot) * inv,
        (g[2] - qn[2] * dot) * inv,
        (g[3] - qn[3] * dot) * inv,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd;

    fn loss(q: &[f64], w: &[[f64; 3]; 3]) -> f64 {
        let (_, qn) = normalize([q[0], q[1], q[2], q[3]]).unwrap();
        let r = rotmat_unit(qn);
        (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| r[i][j] * w[i][j])
            .sum()
    }

    #[test]
    fn rotation_is_orthonormal_and_vjp_matches_fd() {
        let w = [[0.3, -1.1, 0.7], [0.2, 0.9, -0.4], [-0.8, 0.5, 1.3]];
        for q in [
            [0.9, 0.2, -0.3, 0.1],
            [2.0, -1.0, 0.5, 3.0],
            [0.01, 0.3, 0.02, -0.05],
        ] {
            let (n, qn) = normalize(q).unwrap();
            let r = rotmat_unit(qn);
            let rrt = crate::math::mat3_mul(&r, &crate::math::mat3_t(&r));
            for i in 0..3 {
                for j in 0..3 {
                    let e: f64 = if i == j { 1.0 } else { 0.0 };
                    assert!((rrt[i][j] - e).abs() < 1e-14);
                }
            }
            let an = normalize_vjp(n, qn, rotmat_unit_vjp(qn, &w));
            let num = fd::central_diff5(|v| loss(v, &w), &q, 1e-4 * n);
            assert!(fd::rel_err_maxabs(&an, &num) < 1e-9, "{an:?} vs {num:?}");
        }
        assert!(normalize([0.0f64; 4]).is_none());
        assert!(normalize([f64::NAN, 1.0, 0.0, 0.0]).is_none());
    }
}
