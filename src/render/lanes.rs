//! Lane maths of the compositor's pixel loops (Eqs. 4-5): the f32 exponential, lane masks and
//! bit selects, the Gaussian exponent and the colour a blend adds. Every function is branch-free
//! for f32, so the loops over a tile row's pixels vectorise, and every pass (forward, backward,
//! the naive reference) calls the same functions, so their skip decisions agree bit for bit. The
//! instruction set the loops are compiled for is chosen at run time ([`crate::simd::Simd`]).
//!
//! The fused multiply-adds (`mul_add`, one rounding) shorten the dependency chain of a lane,
//! which bounds the kernels: with them (and Estrin's scheme in [`exp_f32`]) the forward and
//! backward tiles take about 20 % and 13 % less time than with separate multiplies and adds
//! (`docs/measurements.md`). Every path gives the same bits (see
//! [`crate::simd`]); on the baseline target they are C library calls and the loops do not
//! vectorise.

use crate::real::Real;

/// exp in the kernels: for f32 a branch-free polynomial ([`exp_f32`], vectorisable, within
/// 2 ulp of exp), for f64 the standard library's exp. Forward, backward and the naive reference
/// all call this, so their decisions agree bit for bit.
#[inline(always)]
pub fn exp_k<R: Real>(x: R) -> R {
    if std::any::TypeId::of::<R>() == std::any::TypeId::of::<f32>() {
        // Exact round trip f32 -> f64 -> f32.
        R::c(exp_f32(x.f64() as f32) as f64)
    } else {
        x.exp()
    }
}

/// exp(x) for f32 without branches (so that loops over pixels vectorise): x clamped to
/// [-87, 88], x = n ln2 + r with |r| <= ln2/2 (Cody-Waite, two-part ln2, fused multiply-adds),
/// exp(r) = 1 + r q(r) with q the degree-6 Taylor polynomial of (e^r - 1) / r (truncation
/// < 6e-9 relative) evaluated by Estrin's scheme (a dependency chain of 4 operations from r to
/// exp(r), against 14 for Horner's scheme with separate multiplies and adds), times 2^n built
/// from the exponent bits. Measured against f64 exp:
/// max relative error 9.1e-8 on [-87, 0] (`exp_f32_is_within_2e_7_of_exp`).
#[inline(always)]
pub fn exp_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    let x = if x < -87.0 { -87.0 } else { x };
    let x = if x > 88.0 { 88.0 } else { x };
    let t = x.mul_add(LOG2E, MAGIC);
    let n = t - MAGIC;
    // n as an integer: the low mantissa bits of t.
    let ni = t.to_bits().wrapping_sub(MAGIC.to_bits());
    let r = (-n).mul_add(LN2_HI, x);
    let r = (-n).mul_add(LN2_LO, r);
    let r2 = r * r;
    let r4 = r2 * r2;
    let q01 = r.mul_add(1.0 / 2.0, 1.0);
    let q23 = r.mul_add(1.0 / 24.0, 1.0 / 6.0);
    let q45 = r.mul_add(1.0 / 720.0, 1.0 / 120.0);
    let q = r4.mul_add(r2.mul_add(1.0 / 5040.0, q45), r2.mul_add(q23, q01));
    let p = r.mul_add(q, 1.0);
    let scale = f32::from_bits(ni.wrapping_add(127) << 23);
    p * scale
}

/// All-ones if `b`, else 0.
#[inline(always)]
pub fn mask(b: bool) -> u32 {
    0u32.wrapping_sub(b as u32)
}

/// `m ? a : b` for a mask from [`mask`]. For f32 a bit select (so that the pixel loops
/// vectorise without masked stores), for f64 a plain select; both exact.
#[inline(always)]
pub fn sel<R: Real>(m: u32, a: R, b: R) -> R {
    if std::any::TypeId::of::<R>() == std::any::TypeId::of::<f32>() {
        let (a, b) = (a.f64() as f32, b.f64() as f32);
        R::c(f32::from_bits((a.to_bits() & m) | (b.to_bits() & !m)) as f64)
    } else if m != 0 {
        a
    } else {
        b
    }
}

/// `c + col alpha t`, the colour one blend adds (Eq. 4), with one rounding (a fused multiply-add)
/// after `col alpha`; shared by every pass.
#[inline(always)]
pub fn add_blend<R: Real>(c: R, col: R, alpha: R, t: R) -> R {
    (col * alpha).mul_add(t, c)
}

/// power = -0.5 (A dx^2 + C dy^2) - B dx dy, the exponent of G, evaluated as
/// (-0.5 A dx - B dy) dx - 0.5 C dy^2 with two fused multiply-adds (one expression shared by all
/// passes so that their skip decisions agree bit for bit).
#[inline(always)]
pub fn power_of<R: Real>(a: R, b: R, c: R, dx: R, dy: R) -> R {
    let h = R::c(-0.5);
    let k1 = -(b * dy);
    let k0 = (h * c) * (dy * dy);
    (h * a).mul_add(dx, k1).mul_add(dx, k0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_f32_is_within_2e_7_of_exp() {
        let mut worst: f64 = 0.0;
        let n = 200_000;
        for k in 0..=n {
            let x = -87.0 + 87.0 * k as f64 / n as f64;
            let xf = x as f32;
            let got = exp_f32(xf) as f64;
            let want = (xf as f64).exp();
            worst = worst.max((got - want).abs() / want);
        }
        println!("exp_f32 max relative error on [-87, 0]: {worst:.2e}");
        assert!(worst < 2e-7, "{worst:e}");
        assert_eq!(exp_f32(0.0), 1.0);
        assert_eq!(exp_k(0.5f64), 0.5f64.exp());
    }
}
