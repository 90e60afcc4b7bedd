//! Learning-rate schedules.
//!
//! The position learning rate follows 3DGS / X-Gaussian / UniSpine-GS `get_expon_lr_func`
//! (`utils/general_utils.py`): a log-linear interpolation from `lr_init` to `lr_final` over
//! `max_steps`, optionally multiplied by a sine-shaped warm-up
//! `delay_mult + (1 - delay_mult) sin(pi/2 clip(t / delay_steps, 0, 1))` when `delay_steps > 0`.
//! Upstream passes `lr_delay_mult = 0.01` but leaves `lr_delay_steps = 0`, so the warm-up has no
//! effect; the same defaults are kept here. The scene extent scales `lr_init` and `lr_final`
//! (`spatial_lr_scale`), which the caller does.

/// `get_expon_lr_func` of 3DGS.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExponLr {
    pub lr_init: f64,
    pub lr_final: f64,
    pub delay_steps: usize,
    pub delay_mult: f64,
    pub max_steps: usize,
}

impl ExponLr {
    /// Learning rate at step `t` (3DGS evaluates it at the 1-based iteration number).
    pub fn at(&self, t: usize) -> f64 {
        if self.lr_init == 0.0 && self.lr_final == 0.0 {
            return 0.0;
        }
        let delay = if self.delay_steps > 0 {
            let r = (t as f64 / self.delay_steps as f64).clamp(0.0, 1.0);
            self.delay_mult + (1.0 - self.delay_mult) * (0.5 * std::f64::consts::PI * r).sin()
        } else {
            1.0
        };
        let s = (t as f64 / self.max_steps.max(1) as f64).clamp(0.0, 1.0);
        delay * (self.lr_init.ln() * (1.0 - s) + self.lr_final.ln() * s).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_linear_end_points_and_midpoint() {
        let e = 1285.36;
        let s = ExponLr {
            lr_init: 1.9e-4 * e,
            lr_final: 1.9e-6 * e,
            delay_steps: 0,
            delay_mult: 0.01,
            max_steps: 20_000,
        };
        assert!((s.at(0) - 1.9e-4 * e).abs() < 1e-15);
        assert!((s.at(20_000) - 1.9e-6 * e).abs() < 1e-15);
        assert!((s.at(40_000) - 1.9e-6 * e).abs() < 1e-15);
        // Geometric mean at half-way.
        assert!((s.at(10_000) - 1.9e-5 * e).abs() < 1e-12);
        // Monotone decreasing.
        assert!(s.at(100) > s.at(101));
    }

    #[test]
    fn delay_follows_the_sine_warm_up() {
        let s = ExponLr {
            lr_init: 1.0,
            lr_final: 1.0,
            delay_steps: 100,
            delay_mult: 0.01,
            max_steps: 1000,
        };
        assert!((s.at(0) - 0.01).abs() < 1e-15);
        let want = 0.01 + 0.99 * (0.25 * std::f64::consts::PI).sin();
        assert!((s.at(50) - want).abs() < 1e-15);
        assert!((s.at(100) - 1.0).abs() < 1e-15);
    }
}
