//! Eq. (1): Sigma = R(q / |q|) S S^T R(q / |q|)^T with S = diag(exp(log_scale)), and its VJP
//! with respect to the pre-activation parameters (log_scale, unnormalised q).

#![allow(clippy::needless_range_loop)] // small fixed-size matrix loops read best indexed

use crate::math::quat::{normalize, normalize_vjp, rotmat_unit, rotmat_unit_vjp};
use crate::math::Mat3;
use crate::real::Real;

/// What the VJP of [`covariance`] needs (recomputed cheaply, so nothing is stored per Gaussian).
#[derive(Clone, Copy, Debug)]
pub struct CovParts<R: Real> {
    /// |q|.
    pub norm: R,
    /// q / |q|.
    pub qn: [R; 4],
    /// R(q / |q|).
    pub rot: Mat3<R>,
    /// exp(log_scale).
    pub scale: [R; 3],
}

/// Eq. (1): the 3D covariance and its parts, or `None` for a degenerate quaternion
/// (|q|^2 < `MIN_QUAT_NORM2` or non-finite).
#[inline(always)]
pub fn covariance<R: Real>(log_scale: [R; 3], q: [R; 4]) -> Option<(Mat3<R>, CovParts<R>)> {
    let (norm, qn) = normalize(q)?;
    let scale = [log_scale[0].exp(), log_scale[1].exp(), log_scale[2].exp()];
    Some(covariance_scaled(norm, qn, scale))
}

/// [`covariance`] from its activated parameters: |q|, q / |q| and exp(log_scale). Branch-free
/// (loops over Gaussians that compute the exponentials first vectorise).
#[inline(always)]
pub fn covariance_scaled<R: Real>(norm: R, qn: [R; 4], scale: [R; 3]) -> (Mat3<R>, CovParts<R>) {
    let rot = rotmat_unit(qn);
    // M = R S; Sigma = M M^T.
    let mut m = rot;
    for row in m.iter_mut() {
        for j in 0..3 {
            row[j] *= scale[j];
        }
    }
    let mut sigma = [[R::zero(); 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            let v = m[i][0] * m[j][0] + m[i][1] * m[j][1] + m[i][2] * m[j][2];
            sigma[i][j] = v;
            sigma[j][i] = v;
        }
    }
    (
        sigma,
        CovParts {
            norm,
            qn,
            rot,
            scale,
        },
    )
}

/// VJP of [`covariance`]. `g` is d L / d Sigma in the *symmetric* convention (g = g^T, each
/// off-diagonal entry carrying half the gradient of the single off-diagonal parameter), which
/// is what `A^T G A` style chain rules produce. Returns (d log_scale, d q) for the unnormalised q.
#[inline(always)]
pub fn covariance_vjp<R: Real>(p: &CovParts<R>, g: &Mat3<R>) -> ([R; 3], [R; 4]) {
    let two = R::c(2.0);
    // Sigma = M M^T with M = R S: dM = (G + G^T) M = 2 G M.
    let mut m = p.rot;
    for row in m.iter_mut() {
        for j in 0..3 {
            row[j] *= p.scale[j];
        }
    }
    let mut dm = [[R::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            dm[i][j] = two * (g[i][0] * m[0][j] + g[i][1] * m[1][j] + g[i][2] * m[2][j]);
        }
    }
    // M_ij = R_ij s_j: dR_ij = dM_ij s_j; ds_j = sum_i dM_ij R_ij; d log s_j = ds_j s_j.
    let mut dr = [[R::zero(); 3]; 3];
    let mut dls = [R::zero(); 3];
    for j in 0..3 {
        let mut ds = R::zero();
        for i in 0..3 {
            dr[i][j] = dm[i][j] * p.scale[j];
            ds += dm[i][j] * p.rot[i][j];
        }
        dls[j] = ds * p.scale[j];
    }
    let dqn = rotmat_unit_vjp(p.qn, &dr);
    (dls, normalize_vjp(p.norm, p.qn, dqn))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd;

    #[test]
    fn covariance_closed_form_and_vjp() {
        // Identity rotation: Sigma = diag(s^2).
        let (s, _) = covariance([0.1f64, -0.5, 1.0], [3.0, 0.0, 0.0, 0.0]).unwrap();
        let e = [0.2f64.exp(), (-1.0f64).exp(), 2.0f64.exp()];
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { e[i] } else { 0.0 };
                assert!((s[i][j] - want).abs() < 1e-14 * want.max(1.0));
            }
        }
        // 90 degrees about z swaps the x and y variances.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let (s, _) = covariance([0.0f64, 1.0, 0.0], [h, 0.0, 0.0, h]).unwrap();
        assert!((s[0][0] - 2.0f64.exp()).abs() < 1e-13 && (s[1][1] - 1.0).abs() < 1e-13);

        // VJP against FD for a symmetric weight (the symmetric-gradient convention).
        let w = [[0.7, -0.3, 0.2], [-0.3, 1.1, 0.5], [0.2, 0.5, -0.9]];
        let x0 = [0.2, -0.4, 0.3, 0.8, -1.5, 0.6, 0.9];
        let f = |v: &[f64]| {
            let (s, _) = covariance([v[0], v[1], v[2]], [v[3], v[4], v[5], v[6]]).unwrap();
            (0..9)
                .map(|k| s[k / 3][k % 3] * w[k / 3][k % 3])
                .sum::<f64>()
        };
        let (_, p) = covariance([x0[0], x0[1], x0[2]], [x0[3], x0[4], x0[5], x0[6]]).unwrap();
        let (dls, dq) = covariance_vjp(&p, &w);
        let an: Vec<f64> = dls.iter().chain(dq.iter()).copied().collect();
        let num = fd::central_diff5(f, &x0, 1e-4);
        assert!(fd::rel_err_maxabs(&an, &num) < 1e-9, "{an:?} vs {num:?}");
    }
}
