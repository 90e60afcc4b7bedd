//! Noise models of generated projections (off by default; seeded, deterministic).
//!
//! `poisson:I0[,SIGMA]` is TIGRE's `CTnoise.add` model, as NAF uses it: with `pmax` the largest
//! noiseless line integral of the dataset, counts `N ~ Poisson(I0 exp(-p / pmax))` (+ Gaussian
//! electronic noise of SIGMA counts), then `p' = -ln(max(N, 1e-6) / I0) * pmax`. Poisson
//! variates are exact (Knuth) below a mean of 30 and the normal approximation
//! `round(lambda + sqrt(lambda) z)` above (hence "Poisson-like"). `gaussian:S` adds
//! N(0, (S * pmax)^2) to every pixel (S relative to the largest projection).
//!
//! One ChaCha8 stream seeded from the dataset seed (mixed with a constant for this purpose),
//! views and pixels in order: the same seed gives the same bits.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};
use crate::image2d::Image2d;

/// Noise model applied to the generated projections.
#[derive(Clone, Copy, Debug, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind")]
pub enum Noise {
    /// Noiseless line integrals.
    #[default]
    None,
    /// TIGRE `CTnoise`-style transmission noise: I0 photons, plus Gaussian electronic noise of
    /// `sigma` counts (NAF: I0 = 1e5, sigma = 10).
    Poisson { i0: f64, sigma: f64 },
    /// Additive Gaussian noise with standard deviation `rel` times the largest projection.
    Gaussian { rel: f64 },
}

impl Noise {
    /// Parse `none`, `poisson:I0`, `poisson:I0,SIGMA` or `gaussian:S`.
    pub fn parse(s: &str) -> Result<Noise> {
        let bad = |msg: &str| {
            Error::invalid(
                "noise",
                format!("`{s}`: {msg} (expected none, poisson:I0[,SIGMA] or gaussian:S)"),
            )
        };
        let num = |t: &str| -> Result<f64> {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| bad(&format!("`{t}` is not a finite non-negative number")))
        };
        let s_trim = s.trim();
        if s_trim == "none" {
            return Ok(Noise::None);
        }
        let (kind, args) = s_trim.split_once(':').ok_or_else(|| bad("no `:`"))?;
        match kind {
            "poisson" => {
                let mut it = args.split(',');
                let i0 = num(it.next().unwrap_or(""))?;
                let sigma = match it.next() {
                    Some(t) => num(t)?,
                    None => 0.0,
                };
                if it.next().is_some() {
                    return Err(bad("too many values"));
                }
                if i0 <= 0.0 {
                    return Err(bad("I0 must be > 0"));
                }
                Ok(Noise::Poisson { i0, sigma })
            }
            "gaussian" => Ok(Noise::Gaussian { rel: num(args)? }),
            _ => Err(bad("unknown noise model")),
        }
    }

    /// Human-readable description (for the manifest).
    pub fn describe(&self) -> String {
        match self {
            Noise::None => "none".into(),
            Noise::Poisson { i0, sigma } => format!(
                "TIGRE CTnoise-style: N ~ Poisson({i0} exp(-p / pmax)) + N(0, {sigma}^2) counts, \
                 p' = -ln(max(N, 1e-6) / {i0}) pmax, pmax = largest noiseless projection value"
            ),
            Noise::Gaussian { rel } => {
                format!("additive Gaussian, sigma = {rel} x largest noiseless projection value")
            }
        }
    }
}

/// A standard normal variate (Box-Muller, one of the pair).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// A Poisson variate: exact (Knuth) for small means, normal approximation above 30.
fn poisson(rng: &mut ChaCha8Rng, lambda: f64) -> f64 {
    if lambda <= 0.0 {
        return 0.0;
    }
    if lambda < 30.0 {
        let l = (-lambda).exp();
        let mut k = 0.0;
        let mut p = 1.0;
        loop {
            p *= rng.random::<f64>();
            if p <= l {
                return k;
            }
            k += 1.0;
        }
    }
    (lambda + lambda.sqrt() * normal(rng)).round().max(0.0)
}

