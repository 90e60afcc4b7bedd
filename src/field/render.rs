//! Rays, stratified sampling and the line-integral renderer of NAF / SAX-NeRF
//! (`src/dataset/tigre.py` `get_rays`, `get_near_far`; `src/render/render.py`), in metres:
//! - ray of pixel (row, col): origin the source, direction `R (u / DSD, v / DSD, 1)` (not
//!   normalised; our camera axes, see [`crate::geometry`]), `u, v` the pixel-centre detector
//!   coordinates including `offDetector`;
//! - `near, far` the same for every ray: `DSO -/+ (largest xy distance of a volume corner from
//!   the axis) -/+ 5 mm`, clipped to `[0, 2 DSO]`, as `t` values along that direction;
//! - `t_i = linspace(near, far, n)`, each jittered uniformly inside its bin
//!   (`lower + (upper - lower) U`, bins bounded by the midpoints), also at evaluation;
//! - points clamped to `+-(bound - 1e-6)`;
//! - `acc = sum_i mu_i delta_i` with `delta_i = (t_{i+1} - t_i) |d|` and the last
//!   `delta = 1e-10 |d|` (a left Riemann sum; no transmittance). `d acc / d mu_i = delta_i`.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::geometry::{Camera, ConeBeam};
use crate::real::Real;

/// Millimetres per metre.
pub const MM: f64 = 1000.0;

/// A ray in metres (unnormalised direction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub o: [f64; 3],
    pub d: [f64; 3],
}

/// The ray of pixel (`col`, `row`) of `cam`, in metres.
pub fn pixel_ray(cam: &Camera, col: usize, row: usize) -> Ray {
    let x = (col as f64 + 0.5 - cam.cx) / cam.fx;
    let y = (row as f64 + 0.5 - cam.cy) / cam.fy;
    let d = cam.cam_dir_to_world([x, y, 1.0]);
    Ray {
        o: [cam.centre[0] / MM, cam.centre[1] / MM, cam.centre[2] / MM],
        d,
    }
}

/// NAF's constant `near, far` (metres) for `geo`.
pub fn near_far(geo: &ConeBeam) -> (f64, f64) {
    let s = geo.volume_size();
    let o = geo.off_origin;
    let mut dmax = 0.0f64;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            let (x, y) = (o[0] + sx * s[0] / 2.0, o[1] + sy * s[1] / 2.0);
            dmax = dmax.max((x * x + y * y).sqrt());
        }
    }
    let tol = 5.0;
    let near = (geo.dso - dmax - tol).max(0.0);
    let far = (geo.dso + dmax + tol).min(2.0 * geo.dso);
    (near / MM, far / MM)
}

/// Stratified sample depths of one ray (`n >= 1`), jittered with `rng`.
pub fn stratified(near: f64, far: f64, n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut t = Vec::with_capacity(n);
    stratified_into(near, far, n, rng, &mut t);
    t
}

/// [`stratified`] into `t` (resized to `n`; no allocation once it has grown).
pub fn stratified_into(near: f64, far: f64, n: usize, rng: &mut ChaCha8Rng, t: &mut Vec<f64>) {
    let z = |i: usize| {
        if n == 1 {
            near
        } else {
            near + (far - near) * i as f64 / (n - 1) as f64
        }
    };
    t.clear();
    t.extend((0..n).map(|i| {
        let lo = if i == 0 {
            z(0)
        } else {
            0.5 * (z(i - 1) + z(i))
        };
        let hi = if i + 1 == n {
            z(n - 1)
        } else {
            0.5 * (z(i) + z(i + 1))
        };
        lo + (hi - lo) * rng.random::<f64>()
    }));
}

/// The seeded generator of one ray's jitter (one stream per purpose, iteration and ray).
pub fn ray_rng(seed: u64, purpose: u64, a: u64, b: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed ^ purpose.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    r.set_stream(a.wrapping_mul(1 << 32) ^ b);
    r
}

/// Sample points (clamped to `+-(bound - 1e-6)`) and their `delta` weights of a ray, appended.
pub fn samples<R: Real>(
    ray: &Ray,
    t: &[f64],
    bound: f64,
    pts: &mut Vec<[R; 3]>,
    delta: &mut Vec<R>,
) {
    let (p0, d0) = (pts.len(), delta.len());
    pts.resize(p0 + t.len(), [R::zero(); 3]);
    delta.resize(d0 + t.len(), R::zero());
    samples_into(ray, t, bound, &mut pts[p0..], &mut delta[d0..]);
}

/// [`samples`] into slices of `t.len()` values.
pub fn samples_into<R: Real>(
    ray: &Ray,
    t: &[f64],
    bound: f64,
    pts: &mut [[R; 3]],
    delta: &mut [R],
) {
    let norm = (ray.d[0] * ray.d[0] + ray.d[1] * ray.d[1] + ray.d[2] * ray.d[2]).sqrt();
    let b = bound - 1e-6;
    for (i, &ti) in t.iter().enumerate() {
        let p = [
            (ray.o[0] + ray.d[0] * ti).clamp(-b, b),
            (ray.o[1] + ray.d[1] * ti).clamp(-b, b),
            (ray.o[2] + ray.d[2] * ti).clamp(-b, b),
        ];
        pts[i] = [R::c(p[0]), R::c(p[1]), R::c(p[2])];
        let dt = if i + 1 < t.len() {
            t[i + 1] - ti
        } else {
            1e-10
        };
        delta[i] = R::c(dt * norm);
    }
}

