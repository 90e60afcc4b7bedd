//! `floor` and `ceil` of an f64 without a library call.
//!
//! The crate is compiled for baseline x86-64, which has no rounding instruction (SSE4.1's
//! `roundsd`), so `f64::floor` and `f64::ceil` are calls into the C library. The projection, the
//! tile binning and the entry packing round a few values per splat; these versions give the
//! same value and the same sign of zero as the library for every input (tested against it), in
//! a handful of inline instructions.

/// 2^52: every f64 of at least this magnitude is an integer.
const TWO_52: f64 = 4_503_599_627_370_496.0;

/// `x.floor()`, bit for bit (NaN and infinities pass through).
#[inline(always)]
pub fn floor(x: f64) -> f64 {
    // False for NaN and infinities, which are their own floor, like every |x| >= 2^52.
    if x.abs() < TWO_52 {
        // Truncation toward zero, exact in this range.
        let t = x as i64 as f64;
        let r = if t > x { t - 1.0 } else { t };
        // floor(x) has the sign of x, zero included (floor(-0.0) = -0.0).
        r.copysign(x)
    } else {
        x
    }
}

/// `x.ceil()`, bit for bit (NaN and infinities pass through).
#[inline(always)]
pub fn ceil(x: f64) -> f64 {
    if x.abs() < TWO_52 {
        let t = x as i64 as f64;
        let r = if t < x { t + 1.0 } else { t };
        // ceil(x) has the sign of x, zero included (ceil(-0.5) = -0.0).
        r.copysign(x)
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn same(x: f64) {
        assert_eq!(floor(x).to_bits(), x.floor().to_bits(), "floor({x:e})");
        assert_eq!(ceil(x).to_bits(), x.ceil().to_bits(), "ceil({x:e})");
    }

    #[test]
    fn edge_values_match_the_library() {
        let two52 = TWO_52;
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            1e-310,
            -1e-310,
            1.0 - f64::EPSILON / 2.0,
            -(1.0 - f64::EPSILON / 2.0),
            two52 - 0.5,
            -(two52 - 0.5),
            two52,
            -two52,
            two52 + 1.0,
            2.0 * two52 + 2.0,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
        ] {
            same(x);
            same(x.next_up());
            same(x.next_down());
        }
    }

    #[test]
    fn random_values_match_the_library() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200_000 {
            // Uniform over a wide range of magnitudes and both signs.
            let m: f64 = rng.random_range(-1.0..1.0);
            let e: i32 = rng.random_range(-40..60);
            same(m * 2f64.powi(e));
            // Arbitrary bit patterns (NaNs, subnormals, huge values included).
            same(f64::from_bits(rng.random()));
        }
        // Every quarter step around the integers the renderer rounds most.
        for k in -4096..4096 {
            same(k as f64 * 0.25);
        }
    }
}
