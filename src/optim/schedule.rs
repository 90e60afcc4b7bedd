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

/// `torch.optim.lr_scheduler.StepLR`: `lr0 * gamma^floor(epoch / step_size)`, the scheduler
/// stepped once per epoch (SAX-NeRF / NAF `src/trainer.py`). Here in iterations: the learning
/// rate of (1-based) iteration `it` is `lr0 * gamma^floor((it - 1) / step)`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepLr {
    pub lr0: f64,
    /// Step in iterations (`lrate_step` epochs x iterations per epoch).
    pub step: usize,
    pub gamma: f64,
}

impl StepLr {
    /// Learning rate of iteration `it` (1-based).
    pub fn at(&self, it: usize) -> f64 {
        let k = it.saturating_sub(1) / self.step.max(1);
        self.lr0 * self.gamma.powi(k.min(i32::MAX as usize) as i32)
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

    #[test]
    fn step_lr_like_torch() {
        // 50 iterations per epoch, step 2 epochs: iterations 1..=100 at lr0, 101..=200 at 0.1 lr0.
        let s = StepLr {
            lr0: 1e-3,
            step: 100,
            gamma: 0.1,
        };
        assert_eq!(s.at(1), 1e-3);
        assert_eq!(s.at(100), 1e-3);
        assert!((s.at(101) - 1e-4).abs() < 1e-18);
        assert!((s.at(200) - 1e-4).abs() < 1e-18);
        assert!((s.at(201) - 1e-5).abs() < 1e-19);
    }
}
