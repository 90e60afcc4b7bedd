//! Adam over one flat parameter vector, as `torch.optim.Adam` (single-tensor, non-capturable,
//! no weight decay): with step count t after the increment,
//! `m <- b1 m + (1 - b1) g`, `v <- b2 v + (1 - b2) g^2`,
//! `p <- p - (lr / (1 - b1^t)) m / (sqrt(v) / sqrt(1 - b2^t) + eps)`.
//! Bias corrections in f64, rounded once per step. ([`crate::optim::Adam`] is laid out over
//! the Gaussians' parameter groups, so it cannot serve a flat vector.)
//! Parallel over fixed chunks; each element's update is independent, so the result is
//! bit-identical for any thread count.

use rayon::prelude::*;

use crate::par::CHUNK;
use crate::real::Real;

/// Adam state.
#[derive(Clone, Debug, PartialEq)]
pub struct FlatAdam<R: Real> {
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    pub m: Vec<R>,
    pub v: Vec<R>,
    pub step: u64,
}

impl<R: Real> FlatAdam<R> {
    /// PyTorch defaults: betas (0.9, 0.999), eps 1e-8.
    pub fn new(n: usize) -> Self {
        FlatAdam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            m: vec![R::zero(); n],
            v: vec![R::zero(); n],
            step: 0,
        }
    }

    /// One step with learning rate `lr`.
    pub fn update(&mut self, p: &mut [R], g: &[R], lr: f64) {
        self.step += 1;
        let t = self.step as i32;
        let bc1 = 1.0 - self.beta1.powi(t);
        let bc2 = 1.0 - self.beta2.powi(t);
        let (b1, b2) = (R::c(self.beta1), R::c(self.beta2));
        let (omb1, omb2) = (R::c(1.0 - self.beta1), R::c(1.0 - self.beta2));
        let step_size = R::c(lr / bc1);
        let bc2s = R::c(bc2.sqrt());
        let eps = R::c(self.eps);
        p.par_chunks_mut(CHUNK)
            .zip(g.par_chunks(CHUNK))
            .zip(self.m.par_chunks_mut(CHUNK))
            .zip(self.v.par_chunks_mut(CHUNK))
            .for_each(|(((p, g), m), v)| {
                for i in 0..p.len() {
                    m[i] = b1 * m[i] + omb1 * g[i];
                    v[i] = b2 * v[i] + omb2 * g[i] * g[i];
                    p[i] -= step_size * m[i] / (v[i].sqrt() / bc2s + eps);
                }
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_steps_by_hand() {
        // p = 1, g = 0.5 then g = -1, lr 0.1.
        let mut a = FlatAdam::<f64>::new(1);
        let mut p = vec![1.0];
        a.update(&mut p, &[0.5], 0.1);
        // t = 1: m = 0.05, v = 0.00025; m / bc1 = 0.5, sqrt(v / bc2) = 0.5 -> step 0.1 * 1.
        assert!((p[0] - (1.0 - 0.1 * 0.5 / (0.5 + 1e-8))).abs() < 1e-15);
        a.update(&mut p, &[-1.0], 0.1);
        let m: f64 = 0.9 * 0.05 - 0.1;
        let v: f64 = 0.999 * 0.00025 + 0.001;
        let want = 1.0
            - 0.1 * 0.5 / (0.5 + 1e-8)
            - (0.1 / (1.0 - 0.81)) * m / (v.sqrt() / (1.0 - 0.999f64.powi(2)).sqrt() + 1e-8);
        assert!((p[0] - want).abs() < 1e-14, "{} {want}", p[0]);
    }
}
