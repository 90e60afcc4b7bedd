//! Activations of the pre-activation parameters (Eq. 1): s = exp(log_scale),
//! alpha = sigmoid(logit), with their derivatives.

use crate::real::Real;

/// Logistic sigmoid 1 / (1 + exp(-x)), evaluated without overflow for either sign of x.
#[inline(always)]
pub fn sigmoid<R: Real>(x: R) -> R {
    if x >= R::zero() {
        R::one() / (R::one() + (-x).exp())
    } else {
        let e = x.exp();
        e / (R::one() + e)
    }
}

/// d sigmoid / dx given y = sigmoid(x): y (1 - y).
#[inline(always)]
pub fn sigmoid_grad_from_output<R: Real>(y: R) -> R {
    y * (R::one() - y)
}

/// Inverse of the sigmoid (logit), for initialisation and tests.
#[inline(always)]
pub fn logit<R: Real>(p: R) -> R {
    (p / (R::one() - p)).ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd;

    #[test]
    fn sigmoid_is_stable_and_matches_fd() {
        assert_eq!(sigmoid(-1000.0f64), 0.0);
        assert_eq!(sigmoid(1000.0f64), 1.0);
        assert!((sigmoid(0.0f64) - 0.5).abs() < 1e-16);
        for &x in &[-7.0, -0.3, 0.0, 0.4, 5.0] {
            let num = fd::central_diff5(|v| sigmoid(v[0]), &[x], 1e-3)[0];
            let an = sigmoid_grad_from_output(sigmoid(x));
            assert!((num - an).abs() <= 1e-10, "{x}: {num} vs {an}");
            assert!((logit(sigmoid(x)) - x).abs() < 1e-9);
        }
    }
}
