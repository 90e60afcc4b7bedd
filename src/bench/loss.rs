//! The loss stage (`unispine bench loss`): the hybrid loss of Eq. (8) with the SPWM-weighted
//! Charbonnier of Eq. (9), and SSIM's forward + backward alone, its fused kernels
//! ([`crate::loss::ssim`]) against its definition ([`crate::loss::ssim::reference`], five
//! whole-image blurs), in f32 on one square image pair, the two taking turns so that a drift of
//! the machine's speed affects both alike. Every round checks that both give the same bits.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{median, timed};
use crate::error::{Error, Result};
use crate::image2d::Image2d;
use crate::loss::{self, ssim, LossConfig};

/// Allowed square image sides and repetitions.
pub const LOSS_SIZES: (usize, usize) = (8, 4096);
pub const LOSS_REPS: (usize, usize) = (1, 1000);

/// Median wall and CPU milliseconds per call of one loss case.
#[derive(Clone, Copy, Debug, Default)]
pub struct LossTiming {
    pub size: usize,
    pub reps: usize,
    /// SSIM forward + backward, fused kernels: (wall, process CPU) ms.
    pub ssim_fused: (f64, f64),
    /// SSIM forward + backward as its definition (five whole-image blurs): (wall, CPU) ms.
    pub ssim_reference: (f64, f64),
    /// The whole loss of Eq. (8) with the weighted Charbonnier (`loss::forward_backward`).
    pub loss: (f64, f64),
}

/// `f`'s value and its (wall, process CPU) milliseconds.
fn timed_ms<T>(f: impl FnOnce() -> T) -> (T, (f64, f64)) {
    let (v, wall, cpu) = timed(f);
    (v, (wall * 1e3, cpu * 1e3))
}

/// Check a case of the loss benchmark; the error names the flag, the value and the allowed
/// range.
pub fn check_loss_case(size: usize, reps: usize) -> Result<()> {
    for (flag, v, (lo, hi)) in [("--sizes", size, LOSS_SIZES), ("--reps", reps, LOSS_REPS)] {
        if !(lo..=hi).contains(&v) {
            return Err(Error::invalid(
                flag,
                format!("{v} is outside the allowed range [{lo}, {hi}]"),
            ));
        }
    }
    Ok(())
}

/// Time the loss at `size`^2 over `reps` rounds; an error if the case is out of range or the
/// fused kernels and the definition disagree in any bit.
pub fn time_loss(size: usize, reps: usize) -> Result<LossTiming> {
    check_loss_case(size, reps)?;
    let mut rng = ChaCha8Rng::seed_from_u64(size as u64);
    let n = size * size;
    let gt: Vec<f32> = (0..n).map(|_| rng.random::<f32>()).collect();
    let render: Vec<f32> = gt.iter().map(|g| g + 0.1 * rng.random::<f32>()).collect();
    let weights: Vec<f32> = (0..n).map(|_| 1.0 + 0.8 * rng.random::<f32>()).collect();
    let img = |v: Vec<f32>| Image2d::from_vec(size, size, v);
    let (gt, render, weights) = (img(gt), img(render), img(weights));
    let cfg = LossConfig::weighted_charbonnier_dssim();
    let (mut fused, mut refer, mut whole) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..reps {
        let (a, ta) = timed_ms(|| ssim::ssim_forward_backward(&render, &gt));
        let (b, tb) = timed_ms(|| ssim::reference::ssim_forward_backward(&render, &gt));
        let same = a.0.to_bits() == b.0.to_bits()
            && a.1
                .data
                .iter()
                .zip(&b.1.data)
                .all(|(p, q)| p.to_bits() == q.to_bits());
        if !same {
            return Err(Error::invalid(
                "ssim",
                format!("the fused kernels and the definition disagree at {size}^2"),
            ));
        }
        let (_, tl) = timed_ms(|| loss::forward_backward(&render, &gt, Some(&weights), &cfg));
        fused.push(ta);
        refer.push(tb);
        whole.push(tl);
    }
    let med = |v: &[(f64, f64)]| {
        (
            median(v.iter().map(|t| t.0).collect()),
            median(v.iter().map(|t| t.1).collect()),
        )
    };
    Ok(LossTiming {
        size,
        reps,
        ssim_fused: med(&fused),
        ssim_reference: med(&refer),
        loss: med(&whole),
    })
}