/// `acc = sum_i mu_i delta_i`, in order.
#[inline]
pub fn line_integral<R: Real>(mu: &[R], delta: &[R]) -> R {
    let mut acc = R::zero();
    for (m, d) in mu.iter().zip(delta) {
        acc += *m * *d;
    }
    acc
}

/// Backward of [`line_integral`]: `g_mu[i] = g_acc delta_i`.
#[inline]
pub fn line_integral_vjp<R: Real>(g_acc: R, delta: &[R], g_mu: &mut [R]) {
    for (g, d) in g_mu.iter_mut().zip(delta) {
        *g = g_acc * *d;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every (seed, purpose, a, b) has a stream of its own (b < 2^32, as a ray index is): the
    /// first draws of a grid of them are all distinct.
    #[test]
    fn ray_streams_differ_for_every_seed_purpose_and_pair() {
        let mut seen = std::collections::HashSet::new();
        for seed in 0..6u64 {
            for purpose in 0..4u64 {
                for a in [0u64, 1, 2, 7, 1 << 20] {
                    for b in [0u64, 1, 2, 3, 1 << 31] {
                        let mut r = ray_rng(seed, purpose, a, b);
                        let first = (r.random::<u64>(), r.random::<u64>());
                        assert!(
                            seen.insert(first),
                            "{seed} {purpose} {a} {b} repeats a stream"
                        );
                    }
                }
            }
        }
    }

    /// NAF's constant near / far hold every point of an off-centre volume at every angle: the
    /// distance from the source (at DSO (cos a, sin a, 0)) to each corner of the box lies in
    /// [near, far], and the farthest and nearest corners come within the 5 mm margin of them.
    #[test]
    fn near_far_hold_every_corner_of_an_off_centre_volume_at_every_angle() {
        for off in [[-30.0, -20.0, 4.0], [25.0, 35.0, -3.0]] {
            let geo = ConeBeam {
                off_origin: off,
                ..ConeBeam::centred([4, 4], [1.0, 1.0], [40, 20, 10], [1.0, 2.0, 3.0])
            };
            let (near, far) = near_far(&geo);
            let (near, far) = (near * MM, far * MM);
            let s = geo.volume_size();
            let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
            for step in 0..3600 {
                let a = step as f64 * std::f64::consts::TAU / 3600.0;
                let src = [geo.dso * a.cos(), geo.dso * a.sin(), 0.0];
                for corner in 0..8 {
                    let p: [f64; 3] = std::array::from_fn(|k| {
                        let sign = if corner >> k & 1 == 1 { 0.5 } else { -0.5 };
                        off[k] + sign * s[k]
                    });
                    // The in-plane distance: NAF's bound ignores z (rays leave the plane by
                    // the cone angle only).
                    let d = ((p[0] - src[0]).powi(2) + (p[1] - src[1]).powi(2)).sqrt();
                    lo = lo.min(d);
                    hi = hi.max(d);
                }
            }
            assert!(
                near <= lo && hi <= far,
                "{off:?}: [{lo}, {hi}] outside [{near}, {far}]"
            );
            assert!(
                lo - near <= 5.0 + 1e-3,
                "{off:?}: near {near} vs nearest {lo}"
            );
            assert!(
                far - hi <= 5.0 + 1e-3,
                "{off:?}: far {far} vs farthest {hi}"
            );
        }
    }

    /// Each pixel's ray, followed for DSD, reaches that pixel's centre on the detector, placed
    /// from the convention alone (NAF / X-Gaussian pose: source at DSO (cos a, sin a, 0),
    /// detector axes u = (-sin a, cos a, 0), v = (0, 0, -1), the detector DSD from the source
    /// along -(cos a, sin a, 0); pixel centre u = (col + 1/2 - W/2) du + offU, likewise v).
    #[test]
    fn a_pixel_ray_reaches_its_pixel_centre_on_the_detector() {
        let geo = ConeBeam {
            off_detector: [7.0, -4.5],
            ..ConeBeam::centred([6, 9], [0.8, 1.3], [4, 4, 4], [1.0; 3])
        };
        let (w, h) = (9usize, 6usize);
        for a in [0.0, 0.7, 2.9] {
            let cam = Camera::new(&geo, a);
            let (s, c) = f64::sin_cos(a);
            let src = [geo.dso * c, geo.dso * s, 0.0];
            let (eu, ev, ez) = ([-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]);
            for (col, row) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1), (4, 2)] {
                let u = (col as f64 + 0.5 - w as f64 / 2.0) * 1.3 + 7.0;
                let v = (row as f64 + 0.5 - h as f64 / 2.0) * 0.8 - 4.5;
                let r = pixel_ray(&cam, col, row);
                for k in 0..3 {
                    let p = (src[k] + geo.dsd * ez[k] + u * eu[k] + v * ev[k]) / MM;
                    assert!((r.o[k] - src[k] / MM).abs() < 1e-12);
                    let hit = r.o[k] + r.d[k] * geo.dsd / MM;
                    assert!(
                        (hit - p).abs() < 1e-12,
                        "angle {a} pixel ({col}, {row}) axis {k}"
                    );
                }
            }
        }
    }
}
