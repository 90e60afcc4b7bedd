//! SPWM, the Structure Prior Weight Map, Eqs. (6)-(7), as the UniSpine-GS code computes it
//! (`structural_attention_map` in `utils/loss_utils.py` and the weight block of `train.py`).
//!
//! ```text
//! Eq. (6)  E = sqrt(gx^2 + gy^2 + 1e-6)       Sobel of the GT, zero padding 1
//!          H = |I - blur(I)|                   Gaussian blur, kernel 3 (made odd), sigma 1.5, zero padding
//!          A = clamp((E + l_hf H - min) / (max - min + 1e-6), 0, 1)      l_hf = 0.5, per image
//! Eq. (7)  tau = clamp(quantile_q(A), 0, tau_max)                      q = 0.85 (linear), tau_max = 0.98
//!          G = clamp((A - tau) / (1 - tau + 1e-6), 0, 1)               (the code's "soft" gate)
//!            or sigmoid((A - tau) / T)                                  (option; the paper's wording)
//!          r(t) = 0 for t <= t_s, else min(1, (t - t_s) / max(1, T_w))  t_s = 2000, T_w = 5000
//!          w = 1 + alpha r(t) G (.) A                                   alpha = 0.8
//! ```
//!
//! The map depends only on the ground-truth view; [`view_prior`] returns the
//! iteration-independent product P = G (.) A, which the trainer caches per view, and
//! [`weights`] forms w = 1 + alpha r(t) P per iteration (one multiply-add per pixel). No gradient
//! flows through w (the code detaches it). `t` is the 1-based iteration of the code's loop.

use rayon::prelude::*;

use crate::image2d::Image2d;
use crate::real::Real;

use super::filters::{blur, gaussian_kernel, sobel};

/// Additive constant under the Sobel square root (UniSpine-GS).
pub const EDGE_EPS: f64 = 1e-6;
/// Added to the min-max range of the per-image normalisation.
pub const NORM_EPS: f64 = 1e-6;
/// Added to 1 - tau in the clamped-linear gate.
pub const GATE_EPS: f64 = 1e-6;

/// The gate G of Eq. (7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GateKind {
    /// clamp((A - tau) / (1 - tau + 1e-6), 0, 1): the UniSpine-GS code (default).
    ClampedLinear,
    /// sigmoid((A - tau) / temperature): a smooth gate, as the paper's word "soft" suggests.
    Sigmoid,
}

/// SPWM settings. Defaults are the UniSpine-GS configuration (`config/example.yaml`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SpwmConfig {
    /// alpha of Eq. (7) (`attn_alpha`, 0.8).
    pub alpha: f64,
    /// lambda_hf of Eq. (6) (`attn_hf_lambda`, 0.5).
    pub hf_lambda: f64,
    /// Blur kernel size (`attn_blur_kernel`, 3; an even size is made odd by +1 as upstream).
    pub blur_kernel: usize,
    /// Blur sigma (`attn_blur_sigma`, 1.5).
    pub blur_sigma: f64,
    /// tau from the quantile of A (true, `attn_adaptive_gate`) or the fixed `fixed_tau`.
    pub adaptive_gate: bool,
    /// q of the adaptive threshold (`attn_gate_quantile`, 0.85; linear interpolation).
    pub quantile: f64,
    /// Upper clamp of the adaptive tau (0.98).
    pub tau_max: f64,
    /// tau when `adaptive_gate` is false (`attn_gate_thresh`, 0.4; unused by every config).
    pub fixed_tau: f64,
    /// Warm-up start t_s (`attn_warmup_start`, 2000).
    pub warmup_start: usize,
    /// Warm-up length (`attn_warmup_iters`, 5000).
    pub warmup_iters: usize,
    /// Gate shape (clamped linear, as the code).
    pub gate: GateKind,
    /// Temperature T of the sigmoid gate (0.05; the paper gives none, the code has no sigmoid).
    pub gate_temperature: f64,
}

impl Default for SpwmConfig {
    fn default() -> Self {
        SpwmConfig {
            alpha: 0.8,
            hf_lambda: 0.5,
            blur_kernel: 3,
            blur_sigma: 1.5,
            adaptive_gate: true,
            quantile: 0.85,
            tau_max: 0.98,
            fixed_tau: 0.4,
            warmup_start: 2000,
            warmup_iters: 5000,
            gate: GateKind::ClampedLinear,
            gate_temperature: 0.05,
        }
    }
}

