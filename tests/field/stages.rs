//! The field trainer's stage timers: every stage of a batch is timed (each sum grows, none goes
//! negative), and timing changes no bit of the loss or the gradient.

use std::sync::Mutex;
use unispine::field::render::{self, Ray};
use unispine::field::train::{Sampling, StageTimes, Workspace};
use unispine::field::{EncoderConfig, Field};
use unispine::simd::Simd;

#[test]
fn every_stage_is_timed_and_timing_changes_no_bit() {
    let mut cfg = crate::small_cfg(EncoderConfig::HashGrid {
        levels: 3,
        features: 2,
        table_size: 64,
        base_resolution: 2,
    });
    cfg.n_samples = 16;
    let field = Field::<f32>::new(&cfg).unwrap();
    let rays: Vec<Ray> = (0..64)
        .map(|i| Ray {
            o: [1.0, 0.0, 0.0],
            d: [-1.0, 0.004 * i as f64 - 0.12, 0.1 - 0.003 * i as f64],
        })
        .collect();
    let targets: Vec<f32> = (0..64).map(|i| 0.01 * i as f32).collect();
    let jitter = |i: usize| render::ray_rng(1, 2, 3, i as u64);
    let sampling = Sampling::new((0.6, 1.4), cfg.n_samples, 0.3, &jitter);
    let simd = Simd::active();
    let mut plain = Workspace::default();
    let loss = plain.loss_and_grad(simd, &field, &rays, &targets, &sampling);
    let times = Mutex::new(StageTimes::default());
    let mut timed = Workspace::default();
    let mut seen = StageTimes::default();
    for call in 0..2 {
        let l = timed.run(simd, &field, &rays, &targets, &sampling, Some(&times));
        assert_eq!(l.to_bits(), loss.to_bits());
        assert!(timed.grad == plain.grad, "timing changed the gradient");
        let t = times.lock().unwrap().clone();
        let pairs = [
            ("sample", t.sample, seen.sample),
            ("encode", t.encode, seen.encode),
            ("mlp_forward", t.mlp_forward, seen.mlp_forward),
            ("render", t.render, seen.render),
            ("mlp_backward", t.mlp_backward, seen.mlp_backward),
            ("encode_backward", t.encode_backward, seen.encode_backward),
        ];
        for (name, now, before) in pairs {
            assert!(now > before, "call {call}: {name} {now} after {before}");
        }
        seen = t;
    }
}
