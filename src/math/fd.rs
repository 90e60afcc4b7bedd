//! Central finite differences in f64, used by every backward-pass test of the crate.
//!
//! Usage: write the forward pass as `f: FnMut(&[f64]) -> f64` of a flat parameter vector (for
//! a stage, a scalar functional such as `sum_k w_k * output_k` with fixed random weights),
//! compute the analytic gradient with the stage's VJP, and compare with
//! [`rel_err_maxabs`]`(&analytic, &central_diff5(f, &x, h))`.
//!
//! **Error metric** ([`rel_err_maxabs`]): `max_k |a_k - n_k| / max_k |n_k|`, i.e. the worst
//! absolute difference normalised by the largest reference component of the group. Unlike a
//! per-element relative error it does not blow up on components that are (nearly) zero, and
//! unlike a plain absolute error it is scale free. Compare one parameter group at a time so
//! that groups with different units (mm, log-scales, logits) do not mask each other.
//!
//! **Step**: [`central_diff`] (2nd order, truncation O(h^2)) and [`central_diff5`] (4th order,
//! O(h^4)); with h ~ 1e-4..1e-3 of the parameter's natural scale the 5-point stencil reaches
//! ~1e-10 relative accuracy on smooth functions, well below the 1e-6 tolerance of the tests.
//! [`central_diff_scaled`] takes one step per component.

/// Gradient of `f` at `x` by the 2-point central difference (f(x+h) - f(x-h)) / 2h.
pub fn central_diff<F: FnMut(&[f64]) -> f64>(mut f: F, x: &[f64], h: f64) -> Vec<f64> {
    let mut v = x.to_vec();
    (0..x.len())
        .map(|k| {
            v[k] = x[k] + h;
            let fp = f(&v);
            v[k] = x[k] - h;
            let fm = f(&v);
            v[k] = x[k];
            (fp - fm) / (2.0 * h)
        })
        .collect()
}

/// Gradient of `f` at `x` by the 4th-order 5-point stencil
/// (-f(x+2h) + 8 f(x+h) - 8 f(x-h) + f(x-2h)) / 12h.
pub fn central_diff5<F: FnMut(&[f64]) -> f64>(f: F, x: &[f64], h: f64) -> Vec<f64> {
    let steps = vec![h; x.len()];
    central_diff_scaled(f, x, &steps)
}

/// [`central_diff5`] with a separate step per component (`steps[k]` for `x[k]`).
pub fn central_diff_scaled<F: FnMut(&[f64]) -> f64>(
    mut f: F,
    x: &[f64],
    steps: &[f64],
) -> Vec<f64> {
    assert_eq!(x.len(), steps.len(), "one step per component");
    let mut v = x.to_vec();
    (0..x.len())
        .map(|k| {
            let h = steps[k];
            let mut at = |d: f64| {
                v[k] = x[k] + d;
                let r = f(&v);
                v[k] = x[k];
                r
            };
            let (p2, p1, m1, m2) = (at(2.0 * h), at(h), at(-h), at(-2.0 * h));
            (-p2 + 8.0 * p1 - 8.0 * m1 + m2) / (12.0 * h)
        })
        .collect()
}

/// Max-abs-normalised relative error `max_k |a_k - b_k| / max_k |b_k|` (b is the reference).
/// Returns the plain max absolute difference when the reference is identically zero.
pub fn rel_err_maxabs(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "compared vectors differ in length");
    let diff = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    let scale = b.iter().map(|y| y.abs()).fold(0.0, f64::max);
    if scale > 0.0 {
        diff / scale
    } else {
        diff
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stencils_are_exact_on_polynomials() {
        // 5-point is exact for quartics (up to rounding), 2-point for quadratics.
        let f = |v: &[f64]| v[0].powi(4) - 3.0 * v[0] * v[1] + v[1] * v[1];
        let x = [1.3, -0.4];
        let g = central_diff5(f, &x, 0.01);
        let want = [4.0 * 1.3f64.powi(3) + 1.2, -3.9 - 0.8];
        assert!(rel_err_maxabs(&g, &want) < 1e-12, "{g:?}");
        let g2 = central_diff(|v: &[f64]| v[0] * v[0], &[2.0], 0.1);
        assert!((g2[0] - 4.0).abs() < 1e-12);
        assert_eq!(rel_err_maxabs(&[1.0, 0.0], &[2.0, 0.0]), 0.5);
        assert_eq!(rel_err_maxabs(&[1e-3], &[0.0]), 1e-3);
    }
}
