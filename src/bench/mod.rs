//! Benchmarks, one home for all of them: the scenes, the timers and the figures that
//! `unispine bench` prints (its ratios are formed from figures of the same run) and the
//! criterion benches in `benches/` use. The stages export kernels only; each file here times
//! one stage:
//!
//! - [`render`]: the rasterizer (forward, backward, phases) on CT-like scenes, with the scene
//!   and geometry every benchmark and the determinism tests share;
//! - [`train`]: where one training iteration's time goes, stage by stage;
//! - [`field`]: the neural-field baselines (peak f32 rate, the MLP's products, iterations);
//! - [`drr`]: the DRR projectors on every instruction set;
//! - [`loss`]: the loss stage (SSIM's fused kernels against its definition).
//!
//! [`render`]: crate::bench::render
//! [`train`]: crate::bench::train
//! [`field`]: crate::bench::field
//! [`drr`]: crate::bench::drr
//! [`loss`]: crate::bench::loss

pub mod drr;
pub mod field;
pub mod loss;
pub mod render;
pub mod train;

/// The median of `v` (the upper one of an even count); `v` must not be empty.
pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `f`'s value, and its wall and process CPU seconds (all threads).
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let c0 = crate::timer::cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID);
    let t0 = std::time::Instant::now();
    let v = f();
    let wall = t0.elapsed().as_secs_f64();
    let cpu = crate::timer::cpu_seconds(libc::CLOCK_PROCESS_CPUTIME_ID) - c0;
    (v, wall, cpu)
}