/// Apply `noise` to every view, in order, from one seeded stream (deterministic).
pub fn add_noise(views: &mut [Image2d<f32>], noise: &Noise, seed: u64) {
    if *noise == Noise::None {
        return;
    }
    // Purpose-specific stream: the seed mixed with a constant naming "noise".
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6e6f_6973_6500_0001);
    let pmax = views
        .iter()
        .flat_map(|v| v.data.iter())
        .fold(0.0f64, |m, &x| m.max(x as f64));
    if pmax <= 0.0 {
        return;
    }
    for v in views.iter_mut() {
        for x in v.data.iter_mut() {
            let p = *x as f64;
            let y = match *noise {
                Noise::None => p,
                Noise::Poisson { i0, sigma } => {
                    let mut n = poisson(&mut rng, i0 * (-p / pmax).exp());
                    if sigma > 0.0 {
                        n += sigma * normal(&mut rng);
                    }
                    -(n.max(1e-6) / i0).ln() * pmax
                }
                Noise::Gaussian { rel } => p + rel * pmax * normal(&mut rng),
            };
            *x = y as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_parses_and_is_seeded() {
        assert_eq!(Noise::parse("none").unwrap(), Noise::None);
        assert_eq!(
            Noise::parse("poisson:1e5,10").unwrap(),
            Noise::Poisson {
                i0: 1e5,
                sigma: 10.0
            }
        );
        assert_eq!(
            Noise::parse("gaussian:0.01").unwrap(),
            Noise::Gaussian { rel: 0.01 }
        );
        for bad in [
            "poisson",
            "poisson:-1",
            "poisson:0",
            "gauss:1",
            "gaussian:x",
            "poisson:1,2,3",
        ] {
            let e = Noise::parse(bad).unwrap_err().to_string();
            assert!(e.contains("noise") && e.contains(bad), "{e}");
        }
        let img = || {
            vec![Image2d::from_vec(
                64,
                64,
                (0..4096).map(|i| (i % 97) as f32 * 0.05).collect(),
            )]
        };
        for noise in [
            Noise::Poisson {
                i0: 1e4,
                sigma: 0.0,
            },
            Noise::Gaussian { rel: 0.02 },
        ] {
            let (mut a, mut b, mut c) = (img(), img(), img());
            add_noise(&mut a, &noise, 3);
            add_noise(&mut b, &noise, 3);
            add_noise(&mut c, &noise, 4);
            assert_eq!(a, b);
            assert_ne!(a, c);
            // Zero-mean-ish perturbation of the right size: with pmax = 4.8, Gaussian sigma
            // is 0.096; Poisson with I0 = 1e4 gives sigma(p') = pmax / sqrt(I0 e^{-p/pmax}),
            // between 0.048 and 0.13.
            let clean = img();
            let d: Vec<f64> = a[0]
                .data
                .iter()
                .zip(&clean[0].data)
                .map(|(x, y)| (x - y) as f64)
                .collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            let sd =
                (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / d.len() as f64).sqrt();
            assert!(mean.abs() < 0.01, "{noise:?}: mean {mean}");
            assert!(sd > 0.04 && sd < 0.14, "{noise:?}: sd {sd}");
        }
    }

    #[test]
    fn poisson_sampler_has_the_right_moments() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for lambda in [0.5, 5.0, 29.0, 100.0, 1e5] {
            let n = 20000;
            let xs: Vec<f64> = (0..n).map(|_| poisson(&mut rng, lambda)).collect();
            let m = xs.iter().sum::<f64>() / n as f64;
            let var = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1) as f64;
            // Standard error of the mean sqrt(lambda / n); of the variance ~ lambda sqrt(2/n).
            assert!(
                (m - lambda).abs() < 5.0 * (lambda / n as f64).sqrt(),
                "{lambda}: {m}"
            );
            assert!((var / lambda - 1.0).abs() < 0.06, "{lambda}: {var}");
        }
    }
}