impl SpwmConfig {
    /// Check the settings; `Err` names the field.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |field: &str, why: &str| {
            Err(crate::Error::Invalid {
                field: format!("spwm.{field}"),
                msg: why.to_string(),
            })
        };
        let finite_nonneg = |v: f64| v.is_finite() && v >= 0.0;
        if !finite_nonneg(self.alpha) {
            return bad("alpha", "must be finite and >= 0");
        }
        if !finite_nonneg(self.hf_lambda) {
            return bad("hf_lambda", "must be finite and >= 0");
        }
        if self.blur_kernel == 0 {
            return bad("blur_kernel", "must be >= 1");
        }
        if !(self.blur_sigma.is_finite() && self.blur_sigma > 0.0) {
            return bad("blur_sigma", "must be finite and > 0");
        }
        if !(0.0..=1.0).contains(&self.quantile) {
            return bad("quantile", "must be in [0, 1]");
        }
        // tau = 1 is allowed, as in the trainer's settings table: the gate's denominator
        // 1 - tau + 1e-6 stays positive, and the gate is then 0 wherever A < 1.
        if !(0.0..=1.0).contains(&self.tau_max) {
            return bad("tau_max", "must be in [0, 1]");
        }
        if !(0.0..=1.0).contains(&self.fixed_tau) {
            return bad("fixed_tau", "must be in [0, 1]");
        }
        if !(self.gate_temperature.is_finite() && self.gate_temperature > 0.0) {
            return bad("gate_temperature", "must be finite and > 0");
        }
        Ok(())
    }

    /// The blur kernel size actually used (odd).
    pub fn odd_blur_kernel(&self) -> usize {
        if self.blur_kernel.is_multiple_of(2) {
            self.blur_kernel + 1
        } else {
            self.blur_kernel
        }
    }
}

/// Every intermediate of Eqs. (6)-(7) for one ground-truth view (for audits and golden files).
#[derive(Clone, Debug)]
pub struct Attention<R: Real> {
    /// Sobel magnitude E.
    pub edge: Image2d<R>,
    /// High-frequency residual H = |I - blur(I)|.
    pub high: Image2d<R>,
    /// Normalised structure map A of Eq. (6).
    pub attention: Image2d<R>,
    /// The gate threshold tau.
    pub tau: f64,
    /// The gate G.
    pub gate: Image2d<R>,
}

/// Linear-interpolated quantile of `v` (numpy / torch `linear`):
/// `sorted[i] + f (sorted[i+1] - sorted[i])` at position q (n - 1) = i + f. The two order
/// statistics are found by selection (O(n)); their values do not depend on the algorithm.
pub fn quantile_linear(v: &[f64], q: f64) -> f64 {
    assert!(!v.is_empty(), "quantile of an empty set");
    let mut s = v.to_vec();
    let n = s.len();
    let pos = q * (n - 1) as f64;
    let i = (pos.floor() as usize).min(n - 1);
    let f = pos - i as f64;
    let (_, &mut lo, upper) = s.select_nth_unstable_by(i, |a, b| a.total_cmp(b));
    if i + 1 < n {
        // sorted[i + 1] is the smallest element of the part above position i.
        let hi =
            upper.iter().copied().fold(
                f64::INFINITY,
                |m, x| {
                    if x.total_cmp(&m).is_lt() {
                        x
                    } else {
                        m
                    }
                },
            );
        lo + f * (hi - lo)
    } else {
        lo
    }
}

/// Warm-up factor r(t) of Eq. (7).
pub fn warmup(iter: usize, cfg: &SpwmConfig) -> f64 {
    if iter <= cfg.warmup_start {
        0.0
    } else {
        ((iter - cfg.warmup_start) as f64 / cfg.warmup_iters.max(1) as f64).min(1.0)
    }
}

fn map<R: Real, F: Fn(f64) -> f64>(x: &Image2d<R>, f: F) -> Image2d<R> {
    Image2d::from_vec(
        x.width,
        x.height,
        x.data.iter().map(|&v| R::c(f(v.f64()))).collect(),
    )
}

/// Eqs. (6)-(7) up to the gate, from the ground-truth view `gt` (its min-max normalised image).
pub fn attention<R: Real>(gt: &Image2d<R>, cfg: &SpwmConfig) -> Attention<R> {
    assert!(!gt.data.is_empty(), "SPWM of an empty image");
    // Eq. (6): E, H, A.
    let (gx, gy) = sobel(gt);
    let eps = R::c(EDGE_EPS);
    let edge = gx.zip_map(&gy, |a, b| (a * a + b * b + eps).sqrt());
    let k = gaussian_kernel(cfg.odd_blur_kernel(), cfg.blur_sigma, 1e-12);
    let bl = blur(gt, &k);
    let high = gt.zip_map(&bl, |x, b| (x - b).abs());
    let lam = R::c(cfg.hf_lambda);
    let raw: Vec<R> = edge
        .data
        .iter()
        .zip(&high.data)
        .map(|(&e, &h)| e + lam * h)
        .collect();
    let lo = raw.iter().fold(R::infinity(), |m, &v| m.min(v)).f64();
    let hi = raw.iter().fold(R::neg_infinity(), |m, &v| m.max(v)).f64();
    let range = hi - lo + NORM_EPS;
    let attention = Image2d::from_vec(
        gt.width,
        gt.height,
        raw.iter()
            .map(|&v| R::c(((v.f64() - lo) / range).clamp(0.0, 1.0)))
            .collect(),
    );
    // Eq. (7): tau and the gate.
    let tau = if cfg.adaptive_gate {
        let a: Vec<f64> = attention.data.iter().map(|v| v.f64()).collect();
        quantile_linear(&a, cfg.quantile).clamp(0.0, cfg.tau_max)
    } else {
        cfg.fixed_tau
    };
    let gate = match cfg.gate {
        GateKind::ClampedLinear => {
            let den = 1.0 - tau + GATE_EPS;
            map(&attention, |a| ((a - tau) / den).clamp(0.0, 1.0))
        }
        GateKind::Sigmoid => {
            let t = cfg.gate_temperature;
            map(&attention, |a| 1.0 / (1.0 + (-(a - tau) / t).exp()))
        }
    };
    Attention {
        edge,
        high,
        attention,
        tau,
        gate,
    }
}

