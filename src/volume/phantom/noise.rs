//! Counter-based noise: every value is a pure function of (seed, purpose, integer position), so
//! the fields built from it are identical for any thread count and any evaluation order.
//! Used by the cancellous-bone texture of the phantom and by the speckle of the ultrasound proxy.

/// SplitMix64 finaliser (Steele, Lea and Flood 2014): a bijective 64-bit mixer.
#[inline(always)]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// 64 random bits for `(key, counter)`; `key` folds the seed and the purpose together.
#[inline(always)]
pub(crate) fn hash2(key: u64, counter: u64) -> u64 {
    mix64(key ^ mix64(counter))
}

/// The key of one purpose under one seed.
pub(crate) fn key(seed: u64, purpose: u64) -> u64 {
    mix64(seed ^ mix64(purpose))
}

/// A uniform number in [0, 1) from the top 53 bits.
#[inline(always)]
pub(crate) fn unit(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Two independent standard normal numbers in f32 from one 64-bit hash (Box-Muller on two
/// 24-bit uniforms): cheaper, for speckle.
#[inline(always)]
pub(crate) fn normal_pair_f32(key: u64, counter: u64) -> (f32, f32) {
    let h = hash2(key, counter);
    let scale = 1.0 / (1u32 << 24) as f32;
    // u1 in (0, 1]: never ln(0).
    let u1 = ((h >> 40) as u32 + 1) as f32 * scale;
    let u2 = ((h >> 16) as u32 & 0xFF_FFFF) as f32 * scale;
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
    (r * c, r * s)
}

/// A value in [-1, 1) at an integer lattice point.
#[inline(always)]
fn lattice(key: u64, i: i64, j: i64, k: i64) -> f64 {
    // Pack three 21-bit signed coordinates into one counter.
    let p = ((i as u64) & 0x1F_FFFF)
        | (((j as u64) & 0x1F_FFFF) << 21)
        | (((k as u64) & 0x1F_FFFF) << 42);
    2.0 * unit(hash2(key, p)) - 1.0
}

/// Smooth value noise in [-1, 1]: lattice values at integer points of `p / cell`, interpolated
/// trilinearly with a smoothstep weight. A pure function of the position.
pub(crate) fn value_noise(key: u64, p: [f64; 3], cell: f64) -> f64 {
    let q = [p[0] / cell, p[1] / cell, p[2] / cell];
    let f = [q[0].floor(), q[1].floor(), q[2].floor()];
    let i0 = [f[0] as i64, f[1] as i64, f[2] as i64];
    let mut w = [0.0; 3];
    for a in 0..3 {
        let t = q[a] - f[a];
        w[a] = t * t * (3.0 - 2.0 * t);
    }
    let mut acc = 0.0;
    for dk in 0..2i64 {
        let wk = if dk == 0 { 1.0 - w[2] } else { w[2] };
        for dj in 0..2i64 {
            let wj = if dj == 0 { 1.0 - w[1] } else { w[1] };
            for di in 0..2i64 {
                let wi = if di == 0 { 1.0 - w[0] } else { w[0] };
                acc += wi * wj * wk * lattice(key, i0[0] + di, i0[1] + dj, i0[2] + dk);
            }
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_have_unit_moments_and_noise_is_bounded() {
        let k = key(7, 1);
        let n = 200_000u64;
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for c in 0..n {
            let (a, b) = normal_pair_f32(k, c);
            s1 += (a + b) as f64;
            s2 += (a * a + b * b) as f64;
        }
        let m = s1 / (2 * n) as f64;
        let v = s2 / (2 * n) as f64 - m * m;
        assert!(m.abs() < 0.01, "f32 mean {m}");
        assert!((v - 1.0).abs() < 0.01, "f32 variance {v}");
        for c in 0..10_000 {
            let p = [c as f64 * 0.37, c as f64 * -0.11, 3.0 + c as f64 * 0.05];
            let v = value_noise(k, p, 1.5);
            assert!((-1.0..=1.0).contains(&v));
        }
        // Continuity: a tiny step changes the value only a little.
        let a = value_noise(k, [1.2345, 2.0, 3.0], 1.5);
        let b = value_noise(k, [1.2346, 2.0, 3.0], 1.5);
        assert!((a - b).abs() < 1e-3);
        assert_ne!(key(7, 1), key(8, 1));
    }
}
