//! Eq. (1): G = {(mu_i, Sigma_i, alpha_i, f_i)}, stored struct-of-arrays, pre-activation:
//! - `means`: mu (world, mm);
//! - `log_scales`: s = exp(log_scale) per axis;
//! - `quats`: q = (w, x, y, z), normalised inside the renderer (its Jacobian is applied in the
//!   backward pass); Sigma = R(q/|q|) diag(s)^2 R^T;
//! - `opacity_logits`: alpha = sigmoid(logit);
//! - `features`: the 16 radiative features f_i (RIRF, Eq. 2) or, for the 3DGS baseline, the 16
//!   single-channel SH coefficients (degree 3).
//!
//! The same struct holds gradients (one entry per parameter) and Adam moments.

use crate::real::Real;

/// Number of radiative features / SH coefficients per Gaussian.
pub const N_FEATURES: usize = 16;

/// A set of Gaussians (or a gradient / optimiser moment of the same shape).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians<R: Real> {
    pub means: Vec<[R; 3]>,
    pub log_scales: Vec<[R; 3]>,
    pub quats: Vec<[R; 4]>,
    pub opacity_logits: Vec<R>,
    pub features: Vec<[R; N_FEATURES]>,
}

impl<R: Real> Gaussians<R> {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there is no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// `n` Gaussians with every parameter zero (the shape of a gradient or Adam moment).
    pub fn zeros(n: usize) -> Self {
        Gaussians {
            means: vec![[R::zero(); 3]; n],
            log_scales: vec![[R::zero(); 3]; n],
            quats: vec![[R::zero(); 4]; n],
            opacity_logits: vec![R::zero(); n],
            features: vec![[R::zero(); N_FEATURES]; n],
        }
    }

    /// The same set in another precision.
    pub fn cast<S: Real>(&self) -> Gaussians<S> {
        fn c<R: Real, S: Real, const N: usize>(v: &[[R; N]]) -> Vec<[S; N]> {
            v.iter().map(|a| a.map(|x| S::c(x.f64()))).collect()
        }
        Gaussians {
            means: c(&self.means),
            log_scales: c(&self.log_scales),
            quats: c(&self.quats),
            opacity_logits: self.opacity_logits.iter().map(|&x| S::c(x.f64())).collect(),
            features: c(&self.features),
        }
    }

    /// Error if any parameter is NaN or infinite, naming the group and the Gaussian.
    pub fn check_finite(&self) -> crate::error::Result<()> {
        // The common case first: one branch-free pass over every value (it vectorises); the
        // loops below, which name the first bad value, run only when it fails.
        fn all_finite<R: Real>(v: &[R]) -> bool {
            v.iter().fold(true, |ok, x| ok & x.is_finite())
        }
        if all_finite(self.means.as_flattened())
            && all_finite(self.log_scales.as_flattened())
            && all_finite(self.quats.as_flattened())
            && all_finite(&self.opacity_logits)
            && all_finite(self.features.as_flattened())
        {
            return Ok(());
        }
        fn chk<R: Real, const N: usize>(name: &str, v: &[[R; N]]) -> crate::error::Result<()> {
            for (i, a) in v.iter().enumerate() {
                if let Some(x) = a.iter().find(|x| !x.is_finite()) {
                    return Err(crate::error::Error::NonFinite {
                        what: format!("Gaussian {i} `{name}`"),
                        index: i,
                        value: x.f64(),
                    });
                }
            }
            Ok(())
        }
        chk("means", &self.means)?;
        chk("log_scales", &self.log_scales)?;
        chk("quats", &self.quats)?;
        for (i, x) in self.opacity_logits.iter().enumerate() {
            if !x.is_finite() {
                return Err(crate::error::Error::NonFinite {
                    what: format!("Gaussian {i} `opacity_logits`"),
                    index: i,
                    value: x.f64(),
                });
            }
        }
        chk("features", &self.features)
    }
}