/// The iteration-independent part of the SPWM weights of one ground-truth view, P = G (.) A
/// (computed once per view and cached).
pub fn view_prior<R: Real>(gt: &Image2d<R>, cfg: &SpwmConfig) -> Image2d<R> {
    let at = attention(gt, cfg);
    at.gate.zip_map(&at.attention, |g, a| g * a)
}

/// The weights w = 1 + alpha r(t) P of Eq. (7) at iteration `iter` from a cached [`view_prior`].
pub fn weights<R: Real>(prior: &Image2d<R>, iter: usize, cfg: &SpwmConfig) -> Image2d<R> {
    let a = R::c(cfg.alpha * warmup(iter, cfg));
    Image2d::from_vec(
        prior.width,
        prior.height,
        prior.data.par_iter().map(|&p| R::one() + a * p).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_matches_numpy_linear() {
        // numpy.quantile([3, 1, 4, 1, 5], q): 0.85 -> 4.4, 0.5 -> 3, 0 -> 1, 1 -> 5.
        let v = [3.0, 1.0, 4.0, 1.0, 5.0];
        assert!((quantile_linear(&v, 0.85) - 4.4).abs() < 1e-15);
        assert_eq!(quantile_linear(&v, 0.5), 3.0);
        assert_eq!(quantile_linear(&v, 0.0), 1.0);
        assert_eq!(quantile_linear(&v, 1.0), 5.0);
        assert_eq!(quantile_linear(&[2.5], 0.85), 2.5);
        // Against a full sort on random data with ties.
        let mut x = 0.123_f64;
        let v: Vec<f64> = (0..1001)
            .map(|_| {
                x = (x * 997.0 + 0.31).fract();
                (x * 50.0).floor() / 50.0
            })
            .collect();
        let mut s = v.clone();
        s.sort_by(|a, b| a.total_cmp(b));
        for q in [0.0f64, 0.1, 0.5, 0.85, 0.999, 1.0] {
            let pos = q * 1000.0;
            let i = (pos.floor() as usize).min(1000);
            let want = if i < 1000 {
                s[i] + (pos - i as f64) * (s[i + 1] - s[i])
            } else {
                s[i]
            };
            assert_eq!(quantile_linear(&v, q).to_bits(), want.to_bits(), "q = {q}");
        }
    }

    #[test]
    fn warmup_schedule() {
        let c = SpwmConfig::default();
        for (t, r) in [
            (0, 0.0),
            (1, 0.0),
            (2000, 0.0),
            (2001, 2e-4),
            (4500, 0.5),
            (7000, 1.0),
            (9000, 1.0),
        ] {
            assert!(
                (warmup(t, &c) - r).abs() < 1e-15,
                "r({t}) = {}",
                warmup(t, &c)
            );
        }
        let c0 = SpwmConfig {
            warmup_iters: 0,
            ..c
        };
        assert_eq!(warmup(2001, &c0), 1.0);
    }

    #[test]
    fn config_defaults_and_validation() {
        let c: SpwmConfig = serde_json::from_str("{}").unwrap();
        assert_eq!(c, SpwmConfig::default());
        assert_eq!(c.odd_blur_kernel(), 3);
        assert_eq!(
            SpwmConfig {
                blur_kernel: 4,
                ..c.clone()
            }
            .odd_blur_kernel(),
            5
        );
        assert!(c.validate().is_ok());
        let e = SpwmConfig {
            quantile: 1.5,
            ..c.clone()
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("spwm.quantile"), "{e}");
        let s: SpwmConfig =
            serde_json::from_str(r#"{"gate": "sigmoid", "gate_temperature": 0.1}"#).unwrap();
        assert_eq!(s.gate, GateKind::Sigmoid);
        assert!(serde_json::from_str::<SpwmConfig>(r#"{"alpah": 1}"#).is_err());
    }
}
