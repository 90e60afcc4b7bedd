//! Inverse of a symmetric 2x2 matrix [[a, b], [b, c]] (Eq. 3: conic = Sigma2D^-1) and its VJP.

use crate::real::Real;

/// (A, B, C) of [[a, b], [b, c]]^-1 = [[c, -b], [-b, a]] / det, with det = ac - b^2.
/// Returns `None` unless det > 0 (a NaN det fails the test too).
#[inline(always)]
pub fn sym2_inverse<R: Real>(a: R, b: R, c: R) -> Option<[R; 3]> {
    let (ok, conic) = sym2_inverse_unchecked(a, b, c);
    ok.then_some(conic)
}

/// [`sym2_inverse`] without a branch (so that loops over Gaussians vectorise): whether the
/// determinant is positive, and the inverse (meaningless when it is not). The same operations.
#[inline(always)]
pub fn sym2_inverse_unchecked<R: Real>(a: R, b: R, c: R) -> (bool, [R; 3]) {
    let det = a * c - b * b;
    let inv = R::one() / det;
    (det > R::zero(), [c * inv, -b * inv, a * inv])
}

/// VJP of [`sym2_inverse`]: given the gradient (gA, gB, gC) of the three conic entries (B is a
/// single parameter, the off-diagonal value), return (ga, gb, gc) for (a, b, c) (b likewise a
/// single parameter). Exact: d(inv)/d(entries) from the closed form, no regulariser (DGR adds
/// 1e-7 to det^2).
#[inline(always)]
pub fn sym2_inverse_vjp<R: Real>(a: R, b: R, c: R, g: [R; 3]) -> [R; 3] {
    let det = a * c - b * b;
    let inv2 = R::one() / (det * det);
    let two = R::c(2.0);
    let [ga_, gb_, gc_] = g;
    // A = c/D, B = -b/D, C = a/D with D = ac - b^2; dD/da = c, dD/db = -2b, dD/dc = a.
    let da = (-c * c * ga_ + b * c * gb_ - b * b * gc_) * inv2;
    let dc = (-b * b * ga_ + a * b * gb_ - a * a * gc_) * inv2;
    let db = (two * b * c * ga_ - (det + two * b * b) * gb_ + two * a * b * gc_) * inv2;
    [da, db, dc]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd;

    #[test]
    fn inverse_vjp_matches_fd() {
        let x = [2.3, -0.7, 1.1];
        let w = [0.3, -1.2, 0.8];
        let f = |v: &[f64]| {
            let q = sym2_inverse(v[0], v[1], v[2]).unwrap();
            q[0] * w[0] + q[1] * w[1] + q[2] * w[2]
        };
        let num = fd::central_diff5(f, &x, 1e-3);
        let an = sym2_inverse_vjp(x[0], x[1], x[2], w);
        assert!(fd::rel_err_maxabs(&an, &num) < 1e-9, "{an:?} {num:?}");
        let q = sym2_inverse(x[0], x[1], x[2]).unwrap();
        // [[a,b],[b,c]] [[A,B],[B,C]] = I
        assert!((x[0] * q[0] + x[1] * q[1] - 1.0).abs() < 1e-14);
        assert!((x[0] * q[1] + x[1] * q[2]).abs() < 1e-14);
        assert!(sym2_inverse(1.0, 2.0, 1.0).is_none());
        assert!(sym2_inverse(f64::NAN, 0.0, 1.0).is_none());
    }
}
